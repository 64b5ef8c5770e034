"""Depth from normals on a real object with ground-truth depth: DiLiGenT reading (issue 46).

For each integration, from DiLiGenT's ground-truth normals and from the normals that
``irtps reconstruct`` fits (its default photometric stereo): the depth error by BiNI's
protocol (MADE: the estimate scaled by the median of ``depth_gt / estimate`` over the mask,
then the mean absolute difference in mm where the truth is known) and the median time of
``--runs`` calls after one warm-up call. Integrations:

- ``bilateral``: ``irtps.integrate_normals(normals, mask, intrinsics=K)``, the pinhole
  camera's discontinuity-preserving integration (log depth);
- ``ls``, ``mestimator``, ``footprint``: the orthographic methods, their heights turned into
  depths as an orthographic camera at the object's median true depth would see them (pixel
  size = that depth / fx), which is what a user without the pinhole gets.

Beside them, ``bini``: BiNI's iteration (k = 2, its defaults) as ``bini_iteration.py``
re-states it, on the same normals, once per tolerance of its conjugate-gradient solves
(``--bini-tolerances``, BiNI's 1e-3 first): the spread shows how much its figure depends on
where those inexact solves stop. Its time is that of a numpy re-statement, not BiNI's own
speed. BiNI's own figures (run on the 2-core development machine, numba) are in
../shared/data/diligent/README.md: 0.221 mm in 0.97 s from the true normals, 3.30 mm from
irtps's; BiNI is GPL and is not run here.

Then the same, ``bilateral`` and ``bini``, on the shared Mitsuba perspective scenes, from
their ground-truth normals and from those that IRT-PS fits (``--scenes``; MADE in scene
units, one run each).

Usage::

    python benches/depth_bench.py [--data ../shared/data/diligent/readingPNG] [--runs 5]
        [--bini-tolerances 1e-3,5e-4,2e-3] [--scenes SCENE ...] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
import warnings
from pathlib import Path

import numpy as np
import scipy.io

import irtps
from bini_iteration import bini_depth

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
SHARED = SHARED_DATA / "diligent" / "readingPNG"
SCENES = [SHARED_DATA / "mitsuba" / name for name in ("cap_persp_cornell", "grooves_persp_dark")]
METHODS = ("bilateral", "ls", "mestimator", "footprint")
#: The normal maps of each table: the data set's true ones and irtps's.
READING_LABELS = ("true_normals", "irtps_normals")
SCENE_LABELS = ("true_normals", "irtps_method_normals")


def made(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    """BiNI's mean absolute depth error after the median-ratio scale."""
    known = mask & np.isfinite(truth) & np.isfinite(estimate) & (estimate > 0)
    scale = np.median(truth[known] / estimate[known])
    return float(np.abs(scale * estimate[known] - truth[known]).mean())


