"""Photometric stereo speed: irtps (Rust) against the obvious numpy implementation.

Both run in this process on the same DiLiGenT-size input (96 lights, 612x512 RGB float32),
interleaved (each irtps run right after a numpy run of its own, the pairs in a random order
each repeat), so that a machine whose speed wanders, and what the runs before leave in the
caches, serve both alike: the figures are the median times and the median of the per-run
ratios,
over every pixel (plain least squares) and over the object's pixels, which is what ``irtps
reconstruct`` fits (numpy's plain least squares against each robust mode of irtps; against
``lobe_share``, the check by which ``irtps reconstruct --robust auto``, the default, chooses
between ``tukey`` and ``lobe``; and against ``photometric_stereo(..., robust="auto")``,
which fits the check's first pixels beside the Tukey fit and decides). Uses
DiLiGenT ball (and reading, when present) from ``../shared``, else synthetic images of the
same size with a disc for the object.

    python benches/ps_bench.py [--repeats 11] [--json ps.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np
from irtps import _core
from irtps.ps.fit import ROBUST_MODES, lobe_share, photometric_stereo

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "diligent"


def numpy_ps(images: np.ndarray, directions: np.ndarray, irradiance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The textbook implementation: ``pinv(L) @ images`` per channel, then normalise."""
    k, h, w, _ = images.shape
    b = images * (np.pi / irradiance)[:, None, None, :]
    g = (np.linalg.pinv(directions) @ b.reshape(k, -1)).reshape(3, h, w, 3)  # (xyz, H, W, rgb)
    g_sum = g.sum(axis=-1)
    norm = np.linalg.norm(g_sum, axis=0)
    normals = np.moveaxis(g_sum / np.maximum(norm, 1e-12), 0, -1)
    albedo = np.linalg.norm(g, axis=0)
    return normals, albedo


def load_inputs() -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]]:
    """(images, mask, directions, irradiance, name) of each input."""
    objects = [
        SHARED / name for name in ("ballPNG", "readingPNG") if (SHARED / name / "light_directions.txt").is_file()
    ]
    if objects:
        from irtps import load_dataset

        return [
            (data.images, data.mask, data.scene.light_directions, data.scene.light_irradiance, f"DiLiGenT {path.name}")
            for path in objects
            for data in [load_dataset(path)]
        ]
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(96, 3))
    directions[:, 2] = np.abs(directions[:, 2]) + 1.0
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    images = rng.random((96, 512, 612, 3), dtype=np.float32)
    rows, cols = np.indices((512, 612))
    disc = (rows - 256) ** 2 + (cols - 306) ** 2 < 150**2
    return [(images, disc, directions, np.ones((96, 3)), "random 96x512x612")]


#: Pause after each run: OpenBLAS's threads spin for a while after numpy's matrix product,
#: and would take the cores from the run that follows.
SETTLE_S = 0.2


def seconds(run) -> float:
    start = time.perf_counter()
    run()
    elapsed = time.perf_counter() - start
    time.sleep(SETTLE_S)
    return elapsed


def measure(images: np.ndarray, mask: np.ndarray, d32: np.ndarray, e32: np.ndarray, repeats: int) -> dict:
    """Median seconds of numpy's plain fit and of each irtps mode, every pixel and the
    object's, and the median of each one's per-repeat speed-up over numpy (``*_x``)."""
    all_pixels = np.ones(mask.shape, bool)
    baselines = {
        "numpy_plain_all": lambda: numpy_ps(images, d32, e32),
        "numpy_plain_object": lambda: numpy_ps(images[:, mask][:, :, None], d32, e32),
    }
    runs = {"irtps_plain_all": lambda: _core.photometric_stereo(images, all_pixels, d32, e32, "none")}
    for mode in ROBUST_MODES:
        runs[f"irtps_{mode}_object"] = lambda mode=mode: _core.photometric_stereo(images, mask, d32, e32, mode)
    runs["irtps_lobe_share_object"] = lambda: lobe_share(images, d32, e32, mask)
    runs["irtps_auto_object"] = lambda: photometric_stereo(images, d32, e32, mask, robust="auto")
    # Each irtps run right after a numpy run of its own, the pairs in a new random order each
    # repeat: a run finds in the caches what the runs before it left of the object's
    # observations (this machine's last level holds 260 MB), so no mode, nor its numpy run,
    # keeps one place in the sequence.
    times: dict[str, list[float]] = {name: [] for name in [*baselines, *runs]}
    ratios: dict[str, list[float]] = {name: [] for name in runs}
    order = np.random.default_rng(0)
    for _ in range(repeats):
        for name in order.permutation(list(runs)):
            run = runs[name]
            baseline = "numpy_plain_all" if name.endswith("_all") else "numpy_plain_object"
            numpy_s, irtps_s = seconds(baselines[baseline]), seconds(run)
            times[baseline].append(numpy_s)
            times[name].append(irtps_s)
            ratios[name].append(numpy_s / irtps_s)
    figures = {f"{name}_s": statistics.median(values) for name, values in times.items()}
    figures.update({f"{name}_x": statistics.median(values) for name, values in ratios.items()})
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=11)
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args()
    results = []
    for images, mask, directions, irradiance, name in load_inputs():
        figures = measure(
            np.ascontiguousarray(images, dtype=np.float32),
            mask,
            directions.astype(np.float32),
            irradiance.astype(np.float32),
            args.repeats,
        )
        figures["input"] = (
            f"{name}: {images.shape[0]} lights, {images.shape[2]}x{images.shape[1]} RGB float32, {int(mask.sum())} object pixels"
        )
        print(f"{figures['input']} (median of {args.repeats})")
        numpy_all, numpy_object = figures["numpy_plain_all_s"], figures["numpy_plain_object_s"]
        print(
            f"  every pixel:  numpy pinv(L) @ images {numpy_all:.3f} s   irtps none {figures['irtps_plain_all_s']:.3f} s   {figures['irtps_plain_all_x']:.1f}x numpy"
        )
        print(f"  object only:  numpy pinv(L) @ images {numpy_object:.3f} s")
        for mode in (*ROBUST_MODES, "lobe_share", "auto"):
            elapsed = figures[f"irtps_{mode}_object_s"]
            ratio = figures[f"irtps_{mode}_object_x"]
            speed = (
                f"{ratio:.1f}x numpy plain"
                if ratio >= 1
                else f"{ratio:.2f}x numpy plain ({1 / ratio:.1f} times slower)"
            )
            print(f"                irtps {mode:<10} {elapsed:.3f} s   {speed}")
        results.append(figures)
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
