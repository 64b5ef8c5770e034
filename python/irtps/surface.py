"""Surface quantities derived from a height field (contract §2)."""

from __future__ import annotations

import numpy as np


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
    height = np.asarray(height, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    dz_dcol = _masked_derivative(height, mask, axis=1)
    dz_drow = _masked_derivative(height, mask, axis=0)
    normals = np.stack([-dz_dcol / pixel_size, dz_drow / pixel_size, np.ones_like(height)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[~mask] = 0.0
    return normals.astype(np.float32)


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
