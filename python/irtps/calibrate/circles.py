"""Circles in an image: a sphere's outline, found by a Hough transform and fitted to sub-pixel
accuracy.

Coordinates are in pixels from the image's top-left corner: pixel (row i, column j) covers
``[j, j + 1] x [i, i + 1]`` and its centre is ``(j + 0.5, i + 0.5)``.
"""

from __future__ import annotations

import re
from typing import NamedTuple

import numpy as np
from scipy import ndimage, optimize

from irtps._shared.checks import check_array, check_finite, check_integer, check_number
from irtps.errors import ArgumentError

__all__ = [
    "Circle",
    "as_circle",
    "find_circles",
    "outermost_outline",
    "outline_contrast",
    "parse_circle",
    "refine_circle",
]

#: The longest side, in pixels, of the image the Hough transform searches (a larger one is
#: reduced by whole-pixel block means first).
HOUGH_SIDE_PX = 320
#: The smallest radius searched, in pixels of the searched image.
MIN_RADIUS_PX = 6
#: Radial samples per pixel along each ray of the sub-pixel fit.
SAMPLES_PER_PX = 8
#: An outline beyond a circle is at least this fraction as steep as the circle's own (a
#: mirror sphere's outline, where it mirrors what stands behind it, can be a tenth as steep as
#: the edges it mirrors).
MIN_RELATIVE_STEEPNESS = 0.01
#: Rays around the circle of the sub-pixel fit.
RAYS = 360


class Circle(NamedTuple):
    """A circle in an image, in pixels from the top-left corner (module docstring)."""

    column: float
    row: float
    radius: float

    def scaled(self, factor: float) -> Circle:
        """The same circle in an image `factor` times as large."""
        return Circle(self.column * factor, self.row * factor, self.radius * factor)

    def __str__(self) -> str:
        return f"({self.column:.2f}, {self.row:.2f}) r {self.radius:.2f} px"


def parse_circle(text: str, name: str = "circle") -> Circle:
    """A circle written ``COLUMN,ROW,RADIUS`` (pixels from the top-left corner).

    Raises
    ------
    ArgumentError
        Naming `name`, when `text` is not three finite numbers with a positive radius.
    """
    parts = [part for part in re.split(r"[,\s]+", text.strip()) if part]
    try:
        values = [float(part) for part in parts]
    except ValueError:
        values = []
    if len(values) != 3 or not np.isfinite(values).all():
        raise ArgumentError(name, f"expected COLUMN,ROW,RADIUS in pixels, got {text!r}")
    if values[2] <= 0:
        raise ArgumentError(name, f"the radius must be positive, got {values[2]:g}")
    return Circle(*values)


def find_circles(image: np.ndarray, count: int) -> list[Circle]:
    """The `count` strongest circles of an image's edges, strongest first.

    Parameters
    ----------
    image : numpy.ndarray
        (H, W) float: e.g. the log of a capture's mean image, where a sphere's outline is an
        edge whatever lights it.
    count : int

    Returns
    -------
    list of Circle
        Whole-pixel centres and radii (`refine_circle` fits them finer); fewer than `count`
        when the edges hold fewer circles.

    Raises
    ------
    ArgumentError
        Naming `image` (not a finite (H, W) array) or `count` (not a positive integer).
    """
    # Imported here: scikit-image would add to the start and the memory of every command.
    from skimage import feature, transform

    image = _image(image)
    count = check_integer("count", count, 1)
    factor = max(1, int(np.ceil(max(image.shape) / HOUGH_SIDE_PX)))
    small = _block_mean(image, factor)
    edges = feature.canny(small, sigma=1.0)
    largest = min(small.shape) // 2
    if largest <= MIN_RADIUS_PX or not edges.any():
        return []
    radii = np.arange(MIN_RADIUS_PX, largest)
    votes = transform.hough_circle(edges, radii)
    separation = MIN_RADIUS_PX
    _, columns, rows, found = transform.hough_circle_peaks(
        votes, radii, total_num_peaks=count, min_xdistance=separation, min_ydistance=separation
    )
    return [
        Circle(float(c) + 0.5, float(r) + 0.5, float(radius)).scaled(factor)
        for c, r, radius in zip(columns, rows, found)
    ]


