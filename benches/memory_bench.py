"""Cost of ``irtps reconstruct``: peak memory against the decoded images, and IRT-PS's wall
time against classic photometric stereo's, side by side.

Runs the command with ``--method ps`` and ``--method irtps`` (defaults otherwise) in child
processes, alternately, on DiLiGenT reading (``../shared``; ball when reading is absent) or
on a data set given with ``--data``, and prints each one's median wall time and its peak
resident memory as a multiple of the decoded images (K x H x W x 3 float32). Targets: classic
PS at most 1.5x the decoded images, IRT-PS at most 2.5x (issue 16), and IRT-PS at most 3x
classic PS's wall time (issue 47).

    python benches/memory_bench.py [--data FOLDER] [--repeats 3] [--json cost.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from irtps import load_dataset

DILIGENT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "diligent"
METHODS = ("ps", "irtps")
#: Targets: peak resident memory over the decoded images, per method.
MEMORY_TARGETS = {"ps": 1.5, "irtps": 2.5}
#: Target: IRT-PS's wall time over classic photometric stereo's.
TIME_TARGET = 3.0


def default_data() -> Path:
    """DiLiGenT reading, else ball."""
    reading = DILIGENT / "readingPNG"
    return reading if reading.is_dir() else DILIGENT / "ballPNG"


def run_once(data: Path, method: str, out: Path) -> tuple[float, float]:
    """(wall seconds, peak resident MiB) of one ``irtps reconstruct`` in a child process."""
    command = [
        sys.executable,
        "-m",
        "irtps.cli",
        "reconstruct",
        str(data),
        "--out",
        str(out),
        "--method",
        method,
        "--quiet",
    ]
    start = time.perf_counter()
    child = subprocess.Popen(command, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    seconds = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed with exit code {child.returncode}")
    return seconds, usage.ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--data", type=Path, default=None, help="data set folder (default: DiLiGenT reading, else ball)"
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="runs of each method (default 3); the median time is quoted"
    )
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args()
    data = args.data or default_data()
    images = load_dataset(data, ground_truth=False).images
    decoded_mib = images.nbytes / 2**20
    shape = images.shape
    del images
    seconds: dict[str, list[float]] = {method: [] for method in METHODS}
    peak_mib: dict[str, float] = dict.fromkeys(METHODS, 0.0)
    with tempfile.TemporaryDirectory() as scratch:
        for repeat in range(args.repeats):
            for method in METHODS:
                wall, peak = run_once(data, method, Path(scratch) / f"{method}{repeat}")
                seconds[method].append(wall)
                peak_mib[method] = max(peak_mib[method], peak)
    median = {method: statistics.median(times) for method, times in seconds.items()}
    print(
        f"{data.name}: images {shape} float32 = {decoded_mib:.0f} MiB decoded; median of {args.repeats} runs of each method"
    )
    for method in METHODS:
        ratio = peak_mib[method] / decoded_mib
        print(
            f"  --method {method:<5}  {median[method]:6.1f} s   peak resident {peak_mib[method]:5.0f} MiB = {ratio:.2f}x the decoded images"
            f" (target <= {MEMORY_TARGETS[method]}x)"
        )
    print(f"  IRT-PS / classic PS wall time: {median['irtps'] / median['ps']:.1f}x (target <= {TIME_TARGET:.0f}x)")
    if args.json:
        figures = {
            "data": str(data),
            "decoded_mib": decoded_mib,
            "seconds": seconds,
            "median_s": median,
            "peak_mib": peak_mib,
        }
        args.json.write_text(json.dumps(figures, indent=2))


if __name__ == "__main__":
    main()
