"""Normal integration that keeps depth discontinuities, for orthographic and pinhole cameras.

The ``"bilateral"`` method of `irtps.geometry.integrate.integrate_normals`, and the only one
for a pinhole camera (``intrinsics``). Each pixel's normal gives the slope of the surface
toward each of its four neighbours: of the height for an orthographic camera, of the
logarithm of the depth along the optical axis for a pinhole. Next to an occluding contour a
pixel agrees with its neighbour on one side and not on the other; as in bilateral normal
integration (Cao et al., "Bilateral Normal Integration", ECCV 2022), each pixel weighs its
two one-sided slope equations along each axis by how well each side agrees with it, and the
weights and the surface are found in turn from the least-squares surface (the core's
``integrate::bilateral``: exact sparse Cholesky solves, the factor's analysis done once).
The weights' sharpness is per squared pixel footprint, so nothing depends on the object's
size, distance or units.

A part of the object that the discontinuities cut off from the rest (a hand in front of a
body) has an offset that normals cannot tell: it keeps the one the least-squares surface
gave it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from irtps import _core
from irtps._shared.checks import check_array, check_finite, check_mask, check_positive
from irtps.errors import ArgumentError
from irtps.model.camera import intrinsics_problem

__all__ = ["BilateralIntegration", "integrate_bilateral"]

#: Sharpness k of the one-sided weights σ(k (Δ_other² − Δ_this²)), Δ in pixel footprints: a
#: jump of one footprint against a smooth side already takes 88 % of the weight from it.
SHARPNESS = 2.0
#: Most re-weighted solves.
MAX_ITERATIONS = 150
#: The re-weighting stops when the weighted energy changes by less than this fraction.
TOLERANCE = 1e-4


@dataclass(frozen=True)
class BilateralIntegration:
    """A surface integrated by `integrate_bilateral`.

    Attributes
    ----------
    surface : numpy.ndarray
        float32 (H, W): with a pinhole camera, the depth along the optical axis, each
        4-connected part of the mask scaled to a median depth of 1 (normals fix a pinhole
        depth map up to scale), NaN outside the mask; with an orthographic one, heights in
        the unit of `pixel_size`, each part's mean at 0, and 0 outside the mask (as
        `irtps.integrate_normals`).
    discontinuities : numpy.ndarray
        bool (H, W, 2): ``[..., 0]`` where the edge to the right neighbour is a depth
        discontinuity, ``[..., 1]`` where the edge to the pixel below is one.
    iterations : int
        Re-weighted solves done.
    converged : bool
        Whether the weights settled before `MAX_ITERATIONS`.
    """

    surface: np.ndarray
    discontinuities: np.ndarray
    iterations: int
    converged: bool


def integrate_bilateral(normals, mask=None, *, intrinsics=None, pixel_size: float = 1.0) -> BilateralIntegration:
    """Integrate normals into a surface that keeps its depth discontinuities.

    Parameters
    ----------
    normals : array_like
        (H, W, 3) normals ``(nx, ny, nz)`` in the contract's frame (x right, y up, z toward
        the camera); need not be unit, must be finite and non-zero inside the mask.
    mask : array_like, optional
        (H, W) bool, the object's pixels; default: every pixel.
    intrinsics : array_like, optional
        The pinhole camera's 3×3 matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels,
        pixel (i, j) centred at image point (j + ½, i + ½) (contract §1b); default: an
        orthographic camera.
    pixel_size : float
        World size of a pixel of an orthographic camera (ignored with `intrinsics`).

    Returns
    -------
    BilateralIntegration

    Raises
    ------
    ArgumentError
        Naming the argument: shapes, non-finite or zero normals inside the mask, an empty
        mask, intrinsics that are not a pinhole's (not 3×3, skew, a last row other than
        0 0 1, a focal length that is not positive, a principal point far outside the image).

    Examples
    --------
    A plane seen through a 90°-wide pinhole, 2 units away along the axis and tilted: its
    depth comes back exactly, up to scale.

    >>> import numpy as np
    >>> K = np.array([[16.0, 0, 16], [0, 16, 16], [0, 0, 1]])
    >>> normal = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
    >>> u, v = np.meshgrid(np.arange(32) + 0.5, np.arange(32) + 0.5)
    >>> rays = np.stack([(u - 16) / 16, -(v - 16) / 16, -np.ones_like(u)], axis=-1)
    >>> depth = -2.0 * normal[2] / (rays @ normal)  # the plane through (0, 0, -2)
    >>> result = integrate_bilateral(np.broadcast_to(normal, (32, 32, 3)), intrinsics=K)
    >>> ratio = result.surface / depth
    >>> bool(np.ptp(ratio) < 1e-3 * ratio.mean()), bool(result.discontinuities.any())
    (True, False)
    """
    normals = check_array("normals", normals, (None, None, 3), nonempty=True)
    mask = check_mask(mask, normals.shape[:2], match="normals")
    check_finite("normals", normals, mask)
    if not mask.any():
        raise ArgumentError("mask", "empty (no pixel set)")
    length = np.linalg.norm(normals, axis=-1)
    zero = mask & (length == 0)
    if zero.any():
        row, column = np.argwhere(zero)[0]
        raise ArgumentError("normals", f"zero normal at row {row}, column {column}: it gives no slope")
    unit = np.where(mask[..., None], normals / np.where(length > 0, length, 1.0)[..., None], 0.0)
    camera = None if intrinsics is None else _pinhole(intrinsics, mask.shape)
    if camera is None:
        pixel_size = check_positive("pixel_size", pixel_size)
    values, cuts, iterations, converged = _core.integrate_bilateral(
        np.ascontiguousarray(unit, dtype=np.float32),
        np.ascontiguousarray(mask),
        camera,
        SHARPNESS,
        MAX_ITERATIONS,
        TOLERANCE,
    )
    parts, count = ndimage.label(mask)
    index = np.arange(1, count + 1)
    if camera is None:
        means = np.asarray(ndimage.mean(values, parts, index))
        surface = np.where(mask, (values - np.concatenate([[0.0], means])[parts]) * pixel_size, 0.0)
    else:
        medians = np.asarray(ndimage.median(values, parts, index))
        surface = np.where(mask, np.exp(values - np.concatenate([[0.0], medians])[parts]), np.nan)
    discontinuities = np.stack([(cuts & 1) != 0, (cuts & 2) != 0], axis=-1)
    return BilateralIntegration(surface.astype(np.float32), discontinuities, int(iterations), bool(converged))


def _pinhole(intrinsics, size: tuple[int, int]) -> tuple[float, float, float, float]:
    """fx, fy, cx, cy of a pinhole's 3×3 matrix for images of `size` (H, W), checked."""
    matrix = check_array("intrinsics", intrinsics, (3, 3))
    if not np.isfinite(matrix).all():
        raise ArgumentError("intrinsics", "non-finite value")
    if matrix[0, 1] != 0 or matrix[1, 0] != 0:
        raise ArgumentError("intrinsics", "skew: only pinholes whose pixel rows and columns are square are supported")
    if not np.array_equal(matrix[2], [0.0, 0.0, 1.0]):
        raise ArgumentError("intrinsics", f"the last row is {matrix[2].tolist()}: a pinhole's matrix ends in 0 0 1")
    fx, fy, cx, cy = (float(matrix[0, 0]), float(matrix[1, 1]), float(matrix[0, 2]), float(matrix[1, 2]))
    problem = intrinsics_problem(fx, fy, cx, cy, size)
    if problem is not None:
        raise ArgumentError(f"intrinsics ({problem[0]})", problem[1])
    return fx, fy, cx, cy
