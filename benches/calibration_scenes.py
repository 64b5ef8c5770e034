#!/usr/bin/env python
"""Light-calibration captures of the same kind as ``../shared/data/calibration/spheres``, with other
lights and the spheres elsewhere, to check that a calibration generalises.

The scene is the shared capture's, as far as its images tell (Mitsuba 3.9.1, ``scalar_rgb``):
this module's scene, given the shared capture's lights and spheres, renders its first image
bit for bit with render seed 0, and the others agree within Monte-Carlo noise (``--compare``):

- the contract frame: x right, y up, z toward the camera, one world unit a pixel; the centre of
  pixel column c, row r is at x = c - W/2, y = H/2 - r;
- the floor: the plane z = 0, a diffuse square of albedo 0.05 and half-side 1000 (its edge
  shows where the chrome sphere mirrors the floor at grazing angles);
- the chrome sphere: Mitsuba's ``roughconductor`` with the measured ``Al``, alpha 0.03 and the
  Beckmann distribution, Mitsuba's default. The shared README says GGX, but its highlights end
  within three pixels of their peak, as Beckmann's do; GGX's long tails are not in its images;
- the matte sphere: diffuse, albedo 0.8;
- both spheres rest on the floor (centre z = radius) and do not overlap in the image;
- the camera: orthographic, at z = 1000 looking down -z, its film W world units wide, box
  pixel filter, independent sampler;
- the integrator: path tracing, ``max_depth`` 4, so the chrome sphere also mirrors the floor
  and the matte sphere;
- one directional light an image, grey.

The lights drawn: directions uniform on the spherical cap within ``max_tilt_deg`` of the view
axis (default 45 degrees: the shared lights are 10 to 42 degrees from it), irradiance 3.3 times
a uniform factor in [0.7, 1.3] (the shared ones: 2.6 to 4.0).

A capture's folder holds, as the shared one: ``exr/NNN.exr`` (linear RGB, float32),
``png/NNN.png`` (sRGB-encoded, 8-bit, clipped, rounded to the nearest level) and
``gt/lights.json`` (``lights``: each ``direction``, unit toward the light, and ``irradiance``
[E, E, E]; ``chrome_sphere`` and ``matte_sphere``: ``center_px`` [column, row], pixels from the
image's top-left corner, and ``radius_px``; a ``note``).

Usage::

    python benches/calibration_scenes.py --out DIR [--count N] [--seed S] [--max-tilt 45]
    python benches/calibration_scenes.py --compare ../shared/data/calibration/spheres

The first renders N captures into DIR/capture_00, DIR/capture_01, ... (capture i from seed
S + i); the second renders a capture's own lights and spheres and prints how far its EXR
images are from the renders, beside how far two renders are from each other.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

try:
    import mitsuba as mi
except ImportError:  # pragma: no cover - depends on the environment
    sys.exit("calibration_scenes.py needs Mitsuba 3: pip install mitsuba (or pip install irtps[bench])")

#: The shared capture's variant, in which this module's scene renders its first image bit for bit.
VARIANT = "scalar_rgb"
mi.set_variant(VARIANT)

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "calibration" / "spheres"
CHROME_BSDF = {"type": "roughconductor", "material": "Al", "distribution": "beckmann", "alpha": 0.03}
MATTE_ALBEDO = 0.8
FLOOR_ALBEDO = 0.05
FLOOR_HALF_SIDE = 1000.0
CAMERA_HEIGHT = 1000.0
MAX_DEPTH = 4
IRRADIANCE = 3.3
IRRADIANCE_SPREAD = 0.3
MAX_TILT_DEG = 45.0
#: Least gap, pixels, between a sphere's circle and the image's border or the other circle.
MARGIN_PX = 2.0
NOTE = "pixel (row, column) of a sphere's centre: row H/2 - y, column W/2 + x; x right, y up, z toward the camera"


def build_scene(spheres: dict, width: int, height: int, spp: int):
    """The Mitsuba scene of a capture, its light still to be aimed (see `render_images`).

    Parameters
    ----------
    spheres : dict
        ``chrome_sphere`` and ``matte_sphere``, each with ``center_px`` ([column, row], pixels
        from the image's top-left corner) and ``radius_px``, as in ``gt/lights.json``.
    width, height : int
        Image size, pixels.
    spp : int
        Samples per pixel.

    Returns
    -------
    mitsuba.Scene
        The scene, with a directional emitter named ``light``.
    """
    transform = mi.ScalarTransform4f

    def sphere(entry: dict, bsdf: dict) -> dict:
        (column, row), radius = entry["center_px"], entry["radius_px"]
        return {
            "type": "sphere",
            "center": [column - width / 2, height / 2 - row, radius],
            "radius": radius,
            "bsdf": bsdf,
        }

    def diffuse(albedo: float) -> dict:
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": albedo}}

    camera = transform().look_at(origin=[0, 0, CAMERA_HEIGHT], target=[0, 0, 0], up=[0, 1, 0])
    return mi.load_dict(
        {
            "type": "scene",
            "sensor": {
                "type": "orthographic",
                "to_world": camera @ transform().scale([width / 2, width / 2, 1]),
                "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": spp},
            },
            "integrator": {"type": "path", "max_depth": MAX_DEPTH},
            "chrome": sphere(spheres["chrome_sphere"], CHROME_BSDF),
            "matte": sphere(spheres["matte_sphere"], diffuse(MATTE_ALBEDO)),
            "floor": {
                "type": "rectangle",
                "to_world": transform().scale([FLOOR_HALF_SIDE, FLOOR_HALF_SIDE, 1]),
                "bsdf": diffuse(FLOOR_ALBEDO),
            },
            "light": {"type": "directional", "direction": [0, 0, -1], "irradiance": {"type": "rgb", "value": 1.0}},
        }
    )


def render_images(scene, lights: list[dict], seeds: list[int]) -> list[np.ndarray]:
    """Render `scene` under each light in turn.

    Parameters
    ----------
    scene : mitsuba.Scene
        A scene from `build_scene`.
    lights : list of dict
        Each with ``direction`` (unit, toward the light, contract frame) and ``irradiance``
        (RGB), as in ``gt/lights.json``.
    seeds : list of int
        Mitsuba's render seed for each light.

    Returns
    -------
    list of numpy.ndarray
        One linear RGB image (H, W, 3) float32 a light.
    """
    params = mi.traverse(scene)
    images = []
    for light, seed in zip(lights, seeds, strict=True):
        travel = [-float(c) for c in light["direction"]]
        up = [0.0, 1.0, 0.0] if abs(travel[1]) < 0.9 else [1.0, 0.0, 0.0]
        # The directional emitter sends its light along its local +z.
        params["light.to_world"] = mi.Transform4f().look_at(origin=[0, 0, 0], target=travel, up=up)
        params["light.irradiance.value"] = mi.Color3f(*[float(e) for e in light["irradiance"]])
        params.update()
        images.append(np.array(mi.render(scene, seed=seed)))
    return images


def srgb8(linear: np.ndarray) -> np.ndarray:
    """A camera's 8-bit image of linear RGB: clipped to [0, 1], sRGB-encoded, rounded.

    Computed in float32, which gives the shared capture's PNG images from its EXR images
    exactly.

    Parameters
    ----------
    linear : numpy.ndarray
        Linear RGB image (H, W, 3).

    Returns
    -------
    numpy.ndarray
        The image (H, W, 3), uint8.
    """
    x = np.clip(np.asarray(linear, dtype=np.float32), 0, 1)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.uint8)


def write_capture(folder: Path, images: list[np.ndarray], truth: dict) -> None:
    """Write a capture in the shared layout: ``exr/NNN.exr``, ``png/NNN.png``, ``gt/lights.json``.

    Parameters
    ----------
    folder : pathlib.Path
        The capture's folder, created if need be.
    images : list of numpy.ndarray
        Linear RGB images (H, W, 3), one a light, in the order of ``truth["lights"]``.
    truth : dict
        The contents of ``gt/lights.json``.
    """
    for sub in ("exr", "png", "gt"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    for k, image in enumerate(images):
        mi.Bitmap(np.asarray(image, dtype=np.float32)).write(str(folder / "exr" / f"{k:03d}.exr"))
        png = mi.Bitmap(srgb8(image))
        png.set_srgb_gamma(True)
        png.write(str(folder / "png" / f"{k:03d}.png"))
    (folder / "gt" / "lights.json").write_text(json.dumps(truth, indent=1))


def random_spheres(rng: np.random.Generator, width: int, height: int, radius_px) -> dict:
    """Random places (and radii) for the two spheres, fully inside the image, apart.

    Each centre is uniform over the places that keep its circle `MARGIN_PX` inside the image;
    a draw whose circles come closer than `MARGIN_PX` is drawn again, so either sphere may be
    left of, right of, above or below the other.

    Parameters
    ----------
    rng : numpy.random.Generator
        Random numbers.
    width, height : int
        Image size, pixels.
    radius_px : tuple
        The chrome and the matte sphere's radius, pixels: each a number, or a pair (low, high)
        to draw it uniformly from.

    Returns
    -------
    dict
        ``chrome_sphere`` and ``matte_sphere`` as in ``gt/lights.json``, centres rounded to
        0.01 pixel.

    Raises
    ------
    ValueError
        When the two spheres do not fit in the image.
    """
    radii = [spec if np.ndim(spec) == 0 else round(float(rng.uniform(*spec)), 2) for spec in radius_px]
    if max(radii) + MARGIN_PX > min(width, height) / 2:
        raise ValueError(f"a sphere of radius {max(radii)} px does not fit in a {width}x{height} image")
    for _ in range(10_000):
        centres = [
            [round(float(rng.uniform(r + MARGIN_PX, size - r - MARGIN_PX)), 2) for size in (width, height)]
            for r in radii
        ]
        if np.hypot(*np.subtract(*centres)) >= sum(radii) + MARGIN_PX:
            return {
                name: {"center_px": centre, "radius_px": radius}
                for name, centre, radius in zip(("chrome_sphere", "matte_sphere"), centres, radii, strict=True)
            }
    raise ValueError(f"spheres of radii {radii} px do not fit side by side in a {width}x{height} image")


def random_lights(rng: np.random.Generator, count: int, max_tilt_deg: float = MAX_TILT_DEG) -> list[dict]:
    """Random grey directional lights, as in ``gt/lights.json``.

    Parameters
    ----------
    rng : numpy.random.Generator
        Random numbers.
    count : int
        Number of lights.
    max_tilt_deg : float
        Largest angle between a light's direction and the view axis (+z), degrees; the
        directions are uniform on that spherical cap.

    Returns
    -------
    list of dict
        Each with ``direction`` (unit, toward the light) and ``irradiance`` [E, E, E], E within
        `IRRADIANCE_SPREAD` of `IRRADIANCE`.
    """
    z = rng.uniform(np.cos(np.radians(max_tilt_deg)), 1.0, count)
    azimuth = rng.uniform(0.0, 2 * np.pi, count)
    side = np.sqrt(1 - z**2)
    strength = IRRADIANCE * rng.uniform(1 - IRRADIANCE_SPREAD, 1 + IRRADIANCE_SPREAD, count)
    return [
        {
            "direction": [float(side[k] * np.cos(azimuth[k])), float(side[k] * np.sin(azimuth[k])), float(z[k])],
            "irradiance": [float(strength[k])] * 3,
        }
        for k in range(count)
    ]


def render_capture(
    folder,
    *,
    seed: int,
    lights: int = 12,
    width: int = 160,
    height: int = 96,
    radius_px=(30, 30),
    spp: int = 64,
    max_tilt_deg: float = MAX_TILT_DEG,
) -> dict:
    """Render and write one calibration capture with random lights and sphere places.

    Parameters
    ----------
    folder : str or pathlib.Path
        Where to write the capture (``exr/``, ``png/``, ``gt/lights.json``).
    seed : int
        Seed of everything random: the spheres' places (and radii), the lights, the renders.
    lights : int
        Number of lights, one image each.
    width, height : int
        Image size, pixels.
    radius_px : tuple
        The chrome and the matte sphere's radius, pixels: each a number, or a pair (low, high)
        to draw it uniformly from.
    spp : int
        Samples per pixel.
    max_tilt_deg : float
        Largest angle between a light's direction and the view axis, degrees.

    Returns
    -------
    dict
        The capture's truth, as written to ``gt/lights.json``.
    """
    rng = np.random.default_rng(seed)
    spheres = random_spheres(rng, width, height, radius_px)
    truth = {"lights": random_lights(rng, lights, max_tilt_deg), **spheres, "note": NOTE}
    seeds = [int(s) for s in rng.integers(0, 2**31, lights)]
    images = render_images(build_scene(spheres, width, height, spp), truth["lights"], seeds)
    write_capture(Path(folder), images, truth)
    return truth


def region_masks(truth: dict, height: int, width: int) -> dict[str, np.ndarray]:
    """Pixels well inside each sphere's circle, and the floor's pixels well outside both.

    Parameters
    ----------
    truth : dict
        A capture's ``gt/lights.json``.
    height, width : int
        Image size, pixels.

    Returns
    -------
    dict of str to numpy.ndarray
        ``chrome``, ``matte`` and ``floor``: boolean masks (H, W), 1.5 pixels clear of the
        circles' edges.
    """
    rows, columns = np.mgrid[0:height, 0:width] + 0.5
    distance = {}
    for name in ("chrome", "matte"):
        (column, row), radius = truth[f"{name}_sphere"]["center_px"], truth[f"{name}_sphere"]["radius_px"]
        distance[name] = np.hypot(columns - column, rows - row) - radius
    return {
        "chrome": distance["chrome"] < -1.5,
        "matte": distance["matte"] < -1.5,
        "floor": (distance["chrome"] > 1.5) & (distance["matte"] > 1.5),
    }


def compare_capture(folder, *, spp: int = 64, seed: int = 0) -> None:
    """Render a capture's own lights and spheres and print how far its EXR images are.

    For each image and region (chrome sphere, matte sphere, floor), the relative difference
    of the region's mean, render over capture minus one; beside it, the same between two
    renders of different seeds, which is the Monte-Carlo noise of such a figure. Also checks
    that `srgb8` gives the capture's PNG images from its EXR images.

    Parameters
    ----------
    folder : str or pathlib.Path
        A capture's folder, in the shared layout.
    spp : int
        Samples per pixel of the renders.
    seed : int
        Render seed of the first image; image k takes ``seed + k``, and the second renders
        ``seed + len(lights) + k``.
    """
    folder = Path(folder)
    truth = json.loads((folder / "gt" / "lights.json").read_text())
    count = len(truth["lights"])
    captured = [np.array(mi.Bitmap(str(folder / "exr" / f"{k:03d}.exr"))) for k in range(count)]
    png_equal = sum(
        np.array_equal(srgb8(image), np.array(mi.Bitmap(str(folder / "png" / f"{k:03d}.png"))))
        for k, image in enumerate(captured)
    )
    height, width = captured[0].shape[:2]
    radius = {truth[name]["radius_px"] for name in ("chrome_sphere", "matte_sphere")}
    print(f"{folder}: {count} images {width}x{height}, sphere radius {sorted(radius)} px")
    print(f"srgb8(EXR) == PNG for {png_equal} of {count} images")
    start = time.perf_counter()
    scene = build_scene(truth, width, height, spp)
    first = render_images(scene, truth["lights"], [seed + k for k in range(count)])
    second = render_images(scene, truth["lights"], [seed + count + k for k in range(count)])
    print(f"rendered 2 x {count} images at {spp} spp in {time.perf_counter() - start:.1f} s")
    masks = region_masks(truth, height, width)
    rows = []
    for ours, again, theirs in zip(first, second, captured, strict=True):
        rows.append(
            [ours[m].mean() / theirs[m].mean() - 1 for m in masks.values()]
            + [ours[m].mean() / again[m].mean() - 1 for m in masks.values()]
        )
    rows = np.array(rows)
    names = list(masks)
    header = "  ".join(f"{n:>8}" for n in names)
    print(
        f"relative difference of region means, render vs capture, then render vs render\n{'image':>8}  {header}  |  {header}"
    )
    for label, row, sign in [
        *((f"{k:5d}", row, "+") for k, row in enumerate(rows)),
        ("mean |.|", np.abs(rows).mean(0), ""),
    ]:
        figures = [f"{v:{sign}8.2%}" for v in row]
        print(f"{label:>8}  " + "  ".join(figures[:3]) + "  |  " + "  ".join(figures[3:]))


def main(argv: list[str] | None = None) -> int:
    """Command line: render captures (``--out``) or compare one with renders (``--compare``).

    Parameters
    ----------
    argv : list of str, optional
        Arguments; ``sys.argv[1:]`` when None.

    Returns
    -------
    int
        Exit status.
    """
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    action = parser.add_mutually_exclusive_group(required=True)
    action.add_argument("--out", type=Path, help="render captures into DIR/capture_00, DIR/capture_01, ...")
    action.add_argument(
        "--compare",
        type=Path,
        nargs="?",
        const=SHARED,
        metavar="FOLDER",
        help=f"render FOLDER's own lights and spheres and compare with its EXR images (default: {SHARED})",
    )
    parser.add_argument("--count", type=int, default=1, help="number of captures (default: 1)")
    parser.add_argument("--seed", type=int, default=0, help="capture i is drawn from seed S + i (default: 0)")
    parser.add_argument(
        "--max-tilt",
        type=float,
        default=MAX_TILT_DEG,
        help=f"largest angle of a light from the view axis, degrees (default: {MAX_TILT_DEG:g})",
    )
    args = parser.parse_args(argv)
    if args.compare:
        compare_capture(args.compare, seed=args.seed)
        return 0
    for i in range(args.count):
        folder = args.out / f"capture_{i:02d}"
        start = time.perf_counter()
        truth = render_capture(folder, seed=args.seed + i, max_tilt_deg=args.max_tilt)
        spheres = ", ".join(
            f"{name.split('_')[0]} at {truth[name]['center_px']} r {truth[name]['radius_px']}"
            for name in ("chrome_sphere", "matte_sphere")
        )
        print(f"{folder}: {len(truth['lights'])} images in {time.perf_counter() - start:.1f} s; {spheres}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
