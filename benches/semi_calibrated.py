"""Unknown light strengths on real objects: DiLiGenT ball and reading as if they came without
``light_intensities.txt`` (issue 49).

For each object, the mean angular error of ``irtps.reconstruct`` (defaults) with the
intensities given, with every light taken as equally strong (what a user who does not know
them would otherwise get), and with the strengths estimated from the images (the data set
read with ``irradiance_known`` False, as a folder without the file is); the estimated
strengths' error against the given ones (each normalised to its median light, per channel);
and the median time of the estimate over ``--runs`` calls after a warm-up.

    python benches/semi_calibrated.py [--runs 5] [--only ballPNG]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

import irtps
from irtps.model.scene import with_emission
from irtps.ps.semi_calibrated import estimate_light_intensities

DILIGENT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "diligent"
OBJECTS = ("ballPNG", "readingPNG")


def mean_error(dataset: irtps.Dataset) -> float:
    """Mean angular error (degrees) of ``irtps.reconstruct``'s normals over the mask."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irtps.IrtpsWarning)
        result = irtps.reconstruct(dataset)
    return float(irtps.angular_error_deg(result.normals, dataset.gt.normal, dataset.mask)[dataset.mask].mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--only", nargs="*", default=list(OBJECTS))
    args = parser.parse_args()
    print("| object | given | all equal | estimated | strengths' error, mean / largest | estimate s |")
    print("|---|---|---|---|---|---|")
    for name in args.only:
        dataset = irtps.load_dataset(DILIGENT / name)
        given = np.array([light.irradiance for light in dataset.scene.lights])
        directions = np.array([light.direction for light in dataset.scene.lights])
        equal = dataclasses.replace(
            dataset,
            scene=dataclasses.replace(
                dataset.scene, lights=tuple(with_emission(light, np.ones(3)) for light in dataset.scene.lights)
            ),
        )
        unknown = dataclasses.replace(equal, irradiance_known=False)
        seconds = []
        for _ in range(args.runs + 1):
            start = time.perf_counter()
            found = estimate_light_intensities(dataset.images, directions, dataset.mask, saturation=dataset.saturation)
            seconds.append(time.perf_counter() - start)
        relative = np.abs(found / (given / np.median(given, axis=0)) - 1)
        print(
            f"| {name} | {mean_error(dataset):.3f}° | {mean_error(equal):.3f}° | {mean_error(unknown):.3f}° "
            f"| {100 * relative.mean():.1f} % / {100 * relative.max():.1f} % | {statistics.median(seconds[1:]):.2f} |"
        )


if __name__ == "__main__":
    main()
