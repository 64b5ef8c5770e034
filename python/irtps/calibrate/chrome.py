"""Light directions from a mirror (chrome) sphere: each light's highlight, and the sphere's
normal there mirrored about the view direction.

The camera is taken as orthographic, looking down -z (the contract's frame: x right, y up,
z toward the camera); circles and positions are in pixels from the image's top-left corner
(`irtps.calibrate.circles`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import ndimage

from irtps.calibrate.circles import Circle

__all__ = [
    "Highlights",
    "SphereWindow",
    "circle_from_highlights",
    "find_highlights",
    "mirror_directions",
    "sphere_window",
]

#: The part of the sphere's radius searched for highlights (the rim mirrors the floor).
SEARCH_RADIUS = 0.95
#: A highlight's core is the pixels above this fraction of its peak, joined to it.
HIGHLIGHT_LEVEL = 0.5
#: Its position is the centroid of the pixels above this fraction of its peak within twice
#: the core's radius (plus 1.5 px): its tails count (a centroid cut at a high level is pulled
#: toward the brightest pixel's centre), what the sphere mirrors further away does not.
TAIL_LEVEL = 0.05
#: A highlight's peak must stand this many robust standard deviations above the disk's others.
MIN_CONTRAST = 8.0
#: A highlight covers at most this fraction of the sphere's disk (a matte sphere's light is broad).
MAX_AREA = 0.03


class Highlights(NamedTuple):
    """Each image's highlight on a sphere."""

    #: (K, 2) column, row of each highlight's centroid in pixels; NaN where none was found.
    positions: np.ndarray
    #: (K,) whether image k has a compact highlight that stands out.
    found: np.ndarray


class SphereWindow(NamedTuple):
    """A sphere's pixels: the window of an image that holds its disk, with each pixel's normal
    (the work on a sphere stays in it, however large the image)."""

    #: The window's rows and columns in the image.
    rows: slice
    columns: slice
    #: (h, w, 3) unit outward normals of the sphere seen orthographically, (0, 0, 1) off the disk.
    normals: np.ndarray
    #: (h, w) each pixel centre's distance from the centre as a fraction of the radius.
    fraction: np.ndarray
    #: (h, w) each pixel centre's row and column in the image.
    centre_rows: np.ndarray
    centre_columns: np.ndarray

    def of(self, stack: np.ndarray) -> np.ndarray:
        """The window of each image of a (K, H, W, ...) stack (a view)."""
        return stack[:, self.rows, self.columns]


def sphere_window(circle: Circle, shape: tuple[int, int]) -> SphereWindow:
    """The window of an image of size `shape` (H, W) that holds the disk of `circle` (empty
    when it lies outside the image), with its pixels' normals.

    Returns
    -------
    SphereWindow
    """
    top, bottom = (
        int(np.clip(value, 0, shape[0]))
        for value in (np.floor(circle.row - circle.radius), np.ceil(circle.row + circle.radius))
    )
    left, right = (
        int(np.clip(value, 0, shape[1]))
        for value in (np.floor(circle.column - circle.radius), np.ceil(circle.column + circle.radius))
    )
    rows, columns = np.mgrid[top:bottom, left:right] + 0.5
    x = (columns - circle.column) / circle.radius
    y = -(rows - circle.row) / circle.radius
    fraction = np.hypot(x, y)
    z = np.sqrt(np.clip(1.0 - x**2 - y**2, 0.0, 1.0))
    normals = np.where((fraction < 1.0)[..., None], np.stack([x, y, z], axis=-1), np.array([0.0, 0.0, 1.0]))
    return SphereWindow(slice(top, bottom), slice(left, right), normals, fraction, rows, columns)


