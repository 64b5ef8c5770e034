"""Surface quantities derived from a height field (contract §2) or a depth map (§1b)."""

from __future__ import annotations

import numpy as np

from irtps._shared.checks import check_array, check_finite, check_instance, check_mask, check_positive
from irtps.errors import ArgumentError
from irtps.model.camera import Camera


def height_to_normals(height: np.ndarray, mask: np.ndarray, pixel_size: float = 1.0) -> np.ndarray:
    """Unit normals ``normalize(-dz/dx, -dz/dy, 1)`` of a height field.

    Slopes are central differences between masked neighbours, one-sided where only one
    neighbour is masked, and 0 where neither is. The frame is the contract's: x grows with
    the column, y grows *upward*, against the row index.

    Parameters
    ----------
    height : numpy.ndarray
        (H, W) heights in world units.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    pixel_size : float
        World size of a pixel.

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3) unit normals, 0 outside the mask.

    Examples
    --------
    >>> import numpy as np
    >>> rows, cols = np.mgrid[0:4, 0:4].astype(float)
    >>> n = height_to_normals(2.0 * cols, np.ones((4, 4), bool))
    >>> np.round(n[1, 1] * np.sqrt(5), 6).tolist()
    [-2.0, 0.0, 1.0]
    """
    height, mask = _checked_surface(height, mask, pixel_size)
    dz_dcol = _masked_derivative(height, mask, axis=1)
    dz_drow = _masked_derivative(height, mask, axis=0)
    normals = _unit_normals(dz_dcol / pixel_size, dz_drow / pixel_size)
    normals[~mask] = 0.0
    return normals.astype(np.float32)


def depth_to_normals(depth: np.ndarray, mask: np.ndarray, camera: Camera) -> np.ndarray:
    """Unit normals of the surface a perspective camera sees at `depth` (contract §1b).

    Each object pixel's point lies on its centre ray at its depth along the optical axis;
    the normal is the cross product of the points' central differences along the columns
    and (upward) along the rows, between masked neighbours, one-sided where only one
    neighbour is masked, facing the camera.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) depth along the optical axis, world units.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    camera : irtps.model.camera.Camera
        A perspective camera of the same image size.

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3) unit normals; 0 outside the mask and at a pixel with no masked
        neighbour along a row or a column.

    Raises
    ------
    ArgumentError
        For an orthographic camera (`height_to_normals` takes its heights), a camera of
        another size, or a depth that is not finite and positive on the mask.

    Examples
    --------
    A plane at constant depth faces the camera along +z wherever it is seen.

    >>> import numpy as np
    >>> camera = Camera(4, 4, projection="perspective", fx=4.0, fy=4.0, cx=2.0, cy=2.0,
    ...                 optical_center=(0.0, 0.0, 10.0))
    >>> n = depth_to_normals(np.full((4, 4), 6.0), np.ones((4, 4), bool), camera)
    >>> (np.round(n[0, 3], 6) + 0.0).tolist()
    [0.0, 0.0, 1.0]
    """
    check_instance("camera", camera, Camera)
    if camera.projection != "perspective":
        raise ArgumentError("camera", "is orthographic: its normals come from heights (height_to_normals)")
    depth = check_array("depth", depth, (camera.height, camera.width), match="the camera")
    mask = check_mask(mask, depth.shape, match="depth")
    check_finite("depth", depth, mask)
    if (depth[mask] <= 0).any():
        raise ArgumentError("depth", "must be positive on the mask (the object lies in front of the camera)")
    points = np.asarray(camera.optical_center) + depth[..., None] * camera.ray_directions()
    along_col = np.stack([_masked_derivative(points[..., c], mask, axis=1) for c in range(3)], axis=-1)
    up_rows = -np.stack([_masked_derivative(points[..., c], mask, axis=0) for c in range(3)], axis=-1)
    normals = np.cross(along_col, up_rows)
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    normals = np.where(length > 0, normals / np.where(length > 0, length, 1.0), 0.0)
    normals[~mask] = 0.0
    return normals.astype(np.float32)


def footprint_normals(height: np.ndarray, mask: np.ndarray, pixel_size: float = 1.0) -> np.ndarray:
    """Mean unit normal over each pixel's footprint on the contract's triangulated surface.

    A pixel's value averages radiance over its square footprint (contract §1), which straddles
    the eight triangle pieces around its vertex. Without shadows, a Lambertian pixel then
    reads ``ρ·E·(l · n̄)/π`` with ``n̄`` this mean of unit normals, whose length is below 1
    where the surface bends inside the footprint (a crease). Photometric stereo measures
    ``ρ·n̄``, so ``|ρ·n̄| / |n̄|`` recovers the albedo there.

    Parameters
    ----------
    height : numpy.ndarray
        (H, W) heights in world units.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    pixel_size : float
        World size of a pixel.

    Returns
    -------
    numpy.ndarray
        float64 (H, W, 3) mean normals (length at most 1) over the meshed part of each
        footprint; 0 where a pixel touches no meshed 2×2 block.

    Examples
    --------
    A V-groove along the columns: the crease pixel's footprint is half on each facet.

    >>> import numpy as np
    >>> height = np.tile(np.abs(np.arange(5.0) - 2), (3, 1))
    >>> n = footprint_normals(height, np.ones((3, 5), bool))
    >>> np.round(n[1, 2], 4).tolist(), round(float(np.linalg.norm(n[1, 1])), 4)
    ([0.0, 0.0, 0.7071], 1.0)
    """
    height, mask = _checked_surface(height, mask, pixel_size)
    rows, cols = height.shape
    normals = np.zeros((rows, cols, 3))
    if rows < 2 or cols < 2:
        return normals
    # Block (i, j): triangle 1 is (i,j) (i+1,j) (i,j+1), triangle 2 (i,j+1) (i+1,j) (i+1,j+1).
    meshed = meshed_blocks(mask)
    h00, h10, h01, h11 = height[:-1, :-1], height[1:, :-1], height[:-1, 1:], height[1:, 1:]
    first = _unit_normals((h01 - h00) / pixel_size, (h10 - h00) / pixel_size)
    second = _unit_normals((h11 - h10) / pixel_size, (h11 - h01) / pixel_size)
    split = (first + second) / 2.0
    weight = np.zeros((rows, cols))
    # The quarter of block (i, j) nearest its corner (i, j) lies in triangle 1, the one
    # nearest (i+1, j+1) in triangle 2, and the other two quarters half in each.
    for (r, c), part in (
        ((slice(None, -1), slice(None, -1)), first),
        ((slice(1, None), slice(1, None)), second),
        ((slice(1, None), slice(None, -1)), split),
        ((slice(None, -1), slice(1, None)), split),
    ):
        normals[r, c] += np.where(meshed[..., None], part, 0.0)
        weight[r, c] += meshed
    return normals / np.maximum(weight, 1.0)[..., None]


