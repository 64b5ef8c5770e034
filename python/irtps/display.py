"""Maps of a reconstruction as images to look at: RGB in [0, 1], top row first.

Every function paints the pixels outside the mask `BACKGROUND` grey, which is also what
the normal-map encoding gives a zero normal, so "no object" looks the same everywhere.
"""

from __future__ import annotations

import numpy as np

from irtps.errors import DatasetError
from irtps.surface import height_to_normals

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
    DatasetError
        If the mask is not (H, W) or is empty.

    Examples
    --------
    >>> import numpy as np
    >>> mask = np.zeros((100, 100), bool); mask[40:60, 10:30] = True
    >>> object_window(mask)
    (slice(39, 61, None), slice(9, 31, None))
    """
    mask = _check_mask(mask)
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
    DatasetError
        Naming the argument whose shape is wrong.

    Examples
    --------
    >>> import numpy as np
    >>> normals = np.array([[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]])
    >>> normal_to_rgb(normals, np.array([[True, False]])).tolist()
    [[[0.5, 0.5, 1.0], [0.5, 0.5, 0.5]]]
    """
    mask = _check_mask(mask)
    normals = _check_image("normals", normals, mask)
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
    mask = _check_mask(mask)
    albedo = _check_image("albedo", albedo, mask)
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
    mask = _check_mask(mask)
    radiance = _check_image("radiance", radiance, mask)
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
    normal (`irtps.surface.height_to_normals`, which differentiates only between masked
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
    DatasetError
        Naming the argument that is malformed.

    Examples
    --------
    >>> import numpy as np
    >>> flat = hillshade(np.zeros((2, 2)), np.ones((2, 2), bool))
    >>> round(float(flat[0, 0, 0]), 4)  # sin 45°
    0.7071
    """
    mask = _check_mask(mask)
    height = np.asarray(height, dtype=np.float64)
    if height.shape != mask.shape:
        raise DatasetError(f"height has shape {height.shape}, expected {mask.shape} to match the mask")
    if not np.isfinite(height[mask]).all():
        raise DatasetError("height is not finite on some masked pixels")
    if not (np.isfinite(pixel_size) and pixel_size > 0):
        raise DatasetError(f"pixel_size must be a positive number, got {pixel_size!r}")
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


def _check_mask(mask) -> np.ndarray:
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise DatasetError(f"mask has shape {mask.shape}, expected (H, W)")
    mask = mask.astype(bool)
    if not mask.any():
        raise DatasetError("mask is empty: no object pixel to show")
    return mask


def _check_image(name: str, image, mask: np.ndarray) -> np.ndarray:
    image = np.asarray(image, dtype=np.float64)
    if image.shape != (*mask.shape, 3):
        raise DatasetError(f"{name} has shape {image.shape}, expected {(*mask.shape, 3)} to match the mask")
    if not np.isfinite(image[mask]).all():
        raise DatasetError(f"{name} is not finite on some masked pixels")
    return image