def find_highlights(gray: np.ndarray, circle: Circle) -> Highlights:
    """Each image's highlight on a sphere: the light it mirrors.

    A pixel of image k counts by how much brighter it is than the median of all images there,
    so what the sphere mirrors under every light (a lit wall, another sphere) cancels and the
    light's own reflection stays. The highlight's core is the pixels above half its peak joined
    to the peak; its position is the centroid, weighted by that excess, of the pixels near the
    core above `TAIL_LEVEL` of the peak.

    Parameters
    ----------
    gray : numpy.ndarray
        (K, H, W) linear brightness of each image.
    circle : Circle
        The sphere's outline.

    Returns
    -------
    Highlights
    """
    window = sphere_window(circle, gray.shape[1:])
    disk = window.fraction < SEARCH_RADIUS
    positions = np.full((len(gray), 2), np.nan)
    found = np.zeros(len(gray), dtype=bool)
    if not disk.any():
        return Highlights(positions, found)
    seen = window.of(gray)
    excess = np.where(disk, seen - np.median(seen, axis=0), 0.0)
    rows, columns = window.centre_rows, window.centre_columns
    for k, image in enumerate(excess):
        peak_at = np.unravel_index(np.argmax(image), image.shape)
        peak = image[peak_at]
        labels, _ = ndimage.label(image > HIGHLIGHT_LEVEL * peak)
        core = labels == labels[peak_at]
        others = image[disk & ~core]
        spread = 1.4826 * np.median(np.abs(others - np.median(others))) if others.size else 0.0
        found[k] = peak > 0 and peak > MIN_CONTRAST * spread and core.sum() <= MAX_AREA * disk.sum()
        if found[k]:
            centre = _centroid(np.where(core, image, 0.0), columns, rows)
            reach = 2.0 * np.sqrt(core.sum() / np.pi) + 1.5
            near = np.hypot(columns - centre[0], rows - centre[1]) <= reach
            positions[k] = _centroid(np.where(near & (image > TAIL_LEVEL * peak), image, 0.0), columns, rows)
    return Highlights(positions, found)


def _centroid(weight: np.ndarray, columns: np.ndarray, rows: np.ndarray) -> tuple[float, float]:
    total = weight.sum()
    return float((weight * columns).sum() / total), float((weight * rows).sum() / total)


def mirror_directions(positions: np.ndarray, circle: Circle) -> np.ndarray:
    """The direction toward each light whose highlight is at `positions` on a mirror sphere.

    Parameters
    ----------
    positions : numpy.ndarray
        (K, 2) column, row in pixels.
    circle : Circle

    Returns
    -------
    numpy.ndarray
        (K, 3) unit vectors ``2 (n.v) n - v`` with v = (0, 0, 1) and n the sphere's normal at
        the highlight (a highlight beyond the outline is taken on it).
    """
    x = (positions[:, 0] - circle.column) / circle.radius
    y = -(positions[:, 1] - circle.row) / circle.radius
    length = np.maximum(np.hypot(x, y), 1.0)
    x, y = x / length, y / length
    normals = np.stack([x, y, np.sqrt(np.clip(1.0 - x**2 - y**2, 0.0, 1.0))], axis=1)
    view = np.array([0.0, 0.0, 1.0])
    return 2.0 * (normals @ view)[:, None] * normals - view


def circle_from_highlights(positions: np.ndarray, directions: np.ndarray) -> tuple[Circle, float]:
    """The mirror sphere's outline that puts each light's highlight where it is seen, given the
    lights' directions (e.g. from a matte sphere).

    A light toward l is mirrored where the normal is the half vector h = (l + v) / ‖l + v‖,
    at ``(column, row) = centre + radius (h_x, -h_y)``: linear in the centre and the radius,
    solved by least squares over the lights.

    Parameters
    ----------
    positions : numpy.ndarray
        (K, 2) column, row of each highlight, K >= 2.
    directions : numpy.ndarray
        (K, 3) unit vectors toward the lights.

    Returns
    -------
    circle : Circle
    residual_px : float
        The RMS distance between the highlights and where the circle puts them: how well the
        two agree.
    """
    half = directions + np.array([0.0, 0.0, 1.0])
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    system = np.zeros((2 * len(positions), 3))
    system[0::2, 0] = 1.0
    system[0::2, 2] = half[:, 0]
    system[1::2, 1] = 1.0
    system[1::2, 2] = -half[:, 1]
    solution = np.linalg.lstsq(system, positions.reshape(-1), rcond=None)[0]
    residual = system @ solution - positions.reshape(-1)
    return Circle(*(float(value) for value in solution)), float(np.sqrt(2.0 * np.mean(residual**2)))
