"""IRT-PS against classic photometric stereo on synthesized scenes unlike the shared ones.

The shared Mitsuba scenes are few, and scenes made the same way but not shared decide
whether IRT-PS generalises. This renders stand-ins with irtps's own renderer (80×80 pixels,
12 lights, 4 bounces, 256 paths a pixel): raised boundaries, textured albedo, a floor with
and without a Cornell box, no floor, each shape filling the frame (``fill``: its edges
leave the image, no floor or wall in view), seen through a pinhole (``irtps synth --camera
perspective``) and lit by point lights near it (``--lights-near``, a rig's LEDs). For each
it prints classic PS's and IRT-PS's mean angular error (defaults, as ``irtps
reconstruct``), and the share of the gap to the floor (classic PS on the direct-only
images) that IRT-PS closes.

With ``--renderer mitsuba`` Mitsuba 3 renders them instead, as the shared scenes were made
(``path`` integrator, 4 bounces at 256 samples per pixel for the images, direct light only
at 64 for the ground truth, ``independent`` sampler, the very triangles of
``Renderer.mesh_arrays()``), under 12 lights drawn at random 10–45° from the camera axis (a
fresh draw per case, seeded; point lights at the case's distance in those directions), and
nine variations follow (`MITSUBA_VARIATIONS`: dark, bright and coloured objects, other wall
colours, 6 and 24 lights, no floor). irtps then
reconstructs images that its own renderer did not make, with Mitsuba's noise, as on unseen
scenes. Before a case is used, Mitsuba's direct images must agree with irtps's within 3 %
(mean absolute difference over the mean), else the script stops.

With ``--noise-limit`` each case also reports the images' noise limit: classic PS on the
images less their expected inter-reflected light (irtps's rendering of the true scene at
1024 paths a pixel). The floor comes from direct-only images, which lack the Monte-Carlo
noise that the inter-reflected light brings into the images; no correction removes that
noise, so the gap to this limit is the share that IRT-PS can close.

Usage::

    python benches/irtps_synthetic.py [--renderer irtps|mitsuba] [--only TEXT ...] [--noise-limit]
        [--json synthetic.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from irtps_accuracy import SHARED_BOUNCES, angular_error, floor_error, noise_limit_error

import irtps
from irtps.model.data import Dataset, GroundTruth
from irtps.errors import IrtpsWarning
from irtps.model.scene import Light
from irtps.render.synth import SHAPES, near_lights

#: The stand-ins' image width and height, pixels.
SIZE = 80

#: (label, synthesize keywords)
CASES = [
    ("pedestal, textured, Cornell", {"shape": "pedestal", "albedo": "textured", "environment": "cornell"}),
    ("cavity, textured, Cornell", {"shape": "cavity", "albedo": "textured", "environment": "cornell"}),
    (
        "relief, textured, Cornell, base 10",
        {"shape": "relief", "albedo": "textured", "environment": "cornell", "base": 10.0},
    ),
    ("cap, Cornell, base 12", {"shape": "cap", "environment": "cornell", "base": 12.0}),
    ("grooves, textured, no floor", {"shape": "grooves", "albedo": "textured", "environment": "none"}),
    ("pedestal, floor only, base 16", {"shape": "pedestal", "environment": "none", "floor": True, "base": 16.0}),
    ("cavity, Cornell, base 20", {"shape": "cavity", "environment": "cornell", "base": 20.0}),
    *(
        (f"{shape}, fills the frame, Cornell", {"shape": shape, "environment": "cornell", "fill": True})
        for shape in SHAPES
    ),
    *(
        (f"{shape}, fills the frame, no floor", {"shape": shape, "environment": "none", "fill": True})
        for shape in ("relief", "grooves")
    ),
    ("cap, pinhole, Cornell", {"shape": "cap", "environment": "cornell", "camera": "perspective"}),
    (
        "cavity, textured, pinhole, Cornell",
        {"shape": "cavity", "albedo": "textured", "environment": "cornell", "camera": "perspective"},
    ),
    ("pedestal, pinhole, Cornell", {"shape": "pedestal", "environment": "cornell", "camera": "perspective"}),
    ("grooves, pinhole, no floor", {"shape": "grooves", "environment": "none", "camera": "perspective"}),
    (
        "relief, pinhole, floor only",
        {"shape": "relief", "environment": "none", "floor": True, "camera": "perspective"},
    ),
    ("cap, LEDs 2 widths away, Cornell", {"shape": "cap", "environment": "cornell", "lights_near": 2.0}),
    (
        "cavity, textured, LEDs 1.5 widths away, Cornell",
        {"shape": "cavity", "albedo": "textured", "environment": "cornell", "lights_near": 1.5},
    ),
    (
        "grooves, LEDs 2 widths away, pinhole, no floor",
        {"shape": "grooves", "environment": "none", "camera": "perspective", "lights_near": 2.0},
    ),
]


#: Mitsuba's bounces and samples per pixel, as the shared scenes were rendered.
MITSUBA_BOUNCES, MITSUBA_SAMPLES, MITSUBA_DIRECT_SAMPLES = SHARED_BOUNCES, 256, 64
#: Largest mean absolute difference between Mitsuba's and irtps's direct images, over their mean.
DIRECT_TOLERANCE = 0.03


#: With ``--renderer mitsuba``, these too: (label, synthesize keywords, changes) where the
#: changes are a uniform RGB ``albedo`` for the object, the Cornell box's ``walls`` (left,
#: right, back, front), the ``lights`` count and their ``zenith_deg`` range.
MITSUBA_VARIATIONS = [
    ("grooves, Cornell", {"shape": "grooves", "environment": "cornell"}, {}),
    ("cavity, albedo 0.3, Cornell", {"shape": "cavity", "environment": "cornell"}, {"albedo": (0.3, 0.3, 0.3)}),
    (
        "cap, albedo 0.95, Cornell, base 6",
        {"shape": "cap", "environment": "cornell", "base": 6.0},
        {"albedo": (0.95, 0.95, 0.95)},
    ),
    ("relief, red, Cornell", {"shape": "relief", "environment": "cornell"}, {"albedo": (0.85, 0.25, 0.15)}),
    (
        "pedestal, blue and yellow walls",
        {"shape": "pedestal", "environment": "cornell"},
        {"walls": ((0.1, 0.2, 0.7), (0.8, 0.7, 0.1), (0.7, 0.7, 0.7), (0.7, 0.7, 0.7))},
    ),
    (
        "cavity, textured, 24 lights 5–60°",
        {"shape": "cavity", "environment": "cornell", "albedo": "textured"},
        {"lights": 24, "zenith_deg": (5.0, 60.0)},
    ),
    (
        "grooves, textured, 6 lights, no floor",
        {"shape": "grooves", "environment": "none", "albedo": "textured"},
        {"lights": 6},
    ),
    ("cap, no floor", {"shape": "cap", "environment": "none"}, {}),
    ("relief, floor only", {"shape": "relief", "environment": "none", "floor": True}, {}),
]


def random_lights(
    count: int, rng: np.random.Generator, zenith_deg: tuple[float, float] = (10.0, 45.0)
) -> tuple[Light, ...]:
    """`count` lights of irradiance π, uniform over the cap `zenith_deg` from the camera axis."""
    cos_z = rng.uniform(np.cos(np.radians(zenith_deg[1])), np.cos(np.radians(zenith_deg[0])), count)
    azimuth = rng.uniform(0, 2 * np.pi, count)
    radial = np.sqrt(1 - cos_z**2)
    directions = np.stack([radial * np.cos(azimuth), radial * np.sin(azimuth), cos_z], axis=1)
    return tuple(Light(direction=d, irradiance=np.full(3, np.pi)) for d in directions)


def mitsuba_dataset(mi, variant: str, keywords: dict, seed: int, changes: dict | None = None) -> Dataset:
    """The case's object and surroundings under random lights, with `changes` (see
    `MITSUBA_VARIATIONS`), rendered by Mitsuba."""
    from mitsuba_scene import MitsubaScene

    from irtps.render.renderer import make_renderer, render

    changes = changes or {}
    geometry, _ = irtps.synthesize(size=SIZE, lights=12, bounces=0, samples=1, **keywords)
    gt, mask = geometry.gt, geometry.mask
    lights = random_lights(
        changes.get("lights", 12), np.random.default_rng(seed), changes.get("zenith_deg", (10.0, 45.0))
    )
    if keywords.get("lights_near") is not None:
        lights = tuple(near_lights(list(lights), keywords["lights_near"] * SIZE))
    scene = replace(geometry.scene, lights=lights)
    if "walls" in changes:
        scene = replace(
            scene,
            environment=replace(
                scene.environment,
                **dict(zip(("albedo_left", "albedo_right", "albedo_back", "albedo_front"), changes["walls"])),
            ),
        )
    albedo = gt.albedo
    if "albedo" in changes:
        albedo = np.where(mask[..., None], np.asarray(changes["albedo"], dtype=np.float32), 0.0).astype(np.float32)
    renderer = make_renderer(scene, gt.height, albedo, mask)
    mitsuba = MitsubaScene(mi, variant, renderer, scene, MITSUBA_BOUNCES, "independent")
    count = len(scene.lights)
    images = np.stack([mitsuba.render(k, MITSUBA_SAMPLES, seed + k)[0] for k in range(count)])
    direct = np.stack(
        [mitsuba.render(k, MITSUBA_DIRECT_SAMPLES, seed + count + k, direct_only=True)[0] for k in range(count)]
    )
    ours = render(
        scene,
        gt.height,
        albedo,
        mask,
        bounces=0,
        samples=MITSUBA_DIRECT_SAMPLES,
        direct_samples=MITSUBA_DIRECT_SAMPLES,
        seed=seed,
    ).direct
    difference = float(np.abs(direct - ours).mean() / ours.mean())
    if difference > DIRECT_TOLERANCE:
        sys.exit(
            f"Mitsuba's direct images differ from irtps's by {100 * difference:.1f} % of their mean: not the same scene"
        )
    truth = GroundTruth(height=gt.height, normal=gt.normal, albedo=albedo, direct=direct, depth=gt.depth)
    return Dataset(scene=scene, images=images, mask=mask, gt=truth, source=f"mitsuba:{geometry.source}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--renderer",
        choices=["irtps", "mitsuba"],
        default="irtps",
        help="which renderer makes the images (default: irtps)",
    )
    parser.add_argument("--only", nargs="+", metavar="TEXT", help="the cases whose label holds one of these")
    parser.add_argument(
        "--noise-limit",
        action="store_true",
        help="also fit the images less their expected inter-reflections (the images' noise limit) and report "
        "the share of the gap to it that IRT-PS closes",
    )
    parser.add_argument("--json", type=Path, help="write the rows here")
    args = parser.parse_args(argv)
    if args.renderer == "mitsuba":
        from mitsuba_scene import import_mitsuba

        mi, _, usable = import_mitsuba(["llvm_ad_rgb", "scalar_rgb"], threads=2)
        if not usable:
            sys.exit("no usable Mitsuba variant")
    rows = []
    extra = " noise limit | its gap closed |" if args.noise_limit else ""
    print(f"| case | classic PS | IRT-PS | floor | gap closed |{extra} stop | first turn / noise (medians) |")
    print("|---|---|---|---|---|" + "---|---|" * args.noise_limit + "---|---|")
    cases = [(label, keywords, {}) for label, keywords in CASES]
    if args.renderer == "mitsuba":
        cases += MITSUBA_VARIATIONS
    if args.only:
        cases = [case for case in cases if any(text in case[0] for text in args.only)]
    for index, (label, keywords, changes) in enumerate(cases):
        if args.renderer == "mitsuba":
            dataset = mitsuba_dataset(mi, usable[0], keywords, seed=1000 * (index + 1), changes=changes)
        else:
            dataset, _ = irtps.synthesize(size=SIZE, lights=12, bounces=4, samples=256, **keywords)
        classic = angular_error(dataset, irtps.reconstruct(dataset).normals)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IrtpsWarning)
            result = irtps.reconstruct(dataset, "irtps")
        corrected = angular_error(dataset, result.normals)
        floor = floor_error(dataset)
        closed = (classic - corrected) / (classic - floor)
        stop = result.stop
        correction = None if stop is None or stop.correction is None else stop.correction.to_dict()
        rows.append(
            {
                "case": label,
                "classic_deg": classic,
                "irtps_deg": corrected,
                "floor_deg": floor,
                "gap_closed": closed,
                "stop": None if stop is None else stop.reason,
                "correction": correction,
            }
        )
        turn = "n/a" if correction is None else f"{correction['change_deg']:.2f}° / {correction['noise_deg']:.2f}°"
        limit_cells = ""
        if args.noise_limit:
            limit = noise_limit_error(dataset, MITSUBA_BOUNCES)
            rows[-1]["noise_limit_deg"] = limit
            rows[-1]["gap_to_noise_limit_closed"] = (classic - corrected) / (classic - limit)
            limit_cells = f" {limit:.2f}° | {100 * rows[-1]['gap_to_noise_limit_closed']:.1f} % |"
        print(
            f"| {label} | {classic:.2f}° | {corrected:.2f}° | {floor:.2f}° | {100 * closed:.1f} % |{limit_cells} {stop.reason if stop else 'n/a'} | {turn} |",
            flush=True,
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