def refine_circle(images: np.ndarray, circle: Circle, band: float = 0.25, rounds: int = 3) -> Circle:
    """A circle fitted to the sharpest change of one image, or of a stack of images, along rays
    from its centre.

    On each of `RAYS` rays from the centre, between ``(1 - band)`` and ``(1 + band)`` times the
    radius, the radial gradient's magnitude is summed over the images, and the position of its
    largest value (a parabola through its samples) is an edge point; the circle is the robust
    (arctan loss) geometric fit to them, and the search is repeated about the fitted circle `rounds`
    times. A sphere's outline is a step in every image of a capture, whichever side of it is
    brighter under each light; the shading inside and the background change smoothly.

    Parameters
    ----------
    images : numpy.ndarray
        (H, W) or (K, H, W) float (e.g. the log of each image's brightness).
    circle : Circle
        Where to search: within a pixel or two of the outline.
    band : float
        The search's half-width as a fraction of the radius.
    rounds : int

    Returns
    -------
    Circle
        `circle` itself when the edge points are too few to fit (fewer than a quarter of the
        rays find one inside the image).

    Raises
    ------
    ArgumentError
        Naming the argument: `images` not a finite (H, W) or (K, H, W) array, `circle` not
        three finite numbers with a positive radius, `band` not in (0, 1), `rounds` not a
        positive integer.
    """
    stack, circle = _stack(images), as_circle(circle)
    band = check_number("band", band)
    if not 0.0 < band < 1.0:
        raise ArgumentError("band", f"must be in (0, 1), got {band!r}")
    rounds = check_integer("rounds", rounds, 1)
    angles = np.linspace(0.0, 2.0 * np.pi, RAYS, endpoint=False)
    height, width = stack.shape[1:]
    for _ in range(rounds):
        radii = np.linspace((1.0 - band) * circle.radius, (1.0 + band) * circle.radius, _samples(circle.radius, band))
        columns = circle.column + np.outer(np.cos(angles), radii)
        rows = circle.row + np.outer(np.sin(angles), radii)
        inside = (columns.min(1) >= 0.5) & (columns.max(1) <= width - 0.5)
        inside &= (rows.min(1) >= 0.5) & (rows.max(1) <= height - 0.5)
        if inside.sum() < RAYS // 4:
            return circle
        where = [rows[inside] - 0.5, columns[inside] - 0.5]
        steepness = np.zeros((int(inside.sum()), len(radii)))
        for image in stack:
            steepness += np.abs(np.gradient(ndimage.map_coordinates(image, where, order=1), radii, axis=1))
        edge_radii = _steepest(steepness, radii)
        edge_columns = circle.column + np.cos(angles[inside]) * edge_radii
        edge_rows = circle.row + np.sin(angles[inside]) * edge_radii
        circle = _fit(edge_columns, edge_rows, circle)
    return circle


def outermost_outline(image: np.ndarray, circle: Circle, min_contrast: float, reach: float = 2.0) -> Circle:
    """The outermost circle about `circle`'s centre, up to `reach` times its radius, whose
    outline stands out of `image` (`outline_contrast` at least `min_contrast`), or `circle`
    when none beyond it does.

    A mirror sphere shows circles inside its outline (the edge of what it mirrors, e.g. a
    floor's horizon); its own outline is the outermost of them. Along rays from the centre, the
    median over rays of the radial gradient's magnitude is taken at each radius; its outermost
    local maximum beyond 1.1 radii that is at least `min_contrast` times the median of the
    magnitudes out there (the surroundings' texture and noise), and at least
    `MIN_RELATIVE_STEEPNESS` of `circle`'s own (surroundings without noise have no texture to
    measure by), is the outline.

    Parameters
    ----------
    image : numpy.ndarray
        (H, W) float.
    circle : Circle
    min_contrast : float
        Over the median radial gradient magnitude beyond 1.1 radii.
    reach : float
        How far out to look, as a multiple of the radius (within the image).

    Returns
    -------
    Circle
        Whole-sample radius (`refine_circle` fits it finer).

    Raises
    ------
    ArgumentError
        Naming `image`, `circle`, `min_contrast` (not a positive number) or `reach` (not above 1).
    """
    image, circle = _image(image), as_circle(circle)
    min_contrast = check_number("min_contrast", min_contrast)
    reach = check_number("reach", reach)
    if min_contrast <= 0:
        raise ArgumentError("min_contrast", f"must be positive, got {min_contrast!r}")
    if reach <= 1.0:
        raise ArgumentError("reach", f"must be above 1, got {reach!r}")
    room = min(circle.column, circle.row, image.shape[1] - circle.column, image.shape[0] - circle.row)
    largest = min(reach * circle.radius, room - 1.0)
    if largest <= 1.1 * circle.radius:
        return circle
    radii = np.arange(0.9 * circle.radius, largest, 1.0 / SAMPLES_PER_PX)
    angles = np.linspace(0.0, 2.0 * np.pi, RAYS, endpoint=False)
    columns = circle.column + np.outer(np.cos(angles), radii)
    rows = circle.row + np.outer(np.sin(angles), radii)
    profiles = ndimage.map_coordinates(image, [rows - 0.5, columns - 0.5], order=1, mode="nearest")
    gradients = np.abs(np.gradient(profiles, radii, axis=1))
    steepness = np.median(gradients, axis=0)
    own = float(steepness[radii <= 1.1 * circle.radius].max())
    texture = float(np.median(gradients[:, radii > 1.1 * circle.radius]))
    peaks = (steepness[1:-1] >= steepness[:-2]) & (steepness[1:-1] >= steepness[2:])
    peaks &= (steepness[1:-1] >= min_contrast * texture) & (steepness[1:-1] >= MIN_RELATIVE_STEEPNESS * own)
    peaks &= radii[1:-1] > 1.1 * circle.radius
    if not peaks.any():
        return circle
    return Circle(circle.column, circle.row, float(radii[1:-1][np.flatnonzero(peaks)[-1]]))


