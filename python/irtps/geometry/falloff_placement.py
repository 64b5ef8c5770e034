"""Where an object stands under point lights near it, from how their light falls off.

Under distant lights, photometric stereo's normals fix the shape's relief but not its
height. Under point lights near the object (contract §4b), each surface point's light
direction and irradiance ``I / r²`` depend on where it stands: the relief stood at the
right height is the one whose Lambertian fit explains the images best. `falloff_placement`
finds that height: it stands the relief at each candidate height (along the camera's rays
for a pinhole: `irtps.geometry.placement.raised`), fits photometric stereo with the lights
at its points, and keeps the height of the smallest relative residual.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from irtps.geometry.placement import Placement, fallback_placement, raised
from irtps.model.data import observation_brightness, pixel_observations, spread_pixels
from irtps.model.scene import PointLight, Scene, lights_at
from irtps.ps.fit import photometric_stereo

__all__ = ["falloff_placement", "falloff_residual"]

#: Lights from which the fit's residual tells heights apart: three fit any surface exactly.
MIN_PLACING_LIGHTS = 4
#: Object pixels compared at most, spread evenly over the mask.
SAMPLE = 4096
#: Heights scanned before the closest one is refined (Brent's method between its neighbours):
#: over the whole range, and near an earlier estimate.
SCAN_STEPS, NEAR_SCAN_STEPS = 24, 6
#: The refined height is found to within this fraction of a pixel's world size.
PRECISION_PIXELS = 0.01


def falloff_residual(
    scene: Scene,
    height: np.ndarray,
    mask: np.ndarray,
    images: np.ndarray,
    *,
    robust: str = "tukey",
    shadow_fraction: float = 0.05,
    saturation: float | None = None,
) -> float:
    """Relative mean absolute residual of photometric stereo with the lights at the points
    of the surface `height` (H, W): ``Σ|fitted − observed| / Σ|observed|`` over the
    observations of `mask`'s pixels that are neither saturated nor in shadow (channels over
    the irradiance summed, below `shadow_fraction` of the pixel's brightest)."""
    points = scene.camera.surface_points(height)[mask]
    directions, irradiance = lights_at(scene, points)
    fit = photometric_stereo(
        images, directions, irradiance, mask, robust=robust, shadow_fraction=shadow_fraction, saturation=saturation
    )
    observed = pixel_observations(images, mask).astype(np.float64)  # (K, N, 3)
    per_light = np.transpose(irradiance, (1, 0, 2))  # (K, N, 3)
    cosine = np.clip(np.einsum("nki,ni->kn", directions, fit.normals[mask]), 0.0, None)
    fitted = fit.albedo[mask][None] * per_light * cosine[..., None] / np.pi
    brightness = observation_brightness(observed.astype(np.float32), per_light.astype(np.float32))
    kept = brightness >= shadow_fraction * brightness.max(axis=0, initial=0.0)
    if saturation is not None:
        kept &= ~np.any(observed >= saturation, axis=-1)
    total = np.abs(observed[kept]).sum()
    return float(np.abs(fitted - observed)[kept].sum() / total) if total > 0 else float("inf")


def falloff_placement(
    scene: Scene,
    relief: np.ndarray,
    mask: np.ndarray,
    images: np.ndarray,
    *,
    robust: str = "tukey",
    shadow_fraction: float = 0.05,
    saturation: float | None = None,
    near: Placement | None = None,
    radius: float = 0.0,
) -> Placement:
    """The base height at which `relief` explains the images best under the scene's point
    lights (`falloff_residual`).

    Parameters
    ----------
    scene : Scene
        With point lights (`irtps.model.scene.PointLight`); a perspective camera's
        orthographic stand-in stands the relief along the pinhole's rays.
    relief : numpy.ndarray
        (H, W) the shape, its mask boundary's median at 0.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    images : numpy.ndarray
        (K, H, W, 3) the images the fit explains.
    robust, shadow_fraction, saturation
        The fit's (`irtps.ps.fit.photometric_stereo`).
    near : Placement, optional
        An earlier estimate for a shape that has since changed: the search is then within
        `radius` of it. By default, heights from the base's depth below the scene's base
        height up to just below the lowest light (and the optical centre) are scanned.
    radius : float
        World units, with `near`.

    Returns
    -------
    Placement
        ``source="falloff"``, its ``object_residual`` the residual at the height found and
        ``object_pixels`` the pixels compared; the fallback (`fallback_placement`), with its
        reason, under fewer than `MIN_PLACING_LIGHTS` lights.
    """
    if len(images) <= MIN_PLACING_LIGHTS - 1:
        return fallback_placement(
            scene,
            f"{len(images)} lights fit any height exactly: the fall-off places the object from {MIN_PLACING_LIGHTS} lights on",
        )
    sample = np.zeros_like(mask)
    sample.flat[spread_pixels(mask, SAMPLE)] = True
    relief = np.where(mask, np.asarray(relief, dtype=np.float64), 0.0)

    def residual(base: float) -> float:
        return falloff_residual(
            scene,
            raised(relief, mask, base, scene),
            sample,
            images,
            robust=robust,
            shadow_fraction=shadow_fraction,
            saturation=saturation,
        )

    low, high = _search_range(scene, relief, mask)
    tolerance = PRECISION_PIXELS * scene.camera.orthographic_pixel_size
    if near is not None:
        low, high = max(low, near.base_height - radius), min(high, near.base_height + radius)
    if high - low > tolerance:
        steps = NEAR_SCAN_STEPS if near is not None else SCAN_STEPS
        bases = np.linspace(low, high, steps + 1)
        values = [residual(float(base)) for base in bases]
        best = int(np.argmin(values))
        left, right = bases[max(best - 1, 0)], bases[min(best + 1, steps)]
        found = minimize_scalar(residual, bounds=(left, right), method="bounded", options={"xatol": tolerance})
        base = float(found.x) if found.fun <= values[best] else float(bases[best])
    else:
        base = 0.5 * (low + high)
    return Placement(
        base_height=base, source="falloff", object_residual=residual(base), object_pixels=int(sample.sum())
    )


def _search_range(scene: Scene, relief: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """Base heights worth scanning: from as far below the scene's base height as the lowest
    point light stands above it, up to where the relief's top would reach the lowest light
    or the optical centre."""
    tops = [light.position[2] for light in scene.lights if isinstance(light, PointLight)]
    pinhole = scene.camera.pinhole
    if pinhole is not None:
        tops.append(pinhole.center_z)
    ceiling = min(tops)
    span = ceiling - scene.base_height
    rise = float(relief[mask].max()) if mask.any() else 0.0
    return scene.base_height - span, ceiling - max(rise, 0.0) - 0.05 * span
