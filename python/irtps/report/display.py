"""Maps of a reconstruction as images to look at: RGB in [0, 1], top row first.

Every function paints the pixels outside the mask `BACKGROUND` grey, which is also what
the normal-map encoding gives a zero normal, so "no object" looks the same everywhere.
"""

from __future__ import annotations

import numpy as np

from irtps._shared.checks import check_image, check_mask, check_positive
from irtps.geometry.surface import height_to_normals

__all__ = ["BACKGROUND", "albedo_to_rgb", "hillshade", "normal_to_rgb", "object_window", "radiance_to_rgb"]

#: Grey level of the pixels outside the mask.
BACKGROUND = 0.5

#: Percentile of the object's channel values that exposure scaling maps to white.
WHITE_PERCENTILE = 99.0


def object_window(mask: np.ndarray, margin: float = 0.05) -> tuple[slice, slice]:
    """The rows and columns to show: the mask's bounding box with a margin, inside the image.

    Parameters
    ----------
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    margin : float
        Extra pixels on each side, as a fraction of the box's larger side (at least 1 pixel).

    Returns
    -------
    (slice, slice)
        Rows and columns, for ``image[rows, cols]``.

    Raises
    ------
    ArgumentError
        If the mask is not (H, W) or is empty.

    Examples
    --------
    >>> import numpy as np
    >>> mask = np.zeros((100, 100), bool); mask[40:60, 10:30] = True
    >>> object_window(mask)
    (slice(39, 61, None), slice(9, 31, None))
    """
    mask = check_mask(mask, nonempty=True)
    rows, cols = np.nonzero(mask)
    extra = max(1, int(round(margin * max(np.ptp(rows) + 1, np.ptp(cols) + 1))))
    height, width = mask.shape
    return (
        slice(max(0, int(rows.min()) - extra), min(height, int(rows.max()) + 1 + extra)),
        slice(max(0, int(cols.min()) - extra), min(width, int(cols.max()) + 1 + extra)),
    )