def outline_contrast(image: np.ndarray, circle: Circle) -> float:
    """How much a circle's outline stands out of an image: the median over rays from its
    centre of the steepest radial gradient within 10 % of the radius, over the median gradient
    magnitude of the whole image (its texture and noise).

    Parameters
    ----------
    image : numpy.ndarray
        (H, W) float.
    circle : Circle

    Returns
    -------
    float
        inf for an image without texture.

    Raises
    ------
    ArgumentError
        Naming `image` (not a finite (H, W) array) or `circle` (not three finite numbers with a
        positive radius).
    """
    image, circle = _image(image), as_circle(circle)
    band = 0.1
    angles = np.linspace(0.0, 2.0 * np.pi, RAYS, endpoint=False)
    radii = np.linspace((1.0 - band) * circle.radius, (1.0 + band) * circle.radius, _samples(circle.radius, band))
    columns = circle.column + np.outer(np.cos(angles), radii)
    rows = circle.row + np.outer(np.sin(angles), radii)
    profiles = ndimage.map_coordinates(image, [rows - 0.5, columns - 0.5], order=1, mode="nearest")
    steepest = float(np.median(np.abs(np.gradient(profiles, radii, axis=1)).max(axis=1)))
    texture = float(np.median(np.hypot(*np.gradient(image))))
    return steepest / texture if texture > 0 else np.inf


def as_circle(circle, name: str = "circle") -> Circle:
    """`circle` (a `Circle` or three numbers: column, row, radius) as a `Circle`.

    Raises
    ------
    ArgumentError
        Naming `name`: not three finite numbers, or a radius that is not positive.
    """
    values = check_array(name, circle, (3,))
    check_finite(name, values, unit="value")
    if values[2] <= 0:
        raise ArgumentError(name, f"the radius must be positive, got {values[2]:g}")
    return Circle(*(float(value) for value in values))


def _image(image) -> np.ndarray:
    image = check_array("image", image, (None, None), nonempty=True)
    check_finite("image", image)
    return image


def _stack(images) -> np.ndarray:
    array = np.asarray(images) if not isinstance(images, (str, bytes)) else images
    if getattr(array, "ndim", None) == 2:
        return _image(array)[None]
    stack = check_array("images", images, (None, None, None), dtype=np.float32, copy=False, nonempty=True)
    check_finite("images", stack)
    return stack


def _samples(radius: float, band: float) -> int:
    return max(8, int(np.ceil(2.0 * band * radius * SAMPLES_PER_PX)))


def _steepest(gradient: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Per row of `gradient`, the radius of its largest value, refined by a parabola."""
    rows = np.arange(gradient.shape[0])
    peak = np.clip(np.argmax(gradient, axis=1), 1, gradient.shape[1] - 2)
    before, at, after = gradient[rows, peak - 1], gradient[rows, peak], gradient[rows, peak + 1]
    curvature = before - 2.0 * at + after
    offset = np.where(curvature < 0, 0.5 * (before - after) / np.where(curvature < 0, curvature, -1.0), 0.0)
    return radii[peak] + np.clip(offset, -0.5, 0.5) * (radii[1] - radii[0])


def _fit(columns: np.ndarray, rows: np.ndarray, start: Circle) -> Circle:
    """The circle nearest to the points, the points far off it (an edge of what a mirror sphere
    mirrors) without weight: a redescending (arctan) loss of scale 0.3 px."""

    def distances(parameters: np.ndarray) -> np.ndarray:
        return np.hypot(columns - parameters[0], rows - parameters[1]) - parameters[2]

    fitted = optimize.least_squares(distances, np.array(start), loss="arctan", f_scale=0.3)
    return Circle(*(float(value) for value in fitted.x))


def _block_mean(image: np.ndarray, factor: int) -> np.ndarray:
    """`image` reduced `factor` times by the means of whole blocks (the ragged edge dropped)."""
    if factor == 1:
        return image
    rows, columns = image.shape[0] // factor, image.shape[1] // factor
    blocks = image[: rows * factor, : columns * factor].reshape(rows, factor, columns, factor)
    return blocks.mean(axis=(1, 3))
