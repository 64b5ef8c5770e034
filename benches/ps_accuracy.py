"""Accuracy of each robust mode of photometric stereo, on every shared data set and on
synthetic glossy pixels.

For each robust mode of ``irtps.photometric_stereo`` (``tukey``, ``lobe``, ``threshold``,
``trim``, ``none``) and for ``auto``, the default of ``irtps reconstruct`` (``lobe`` where the
``irtps.lobe_share`` is at least one half, else ``tukey``), this prints the mean angular
error on the shared data sets (DiLiGenT objects; Mitsuba renders, with and without
inter-reflection) and on synthetic pixels whose normals cover
the visible hemisphere, under 96 lights spread like DiLiGenT's: a Lambertian term plus a
Blinn-Phong highlight of several exponents, with soft cast shadows (the observation scaled
by 0 to 0.3) on a random share of the observations; then reflectance that Lambert's law with a few
outliers does not describe: microfacet plastics and metals (a GGX lobe with Smith
shadowing and Schlick's Fresnel term, as physically based renderers use, spread over many
lights) and rough matte surfaces (Oren-Nayar, non-Lambertian on every observation). The synthetic part needs no shared data.

Usage::

    python benches/ps_accuracy.py                  # shared data sets and synthetic pixels
    python benches/ps_accuracy.py --synthetic-only
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import irtps
from irtps.ps.fit import ROBUST_MODES, choose_robust, lobe_share, photometric_stereo

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
#: (Blinn-Phong exponent, highlight strength, share of observations in soft cast shadow)
GLOSSY_CASES = [
    (5, 0.3, 0.0),
    (10, 0.3, 0.0),
    (10, 0.3, 0.3),
    (50, 0.3, 0.0),
    (50, 0.3, 0.3),
    (200, 0.5, 0.0),
    (200, 0.5, 0.3),
    (1, 0.0, 0.5),
]
#: (name, GGX roughness α, Fresnel reflectance at normal incidence, diffuse albedo)
MICROFACET_CASES = [
    ("GGX plastic, α 0.1", 0.1, 0.04, 0.5),
    ("GGX plastic, α 0.3", 0.3, 0.04, 0.5),
    ("GGX metal, α 0.2, diffuse 0.05", 0.2, 0.9, 0.05),
    ("GGX metal, α 0.4, diffuse 0.05", 0.4, 0.9, 0.05),
    ("GGX metal, α 0.3, diffuse 0.2", 0.3, 0.7, 0.2),
]
#: Oren-Nayar roughness σ (radians) of the rough matte cases.
ROUGH_MATTE_SIGMAS = [0.3, 0.6]


def lights(count: int = 96) -> np.ndarray:
    """Unit directions on a spiral between 20° and 85° of elevation."""
    k = np.arange(count)
    azimuth, elevation = k * 2.4, np.radians(20 + 65 * (k + 0.5) / count)
    return np.stack(
        [np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)], axis=1
    )


def hemisphere_normals(count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, 3) random unit normals facing the camera, fewer near grazing."""
    normals = rng.normal(size=(count, 3))
    normals[:, 2] = np.abs(normals[:, 2]) + 0.3
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def half_vectors(directions: np.ndarray) -> np.ndarray:
    """(K, 3) unit vectors halfway between each light and the camera (along +z)."""
    half = directions + np.array([0.0, 0.0, 1.0])
    return half / np.linalg.norm(half, axis=1, keepdims=True)


