"""Normal integration: a height field from a normal map (contract §1, §2 and §6).

The functions here turn a field of unit normals (as estimated by photometric stereo)
into heights, following the discrete formulations of Quéau, Durou & Aujol,
*Normal integration: a survey*, J. Math. Imaging Vis. 60 (2018):

- :func:`integrate_normals` with ``method="ls"`` (the default) solves the discrete
  least-squares problem over an arbitrary mask, with forward *and* backward differences
  between masked 4-neighbours and a free (natural) boundary; ``method="mestimator"``
  makes it robust to outliers by iteratively re-weighted least squares
  (`irtps.geometry.least_squares_integration`); ``method="footprint"`` matches the slopes
  with central differences (`irtps.geometry.footprint_integration`); ``method="dct"``
  (Simchony, Chellappa & Shao 1990) and ``method="fc"`` (Frankot & Chellappa 1988) are the
  fast spectral solvers for a full rectangular normal map
  (`irtps.geometry.spectral_integration`).
- :func:`irtps.geometry.boundary.place_height` fixes the free constant as the contract asks:
  the median height of the mask boundary is put at the floor height (or a given base height).

The frame is the contract's: x grows with the column index, y grows *upward* (against
the row index), z points toward the orthographic camera, and a normal is
``normalize(-dz/dx, -dz/dy, 1)``. :func:`irtps.geometry.surface.height_to_normals` is the inverse
direction.
"""

from __future__ import annotations

import numpy as np

from irtps._shared.checks import (
    check_array,
    check_choice,
    check_finite,
    check_integer,
    check_mask,
    check_positive,
    document_choices,
)
from irtps.errors import ArgumentError
from irtps.geometry.bilateral_integration import integrate_bilateral
from irtps.geometry.footprint_integration import integrate_footprint
from irtps.geometry.least_squares_integration import IRLS_INNER_TOLERANCE, LeastSquaresProblem
from irtps.geometry.spectral_integration import integrate_dct, integrate_fc
from irtps.model.constants import INTEGRATION_METHODS

__all__ = ["integrate_normals", "normals_to_gradients"]

#: The integration methods, declared by the model (the options list them).
METHODS = INTEGRATION_METHODS
ROBUST_WEIGHTS = ("huber", "cauchy")
_DEFAULT_TOLERANCE = {"ls": 1e-5, "mestimator": 1e-4}


def normals_to_gradients(normals, mask=None, *, max_slope: float = 10.0):
    """Surface slopes ``p = dz/dx`` and ``q = dz/dy`` from normals.

    ``p = -nx / nz`` and ``q = -ny / nz`` in the contract's frame (x right, y up). Normals
    need not be unit length. Where ``nz`` is close to 0, or not positive (a normal facing
    away from the camera), the slope does not blow up: ``nz`` is taken as a tiny positive
    number, so that the slope keeps the sign of ``-nx`` (resp. ``-ny``), and ``|p|`` and
    ``|q|`` are clipped to `max_slope`. A zero normal gives zero slopes.

    Parameters
    ----------
    normals : array_like
        (H, W, 3) normals ``(nx, ny, nz)``.
    mask : array_like, optional
        (H, W) bool, the object's pixels; default: every pixel. Outside it the slopes are 0.
    max_slope : float
        Largest slope magnitude returned (default 10, about 84°).

    Returns
    -------
    p, q : numpy.ndarray
        float64 (H, W) slopes along +x (columns) and +y (up, against the rows).

    Raises
    ------
    ArgumentError
        If `normals` is not (H, W, 3), has non-finite values inside the mask, or `mask` has
        another shape.

    Examples
    --------
    >>> import numpy as np
    >>> n = np.array([[[-1.0, 0.5, 2.0]]])  # need not be unit
    >>> p, q = normals_to_gradients(n)
    >>> float(p[0, 0]), float(q[0, 0])
    (0.5, -0.25)
    """
    normals, mask = _check_normals_mask(normals, mask)
    max_slope = check_positive("max_slope", max_slope)
    return _gradients(normals, mask, max_slope)


