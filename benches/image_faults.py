"""Faulty images: how far each image's agreement with the fit shows them, and what leaving
them out gives back, on every shared data set.

For each data set under ``../shared/data``: the default reconstruction of the images as they
are, then (on the real objects, whose rigs are the ones that go wrong) with images 1-20 made
1.2x and 1.5x too bright, 5 images spread over the set 2x, and images 1-20 shifted by 3
pixels (taken as the object moved). Prints the range of `Reconstruction.image_agreement`'s
brightness and spread over the sound images and over the faulty ones, and the mean angular
error as it is, with the faulty images left out (`irtps.exclude_images`) and with each
light's irradiance scaled by its image's brightness (``correct_brightness``).

Usage::

    python benches/image_faults.py
    python benches/image_faults.py --only readingPNG
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
from pathlib import Path

import numpy as np

import irtps
from irtps.errors import IrtpsWarning

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FIRST_20 = range(20)
#: The faults tried on real objects: a name, the images (from 0) and what is done to them.
FAULTS = (
    ("1-20 x1.2", FIRST_20, lambda images: images * 1.2),
    ("1-20 x1.5", FIRST_20, lambda images: images * 1.5),
    ("5 images x2", (3, 30, 50, 70, 90), lambda images: images * 2.0),
    ("1-20 shifted", FIRST_20, lambda images: np.roll(images, 3, axis=2)),
)


def error(dataset, result) -> float:
    return irtps.evaluate(mask=dataset.mask, normals=result.normals, gt=dataset.gt).normal_mean_angular_deg


def spread(values: np.ndarray) -> str:
    return f"{np.nanmin(values):.3f}-{np.nanmax(values):.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", nargs="+", help="data set names (default: every one under ../shared/data)")
    args = parser.parse_args()
    folders = sorted(
        path
        for path in SHARED.glob("*/*")
        if path.is_dir() and ((path / "scene.json").exists() or (path / "light_directions.txt").exists())
    )
    if args.only:
        folders = [path for path in folders if path.name in args.only]
    if not folders:
        sys.exit(f"no data set found under {SHARED}")
    warnings.simplefilter("ignore", IrtpsWarning)
    for folder in folders:
        dataset = irtps.load_dataset(folder)
        result = irtps.reconstruct(dataset)
        agreement = result.image_agreement
        corrected = irtps.reconstruct(dataset, correct_brightness=True)
        print(
            f"{folder.name:18s} as given      brightness {spread(agreement.brightness)}  spread {spread(agreement.spread)}  "
            f"error {error(dataset, result):.3f}, brightness corrected {error(dataset, corrected):.3f}",
            flush=True,
        )
        if not dataset.scene.relative_irradiance:
            continue  # rendered: the lights are exactly as recorded
        for label, images, fault in FAULTS:
            faulty = dataclasses.replace(dataset, images=dataset.images.copy())
            faulty.images[list(images)] = fault(faulty.images[list(images)])
            agreement = irtps.reconstruct(faulty).image_agreement
            bad = np.zeros(len(dataset.names), bool)
            bad[list(images)] = True
            left_out = irtps.reconstruct(
                irtps.exclude_images(faulty, ",".join(dataset.names[k] for k in np.flatnonzero(bad)))
            )
            corrected = irtps.reconstruct(faulty, correct_brightness=True)
            print(
                f"{folder.name:18s} {label:13s} brightness sound {spread(agreement.brightness[~bad])}, faulty {spread(agreement.brightness[bad])}  "
                f"spread sound {spread(agreement.spread[~bad])}, faulty {spread(agreement.spread[bad])}  "
                f"error {error(dataset, irtps.reconstruct(faulty)):.3f}, faulty left out {error(dataset, left_out):.3f}, "
                f"brightness corrected {error(dataset, corrected):.3f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
