"""Light calibration (``irtps.calibrate_lights``, issue 49) against the truth of Mitsuba
captures: the shared one (``shared/data/calibration/spheres``, its 8-bit sRGB PNG images and
its linear EXR images, circles found by irtps) and, with ``--rendered N``, N more rendered
here the same way with other lights and the spheres elsewhere (``calibration_scenes.py``,
Mitsuba 3 needed: ``pip install "irtps[bench]"``).

For each capture: the light directions' mean and largest angular error, the relative
strengths' largest error (each normalised by the mean ratio to the truth, per channel) and
the absolute ones' (``matte_albedo`` the sphere's 0.8, not normalised), the
distance of each sphere's circle from the truth, and the median time of the calibration over
``--runs`` calls (images already read). Then the mirror sphere alone, as a capture without a
matte sphere gives it: the images cut to a square about it (1.3 radii each way, the matte
sphere outside it; it still shows in the mirror), its directions' mean and largest error.

    python benches/calibration_bench.py [--runs 5] [--rendered 8 --seed 1 --max-tilt 45]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import irtps
from irtps.io.capture import capture_image_paths, read_capture

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "calibration" / "spheres"
#: The matte sphere's albedo in the shared capture and in those `calibration_scenes.py` renders.
MATTE_ALBEDO = 0.8


def check(folder: Path, truth: dict, runs: int) -> dict:
    """The calibration of the images in `folder` against `truth` (a ``gt/lights.json``)."""
    capture = read_capture(capture_image_paths(folder))
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        calibration = irtps.calibrate_lights(capture.images, saturated=capture.saturated)
        times.append(time.perf_counter() - start)
    directions = np.array([light["direction"] for light in truth["lights"]])
    irradiance = np.array([light["irradiance"] for light in truth["lights"]])
    errors = np.degrees(np.arccos(np.clip(np.sum(calibration.directions * directions, axis=1), -1, 1)))
    row = {
        "directions_mean_deg": float(errors.mean()),
        "directions_max_deg": float(errors.max()),
        "strengths_max_pct": None,
        "chrome_px": _distance(calibration.chrome, truth["chrome_sphere"]),
        "matte_px": _distance(calibration.matte, truth["matte_sphere"]),
        "seconds": statistics.median(times),
    }
    row["absolute_max_pct"] = None
    if calibration.irradiance is not None:
        ratio = calibration.irradiance / irradiance
        row["strengths_max_pct"] = float(100 * np.abs(ratio / ratio.mean(axis=0) - 1).max())
        absolute = irtps.calibrate_lights(capture.images, saturated=capture.saturated, matte_albedo=MATTE_ALBEDO)
        row["absolute_max_pct"] = float(100 * np.abs(absolute.irradiance / irradiance - 1).max())
    row["chrome_alone"] = _chrome_alone(capture.images, capture.saturated, truth, directions)
    return row


def _chrome_alone(images: np.ndarray, saturated: np.ndarray, truth: dict, directions: np.ndarray) -> str:
    """The mirror sphere's directions' mean / largest error from the images cut about it."""
    (column, row), radius = truth["chrome_sphere"]["center_px"], truth["chrome_sphere"]["radius_px"]
    top, bottom = max(0, int(row - 1.3 * radius)), min(images.shape[1], int(np.ceil(row + 1.3 * radius)))
    left, right = max(0, int(column - 1.3 * radius)), min(images.shape[2], int(np.ceil(column + 1.3 * radius)))
    (matte_column, matte_row), matte_radius = truth["matte_sphere"]["center_px"], truth["matte_sphere"]["radius_px"]
    nearest = np.hypot(np.clip(matte_column, left, right) - matte_column, np.clip(matte_row, top, bottom) - matte_row)
    if nearest < matte_radius:
        return "-"
    calibration = irtps.calibrate_lights(
        images[:, top:bottom, left:right], saturated=saturated[:, top:bottom, left:right]
    )
    errors = np.degrees(np.arccos(np.clip(np.sum(calibration.directions * directions, axis=1), -1, 1)))
    return f"{errors.mean():.3f} / {errors.max():.3f}"


def _distance(circle, true: dict) -> float | None:
    if circle is None:
        return None
    return float(np.hypot(circle.column - true["center_px"][0], circle.row - true["center_px"][1]))


def _line(name: str, row: dict) -> str:
    strengths = " / ".join(
        "-" if row[key] is None else f"{row[key]:.2f}" for key in ("strengths_max_pct", "absolute_max_pct")
    )
    circles = " / ".join("-" if row[key] is None else f"{row[key]:.2f}" for key in ("chrome_px", "matte_px"))
    return (
        f"| {name} | {row['directions_mean_deg']:.3f} | {row['directions_max_deg']:.3f} | {strengths} | "
        f"{circles} | {row['seconds']:.2f} | {row['chrome_alone']} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--rendered", type=int, default=0, help="captures to render with Mitsuba and check too")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--max-tilt", type=float, default=45.0, help="rendered lights' largest angle from the view axis"
    )
    args = parser.parse_args()
    print(
        "| capture | directions mean ° | max ° | strengths max %, relative / absolute | circle off px (chrome / matte) "
        "| seconds "
        "| mirror sphere alone, mean / max ° |"
    )
    print("|---|---|---|---|---|---|---|")
    truth = json.loads((SHARED / "gt" / "lights.json").read_text())
    for kind in ("png", "exr"):
        print(_line(f"shared {kind}", check(SHARED / kind, truth, args.runs)), flush=True)
    if args.rendered:
        from calibration_scenes import render_capture

        with tempfile.TemporaryDirectory() as temp:
            for k in range(args.rendered):
                folder = Path(temp) / f"capture_{k}"
                render_capture(folder, seed=args.seed + k, max_tilt_deg=args.max_tilt)
                truth = json.loads((folder / "gt" / "lights.json").read_text())
                print(_line(f"rendered seed {args.seed + k} png", check(folder / "png", truth, args.runs)), flush=True)


if __name__ == "__main__":
    main()
