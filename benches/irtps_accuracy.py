"""IRT-PS against classic photometric stereo on every shared data set, with defaults.

For each data set under ``../shared/data`` (Mitsuba renders and DiLiGenT objects) this runs
classic photometric stereo and IRT-PS with their defaults, as ``irtps reconstruct`` does, and
prints the mean angular error of each, the share of the gap to the floor (classic PS on the
direct-only images, where the data set has them) that IRT-PS closes, the placement and the
passes. ``--passes 16`` also runs 16 passes without the early stop, and the result after at
most 5, on the data sets with direct-only images (the Mitsuba renders), to check how fast
the loop converges.

Usage::

    python benches/irtps_accuracy.py                     # all shared data sets
    python benches/irtps_accuracy.py --only pedestal_cornell --passes 16
    python benches/irtps_accuracy.py --json accuracy.json
    python benches/irtps_accuracy.py --samples 128       # IRT-PS with 128 paths per pixel
    python benches/irtps_accuracy.py --no-denoise        # its estimates not filtered
    python benches/irtps_accuracy.py --noise-limit       # and the images' noise limit

The noise limit is classic PS on the images less their expected inter-reflections (irtps's
rendering of the true scene at 1024 paths a pixel): the direct-only floor lacks the images'
Monte-Carlo noise, which no correction removes.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import irtps
from irtps.errors import DatasetError, IrtpsWarning
from irtps.model.options import ReconstructOptions
from irtps.model.scene import orthographic_scene
from irtps.irt.pipeline import fit_photometric_stereo, resolve_options, settled_near_fit, with_chosen_robust
from irtps.render.renderer import render

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
#: Paths a pixel of the expected inter-reflections that `noise_limit_error` removes.
NOISE_LIMIT_PATHS = 1024
#: Indirect bounces in the shared Mitsuba images (their README: ``max_depth = 6``).
SHARED_BOUNCES = 4


def angular_error(dataset, normals) -> float:
    return irtps.evaluate(mask=dataset.mask, normals=normals, gt=dataset.gt).normal_mean_angular_deg


def floor_error(dataset) -> float | None:
    """Classic (robust) PS on the direct-only images: what removing every inter-reflection
    would reach."""
    if dataset.gt is None or dataset.gt.direct is None:
        return None
    # A pinhole camera's data set is fitted as reconstruct fits it, through its orthographic stand-in.
    dataset = dataclasses.replace(dataset, scene=orthographic_scene(dataset.scene, str(dataset.source)))
    options = resolve_options(dataset, ReconstructOptions())
    if dataset.scene.has_point_lights:
        # Near lights: the shape, and the lights at it, settled on the direct images alone.
        fit, _, _ = settled_near_fit(dataset, dataset.gt.direct, options)
        return angular_error(dataset, fit.normals)
    options = with_chosen_robust(options, fit_photometric_stereo(dataset, dataset.images, options))
    return angular_error(dataset, fit_photometric_stereo(dataset, dataset.gt.direct, options).normals)


def noise_limit_error(dataset, bounces: int) -> float | None:
    """Classic PS as `floor_error` fits it, on the images less their expected inter-reflected
    light (irtps's rendering of the true scene, `NOISE_LIMIT_PATHS` paths a pixel, `bounces`
    bounces): what removing the inter-reflections exactly would reach with the images' own
    Monte-Carlo noise, which the direct-only floor does not have."""
    gt = dataset.gt
    if gt is None or gt.direct is None or gt.height is None:
        return None
    expected = render(
        dataset.scene,
        gt.height,
        gt.albedo,
        dataset.mask,
        bounces=bounces,
        samples=NOISE_LIMIT_PATHS,
        direct_samples=64,
        seed=1,
    ).indirect
    cleaned = (dataset.images - expected).astype(np.float32)
    return floor_error(dataclasses.replace(dataset, gt=dataclasses.replace(gt, direct=cleaned)))


def measure(path: Path, passes: int | None, settings: dict, noise_limit: bool = False) -> dict:
    dataset = irtps.load_dataset(path)
    classic = angular_error(dataset, irtps.reconstruct(dataset).normals)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", IrtpsWarning)
        result = irtps.reconstruct(dataset, "irtps", **settings)
    seconds = time.perf_counter() - start
    irtps_error = angular_error(dataset, result.normals)
    floor = floor_error(dataset)
    row = {
        "data": path.name,
        "classic_deg": classic,
        "irtps_deg": irtps_error,
        "floor_deg": floor,
        "gap_closed": None if floor is None else (classic - irtps_error) / (classic - floor),
        "worse_than_classic_deg": irtps_error - classic,
        "passes": len(result.history),
        "chosen_pass": result.chosen,
        "stop": None if result.stop is None else result.stop.reason,
        "correction": None
        if result.stop is None or result.stop.correction is None
        else result.stop.correction.to_dict(),
        "placement": result.placement.to_dict(),
        "residuals": [step.residual["object"] for step in result.history],
        "seconds": seconds,
        "warnings": [str(w.message) for w in caught],
    }
    if noise_limit:
        limit = noise_limit_error(dataset, SHARED_BOUNCES)
        row["noise_limit_deg"] = limit
        row["gap_to_noise_limit_closed"] = None if limit is None else (classic - irtps_error) / (classic - limit)
    if passes is not None and floor is not None:
        long = irtps.reconstruct(dataset, "irtps", iterations=passes, early_stop=False, **settings)
        short = irtps.reconstruct(dataset, "irtps", iterations=5, **settings)
        row[f"error_{passes}_passes_deg"] = angular_error(dataset, long.normals)
        row["error_at_most_5_passes_deg"] = angular_error(dataset, short.normals)
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--shared", type=Path, default=SHARED, help="the shared data folder (default: ../shared/data)")
    parser.add_argument("--only", nargs="+", help="data set names to run (default: all)")
    parser.add_argument(
        "--passes",
        type=int,
        help="also run this many passes without the early stop, and at most 5 (data sets with direct-only images)",
    )
    parser.add_argument("--samples", type=int, help="camera paths per pixel of IRT-PS's estimates (default: irtps's)")
    parser.add_argument(
        "--no-denoise", action="store_true", help="IRT-PS without the filter of its estimates (irtps.render.denoise)"
    )
    parser.add_argument(
        "--noise-limit",
        action="store_true",
        help="also fit the images less their expected inter-reflections (the images' noise limit) and report "
        "the share of the gap to it that IRT-PS closes",
    )
    parser.add_argument("--json", type=Path, help="write the rows here")
    args = parser.parse_args(argv)
    paths = sorted(p for group in ("mitsuba", "diligent") for p in (args.shared / group).glob("*") if p.is_dir())
    if args.only:
        paths = [p for p in paths if p.name in args.only]
    if not paths:
        print(f"no data sets under {args.shared}", file=sys.stderr)
        return 1
    rows = []
    print("| data | classic PS | IRT-PS | floor | gap closed | passes (chosen) | stop | placement | seconds |")
    print("|---|---|---|---|---|---|---|---|---|")
    for path in paths:
        settings = ({} if args.samples is None else {"samples": args.samples}) | (
            {"denoise": False} if args.no_denoise else {}
        )
        try:
            row = measure(path, args.passes, settings, args.noise_limit)
        except DatasetError as err:
            print(f"| {path.name} | refused: {err} | | | | | | | |", flush=True)
            continue
        rows.append(row)
        floor = "n/a" if row["floor_deg"] is None else f"{row['floor_deg']:.2f}°"
        closed = "n/a" if row["gap_closed"] is None else f"{100 * row['gap_closed']:.1f} %"
        placement = f"{row['placement']['base_height']:.2f} ({row['placement']['source']})"
        print(
            f"| {row['data']} | {row['classic_deg']:.3f}° | {row['irtps_deg']:.3f}° | {floor} | {closed} | {row['passes']} ({row['chosen_pass']}) | {row['stop']} | {placement} | {row['seconds']:.1f} |",
            flush=True,
        )
        if row.get("noise_limit_deg") is not None:
            print(
                f"|   | noise limit {row['noise_limit_deg']:.3f}°: {100 * row['gap_to_noise_limit_closed']:.1f} % of its gap closed | | | | | | | |",
                flush=True,
            )
        if f"error_{args.passes}_passes_deg" in row:
            print(
                f"|   | {args.passes} passes: {row[f'error_{args.passes}_passes_deg']:.3f}° | at most 5: {row['error_at_most_5_passes_deg']:.3f}° | | | | | | |",
                flush=True,
            )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