def integrate(method: str, normals: np.ndarray, mask: np.ndarray, K: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Depth along the optical axis from `normals` by `method` (see the module)."""
    if method == "bilateral":
        return irtps.integrate_normals(normals, mask, intrinsics=K)
    distance = float(np.nanmedian(depth[mask]))
    height = irtps.integrate_normals(normals, mask, pixel_size=distance / K[0, 0], method=method)
    return np.where(mask, distance - height, np.nan)


def timed(method: str, normals, mask, K, depth, runs: int) -> tuple[float, np.ndarray]:
    """Median seconds of `runs` calls after one warm-up call, and the last result."""
    result = integrate(method, normals, mask, K, depth)
    seconds = []
    for _ in range(runs):
        start = time.perf_counter()
        result = integrate(method, normals, mask, K, depth)
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds), result


def tolerances(text: str) -> list[float]:
    """Comma-separated positive conjugate-gradient tolerances."""
    values = [float(part) for part in text.split(",") if part.strip()]
    if not values or not all(0.0 < value < 1.0 for value in values):
        raise argparse.ArgumentTypeError(f"expected tolerances in (0, 1), got {text!r}")
    return values


def one_run_row(method: str, depth_from, normal_maps: dict, mask: np.ndarray, depth: np.ndarray) -> dict:
    """MADE and seconds of one call of `depth_from` (normals → depth) on each of `normal_maps`
    (label → normals)."""
    row: dict = {"method": method}
    for label, normals in normal_maps.items():
        start = time.perf_counter()
        estimate = depth_from(normals)
        row[f"seconds_{label}"] = time.perf_counter() - start
        row[f"made_{label}"] = made(estimate, depth, mask)
    return row


def print_row(row: dict, labels: tuple[str, str], digits: int) -> None:
    """One table line: the method, then MADE and time per normal map."""
    cells = " ".join(f"{row[f'made_{label}']:>14.{digits}f} {row[f'seconds_{label}']:>7.3f}s" for label in labels)
    print(f"{row['method']:<16} {cells}")


def bini_depth_from(mask: np.ndarray, K: np.ndarray, cg_tol: float):
    """normals → depth by BiNI's iteration (re-stated) at one conjugate-gradient tolerance."""
    return lambda normals: bini_depth(normals, mask, K, cg_tol=cg_tol)[0]


def scene_rows(scene: Path, cg_tolerances: list[float]) -> list[dict]:
    """``bilateral`` and BiNI's iteration from a rendered scene's ground-truth normals and
    from those that ``irtps reconstruct --method irtps`` fits (one run each)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irtps.IrtpsWarning)
        dataset = irtps.load_dataset(scene)
        fitted = irtps.reconstruct(dataset, "irtps").normals
    K = dataset.scene.camera.intrinsics()
    truth = dataset.gt.normal
    mask = dataset.mask & (np.linalg.norm(truth, axis=-1) > 0.5)
    depth = np.where(mask, dataset.gt.depth, np.nan)
    normal_maps = dict(zip(SCENE_LABELS, (truth, fitted)))
    integrations = [("bilateral", lambda normals: irtps.integrate_normals(normals, mask, intrinsics=K))]
    integrations += [(f"bini cg {cg_tol:g}", bini_depth_from(mask, K, cg_tol)) for cg_tol in cg_tolerances]
    return [
        one_run_row(method, depth_from, normal_maps, mask, depth) | {"scene": scene.name}
        for method, depth_from in integrations
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=SHARED, help="a DiLiGenT object with K.txt and depth_gt.npz")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument(
        "--bini-tolerances",
        type=tolerances,
        default=[1e-3, 5e-4, 8e-4, 1.25e-3, 2e-3],
        help="conjugate-gradient tolerances for BiNI's iteration, comma-separated (default: 1e-3 and ×0.5–×2)",
    )
    parser.add_argument(
        "--scenes", type=Path, nargs="*", default=SCENES, help="rendered perspective scenes with gt/depth.exr"
    )
    parser.add_argument("--json", type=Path, help="also write the rows as JSON")
    args = parser.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irtps.IrtpsWarning)
        dataset = irtps.load_dataset(args.data)
        fitted = irtps.reconstruct(dataset).normals
    K = np.loadtxt(args.data / "K.txt")
    depth = np.load(args.data / "depth_gt.npz")["depth_gt"].astype(np.float64)
    truth = scipy.io.loadmat(args.data / "Normal_gt.mat")["Normal_gt"].astype(np.float32)
    mask = dataset.mask
    rows = []
    print(
        f"{args.data.name}: {int(mask.sum())} pixels; MADE in mm; times: median of {args.runs} after a warm-up "
        "(bini: one run)"
    )
    print(f"{'method':<16} {'true normals':>14} {'time':>8} {'irtps normals':>14} {'time':>8}")
    for method in METHODS:
        true_seconds, from_truth = timed(method, truth, mask, K, depth, args.runs)
        fitted_seconds, from_fit = timed(method, fitted, mask, K, depth, args.runs)
        row = {
            "method": method,
            "made_true_normals": made(from_truth, depth, mask),
            "seconds_true_normals": true_seconds,
            "made_irtps_normals": made(from_fit, depth, mask),
            "seconds_irtps_normals": fitted_seconds,
        }
        rows.append(row)
        print_row(row, READING_LABELS, 3)
    normal_maps = dict(zip(READING_LABELS, (truth, fitted)))
    for cg_tol in args.bini_tolerances:
        rows.append(one_run_row(f"bini cg {cg_tol:g}", bini_depth_from(mask, K, cg_tol), normal_maps, mask, depth))
        print_row(rows[-1], READING_LABELS, 3)
    for scene in args.scenes:
        print(f"\n{scene.name}: MADE in scene units (one run each)")
        print(f"{'method':<16} {'true normals':>14} {'time':>8} {'IRT-PS normals':>14} {'time':>8}")
        for row in scene_rows(scene, args.bini_tolerances):
            rows.append(row)
            print_row(row, SCENE_LABELS, 4)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