def meshed_blocks(mask: np.ndarray) -> np.ndarray:
    """bool (H - 1, W - 1): the 2×2 blocks of pixels all four of which `mask` sets, those that
    the contract's surface spans with two triangles (§2); block (i, j) has pixel (i, j) as its
    top-left corner.

    Examples
    --------
    >>> import numpy as np
    >>> meshed_blocks(np.array([[1, 1, 0], [1, 1, 1]], bool)).tolist()
    [[True, False]]
    """
    mask = check_mask(mask)
    return mask[:-1, :-1] & mask[1:, :-1] & mask[:-1, 1:] & mask[1:, 1:]


def surface_albedo(
    albedo_ps: np.ndarray, height: np.ndarray, mask: np.ndarray, pixel_size: float = 1.0, *, largest: float | None = 1.0
) -> np.ndarray:
    """The albedo of the triangulated surface that explains photometric stereo's fit.

    Photometric stereo measures ``ρ·n̄``, with ``n̄`` the mean unit normal over the pixel's
    footprint (`irtps.geometry.surface.footprint_normals`); where the surface bends inside a footprint,
    ``|n̄| < 1`` and the fitted albedo reads low (by 30 % on the crease of a right-angled
    V-groove). Rendering the surface with that albedo would darken every bounce off a crease.
    This divides by ``|n̄|`` of the surface `height` (not below 0.5) and clips to
    [0, `largest`] (no upper bound when `largest` is None: an albedo fitted under relative
    irradiance is in the irradiance's units, see `irtps.render.radiometry`).

    Parameters
    ----------
    albedo_ps : numpy.ndarray
        (H, W, 3) albedo fitted by photometric stereo.
    height, mask, pixel_size
        The surface, as for `irtps.geometry.surface.footprint_normals`.

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3).

    Examples
    --------
    >>> import numpy as np
    >>> height = np.tile(np.abs(np.arange(5.0) - 2), (3, 1))
    >>> fitted = np.full((3, 5, 3), 0.5)
    >>> np.round(surface_albedo(fitted, height, np.ones((3, 5), bool))[1, 1:4, 0].astype(float), 4).tolist()
    [0.5, 0.7071, 0.5]
    """
    check_array("albedo_ps", albedo_ps, (*np.shape(height), 3), match="height", dtype=None)
    length = np.linalg.norm(footprint_normals(height, mask, pixel_size), axis=-1)
    return np.clip(albedo_ps / np.maximum(length, 0.5)[..., None], 0.0, largest).astype(np.float32)


def _checked_surface(height, mask, pixel_size) -> tuple[np.ndarray, np.ndarray]:
    """`height` as float64 (H, W), finite on the mask, and `mask` as bool of its shape;
    `pixel_size` positive."""
    height = check_array("height", height, (None, None), nonempty=True)
    check_positive("pixel_size", pixel_size)
    mask = check_mask(mask, height.shape, match="height")
    check_finite("height", height, mask)
    return height, mask


def _unit_normals(dz_dx: np.ndarray, dz_drow: np.ndarray) -> np.ndarray:
    """Unit normals from the slope along x and along the row index (y grows against it)."""
    normals = np.stack([-dz_dx, dz_drow, np.ones_like(dz_dx)], axis=-1)
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def _masked_derivative(values: np.ndarray, mask: np.ndarray, axis: int) -> np.ndarray:
    """Derivative along `axis` per pixel step, using only masked neighbours."""
    padded_v = np.pad(values, [(1, 1) if a == axis else (0, 0) for a in range(2)])
    padded_m = np.pad(mask, [(1, 1) if a == axis else (0, 0) for a in range(2)])
    n = values.shape[axis]
    before_v, after_v = np.take(padded_v, range(0, n), axis), np.take(padded_v, range(2, n + 2), axis)
    before_m, after_m = np.take(padded_m, range(0, n), axis), np.take(padded_m, range(2, n + 2), axis)
    central = (after_v - before_v) / 2.0
    forward = after_v - values
    backward = values - before_v
    return np.where(before_m & after_m, central, np.where(after_m, forward, np.where(before_m, backward, 0.0)))
