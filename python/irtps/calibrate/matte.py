"""Light directions and strengths from a matte (Lambertian) sphere: its shading under each
light, ``rho E max(0, n.l) / pi`` at the sphere's known normals (`irtps.calibrate.chrome.sphere_window`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import optimize

from irtps.calibrate.chrome import sphere_window
from irtps.calibrate.circles import Circle

__all__ = ["Shading", "fit_matte_circle", "fit_shading", "matte_irradiance"]

#: The part of the sphere's radius whose pixels are fitted (the rim's pixels also see the floor).
FIT_RADIUS = 0.95
#: Pixels fitted: lit at least this much (n.l), away from the shadow's edge, where the light
#: bounced from the surroundings weighs most.
MIN_COSINE = 0.15
#: Pixels whose strength is taken: lit at least this much (n.l).
STRENGTH_COSINE = 0.3
#: Pixels further from the fit than this many robust standard deviations of its residual are
#: left out of the next round (noise spikes, dust).
OUTLIER = 5.0
#: The part of the sphere's radius whose pixels fit its circle (`fit_matte_circle`).
CIRCLE_FIT_RADIUS = 0.9
#: About how many pixels fit the circle (every n-th is taken, for large spheres).
CIRCLE_FIT_PIXELS = 20000
#: Rounds of choosing the lit pixels by the fit and fitting them again.
ROUNDS = 5


class Shading(NamedTuple):
    """The Lambertian fit to a sphere's pixels under each light."""

    #: (K, 3) unit vectors toward the lights.
    directions: np.ndarray
    #: (K,) the fit's scale: albedo times irradiance over pi.
    scale: np.ndarray
    #: (K,) the fit's RMS residual over the fitted pixels, relative to their RMS brightness.
    residual: np.ndarray


def fit_shading(gray: np.ndarray, saturated: np.ndarray, circle: Circle) -> Shading:
    """Each light's direction and scale from a Lambertian sphere: ``I = n . b`` by least squares
    over the pixels it lights, b = scale x direction; each round fits again the pixels the last
    fit lights (n.l above `MIN_COSINE`) and explains (within `OUTLIER` robust standard
    deviations).

    Parameters
    ----------
    gray : numpy.ndarray
        (K, H, W) linear brightness of each image.
    saturated : numpy.ndarray
        (K, H, W) bool: pixels clipped in any channel, left out.
    circle : Circle
        The sphere's outline.

    Returns
    -------
    Shading
        A light that lights fewer than 3 unclipped pixels has direction (0, 0, 0) and residual inf.
    """
    window = sphere_window(circle, gray.shape[1:])
    disk = window.fraction < FIT_RADIUS
    pixel_normals = window.normals[disk]
    seen, clipped = window.of(gray), window.of(saturated)
    directions = np.zeros((len(gray), 3))
    scales = np.zeros(len(gray))
    residuals = np.full(len(gray), np.inf)
    for k in range(len(gray)):
        values, usable = seen[k][disk], ~clipped[k][disk]
        chosen = usable & (values > 0.1 * values[usable].max()) if usable.any() else usable
        for _ in range(ROUNDS):
            if chosen.sum() < 3:
                break
            vector = np.linalg.lstsq(pixel_normals[chosen], values[chosen], rcond=None)[0]
            scale = float(np.linalg.norm(vector))
            if scale == 0.0:
                break
            directions[k], scales[k] = vector / scale, scale
            error = values[chosen] - pixel_normals[chosen] @ vector
            residuals[k] = float(np.sqrt(np.mean(error**2) / max(np.mean(values[chosen] ** 2), 1e-30)))
            error = values - pixel_normals @ vector
            spread = 1.4826 * np.median(np.abs(error[chosen]))
            chosen = usable & (pixel_normals @ directions[k] > MIN_COSINE) & (np.abs(error) <= OUTLIER * spread)
    return Shading(directions, scales, residuals)


