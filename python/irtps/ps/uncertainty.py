"""How precisely the images fix each pixel's normal: the standard error of a least-squares
normal, from the spread of its own fit's residual.

A pixel's brightness under light k (its channels over the light's irradiance, summed) is
fitted as g·lₖ, g = ρn. With the residual's variance s² per observation (over the K' − 3
degrees of freedom of its K' observations), the covariance of g is s²(LᵀL)⁻¹; the part
across n, over ‖g‖, is the normal's angular standard error. Whatever the Lambertian model
does not explain (gloss, shadow edges, sensor noise, inter-reflections) counts in s: it is
the precision the images give the normal under that model, the scale against which IRT-PS
judges whether a correction of the images changes anything (`irtps.irt.early_exit`).
"""

from __future__ import annotations

import numpy as np

from irtps._shared.checks import check_array, check_finite, check_images_finite, check_mask
from irtps.model.data import observation_brightness, pixel_observations
from irtps.ps.fit import checked_lights

__all__ = ["normal_standard_error"]

#: Fewest observations that leave the residual a degree of freedom (three fix g).
MIN_OBSERVATIONS = 4


def normal_standard_error(
    images: np.ndarray,
    light_directions: np.ndarray,
    light_irradiance: np.ndarray,
    mask: np.ndarray,
    usable: np.ndarray | None = None,
) -> np.ndarray:
    """Angular standard error, in degrees, of each masked pixel's least-squares normal.

    Parameters
    ----------
    images : numpy.ndarray
        (K, H, W, 3) images under K distant lights.
    light_directions : numpy.ndarray
        (K, 3) unit vectors toward the lights; or (N, K, 3) at each of `mask`'s N pixels
        (row-major), for point lights near the object (`irtps.model.scene.lights_at`).
    light_irradiance : numpy.ndarray
        (K, 3) each light's RGB irradiance; or (N, K, 3) at each of `mask`'s pixels.
    mask : numpy.ndarray
        bool (H, W): the pixels measured.
    usable : numpy.ndarray, optional
        bool (K, H, W, 1): the observations fitted (e.g. not in shadow, not saturated:
        `irtps.render.residual.compared_observations`); default all.

    Returns
    -------
    numpy.ndarray
        float32 (H, W): NaN outside `mask`, and where fewer than 4 observations, lights
        (nearly) coplanar or a zero brightness leave the normal or its error undetermined.

    Raises
    ------
    ArgumentError
        Naming the argument: arrays of the wrong shape or empty, non-finite images on the
        mask, light directions or irradiance that are not finite or out of range.

    Examples
    --------
    A pixel lit by four lights: exact images fix its normal exactly, and noise of 1 % of its
    brightness leaves it within a fraction of a degree.

    >>> import numpy as np
    >>> lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8]])
    >>> brightness = lights @ np.array([0.0, 0.0, 1.0])
    >>> images = np.repeat(brightness[:, None, None, None], 3, axis=3) / 3
    >>> mask = np.ones((1, 1), bool)
    >>> round(float(normal_standard_error(images, lights, np.ones((4, 3)), mask)[0, 0]), 6)
    0.0
    >>> noisy = images * np.array([1.01, 0.99, 1.01, 0.99])[:, None, None, None]
    >>> 0.1 < float(normal_standard_error(noisy, lights, np.ones((4, 3)), mask)[0, 0]) < 2
    True
    """
    images = check_array("images", images, (None, None, None, 3), dtype=None, nonempty=True, copy=False)
    count = images.shape[0]
    mask = check_mask(mask, images.shape[1:3], match="images")
    check_images_finite("images", images, mask)
    if np.ndim(light_directions) == 3:
        shape = (int(mask.sum()), count, 3)
        directions = check_array("light_directions", light_directions, shape, dtype=np.float64)
        irradiance = check_array("light_irradiance", light_irradiance, shape, dtype=np.float64)
        check_finite("light_directions", directions)
        check_finite("light_irradiance", irradiance)
        per_light = np.transpose(irradiance, (1, 0, 2))  # (K, N, 3)
    else:
        checked_lights(light_directions, light_irradiance, count)
        directions = np.asarray(light_directions, dtype=np.float64)
        per_light = np.asarray(light_irradiance, dtype=np.float64)[:, None, :]
    error = np.full(mask.shape, np.nan, dtype=np.float32)
    if not mask.any():
        return error
    # Each pixel's light directions, (N, K, 3) whether shared or its own.
    pixel_directions = np.broadcast_to(directions, (int(mask.sum()), count, 3))
    brightness = observation_brightness(pixel_observations(images, mask), per_light.astype(np.float32)).astype(
        np.float64
    )  # (K, N)
    weight = (
        np.ones_like(brightness)
        if usable is None
        else pixel_observations(check_array("usable", usable, (count, *mask.shape, 1), dtype=bool, copy=False), mask)[
            ..., 0
        ]
    ).astype(np.float64)
    normal_matrix = np.einsum("kn,nki,nkj->nij", weight, pixel_directions, pixel_directions)
    determined = (weight.sum(axis=0) >= MIN_OBSERVATIONS) & (np.linalg.det(normal_matrix) > 1e-9)
    inverse = np.zeros_like(normal_matrix)
    inverse[determined] = np.linalg.inv(normal_matrix[determined])
    g = np.einsum("nij,nj->ni", inverse, np.einsum("kn,nki,kn->ni", weight, pixel_directions, brightness))
    misfit = brightness - np.einsum("nki,ni->kn", pixel_directions, g)
    variance = (weight * misfit**2).sum(axis=0) / np.maximum(weight.sum(axis=0) - 3, 1)
    length = np.linalg.norm(g, axis=1)
    determined &= length > 0
    normal = g / np.where(length > 0, length, 1.0)[:, None]
    across = np.eye(3) - normal[:, :, None] * normal[:, None, :]
    spread = np.einsum("nij,njk,nki->n", across, inverse, across) * variance
    values = np.degrees(np.sqrt(np.maximum(spread, 0.0)) / np.where(length > 0, length, 1.0))
    error[mask] = np.where(determined, values, np.nan)
    return error
