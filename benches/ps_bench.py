"""Photometric stereo speed: irtps (Rust) against the obvious numpy implementation.

Both run in this process on the same DiLiGenT-size input (96 lights, 612x512 RGB float32) and
the medians of several runs are compared. Uses DiLiGenT ball when ``../shared`` is present,
else synthetic images of the same size.

    python benches/ps_bench.py [--repeats 5] [--json ps.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from irtps import _core

BALL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "diligent" / "ballPNG"


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


def load_input() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    if (BALL / "light_directions.txt").is_file():
        from irtps import load_dataset

        data = load_dataset(BALL)
        return data.images, data.mask, data.scene.light_directions, data.scene.light_irradiance, "DiLiGenT ball"
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(96, 3))
    directions[:, 2] = np.abs(directions[:, 2]) + 1.0
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    images = rng.random((96, 512, 612, 3), dtype=np.float32)
    return images, np.ones((512, 612), bool), directions, np.ones((96, 3)), "random 96x512x612"


def median_seconds(run, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args()
    images, mask, directions, irradiance, name = load_input()
    images = np.ascontiguousarray(images, dtype=np.float32)
    all_pixels = np.ones(mask.shape, bool)
    d32, e32 = directions.astype(np.float32), irradiance.astype(np.float32)
    figures = {
        "input": f"{name}: {images.shape[0]} lights, {images.shape[2]}x{images.shape[1]} RGB float32",
        "numpy_plain_s": median_seconds(lambda: numpy_ps(images, directions.astype(np.float32), e32), args.repeats),
        "irtps_plain_s": median_seconds(lambda: _core.photometric_stereo(images, all_pixels, d32, e32, "none"), args.repeats),
        "irtps_robust_s": median_seconds(lambda: _core.photometric_stereo(images, all_pixels, d32, e32, "tukey"), args.repeats),
    }
    figures["speedup_plain"] = figures["numpy_plain_s"] / figures["irtps_plain_s"]
    figures["speedup_robust_vs_numpy_plain"] = figures["numpy_plain_s"] / figures["irtps_robust_s"]
    print(figures["input"] + f" (all pixels, median of {args.repeats})")
    print(f"  numpy pinv(L) @ images   {figures['numpy_plain_s']:.3f} s")
    print(f"  irtps plain              {figures['irtps_plain_s']:.3f} s   {figures['speedup_plain']:.1f}x numpy")
    print(f"  irtps robust             {figures['irtps_robust_s']:.3f} s   {figures['speedup_robust_vs_numpy_plain']:.1f}x numpy plain")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))


if __name__ == "__main__":
    main()