def fit_matte_circle(gray: np.ndarray, saturated: np.ndarray, circle: Circle) -> Circle:
    """A matte sphere's circle fitted to its shading: the centre and radius whose normals let
    a Lambertian fit explain the sphere's lit pixels best.

    The outline of a matte sphere is a poor ruler: its shading falls steeply toward the rim
    under most lights, which moves the steepest edge inward, and the rim also sees the floor.
    The shading inside does not have these faults, and the normals it is explained with depend
    on the centre and the radius. The pixels are those `fit_shading` fits with `circle`,
    within 0.9 of its radius; for a trial circle, each light's ``b`` is solved by least squares
    (variable projection) and the residuals of all lights are minimised over the circle's three
    numbers.

    Parameters
    ----------
    gray : numpy.ndarray
        (K, H, W) linear brightness of each image.
    saturated : numpy.ndarray
        (K, H, W) bool: clipped pixels, left out.
    circle : Circle
        The outline's circle, within a pixel or so.

    Returns
    -------
    Circle
        `circle` itself when fewer than 3 lights light enough pixels to fit.
    """
    shading = fit_shading(gray, saturated, circle)
    window = sphere_window(circle, gray.shape[1:])
    index_rows, index_columns = np.nonzero(window.fraction < CIRCLE_FIT_RADIUS)
    step = max(1, len(index_rows) // CIRCLE_FIT_PIXELS)
    index_rows, index_columns = index_rows[::step], index_columns[::step]
    rows, columns = window.centre_rows[index_rows, index_columns], window.centre_columns[index_rows, index_columns]
    pixel_normals = window.normals[index_rows, index_columns]
    seen, clipped = window.of(gray), window.of(saturated)
    chosen = []
    for k in np.flatnonzero(np.isfinite(shading.residual)):
        values = seen[k][index_rows, index_columns]
        error = values - shading.scale[k] * pixel_normals @ shading.directions[k]
        spread = 1.4826 * np.median(np.abs(error))
        lit = (pixel_normals @ shading.directions[k] > MIN_COSINE) & (np.abs(error) <= OUTLIER * spread)
        lit &= ~clipped[k][index_rows, index_columns]
        if lit.sum() >= 3:
            chosen.append((values[lit], rows[lit], columns[lit]))
    if len(chosen) < 3:
        return circle

    def residuals(parameters: np.ndarray) -> np.ndarray:
        column, row, radius = parameters
        parts = []
        for values, pixel_rows, pixel_columns in chosen:
            x = (pixel_columns - column) / radius
            y = -(pixel_rows - row) / radius
            trial = np.stack([x, y, np.sqrt(np.clip(1.0 - x**2 - y**2, 0.0, 1.0))], axis=1)
            vector = np.linalg.lstsq(trial, values, rcond=None)[0]
            parts.append((values - trial @ vector) / max(float(np.sqrt(np.mean(values**2))), 1e-30))
        return np.concatenate(parts)

    fitted = optimize.least_squares(residuals, np.array(circle), x_scale=[1.0, 1.0, 1.0], diff_step=1e-4)
    return Circle(*(float(value) for value in fitted.x))


def matte_irradiance(
    images: np.ndarray, saturated: np.ndarray, circle: Circle, directions: np.ndarray, albedo: float
) -> np.ndarray:
    """Each light's RGB irradiance from a matte sphere of known albedo: the median of
    ``pi I / (albedo n.l)`` over the sphere's well-lit, unclipped pixels.

    Parameters
    ----------
    images : numpy.ndarray
        (K, H, W, 3) linear images.
    saturated : numpy.ndarray
        (K, H, W) bool: pixels clipped in any channel, left out.
    circle : Circle
        The sphere's outline.
    directions : numpy.ndarray
        (K, 3) unit vectors toward the lights.
    albedo : float
        The sphere's albedo (1.0 gives irradiances relative to a white sphere).

    Returns
    -------
    numpy.ndarray
        (K, 3); NaN for a light that lights none of the sphere's pixels well.
    """
    window = sphere_window(circle, images.shape[1:3])
    disk = window.fraction < FIT_RADIUS
    seen, clipped = window.of(images), window.of(saturated)
    irradiance = np.full((len(images), 3), np.nan)
    for k in range(len(images)):
        cosine = window.normals[disk] @ directions[k]
        lit = (cosine > STRENGTH_COSINE) & ~clipped[k][disk]
        if lit.any():
            values = seen[k][disk][lit]
            irradiance[k] = np.median(np.pi * values / (albedo * cosine[lit, None]), axis=0)
    return irradiance
