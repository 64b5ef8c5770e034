"""How bright each image is against a fit: the check that finds a capture's faulty images.

Photometric stereo takes each image's light irradiance as given. An image whose light
misfired, whose exposure differs, or that was taken as the object moved, is brighter or
darker than the fit of all the images says it should be, on most of the object at once; a
robust fit sets it aside pixel by pixel, so the fit barely moves, and the image stands out.
`image_brightness` measures that per image; ``irtps reconstruct`` prints the images farthest
from the others and records every one in ``run.json``, and ``--exclude-images`` leaves out
those the user judges faulty (`irtps.image_selection`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from irtps._checks import check_array, check_mask, check_positive
from irtps.data import pixel_observations, spread_pixels
from irtps.errors import ArgumentError

__all__ = ["MIN_PIXELS", "SAMPLE", "WELL_LIT", "format_image_brightness", "image_brightness"]

#: Least cosine between a pixel's fitted normal and a light for the pixel to count in that
#: light's image (60° from the light): away from grazing light, where the fall-off of real
#: surfaces departs from Lambert's most.
WELL_LIT = 0.5
#: Fewest pixels an image needs for its brightness to be given.
MIN_PIXELS = 20
#: Object pixels measured by default, spread evenly over the mask: the median of a few
#: thousand ratios is within a few thousandths of all of them, at a fraction of the time.
SAMPLE = 4096


def image_brightness(
    images: np.ndarray,
    light_directions: np.ndarray,
    light_irradiance: np.ndarray,
    normals: np.ndarray,
    albedo: np.ndarray,
    mask: np.ndarray,
    *,
    saturation: float | None = None,
    sample: int = SAMPLE,
) -> np.ndarray:
    """Each image's brightness against a Lambertian fit, relative to the other images'.

    For image k: the median, over the pixels of `mask` (`sample` of them, spread evenly over
    it, when it has more) whose fitted normal the light lights well (``n·l`` at least
    `WELL_LIT`) and whose observation is neither saturated nor black, of the observed
    brightness (channels summed) over the fitted one, ``ρ ⊙ E_k · (n·l) / π``; then divided
    by the median over the images. An image whose
    light or exposure is off by a factor shows about that factor; on real objects, sound
    images stay within a few per cent (DiLiGenT ball 0.94–1.01, reading 0.94–1.07).

    Parameters
    ----------
    images : numpy.ndarray
        (K, H, W, 3) linear RGB.
    light_directions, light_irradiance : numpy.ndarray
        (K, 3) each: unit directions toward the lights, RGB irradiance.
    normals, albedo : numpy.ndarray
        (H, W, 3) each: the fit's unit normals and RGB albedo.
    mask : numpy.ndarray
        (H, W) bool: the pixels to use (the fitted ones).
    saturation : float, optional
        Observations with a channel at or above it are left out.
    sample : int
        Most pixels measured.

    Returns
    -------
    numpy.ndarray
        float64 (K,): 1 for an image as bright as the median image; NaN for an image with
        fewer than `MIN_PIXELS` such pixels.

    Raises
    ------
    ArgumentError
        Naming the argument: shapes that disagree, a mask with no pixel, a `saturation`
        that is not positive, a `sample` below 1.

    Examples
    --------
    >>> import numpy as np
    >>> lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8], [0, -0.6, 0.8]])
    >>> normals = np.zeros((8, 8, 3)); normals[..., 2] = 1
    >>> albedo = np.full((8, 8, 3), 0.5)
    >>> images = np.stack([np.full((8, 8, 3), 0.5 * l[2] / np.pi) for l in lights])
    >>> images[3] *= 1.5  # a light brighter than recorded
    >>> image_brightness(images, lights, np.ones((5, 3)), normals, albedo, np.ones((8, 8), bool)).round(3)
    array([1. , 1. , 1. , 1.5, 1. ])
    """
    images = check_array("images", images, (None, None, None, 3), dtype=np.float32, copy=False)
    count, size = images.shape[0], images.shape[1:3]
    directions = check_array("light_directions", light_directions, (count, 3), dtype=np.float64)
    irradiance = check_array("light_irradiance", light_irradiance, (count, 3), dtype=np.float64)
    normals = check_array("normals", normals, (*size, 3), dtype=np.float32, copy=False)
    albedo = check_array("albedo", albedo, (*size, 3), dtype=np.float32, copy=False)
    mask = check_mask(mask, size, match="images", nonempty=True)
    if saturation is not None:
        saturation = check_positive("saturation", saturation)
    if isinstance(sample, bool) or not (isinstance(sample, (int, np.integer)) and sample >= 1):
        raise ArgumentError("sample", f"{sample!r} is not a positive integer")
    chosen = spread_pixels(mask, int(sample))
    mask = np.zeros_like(mask)
    mask.flat[chosen] = True
    observed = pixel_observations(images, mask)  # (K, N, 3)
    # Channel by channel: numpy reduces a last axis of 3 several times slower.
    red, green, blue = observed[..., 0], observed[..., 1], observed[..., 2]
    summed = red + green + blue
    cosine = directions @ normals[mask].T.astype(np.float64)  # (K, N)
    fitted = (irradiance @ albedo[mask].T.astype(np.float64)) * cosine / np.pi
    usable = (cosine >= WELL_LIT) & (fitted > 0) & (summed > 0)
    if saturation is not None:
        usable &= (red < saturation) & (green < saturation) & (blue < saturation)
    ratio = np.divide(summed, fitted, out=np.zeros_like(fitted), where=usable)
    brightness = np.array([np.median(ratio[k, usable[k]]) if usable[k].sum() >= MIN_PIXELS else np.nan for k in range(count)])
    if np.isnan(brightness).all():
        return brightness
    return brightness / np.nanmedian(brightness)


def format_image_brightness(names: Sequence[str], brightness: Sequence[float] | np.ndarray, shown: int = 3) -> str:
    """One line on the images' brightness: its range and the images farthest from the rest.

    Examples
    --------
    >>> format_image_brightness(["001.png", "002.png", "003.png", "004.png"], [1.0, 0.97, 1.52, float("nan")])
    "images' brightness against the fit: 0.97 to 1.52 of the median image's (1 image without enough well-lit pixels); farthest 003.png 1.52, 002.png 0.97, 001.png 1.00"
    """
    values = np.asarray(brightness, dtype=np.float64)
    if len(names) != len(values):
        raise ArgumentError("brightness", f"{len(values)} values for {len(names)} images")
    known = np.flatnonzero(~np.isnan(values))
    if known.size == 0:
        return "images' brightness against the fit: no image has enough well-lit pixels"
    missing = len(values) - known.size
    note = f" ({missing} image{'s' if missing > 1 else ''} without enough well-lit pixels)" if missing else ""
    farthest = known[np.argsort(-np.abs(np.log(values[known])), kind="stable")][:shown]
    listed = ", ".join(f"{names[k]} {values[k]:.2f}" for k in farthest)
    return f"images' brightness against the fit: {values[known].min():.2f} to {values[known].max():.2f} of the median image's{note}; farthest {listed}"
