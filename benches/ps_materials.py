#!/usr/bin/env python
"""Each robust photometric-stereo mode on DiLiGenT's shapes (and irtps synth's) rendered by Mitsuba 3 in other materials.

The synthetic pixels of ``benches/ps_accuracy.py`` have no shape: no cast shadow, no
inter-reflection. Here the shapes are DiLiGenT's own (ball, reading: the ground-truth
normals of ``../shared/data/diligent``, averaged over ``--downsample``² blocks and integrated
into a height field) or those of ``irtps synth`` (cap, cavity, grooves, relief, pedestal),
alone in the dark, and Mitsuba 3 renders them under DiLiGenT's 96
light directions (irradiance π) with physically based BSDFs: Lambertian, rough plastics
(GGX, a white specular coat over a diffuse base) and rough conductors (GGX, measured
aluminium and copper). Paths of up to 4 bounces (``max_depth`` 6), ``--samples`` per pixel.
For each, the mean angular error of every ``--robust`` mode against the height field's
normals (scene contract §2), how far ``auto`` (the default) is below plain least squares, and
the share of the object's pixels that take a lobe in ``auto``'s check (``irtps.lobe_share``,
the lobe fit cut to ``irtps.ps.fit.LOBE_CHECK_ROUNDS`` rounds, from which ``auto`` picks
``lobe``, from one half on, or ``tukey``). With ``--irtps``, also
the error of ``irtps.reconstruct``'s IRT-PS (defaults; the object's own inter-reflections, in
a scene of the shape alone with the render's lights) beside its classic photometric stereo:
whether IRT-PS, whose rendering is Lambertian, holds on glossy and metallic objects.

    python benches/ps_materials.py [--objects ballPNG readingPNG] [--downsample 2]
        [--samples 32] [--irtps] [--json PATH] [--cache DIR]
    python benches/ps_materials.py --objects cap cavity grooves relief pedestal [--size 160]

Needs Mitsuba 3 (``pip install mitsuba``; its LLVM variant needs libLLVM, see
``benches/mitsuba_compare.py``) and ``../shared/data/diligent``.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from mitsuba_scene import MitsubaScene, import_mitsuba
from ps_accuracy import COLUMNS, mode_errors

import irtps
from irtps import height_to_normals, integrate_normals
from irtps.errors import IrtpsWarning
from irtps.model.metrics import angular_error_deg
from irtps.render.renderer import make_renderer
from irtps.model.scene import Camera, Light, Scene
from irtps.render.synth import SHAPES

DILIGENT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "diligent"
#: Diffuse reflectance of the Lambertian and plastic materials' base.
BASE = 0.6
#: (name, Mitsuba BSDF)
MATERIALS = [
    ("Lambertian 0.6", {"type": "diffuse", "reflectance": {"type": "rgb", "value": BASE}}),
    (
        "rough plastic α 0.1, diffuse 0.6",
        {
            "type": "roughplastic",
            "distribution": "ggx",
            "alpha": 0.1,
            "diffuse_reflectance": {"type": "rgb", "value": BASE},
        },
    ),
    (
        "rough plastic α 0.3, diffuse 0.6",
        {
            "type": "roughplastic",
            "distribution": "ggx",
            "alpha": 0.3,
            "diffuse_reflectance": {"type": "rgb", "value": BASE},
        },
    ),
    (
        "rough plastic α 0.2, diffuse 0.1",
        {
            "type": "roughplastic",
            "distribution": "ggx",
            "alpha": 0.2,
            "diffuse_reflectance": {"type": "rgb", "value": 0.1},
        },
    ),
    ("rough aluminium α 0.2", {"type": "roughconductor", "material": "Al", "distribution": "ggx", "alpha": 0.2}),
    ("rough copper α 0.4", {"type": "roughconductor", "material": "Cu", "distribution": "ggx", "alpha": 0.4}),
]


def diligent_shape(folder: Path, downsample: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(height, mask, light directions) of a DiLiGenT object: its true normals averaged over
    `downsample`² blocks (a block is the object's only where all its pixels are), integrated,
    the lowest point raised to 1."""
    dataset = irtps.load_dataset(folder)
    rows, cols = (size // downsample * downsample for size in dataset.mask.shape)
    blocks = (rows // downsample, downsample, cols // downsample, downsample)
    mask = dataset.mask[:rows, :cols].reshape(blocks).all(axis=(1, 3))
    normals = dataset.gt.normal[:rows, :cols].reshape(*blocks, 3).mean(axis=(1, 3))
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    height = integrate_normals(normals, mask)
    height = np.where(mask, height - height[mask].min() + 1.0, 0.0).astype(np.float32)
    return height, mask, dataset.scene.light_directions


def synthetic_shape(name: str, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(height, mask, light directions) of an ``irtps synth`` shape, `size` pixels square,
    under DiLiGenT ball's 96 light directions: shapes DiLiGenT does not have (a cavity,
    grooves, a pedestal with a trench), to see the robust modes off DiLiGenT's own."""
    height, mask = SHAPES[name](size, np.random.default_rng(0))
    return np.where(mask, height, 0.0).astype(np.float32), mask, diligent_directions()


@functools.cache
def diligent_directions() -> np.ndarray:
    """DiLiGenT ball's 96 light directions, its images read once for every synthetic shape."""
    return irtps.load_dataset(DILIGENT / "ballPNG").scene.light_directions


def shape_scene(height: np.ndarray, mask: np.ndarray, directions: np.ndarray):
    """(scene, renderer) of the shape alone in the dark under each direction (irradiance π),
    albedo `BASE`: the triangles that every material's Mitsuba scene takes."""
    lights = tuple(Light(direction=d, irradiance=np.full(3, np.pi)) for d in directions)
    scene = Scene(camera=Camera(mask.shape[1], mask.shape[0], 1.0), lights=lights)
    albedo = np.where(mask[..., None], BASE, 0.0).repeat(3, axis=2).astype(np.float32)
    return scene, make_renderer(scene, height, albedo, mask)


def render_material(
    mi, variant: str, scene, renderer, bsdf: dict, samples: int, cache: Path | None = None
) -> np.ndarray:
    """(K, H, W, 3) images of the shape in `bsdf` under each light, 4 bounces; with `cache`,
    read from there when an earlier run rendered the same (the renders are seeded), else
    written there."""
    path = None
    if cache is not None:
        key = hashlib.sha256(json.dumps([mi.__version__, variant, bsdf, samples], sort_keys=True).encode())
        for array in (*renderer.mesh_arrays()[:2], *(light.direction for light in scene.lights)):
            key.update(np.ascontiguousarray(array).tobytes())
        path = cache / f"{key.hexdigest()[:24]}.npy"
    if path is not None and path.is_file():
        return np.load(path)
    mitsuba = MitsubaScene(mi, variant, renderer, scene, 4, "independent", bsdf=bsdf)
    images = np.stack([mitsuba.render(k, samples, seed=k)[0] for k in range(len(scene.lights))])
    if path is not None:
        cache.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(".partial.npy")
        np.save(partial, images)
        partial.replace(path)
    return images


def reconstruction_errors(dataset: irtps.Dataset) -> dict[str, float]:
    """Mean angular error (degrees) of `irtps.reconstruct`'s IRT-PS of `dataset` (``"irtps"``,
    defaults) and of its pass 0, classic photometric stereo (``"ps"``), from one run."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IrtpsWarning)  # IRT-PS returning classic PS's pass says so
        result = irtps.reconstruct(dataset, "irtps")
    return {
        "ps": result.history[0].metrics["normal_mean_angular_deg"],
        "irtps": float(np.nanmean(angular_error_deg(result.normals, dataset.gt.normal, dataset.mask))),
    }


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not a positive integer")
    return value


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--objects",
        nargs="+",
        default=["ballPNG", "readingPNG"],
        help=f"DiLiGenT objects, or shapes of irtps synth ({', '.join(SHAPES)}), to render (default: ballPNG readingPNG)",
    )
    parser.add_argument(
        "--size", type=positive_int, default=160, help="side of a synthetic shape's image, pixels (default: 160)"
    )
    parser.add_argument(
        "--downsample", type=positive_int, default=2, help="block size of the shape's pixels (default: 2)"
    )
    parser.add_argument("--samples", type=positive_int, default=32, help="Mitsuba samples per pixel (default: 32)")
    parser.add_argument(
        "--irtps",
        action="store_true",
        help="also reconstruct each render with IRT-PS (irtps.reconstruct), beside its pass 0, classic photometric stereo",
    )
    parser.add_argument("--json", type=Path, help="write the rows here")
    parser.add_argument(
        "--cache",
        type=Path,
        help="keep the renders in this folder and take them from there when run again (after a change to irtps's fits, not to the renders)",
    )
    args = parser.parse_args(argv)
    missing = [name for name in [*args.objects, "ballPNG"] if name not in SHAPES and not (DILIGENT / name).is_dir()]
    if missing:
        sys.exit(
            f"ps_materials.py needs the DiLiGenT objects in {DILIGENT}: {', '.join(sorted(set(missing)))} not found"
        )
    mi, _, usable = import_mitsuba(["llvm_ad_rgb", "scalar_rgb"], threads=2)
    if not usable:
        sys.exit("no usable Mitsuba variant")
    print(f"Mitsuba {mi.__version__} ({usable[0]}), {args.samples} samples per pixel, 4 bounces, 96 DiLiGenT lights")
    reconstructions = ("classic", "IRT-PS") if args.irtps else ()
    print(
        "| shape | material | "
        + " | ".join(f"`{column}`" for column in COLUMNS)
        + " | `auto` against `none` | lobe share |"
        + "".join(f" {name} |" for name in reconstructions)
    )
    print("|---|---|" + "---|" * (len(COLUMNS) + 2 + len(reconstructions)))
    rows = []
    for name in args.objects:
        height, mask, directions = (
            synthetic_shape(name, args.size) if name in SHAPES else diligent_shape(DILIGENT / name, args.downsample)
        )
        truth = height_to_normals(height, mask)
        irradiance = np.full((len(directions), 3), np.pi, dtype=np.float32)
        scene, renderer = shape_scene(height, mask, directions)
        for material, bsdf in MATERIALS:
            start = time.perf_counter()
            images = render_material(mi, usable[0], scene, renderer, bsdf, args.samples, args.cache)
            errors, share = mode_errors(images, directions, irradiance, mask, truth)
            change = errors["auto"] / errors["none"] - 1
            label = f"{name} ({mask.shape[1]}×{mask.shape[0]}, {int(mask.sum())} px)"
            row = {
                "shape": name,
                "material": material,
                "errors_deg": errors,
                "auto_vs_none": change,
                "lobe_share": share,
            }
            if args.irtps:
                row["reconstruct_deg"] = reconstruction_errors(
                    irtps.Dataset(
                        scene=scene, images=images, mask=mask, gt=irtps.GroundTruth(height=height, normal=truth)
                    )
                )
            rows.append({**row, "seconds": time.perf_counter() - start})
            print(
                f"| {label} | {material} | "
                + " | ".join(f"{errors[column]:.2f}°" for column in COLUMNS)
                + f" | {100 * change:+.0f} % | {100 * share:.0f} % |"
                + "".join(f" {row['reconstruct_deg'][method]:.2f}° |" for method in ("ps", "irtps") if args.irtps),
                flush=True,
            )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
