"""Finding the calibration spheres in a capture: the strongest circles of the mean image's
outline, told apart by how each image lights them (a mirror sphere shows one compact
highlight per light; a matte sphere is shaded as a Lambertian surface)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import ndimage

from irtps.calibrate.chrome import find_highlights
from irtps._shared.checks import check_array, check_finite
from irtps.calibrate.circles import (
    Circle,
    as_circle,
    find_circles,
    outermost_outline,
    outline_contrast,
    refine_circle,
)
from irtps.calibrate.matte import fit_matte_circle, fit_shading

__all__ = ["Spheres", "find_spheres", "outline_image"]

#: Circles of the Hough transform examined.
CANDIDATES = 12
#: The radial band, as a fraction of the radius, where a found circle's outline is fitted.
OUTLINE_BAND = 0.1
#: A sphere's outline is this many times steeper than the outline image's median gradient.
MIN_OUTLINE_CONTRAST = 8.0
#: A mirror sphere shows a compact highlight in at least this fraction of the images.
MIN_HIGHLIGHT_SHARE = 0.5
#: A matte sphere's Lambertian fit leaves at most this relative residual (median over images).
MAX_SHADING_RESIDUAL = 0.1


class Spheres(NamedTuple):
    """The calibration spheres of a capture; None for one not found or not given."""

    chrome: Circle | None
    matte: Circle | None


def outline_image(gray: np.ndarray) -> np.ndarray:
    """The log of the capture's mean image, where a sphere's outline is an edge whichever light
    lights it, however dark the sphere or its surroundings; isolated bright or dark pixels
    (noise, dust) are removed by a 3 x 3 median. A thousandth of the image's 99th percentile is
    added before the log (so a highlight's peak does not set the scale).

    Parameters
    ----------
    gray : numpy.ndarray
        (K, H, W) linear brightness of each image.

    Returns
    -------
    numpy.ndarray
        (H, W).

    Raises
    ------
    ArgumentError
        Naming `gray`: not a finite (K, H, W) array.
    """
    mean = _stack(gray).mean(axis=0)
    floor = 1e-3 * max(float(np.percentile(mean, 99)), 1e-30)
    return ndimage.median_filter(np.log(mean + floor), size=3)


def find_spheres(
    gray: np.ndarray, saturated: np.ndarray, *, chrome: Circle | None = None, matte: Circle | None = None
) -> Spheres:
    """The capture's mirror sphere and matte sphere, those not given found.

    Each of the `CANDIDATES` strongest circles of `outline_image` is fitted to its outline in
    every image, each over its 99th percentile (`refine_circle`), and judged: a sphere's
    outline stands out of the image (`outline_contrast` at least `MIN_OUTLINE_CONTRAST`); it is
    a matte sphere when a Lambertian fit explains its pixels within `MAX_SHADING_RESIDUAL`,
    else a mirror sphere when at least half of the images show a compact highlight on it
    (`irtps.calibrate.chrome.find_highlights`), whose outline is the outermost circle about
    its centre that stands out (`outermost_outline`: inside, it shows the edges of what it
    mirrors). The strongest circle of each kind that
    overlaps no sphere already taken is kept; a matte sphere's circle is then fitted to its
    shading (`irtps.calibrate.matte.fit_matte_circle`).

    Parameters
    ----------
    gray : numpy.ndarray
        (K, H, W) linear brightness of each image.
    saturated : numpy.ndarray
        (K, H, W) bool: clipped pixels.
    chrome, matte : Circle, optional
        Circles the user gives, taken as they are.

    Returns
    -------
    Spheres

    Raises
    ------
    ArgumentError
        Naming the argument: `gray` not a finite (K, H, W) array, `saturated` of another shape,
        a circle not three finite numbers with a positive radius.
    """
    gray = _stack(gray)
    saturated = check_array("saturated", saturated, gray.shape, match="gray", dtype=bool)
    chrome = None if chrome is None else as_circle(chrome, "chrome")
    matte = None if matte is None else as_circle(matte, "matte")
    if chrome is not None and matte is not None:
        return Spheres(chrome, matte)
    outline, edges = outline_image(gray), _normalised(gray)
    for found in find_circles(outline, CANDIDATES):
        taken = [circle for circle in (chrome, matte) if circle is not None]
        if any(_overlap(found, circle) for circle in taken):
            continue
        circle = refine_circle(edges, found, band=OUTLINE_BAND)
        if outline_contrast(outline, circle) < MIN_OUTLINE_CONTRAST:
            continue
        if matte is None and _is_matte(gray, saturated, circle):
            matte = fit_matte_circle(gray, saturated, circle)
        elif chrome is None and _is_mirror(gray, circle):
            outer = outermost_outline(outline, circle, MIN_OUTLINE_CONTRAST)
            chrome = circle if outer == circle else refine_circle(edges, outer, band=OUTLINE_BAND)
    return Spheres(chrome, matte)


def _normalised(gray: np.ndarray) -> np.ndarray:
    """Each image over its 99th percentile: every light's edges count alike, and a blurred
    step's steepest point stays at the step (it would not in the log)."""
    scale = np.maximum(np.percentile(gray.reshape(len(gray), -1), 99, axis=1), 1e-30)
    return gray / scale[:, None, None]


def _stack(gray) -> np.ndarray:
    gray = check_array("gray", gray, (None, None, None), dtype=np.float32, copy=False, nonempty=True)
    check_finite("gray", gray)
    return gray


def _is_mirror(gray: np.ndarray, circle: Circle) -> bool:
    return bool(find_highlights(gray, circle).found.mean() >= MIN_HIGHLIGHT_SHARE)


def _is_matte(gray: np.ndarray, saturated: np.ndarray, circle: Circle) -> bool:
    return bool(np.median(fit_shading(gray, saturated, circle).residual) <= MAX_SHADING_RESIDUAL)


def _overlap(first: Circle, second: Circle) -> bool:
    return bool(np.hypot(first.column - second.column, first.row - second.row) < first.radius + second.radius)