def as_images(shading: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(K, count, 1, 3) images of (count, K) shading (radiance × π / E), with 0.5 % noise."""
    shading = shading * (1 + 0.005 * rng.normal(size=shading.shape))
    return np.repeat((shading.T / np.pi)[:, :, None, None], 3, axis=3).astype(np.float32)


def glossy_pixels(
    directions: np.ndarray, exponent: float, strength: float, shadowed: float, count: int = 20000, seed: int = 0
):
    """(K, count, 1, 3) images and (count, 1, 3) true normals of synthetic glossy pixels."""
    rng = np.random.default_rng(seed)
    normals = hemisphere_normals(count, rng)
    cosine = normals @ directions.T
    half = half_vectors(directions)
    highlight = strength * (exponent + 8) / 8 * np.clip(normals @ half.T, 0, None) ** exponent * (cosine > 0)
    shading = 0.6 * np.clip(cosine, 0, None) + highlight
    shadow = np.where(rng.random(shading.shape) < shadowed, 0.3 * rng.random(shading.shape), 1.0)
    return as_images(shading * shadow, rng), normals[:, None, :]


def microfacet_pixels(
    directions: np.ndarray, alpha: float, fresnel0: float, diffuse: float, count: int = 20000, seed: int = 0
):
    """Images and true normals of pixels with a Lambertian term plus a GGX microfacet lobe.

    The lobe is Cook-Torrance's ``D G F / (4 (n·l)(n·v))`` with the GGX distribution of
    roughness ``alpha``, Schlick's approximations of Smith's shadowing (``k = α / 2``) and of
    Fresnel's reflectance (``fresnel0`` at normal incidence); the camera looks along -z.
    """
    rng = np.random.default_rng(seed)
    normals = hemisphere_normals(count, rng)
    cosine = normals @ directions.T
    lit = np.clip(cosine, 1e-4, 1)
    half = half_vectors(directions)
    n_h, n_v, v_h = np.clip(normals @ half.T, 0, 1), normals[:, 2:3], half[:, 2]
    spread = n_h**2 * (alpha**2 - 1) + 1
    distribution = alpha**2 / (np.pi * spread**2)
    k = alpha / 2
    shadowing = n_v / (n_v * (1 - k) + k) * lit / (lit * (1 - k) + k)
    fresnel = fresnel0 + (1 - fresnel0) * (1 - v_h) ** 5
    brdf = diffuse / np.pi + distribution * shadowing * fresnel / (4 * lit * n_v)
    return as_images(np.pi * np.where(cosine > 0, brdf * cosine, 0.0), rng), normals[:, None, :]


def rough_matte_pixels(directions: np.ndarray, sigma: float, albedo: float = 0.6, count: int = 20000, seed: int = 0):
    """Images and true normals of pixels of Oren-Nayar's rough matte reflectance (roughness
    ``sigma`` in radians, qualitative model); the camera looks along -z."""
    rng = np.random.default_rng(seed)
    normals = hemisphere_normals(count, rng)
    cosine = normals @ directions.T
    s2 = sigma**2
    a, b = 1 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)
    view = np.array([0.0, 0.0, 1.0])
    n_v = normals[:, 2:3]
    incident, exitant = np.arccos(np.clip(cosine, -1, 1)), np.arccos(np.clip(n_v, -1, 1))
    light_tangent = directions[None] - cosine[..., None] * normals[:, None]
    view_tangent = view - n_v * normals
    light_tangent /= np.linalg.norm(light_tangent, axis=2, keepdims=True) + 1e-12
    view_tangent /= np.linalg.norm(view_tangent, axis=1, keepdims=True) + 1e-12
    azimuth_cosine = np.clip((light_tangent * view_tangent[:, None]).sum(axis=2), 0, None)
    larger, smaller = np.maximum(incident, exitant), np.minimum(incident, exitant)
    brdf = albedo / np.pi * (a + b * azimuth_cosine * np.sin(larger) * np.tan(smaller))
    return as_images(np.pi * np.where(cosine > 0, brdf * cosine, 0.0), rng), normals[:, None, :]


#: The table's columns: each robust mode of the fit, then the reconstruction's default.
COLUMNS = (*ROBUST_MODES, "auto")


def mode_errors(
    images: np.ndarray,
    directions: np.ndarray,
    irradiance: np.ndarray,
    mask: np.ndarray,
    truth: np.ndarray,
    saturation: float | None = None,
) -> tuple[dict[str, float], float]:
    """The mean angular error of each of `COLUMNS` (``"auto"``: the mode `choose_robust`
    picks from the `lobe_share`, as ``irtps reconstruct`` does), and the lobe share."""
    errors = {}
    for mode in ROBUST_MODES:
        fit = photometric_stereo(images, directions, irradiance, mask, robust=mode, saturation=saturation)
        errors[mode] = mean_error_deg(fit.normals, truth, mask)
    share = lobe_share(images, directions, irradiance, mask, saturation=saturation)
    errors["auto"] = errors[choose_robust(share)]
    return errors, share


def synthetic_row(
    name: str, images: np.ndarray, truth: np.ndarray, directions: np.ndarray, irradiance: np.ndarray
) -> str:
    """The table row of every column's mean angular error on synthetic pixels."""
    errors, _ = mode_errors(images, directions, irradiance, np.ones(truth.shape[:2], bool), truth)
    return _row(name, [errors[column] for column in COLUMNS])


def mean_error_deg(normals: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    cosine = np.clip((normals * truth).sum(axis=-1), -1, 1)
    return float(np.degrees(np.arccos(cosine))[mask].mean())


def shared_rows(shared: Path) -> list[tuple[str, list[float]]]:
    rows = []
    for folder in sorted(p for group in ("diligent", "mitsuba") for p in (shared / group).glob("*") if p.is_dir()):
        data = irtps.load_dataset(folder)
        sets = [("", data.images)] + ([(" gt/direct", data.gt.direct)] if data.gt.direct is not None else [])
        for suffix, images in sets:
            errors, _ = mode_errors(
                images,
                data.scene.light_directions,
                data.scene.light_irradiance,
                data.mask,
                data.gt.normal,
                data.saturation,
            )
            rows.append((folder.name + suffix, [errors[column] for column in COLUMNS]))
            print(_row(*rows[-1]), flush=True)
    return rows


def _row(name: str, errors: list[float]) -> str:
    best = min(errors)
    cells = [f"**{e:.2f}°**" if e == best else f"{e:.2f}°" for e in errors]
    return f"| {name} | " + " | ".join(cells) + " |"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--shared", type=Path, default=SHARED, help="the shared data folder (default: ../shared/data)")
    parser.add_argument("--synthetic-only", action="store_true", help="skip the shared data sets")
    args = parser.parse_args(argv)
    print("| data | " + " | ".join(f"`{m}`" for m in COLUMNS) + " |")
    print("|---|" + "---|" * len(COLUMNS))
    if not args.synthetic_only and args.shared.is_dir():
        shared_rows(args.shared)
    directions = lights()
    irradiance = np.full((len(directions), 3), np.pi, dtype=np.float32)
    for exponent, strength, shadowed in GLOSSY_CASES:
        name = f"synthetic: exponent {exponent}, highlight {strength}, {100 * shadowed:.0f} % soft shadows"
        print(
            synthetic_row(name, *glossy_pixels(directions, exponent, strength, shadowed), directions, irradiance),
            flush=True,
        )
    for name, alpha, fresnel0, diffuse in MICROFACET_CASES:
        print(
            synthetic_row(
                f"synthetic: {name}", *microfacet_pixels(directions, alpha, fresnel0, diffuse), directions, irradiance
            ),
            flush=True,
        )
    for sigma in ROUGH_MATTE_SIGMAS:
        print(
            synthetic_row(
                f"synthetic: Oren-Nayar rough matte, σ {sigma}",
                *rough_matte_pixels(directions, sigma),
                directions,
                irradiance,
            ),
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
