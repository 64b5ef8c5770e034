"""Unknown light strengths on real objects: DiLiGenT ball and reading as if they came without
``light_intensities.txt`` (issue 49).

For each object, the mean angular error of ``irtps.reconstruct`` (defaults) with the
intensities given, with every light taken as equally strong (what a user who does not know
them would otherwise get), and with the strengths estimated from the images (the data set
read with ``irradiance_known`` False, as a folder without the file is); the estimated
strengths' error against the given ones (each normalised to its median light, per channel);
and the median time of the estimate over ``--runs`` calls after a warm-up.

Then each object as a dome user would hold it (an RTI folder, `irtps.io.rti`): its images
sRGB-encoded into 8-bit JPEG files at quality 95 (Pillow), a ``.lp`` file of its light
directions, its mask, no intensities; the mean angular error of ``irtps.reconstruct`` on it.

Last, IRT-PS (defaults) on the shared Mitsuba scenes of distant lights with their strengths
given, given as absolute but off by a factor (what a calibration whose matte sphere's albedo
was misstated gives), and estimated: estimated strengths are relative (the median light's is
1), so IRT-PS must find their scale from the images (`irtps.render.radiometry`) before it
renders the inter-reflections.

    python benches/semi_calibrated.py [--runs 5] [--only ballPNG] [--scenes cap_cornell]
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from PIL import Image

import irtps
from irtps.model.scene import with_emission
from irtps.ps.semi_calibrated import estimate_light_intensities

DILIGENT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "diligent"
MITSUBA = DILIGENT.parent / "mitsuba"
OBJECTS = ("ballPNG", "readingPNG")
#: The shared Mitsuba scenes of distant lights (semi-calibrated photometric stereo needs them).
SCENES = ("cap_cornell", "grooves_dark", "pedestal_cornell", "cap_persp_cornell", "grooves_persp_dark")
#: Absolute strengths off by these factors: a matte sphere's albedo given 25 % and 10 % too
#: high, and 10 % and 25 % too low (`irtps calibrate --matte-albedo`); a capture taken at
#: twice or half the calibration's exposure.
MISSTATED = (0.5, 0.8, 0.9, 1.1, 1.25, 2.0)


def reconstructed(dataset: irtps.Dataset, method: str = "ps") -> irtps.Reconstruction:
    """``irtps.reconstruct`` with its defaults, its warnings (the estimate's) silenced."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irtps.IrtpsWarning)
        return irtps.reconstruct(dataset, method)


def mean_error(dataset: irtps.Dataset, method: str = "ps") -> float:
    """Mean angular error (degrees) of ``irtps.reconstruct``'s normals over the mask where the
    true normal is known."""
    normals = reconstructed(dataset, method).normals
    return irtps.evaluate(mask=dataset.mask, normals=normals, gt=dataset.gt).normal_mean_angular_deg


def without_strengths(dataset: irtps.Dataset) -> irtps.Dataset:
    """`dataset` read as a folder without its lights' strengths is: all equal, and unknown."""
    lights = tuple(with_emission(light, np.ones(3)) for light in dataset.scene.lights)
    return dataclasses.replace(dataset, scene=dataclasses.replace(dataset.scene, lights=lights), irradiance_known=False)


def misstated(dataset: irtps.Dataset, factor: float) -> irtps.Dataset:
    """`dataset` with absolute strengths `factor` times the true ones: a calibration whose
    matte sphere's albedo was given 1 / `factor` times its own."""
    lights = tuple(with_emission(light, light.irradiance * factor) for light in dataset.scene.lights)
    return dataclasses.replace(dataset, scene=dataclasses.replace(dataset.scene, lights=lights))


def irtps_row(path: Path) -> str:
    """IRT-PS on a scene with its strengths given, given as absolute but misstated by each of
    `MISSTATED`, and estimated, and the scale it found."""
    dataset = irtps.load_dataset(path)
    unknown = without_strengths(dataset)
    result = reconstructed(unknown, "irtps")
    error = irtps.evaluate(mask=dataset.mask, normals=result.normals, gt=dataset.gt).normal_mean_angular_deg
    wrong = " / ".join(f"{mean_error(misstated(dataset, factor), 'irtps'):.3f}°" for factor in MISSTATED)
    return (
        f"| {path.name} | {mean_error(dataset):.3f}° | {mean_error(dataset, 'irtps'):.3f}° | {wrong} "
        f"| {mean_error(unknown):.3f}° | {error:.3f}° | {result.albedo_scale.factor:.3g} (pass {result.chosen}) |"
    )


def as_rti_folder(dataset: irtps.Dataset, source: Path, folder: Path) -> Path:
    """`dataset` as a dome user's RTI folder in `folder`: 8-bit sRGB JPEG images (quality 95),
    ``capture.lp`` and the mask."""
    lines = [str(len(dataset.images))]
    for k, (image, direction) in enumerate(zip(dataset.images, dataset.scene.light_directions, strict=True)):
        linear = np.clip(image, 0.0, 1.0)
        encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
        name = f"capture_{k + 1:03d}.jpg"
        Image.fromarray(np.rint(encoded * 255).astype(np.uint8)).save(folder / name, quality=95)
        lines.append(f"{name} {direction[0]:.6f} {direction[1]:.6f} {direction[2]:.6f}")
    (folder / "capture.lp").write_text("\n".join(lines) + "\n")
    shutil.copy(source / "mask.png", folder / "mask.png")
    return folder


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--only", nargs="*", default=list(OBJECTS))
    parser.add_argument("--scenes", nargs="*", default=list(SCENES), help="Mitsuba scenes for IRT-PS")
    args = parser.parse_args()
    print(
        "| object | given | all equal | estimated | strengths' error, mean / largest | estimate s | RTI folder, JPEG |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in args.only:
        dataset = irtps.load_dataset(DILIGENT / name)
        given = np.array([light.irradiance for light in dataset.scene.lights])
        directions = np.array([light.direction for light in dataset.scene.lights])
        unknown = without_strengths(dataset)
        equal = dataclasses.replace(unknown, irradiance_known=True)
        seconds = []
        for _ in range(args.runs + 1):
            start = time.perf_counter()
            found = estimate_light_intensities(dataset.images, directions, dataset.mask, saturation=dataset.saturation)
            seconds.append(time.perf_counter() - start)
        relative = np.abs(found / (given / np.median(given, axis=0)) - 1)
        with tempfile.TemporaryDirectory() as folder:
            rti = irtps.load_dataset(as_rti_folder(dataset, DILIGENT / name, Path(folder)))
        rti.gt = dataset.gt
        print(
            f"| {name} | {mean_error(dataset):.3f}° | {mean_error(equal):.3f}° | {mean_error(unknown):.3f}° "
            f"| {100 * relative.mean():.1f} % / {100 * relative.max():.1f} % | {statistics.median(seconds[1:]):.2f} "
            f"| {mean_error(rti):.3f}° |"
        )
    if args.scenes:
        print()
        print(
            "| scene | classic PS, given | IRT-PS, given | IRT-PS, given ×"
            + " / ×".join(f"{factor:g}" for factor in MISSTATED)
            + " | classic PS, estimated | IRT-PS, estimated | scale found |"
        )
        print("|---|---|---|---|---|---|---|")
        for name in args.scenes:
            print(irtps_row(MITSUBA / name), flush=True)


if __name__ == "__main__":
    main()
