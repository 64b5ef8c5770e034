"""How each image agrees with a fit: the check that finds a capture's faulty images.

Photometric stereo takes each image's light and exposure as given and the object as still.
A robust fit sets a faulty image aside pixel by pixel, so the fit barely moves, and the image
stands out against it: one whose light misfired or whose exposure differs is brighter or
darker than the fit says on most of the object at once (its *brightness*); one taken as the
object or the camera moved disagrees with the fit pixel by pixel, both ways (its *spread*).
`image_agreement` measures both per image; ``irtps reconstruct`` prints the images farthest
from the others and records every one in ``run.json``, and ``--exclude-images`` leaves out
those the user judges faulty (`irtps.io.image_selection`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from irtps._shared.checks import check_array, check_mask, check_positive
from irtps.model.data import pixel_observations, spread_pixels
from irtps.errors import ArgumentError
from irtps.ps.robust_stats import median_and_sigma

__all__ = ["MIN_PIXELS", "SAMPLE", "WELL_LIT", "ImageAgreement", "format_image_agreement", "image_agreement"]

#: Least cosine between a pixel's fitted normal and a light for the pixel to count in that
#: light's image (60° from the light): away from grazing light, where the fall-off of real
#: surfaces departs from Lambert's most.
WELL_LIT = 0.5
#: Fewest pixels an image needs for its figures to be given.
MIN_PIXELS = 20
#: Object pixels measured by default, spread evenly over the mask: the median of a few
#: thousand ratios is within a few thousandths of all of them, at a fraction of the time.
SAMPLE = 4096


@dataclass(frozen=True)
class ImageAgreement:
    """How each image agrees with a fit (`image_agreement`).

    Attributes
    ----------
    brightness : numpy.ndarray
        float64 (K,): the median over the pixels of observed over fitted brightness, over
        the median image's: an image whose light or exposure is off by a factor shows about
        that factor. NaN for an image with too few pixels.
    spread : numpy.ndarray
        float64 (K,): the robust standard deviation (1.4826 × the median absolute deviation)
        over the pixels of the logarithm of that ratio: how far a pixel typically departs
        from the image's brightness, relatively; an image taken as the object moved spreads
        wider than the others. NaN likewise.
    """

    brightness: np.ndarray
    spread: np.ndarray

    def to_dict(self) -> dict[str, list[float | None]]:
        """Each figure as a list, null where not known, for ``run.json``."""
        return {
            name: [None if np.isnan(value) else round(float(value), 4) for value in values]
            for name, values in (("brightness", self.brightness), ("spread", self.spread))
        }

    @classmethod
    def from_dict(cls, record: object) -> ImageAgreement:
        """The figures of `to_dict`.

        Raises
        ------
        ArgumentError
            Naming ``image_agreement``, if `record` is not two lists of numbers (or nulls)
            of one length.
        """
        try:
            figures = [
                np.array([np.nan if value is None else value for value in record[name]], dtype=np.float64)  # type: ignore[index]
                for name in ("brightness", "spread")
            ]
        except (KeyError, TypeError, ValueError):
            figures = []
        if len(figures) != 2 or figures[0].shape != figures[1].shape or figures[0].ndim != 1:
            raise ArgumentError(
                "image_agreement", "expected lists 'brightness' and 'spread' of numbers or nulls, of one length"
            )
        return cls(*figures)


def image_agreement(
    images: np.ndarray,
    light_directions: np.ndarray,
    light_irradiance: np.ndarray,
    normals: np.ndarray,
    albedo: np.ndarray,
    mask: np.ndarray,
    *,
    saturation: float | None = None,
    sample: int = SAMPLE,
) -> ImageAgreement:
    """Each image's agreement with a Lambertian fit: its brightness and its spread.

    For image k, over the pixels of `mask` (`sample` of them, spread evenly over it, when it
    has more) whose fitted normal the light lights well (``n·l`` at least `WELL_LIT`) and
    whose observation is neither saturated nor black, the ratio of the observed brightness
    (channels summed) to the fitted one, ``ρ ⊙ E_k · (n·l) / π``. Brightness: its median,
    over the median image's. Spread: the robust standard deviation of its logarithm. On real
    objects, sound images stay within a few per cent of the median brightness and spread a
    few per cent (more on an object whose folds hold shadows the fit leaves out); an image
    shifted by a few pixels spreads several times wider (``benches/image_faults.py``, whose
    figures are in docs/accuracy.md).

    Parameters
    ----------
    images : numpy.ndarray
        (K, H, W, 3) linear RGB.
    light_directions, light_irradiance : numpy.ndarray
        (K, 3) each: unit directions toward the lights, RGB irradiance; or (N, K, 3) each, at
        each of `mask`'s N pixels (row-major), for lights whose direction changes across the
        object (point lights near it: `irtps.model.scene.lights_at`).
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
    ImageAgreement
        NaN for an image with fewer than `MIN_PIXELS` such pixels.

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
    >>> images[4, ::2] *= 1.1; images[4, 1::2] /= 1.1  # an image that disagrees row by row
    >>> agreement = image_agreement(images, lights, np.ones((5, 3)), normals, albedo, np.ones((8, 8), bool))
    >>> agreement.brightness.round(3), agreement.spread.round(3)
    (array([1. , 1. , 1. , 1.5, 1. ]), array([0.   , 0.   , 0.   , 0.   , 0.141]))
    """
    images = check_array("images", images, (None, None, None, 3), dtype=np.float32, copy=False)
    count, size = images.shape[0], images.shape[1:3]
    normals = check_array("normals", normals, (*size, 3), dtype=np.float32, copy=False)
    albedo = check_array("albedo", albedo, (*size, 3), dtype=np.float32, copy=False)
    mask = check_mask(mask, size, match="images", nonempty=True)
    lights = (int(mask.sum()), count, 3) if np.ndim(light_directions) == 3 else (count, 3)
    directions = check_array("light_directions", light_directions, lights, dtype=np.float64)
    irradiance = check_array("light_irradiance", light_irradiance, lights, dtype=np.float64)
    if saturation is not None:
        saturation = check_positive("saturation", saturation)
    if isinstance(sample, bool) or not (isinstance(sample, (int, np.integer)) and sample >= 1):
        raise ArgumentError("sample", f"{sample!r} is not a positive integer")
    chosen = spread_pixels(mask, int(sample))
    if directions.ndim == 3:
        among = np.searchsorted(np.flatnonzero(mask), chosen)
        directions, irradiance = directions[among], irradiance[among]
    mask = np.zeros_like(mask)
    mask.flat[chosen] = True
    observed = pixel_observations(images, mask)  # (K, N, 3)
    # Channel by channel: numpy reduces a last axis of 3 several times slower.
    red, green, blue = observed[..., 0], observed[..., 1], observed[..., 2]
    summed = red + green + blue
    fitted_normals, fitted_albedo = normals[mask].astype(np.float64), albedo[mask].astype(np.float64)
    if directions.ndim == 3:
        cosine = np.einsum("nki,ni->kn", directions, fitted_normals)  # (K, N)
        fitted = np.einsum("nkc,nc->kn", irradiance, fitted_albedo) * cosine / np.pi
    else:
        cosine = directions @ fitted_normals.T
        fitted = (irradiance @ fitted_albedo.T) * cosine / np.pi
    usable = (cosine >= WELL_LIT) & (fitted > 0) & (summed > 0)
    if saturation is not None:
        usable &= (red < saturation) & (green < saturation) & (blue < saturation)
    log_ratio = np.log(np.divide(summed, fitted, out=np.ones_like(fitted), where=usable))
    brightness, spread = np.full(count, np.nan), np.full(count, np.nan)
    for k in range(count):
        values = log_ratio[k, usable[k]]
        if values.size >= MIN_PIXELS:
            center, spread[k] = median_and_sigma(values)
            brightness[k] = np.exp(center)
    if not np.isnan(brightness).all():
        brightness /= np.nanmedian(brightness)
    return ImageAgreement(brightness, spread)


def format_image_agreement(names: Sequence[str], agreement: ImageAgreement, shown: int = 3) -> list[str]:
    """Two lines on how the images agree with the fit: the range of their brightness and of
    their spread, each with the `shown` images farthest out.

    Examples
    --------
    >>> agreement = ImageAgreement(np.array([1.0, 0.97, 1.52, np.nan]), np.array([0.02, 0.03, 0.02, np.nan]))
    >>> for line in format_image_agreement(["001.png", "002.png", "003.png", "004.png"], agreement, shown=2):
    ...     print(line)
    images' brightness against the fit: 0.97 to 1.52 of the median image's; farthest 003.png 1.52, 002.png 0.97 (1 image with too few well-lit pixels)
    images' spread about the fit: 2.0 to 3.0 % a pixel; widest 002.png 3.0 %, 001.png 2.0 %
    """
    if len(names) != len(agreement.brightness):
        raise ArgumentError("agreement", f"{len(agreement.brightness)} images' figures for {len(names)} names")
    known = np.flatnonzero(~np.isnan(agreement.brightness))
    if known.size == 0:
        return ["images' agreement with the fit: no image has enough well-lit pixels"]
    missing = len(names) - known.size
    note = f" ({missing} image{'s' if missing > 1 else ''} with too few well-lit pixels)" if missing else ""
    brightness, spread = agreement.brightness[known], agreement.spread[known]
    farthest = known[np.argsort(-np.abs(np.log(brightness)), kind="stable")][:shown]
    widest = known[np.argsort(-spread, kind="stable")][:shown]
    return [
        f"images' brightness against the fit: {brightness.min():.2f} to {brightness.max():.2f} of the median image's; farthest "
        + ", ".join(f"{names[k]} {agreement.brightness[k]:.2f}" for k in farthest)
        + note,
        f"images' spread about the fit: {100 * spread.min():.1f} to {100 * spread.max():.1f} % a pixel; widest "
        + ", ".join(f"{names[k]} {100 * agreement.spread[k]:.1f} %" for k in widest),
    ]