@document_choices(method=METHODS, robust_weight=ROBUST_WEIGHTS)
def integrate_normals(
    normals,
    mask=None,
    *,
    pixel_size: float = 1.0,
    method: str | None = None,
    robust_weight: str = "huber",
    max_slope: float = 10.0,
    iterations: int = 5,
    tolerance: float | None = None,
    intrinsics=None,
) -> np.ndarray:
    """Heights from a normal map by normal integration.

    The slopes ``p = dz/dx = -nx/nz`` and ``q = dz/dy = -ny/nz`` are taken from the normals
    (see :func:`normals_to_gradients`; y is up, so ``dz/drow = -q``) and integrated into
    heights at the pixel centres.

    Methods (Quéau, Durou & Aujol 2018):

    ``"ls"``
        Least squares over an arbitrary mask. Every pair of masked 4-neighbours gives a
        forward difference (matched with the slope at the first pixel) and a backward
        difference (matched with the slope at the second one); pixels without a masked
        neighbour on a side simply have no difference there, which is the free (natural)
        boundary condition. The normal equations are a weighted graph Laplacian. They depend
        on the mask only, and are set up once for as long as the mask stays the same (the
        IRT-PS passes): factored by faer's sparse Cholesky (up to 100 k pixels), or beyond
        solved by conjugate gradients preconditioned with an algebraic multigrid V-cycle
        (pyamg).
    ``"mestimator"``
        The same functional with a robust penalty on each difference (each forward and
        each backward difference gets its own weight, so a wrong normal only loses the
        differences matched with *its* slope): iteratively re-weighted least squares,
        warm-started from ``"ls"``, with Huber or Cauchy weights (`robust_weight`) of the
        residuals over a robust scale (1.4826 × their median absolute deviation),
        `iterations` re-weightings. Outliers in the normals (gross errors at a few per
        cent of the pixels) then barely affect the surface. The solves reuse the AMG
        hierarchy of the unweighted system (and rebuild it only if it stops working).
    ``"footprint"``
        Least squares with the discretisation that matches how an image is formed: a
        pixel averages the surface over its footprint, so photometric stereo measures the
        footprint-mean slope, which on the contract's piecewise-linear surface is the
        *central* difference of the neighbouring heights. Central differences between
        masked neighbours (one-sided at the mask edge), weakly coupled by forward
        differences to tie the odd and even pixels together. Unlike ``"ls"``, it keeps
        creases sharp (a V-groove's bottom is not blunted), which matters when the surface
        is rendered again, as in IRT-PS. Set up once per mask as ``"ls"`` is, factored up
        to 100 k pixels as well (the factor's fill-in is larger than ``"ls"``'s).
    ``"bilateral"``
        Keeps depth discontinuities (occluding contours), which the methods above join with
        a ramp: each pixel weighs its one-sided slope equations by how well each side agrees
        with it (`irtps.geometry.bilateral_integration`). The only method for a pinhole
        camera (`intrinsics`), and its default.
    ``"dct"``
        Full rectangle only (`mask` all true or None): the same least-squares problem,
        whose normal equations are the Poisson equation with Neumann boundary, solved
        exactly by a discrete cosine transform (Simchony, Chellappa & Shao 1990).
    ``"fc"``
        Full rectangle only: Frankot & Chellappa (1988), the projection of the slopes onto
        the integrable (periodic) surfaces by a Fourier transform. It assumes a periodic
        surface; on other surfaces prefer ``"dct"``.

    Parameters
    ----------
    normals : array_like
        (H, W, 3) normals ``(nx, ny, nz)`` in the contract's frame; need not be unit.
        Values outside the mask are ignored.
    mask : array_like, optional
        (H, W) bool, the object's pixels; default: every pixel. Each 4-connected component
        of the mask is integrated on its own (it has its own free constant).
    pixel_size : float
        World size of a pixel; heights are in the same unit (ignored with `intrinsics`).
    method : str, optional
        See above; default ``"ls"``, or ``"bilateral"`` with `intrinsics`.
    robust_weight : str
        Weight function of ``"mestimator"`` (ignored by the other methods).
    max_slope : float
        Slopes are clipped to ``[-max_slope, max_slope]`` (default 10, about 84°), so that
        normals with ``nz`` near or below 0 stay bounded.
    iterations : int
        Number of re-weightings of ``"mestimator"`` (default 5; ignored by the other
        methods; 0 gives the least-squares solution). When an intermediate solve has
        nothing left to do at its tolerance, the remaining re-weightings would repeat it
        and only the last, accurate one is done.
    tolerance : float, optional
        Relative residual ``||b - A z|| / ||b||`` at which the conjugate gradients of
        ``"ls"``, ``"footprint"`` and ``"mestimator"`` stop (ignored by the spectral methods
        and where the system is factored, whose solution is exact to rounding). Default:
        1e-5 for ``"ls"``, which puts the solver's error well below the discretisation's
        on smooth surfaces; 1e-4 for ``"mestimator"``, whose own error (the outliers'
        residual influence) is far larger than that. The intermediate re-weighted solves
        of ``"mestimator"`` stop at ``max(tolerance, 1e-3)``.
    intrinsics : array_like, optional
        A pinhole camera's 3×3 matrix in pixels (contract §1b: pixel (i, j) centred at image
        point (j + ½, i + ½)): the normals are integrated into the depth along the optical
        axis instead of heights, with ``"bilateral"``.

    Returns
    -------
    numpy.ndarray
        float32 (H, W) heights, 0 outside the mask. They are *centred*: the mean height of
        each 4-connected component of the mask is 0. With `intrinsics`: the depth along the
        optical axis, each 4-connected component scaled to a median depth of 1 (normals fix
        a pinhole's depth only up to scale), NaN outside the mask. Use
        :func:`irtps.geometry.boundary.place_height` to put the object on the floor as the
        contract (§6) asks.

    Raises
    ------
    ArgumentError
        (a ``ValueError`` and an :class:`irtps.errors.IrtpsError`) naming the argument: a
        shape mismatch, non-finite normals inside the mask, an empty mask, an unknown
        `method` or `robust_weight`, a non-positive `pixel_size`, `max_slope` or
        `tolerance`, or ``"dct"``/``"fc"`` with a mask that is not the full rectangle.

    See Also
    --------
    irtps.geometry.boundary.place_height : put the integrated object on the floor.
    irtps.geometry.surface.height_to_normals : the inverse direction.

    Examples
    --------
    A plane rising by 0.5 per unit of x and 0.25 per unit of y (y up, against the rows):

    >>> import numpy as np
    >>> n = np.empty((32, 32, 3))
    >>> n[...] = np.array([-0.5, -0.25, 1.0]) / np.linalg.norm([-0.5, -0.25, 1.0])
    >>> z = integrate_normals(n, pixel_size=2.0)
    >>> round(float(z[0, 1] - z[0, 0]), 4), round(float(z[0, 0] - z[1, 0]), 4)
    (1.0, 0.5)
    """
    if method is None:
        method = "ls" if intrinsics is None else "bilateral"
    check_choice("method", method, METHODS)
    if intrinsics is not None and method != "bilateral":
        raise ArgumentError(
            "method",
            f"{method!r} integrates heights seen orthographically: a pinhole camera (intrinsics) takes 'bilateral'",
        )
    if method == "bilateral":
        return integrate_bilateral(normals, mask, intrinsics=intrinsics, pixel_size=pixel_size).surface
    normals, mask = _check_normals_mask(normals, mask)
    pixel_size = check_positive("pixel_size", pixel_size)
    max_slope = check_positive("max_slope", max_slope)
    if tolerance is None:
        tolerance = _DEFAULT_TOLERANCE.get(method, 1e-5)
    tolerance = check_positive("tolerance", tolerance)
    iterations = check_integer("iterations", iterations, 0)
    if method == "mestimator":
        check_choice("robust_weight", robust_weight, ROBUST_WEIGHTS)
    if not mask.any():
        raise ArgumentError("mask", "empty (no pixel set)")

    p, q = _gradients(normals, mask, max_slope)
    # Height steps per pixel step: along a row (+column) dz = p*s, down a column (+row) dz = -q*s.
    gc = p * pixel_size
    gr = -q * pixel_size

    if method in ("dct", "fc"):
        if not mask.all():
            raise ArgumentError(
                "mask",
                f"method {method!r} needs the full rectangle (every pixel masked); "
                f"{int((~mask).sum())} pixels are unmasked: use method='ls'",
            )
        z = integrate_dct(gc, gr) if method == "dct" else integrate_fc(gc, gr)
        z -= z.mean()
        return z.astype(np.float32)
    if method == "footprint":
        return integrate_footprint(mask, gc, gr, tolerance)

    problem = LeastSquaresProblem(mask, gc, gr)
    if method == "mestimator" and iterations > 0:
        # The least-squares start only needs the accuracy of the intermediate solves.
        z = problem.solve_ls(max(tolerance, IRLS_INNER_TOLERANCE), robust_start=True)
        z = problem.solve_robust(z, robust_weight, iterations, tolerance)
    else:
        z = problem.solve_ls(tolerance)
    return problem.to_image(z)


# --------------------------------------------------------------------------- checks


def _check_normals_mask(normals, mask):
    normals = check_array("normals", normals, (None, None, 3), nonempty=True)
    mask = check_mask(mask, normals.shape[:2], match="normals")
    check_finite("normals", normals, mask)
    return normals, mask


def _gradients(normals, mask, max_slope):
    nx, ny, nz = normals[..., 0], normals[..., 1], normals[..., 2]
    # nz <= tiny (grazing or back-facing): a tiny positive nz, so the slope keeps the sign
    # of -nx (resp. -ny), then clipped. Scaled by the normal's length: normals need not be unit.
    # (Values outside the mask may be anything, NaN included: no warnings, zeroed below.)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        length = np.sqrt(nx * nx + ny * ny + nz * nz)
        tiny = 1e-12 * np.maximum(length, 1e-300)
        nz_safe = np.maximum(nz, tiny)
        p = np.clip(-nx / nz_safe, -max_slope, max_slope)
        q = np.clip(-ny / nz_safe, -max_slope, max_slope)
    p[~mask] = 0.0
    q[~mask] = 0.0
    return p, q
