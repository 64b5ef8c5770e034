"""Peak memory of ``irtps reconstruct`` against the size of the decoded images.

Runs the command in a child process on DiLiGenT ball (``../shared``) or on a data set given
with ``--data``, and prints its peak resident memory as a multiple of the decoded images
(K x H x W x 3 float32). Target (issue 3): at most 3x.

    python benches/memory_bench.py [--data FOLDER]
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

from irtps import load_dataset

BALL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "diligent" / "ballPNG"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=BALL, help="data set folder (default: DiLiGenT ball)")
    args = parser.parse_args()
    images = load_dataset(args.data, ground_truth=False).images
    decoded_mib = images.nbytes / 2**20
    shape = images.shape
    del images
    with tempfile.TemporaryDirectory() as out:
        command = [sys.executable, "-m", "irtps.cli", "reconstruct", str(args.data), "--out", str(Path(out) / "r"), "--quiet"]
        subprocess.run(command, check=True)
    peak_mib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"{args.data.name}: images {shape} float32 = {decoded_mib:.0f} MiB decoded")
    print(f"  irtps reconstruct peak resident memory {peak_mib:.0f} MiB = {peak_mib / decoded_mib:.2f}x the decoded images (target <= 3x)")


if __name__ == "__main__":
    main()