def normal_to_rgb(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The standard normal-map encoding ``(n + 1) / 2``.

    Red grows with x (right), green with y (up), blue with z (toward the camera); a
    normal facing the camera is (0.5, 0.5, 1), a light blue.

    Parameters
    ----------
    normals : numpy.ndarray
        (H, W, 3) unit normals (nx, ny, nz).
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3) in [0, 1]; `BACKGROUND` outside the mask.

    Raises
    ------
    ArgumentError
        Naming the argument whose shape is wrong.

    Examples
    --------
    >>> import numpy as np
    >>> normals = np.array([[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]])
    >>> normal_to_rgb(normals, np.array([[True, False]])).tolist()
    [[[0.5, 0.5, 1.0], [0.5, 0.5, 0.5]]]
    """
    mask = check_mask(mask, nonempty=True)
    normals = check_image("normals", normals, mask)
    rgb = np.clip((normals + 1.0) / 2.0, 0.0, 1.0)
    return _with_background(rgb, mask)


def albedo_to_rgb(albedo: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, float]:
    """Albedo for display: as it is when it is a reflectance, scaled down when brighter than white.

    An albedo in [0, 1] (a reflectance) is shown unscaled, so 0.5 looks like a mid-grey
    card. When the lights' intensities were unknown the albedo is known only up to scale
    and can exceed 1; it is then divided by the 99th percentile of the object's channel
    values, which keeps the colours and makes that percentile white. The result is
    sRGB-encoded.

    Parameters
    ----------
    albedo : numpy.ndarray
        (H, W, 3) linear RGB albedo.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.

    Returns
    -------
    rgb : numpy.ndarray
        float32 (H, W, 3) sRGB in [0, 1]; `BACKGROUND` outside the mask.
    scale : float
        The factor applied before encoding: 1, or 1 / the 99th percentile.

    Examples
    --------
    >>> import numpy as np
    >>> mask = np.ones((1, 2), bool)
    >>> rgb, scale = albedo_to_rgb(np.full((1, 2, 3), 0.5), mask)
    >>> scale, round(float(rgb[0, 0, 0]), 4)
    (1.0, 0.7354)
    >>> rgb, scale = albedo_to_rgb(np.full((1, 2, 3), 4.0), mask)
    >>> scale, float(rgb[0, 0, 0])
    (0.25, 1.0)
    """
    mask = check_mask(mask, nonempty=True)
    albedo = check_image("albedo", albedo, mask)
    white = _white_level(albedo, mask)
    scale = 1.0 / white if white > 1.0 else 1.0
    return _with_background(_srgb(albedo * scale), mask), scale


def radiance_to_rgb(radiance: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, float]:
    """Linear light (e.g. the estimated inter-reflections) exposed for display.

    The image is scaled so that the 99th percentile of the object's channel values is
    white, which keeps the colours, then sRGB-encoded. An image that is zero everywhere
    on the object stays black (scale 1).

    Parameters
    ----------
    radiance : numpy.ndarray
        (H, W, 3) linear RGB radiance.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.

    Returns
    -------
    rgb : numpy.ndarray
        float32 (H, W, 3) sRGB in [0, 1]; `BACKGROUND` outside the mask.
    scale : float
        The factor applied before encoding.

    Examples
    --------
    >>> import numpy as np
    >>> radiance = np.tile([0.02, 0.01, 0.0], (2, 2, 1))  # reddish everywhere
    >>> rgb, scale = radiance_to_rgb(radiance, np.ones((2, 2), bool))
    >>> round(scale, 6), [round(float(v), 4) for v in rgb[0, 0]]
    (50.0, [1.0, 0.7354, 0.0])
    """
    mask = check_mask(mask, nonempty=True)
    radiance = check_image("radiance", radiance, mask)
    white = _white_level(radiance, mask)
    scale = 1.0 / white if white > 0.0 else 1.0
    return _with_background(_srgb(radiance * scale), mask), scale


def hillshade(
    height: np.ndarray,
    mask: np.ndarray,
    pixel_size: float = 1.0,
    *,
    azimuth_deg: float = 315.0,
    altitude_deg: float = 45.0,
) -> np.ndarray:
    """A shaded relief of a height field: a matte grey surface under one distant light.

    As in cartography, the light comes from ``azimuth_deg`` measured clockwise from the
    image's up direction (315°: the upper left) at ``altitude_deg`` above the image
    plane. Each pixel's grey is ``max(0, n · l)`` with ``n`` the height field's own
    normal (`irtps.geometry.surface.height_to_normals`, which differentiates only between masked
    pixels, so the object's outline casts no false cliff); a flat pixel gets
    ``sin(altitude)``.

    Parameters
    ----------
    height : numpy.ndarray
        (H, W) heights in world units.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    pixel_size : float
        World size of a pixel, which fixes the slopes.
    azimuth_deg, altitude_deg : float
        Direction of the light.

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3) grey in [0, 1]; `BACKGROUND` outside the mask.

    Raises
    ------
    ArgumentError
        Naming the argument that is malformed.

    Examples
    --------
    >>> import numpy as np
    >>> flat = hillshade(np.zeros((2, 2)), np.ones((2, 2), bool))
    >>> round(float(flat[0, 0, 0]), 4)  # sin 45°
    0.7071
    """
    mask = check_mask(mask, nonempty=True)
    height = check_image("height", height, mask, channels=None)
    pixel_size = check_positive("pixel_size", pixel_size)
    azimuth, altitude = np.radians(azimuth_deg), np.radians(altitude_deg)
    light = np.array([np.cos(altitude) * np.sin(azimuth), np.cos(altitude) * np.cos(azimuth), np.sin(altitude)])
    shade = np.clip(height_to_normals(height, mask, pixel_size) @ light, 0.0, 1.0)
    return _with_background(np.repeat(shade[..., None], 3, axis=2), mask)


def _white_level(image: np.ndarray, mask: np.ndarray) -> float:
    return float(np.percentile(image[mask], WHITE_PERCENTILE))


def _srgb(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of values clipped to [0, 1]."""
    linear = np.clip(linear, 0.0, 1.0)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(linear, 1.0 / 2.4) - 0.055)


def _with_background(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return np.where(mask[..., None], rgb, BACKGROUND).astype(np.float32)
