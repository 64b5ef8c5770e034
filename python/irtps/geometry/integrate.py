"""Normal integration: a height field from a normal map (contract §1, §2 and §6).

The functions here turn a field of unit normals (as estimated by photometric stereo)
into heights, following the discrete formulations of Quéau, Durou & Aujol,
*Normal integration: a survey*, J. Math. Imaging Vis. 60 (2018):

- :func:`integrate_normals` with ``method="ls"`` (the default) solves the discrete
  least-squares problem over an arbitrary mask, with forward *and* backward differences
  between masked 4-neighbours and a free (natural) boundary; ``method="mestimator"``
  makes it robust to outliers by iteratively re-weighted least squares; ``method="dct"``
  (Simchony, Chellappa & Shao 1990) and ``method="fc"`` (Frankot & Chellappa 1988) are the
  fast spectral solvers for a full rectangular normal map.
- :func:`place_height` fixes the free constant as the contract asks: the median height of
  the mask boundary is put at the floor height (or a given base height).

The frame is the contract's: x grows with the column index, y grows *upward* (against
the row index), z points toward the orthographic camera, and a normal is
``normalize(-dz/dx, -dz/dy, 1)``. :func:`irtps.geometry.surface.height_to_normals` is the inverse
direction.
"""

from __future__ import annotations

import hashlib
import threading

import numpy as np
import scipy.fft
import scipy.ndimage
import scipy.sparse

from irtps._shared.checks import (
    check_array,
    check_choice,
    check_finite,
    check_integer,
    check_mask,
    check_number,
    check_positive,
    document_choices,
)
from irtps.errors import ArgumentError
from irtps.model.constants import INTEGRATION_METHODS
from irtps.ps.robust_stats import median_and_sigma

__all__ = ["integrate_normals", "mask_boundary", "normals_to_gradients", "place_height"]

#: The integration methods, declared by the model (the options list them).
METHODS = INTEGRATION_METHODS
ROBUST_WEIGHTS = ("huber", "cauchy")
# Tuning constants giving 95 % efficiency on Gaussian residuals (in units of the scale).
_HUBER_K = 1.345
_CAUCHY_K = 2.385
# 4-connectivity: the finite differences only ever join 4-neighbours. The mask's components
# and boundary come from scipy.ndimage (label, binary_erosion), not scikit-image: its
# measure.label does the same labelling, and segmentation.find_boundaries(mode="inner") does
# not count the image border as boundary, which place_height needs; scikit-image has no
# normal integration, so it would be a dependency for nothing scipy does not already do.
_FOUR = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)
# Size below which the AMG hierarchy stops coarsening (then a sparse LU).
_MAX_COARSE = 300
# Ruge-Stuben interpolation: "direct" sets up faster than "classical" on these
# Laplacians (1024x1024 disc: 0.6-0.8 s against 1.0-1.8 s on a busy 2-core machine), for
# 6-7 instead of 5 conjugate-gradient iterations (about 0.08 s each at that size).
_INTERPOLATION = "direct"
# Tolerance of the intermediate IRLS solves; more than _REUSE_LIMIT iterations with the
# unweighted hierarchy and the hierarchy is rebuilt for the weighted matrix.
_IRLS_INNER_TOLERANCE = 1e-3
_REUSE_LIMIT = 25
_MAX_PCG_ITERATIONS = 1000
_DEFAULT_TOLERANCE = {"ls": 1e-5, "mestimator": 1e-4}
#: Largest systems (unknowns) solved by faer's sparse Cholesky factorisation, factored once
#: per mask; larger ones by AMG-PCG, the hierarchy set up once per mask. Measured on a disc
#: (benches/integration_bench.py --solvers, 2 busy cores): the factor wins from the second
#: solve on (IRT-PS, 6 passes at 512x512: ls 0.55 s against 1.14 s with pyamg, footprint
#: 1.6 s against 2.7 s) but its fill-in grows faster than the system (AMD ordering): at
#: 1024x1024 (667 k unknowns) the footprint factor holds 958 MB, 7.8 s to factor, where
#: pyamg needs a few tens of MB; the ls factor there holds 264 MB (3.2 s for 6 passes,
#: against 5.1 s). A single solve (classic PS) is up to 2x slower by the factor at 512x512
#: (footprint 1.2 s against 0.7 s), and a kept footprint factor of 187 MB there would be
#: most of what IRT-PS may hold beside 512x512 images: the factor is kept up to 100 k
#: unknowns (about 75 MB for footprint, less for ls; as fast as pyamg for one solve at
#: 128x128), where the loop's later passes are its gain, and pyamg, set up once, beyond.
_LS_DIRECT_LIMIT = 100_000
_FOOTPRINT_DIRECT_LIMIT = 100_000
_PRESMOOTHER = ("gauss_seidel", {"sweep": "symmetric"})
_POSTSMOOTHER = ("gauss_seidel", {"sweep": "symmetric"})


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
    method: str = "ls",
    robust_weight: str = "huber",
    max_slope: float = 10.0,
    iterations: int = 5,
    tolerance: float | None = None,
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
        to 300 k pixels (the factor's fill-in is larger: about 1 GB at 1024×1024).
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
        World size of a pixel; heights are in the same unit.
    method : str
        See above.
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

    Returns
    -------
    numpy.ndarray
        float32 (H, W) heights, 0 outside the mask. They are *centred*: the mean height of
        each 4-connected component of the mask is 0. Use :func:`place_height` to put the
        object on the floor as the contract (§6) asks.

    Raises
    ------
    ArgumentError
        (a ``ValueError`` and an :class:`irtps.errors.IrtpsError`) naming the argument: a
        shape mismatch, non-finite normals inside the mask, an empty mask, an unknown
        `method` or `robust_weight`, a non-positive `pixel_size`, `max_slope` or
        `tolerance`, or ``"dct"``/``"fc"`` with a mask that is not the full rectangle.

    See Also
    --------
    place_height : put the integrated object on the floor.
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
    normals, mask = _check_normals_mask(normals, mask)
    pixel_size = check_positive("pixel_size", pixel_size)
    max_slope = check_positive("max_slope", max_slope)
    if tolerance is None:
        tolerance = _DEFAULT_TOLERANCE.get(method, 1e-5)
    tolerance = check_positive("tolerance", tolerance)
    check_choice("method", method, METHODS)
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
        z = _integrate_dct(gc, gr) if method == "dct" else _integrate_fc(gc, gr)
        z -= z.mean()
        return z.astype(np.float32)
    if method == "footprint":
        return _integrate_footprint(mask, gc, gr, tolerance)

    problem = _Problem(mask, gc, gr)
    if method == "mestimator" and iterations > 0:
        # The least-squares start only needs the accuracy of the intermediate solves.
        z = problem.solve_ls(max(tolerance, _IRLS_INNER_TOLERANCE), robust_start=True)
        z = problem.solve_robust(z, robust_weight, iterations, tolerance)
    else:
        z = problem.solve_ls(tolerance)
    return problem.to_image(z)


def place_height(height, mask=None, *, base_height: float = 0.0, per_component: bool = True) -> np.ndarray:
    """Shift heights so that the object stands at a base height (contract §6).

    The median height over the mask boundary is set to `base_height`. Boundary pixels are
    the masked pixels with at least one unmasked 4-neighbour, or on the image border. By
    default each 4-connected component of the mask is shifted on its own, as normal
    integration leaves each with its own free constant.

    Parameters
    ----------
    height : array_like
        (H, W) heights, e.g. from :func:`integrate_normals`.
    mask : array_like, optional
        (H, W) bool, the object's pixels; default: every pixel.
    base_height : float
        Height to put the boundary median at: the floor height, 0 when there is no floor.
    per_component : bool
        Shift each 4-connected component of the mask separately (default); if False, one
        shift for the whole mask, from the median over all its boundary pixels.

    Returns
    -------
    numpy.ndarray
        float32 (H, W) heights, 0 outside the mask.

    Raises
    ------
    ArgumentError
        If `height` is not 2-D, has non-finite values inside the mask, `mask` has another
        shape or is empty, or `base_height` is not finite.

    Examples
    --------
    >>> import numpy as np
    >>> h = np.full((5, 5), 3.0)
    >>> h[2, 2] = 7.0
    >>> z = place_height(h, base_height=1.0)
    >>> float(z[0, 0]), float(z[2, 2])
    (1.0, 5.0)
    """
    height = check_array("height", height, (None, None), nonempty=True)
    mask = check_mask(mask, height.shape, match="height")
    if not mask.any():
        raise ArgumentError("mask", "empty (no pixel set)")
    check_finite("height", height, mask)
    base_height = check_number("base_height", base_height)

    boundary = mask_boundary(mask)
    out = np.zeros(height.shape, np.float64)
    if per_component:
        labels, count = scipy.ndimage.label(mask, structure=_FOUR)
        medians = scipy.ndimage.median(height, labels=np.where(boundary, labels, 0), index=np.arange(1, count + 1))
        shift = np.concatenate([[0.0], base_height - np.asarray(medians, np.float64)])
        out[mask] = height[mask] + shift[labels[mask]]
    else:
        out[mask] = height[mask] + (base_height - np.median(height[boundary]))
    return out.astype(np.float32)


def mask_boundary(mask) -> np.ndarray:
    """The boundary pixels of a mask: masked, with an unmasked 4-neighbour or on the border.

    Parameters
    ----------
    mask : array_like
        (H, W) bool.

    Returns
    -------
    numpy.ndarray
        (H, W) bool.

    Examples
    --------
    >>> import numpy as np
    >>> m = np.zeros((5, 5), bool)
    >>> m[1:4, 1:4] = True
    >>> mask_boundary(m).astype(int)[1:4, 1:4].tolist()
    [[1, 1, 1], [1, 0, 1], [1, 1, 1]]
    """
    mask = check_mask(mask)
    inner = scipy.ndimage.binary_erosion(mask, structure=_FOUR, border_value=0)
    return mask & ~inner


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


# --------------------------------------------------------------------------- spectral methods


def _integrate_dct(gc, gr):
    """Least squares on the full grid: Neumann Poisson equation, exact by DCT-II."""
    h, w = gc.shape
    # Edge targets (average of forward and backward): the normal equations are L z = -div g.
    ec = 0.5 * (gc[:, :-1] + gc[:, 1:])
    er = 0.5 * (gr[:-1, :] + gr[1:, :])
    b = np.zeros((h, w))
    b[:, 1:] += ec
    b[:, :-1] -= ec
    b[1:, :] += er
    b[:-1, :] -= er
    # L is the graph Laplacian of the grid (Neumann), diagonal in the orthonormal DCT-II basis.
    lam_r = 2.0 - 2.0 * np.cos(np.pi * np.arange(h) / h)
    lam_c = 2.0 - 2.0 * np.cos(np.pi * np.arange(w) / w)
    lam = lam_r[:, None] + lam_c[None, :]
    lam[0, 0] = 1.0
    bh = scipy.fft.dctn(b, type=2, norm="ortho")
    zh = bh / lam
    zh[0, 0] = 0.0
    return scipy.fft.idctn(zh, type=2, norm="ortho")


def _integrate_fc(gc, gr):
    """Frankot-Chellappa: least-squares projection onto periodic integrable surfaces."""
    h, w = gc.shape
    wc = 2.0 * np.pi * scipy.fft.fftfreq(w)[None, :]
    wr = 2.0 * np.pi * scipy.fft.fftfreq(h)[:, None]
    gch = scipy.fft.fft2(gc)
    grh = scipy.fft.fft2(gr)
    denom = wc * wc + wr * wr
    denom[0, 0] = 1.0
    zh = (-1j * wc * gch - 1j * wr * grh) / denom
    zh[0, 0] = 0.0
    return np.real(scipy.fft.ifft2(zh))


# --------------------------------------------------------------------------- footprint

#: Weight of the forward differences that couple odd and even pixels in ``"footprint"``.
#: Central differences leave the odd and even pixels free to drift apart: on a 512-pixel
#: object, 0.05 let a pixel-scale ripple grow (a quarter of DiLiGenT ball's pixels came out
#: locally concave, then bright with false inter-reflections inside IRT-PS). 0.3 keeps the
#: ripple down (94 % convex, as against 97 % with ``"ls"``) and creases still sharp.
_FOOTPRINT_COUPLING = 0.3


def _integrate_footprint(mask, gc, gr, tolerance):
    """Least squares on central differences (one-sided at the mask edge), weakly coupled."""
    system = _cached(("footprint", _mask_key(mask)), lambda: _FootprintSystem(mask).with_solver())
    return system.solve(gc, gr, tolerance)


class _FootprintSystem:
    """The normal equations of ``"footprint"`` on one mask: they depend on the mask only.

    The rows of the least-squares system ``diag(w) A z = diag(w) T g`` are the central
    differences (one-sided at the mask edge) and the coupling forward differences of each
    axis; ``g`` is the slopes ``(gc, gr)`` raveled and ``T`` picks (or averages) the slopes
    each row is matched with. The first pixel of each 4-connected component is pinned to
    0, which leaves the normal matrix ``A_f^T W^2 A_f`` (over the free pixels)
    positive definite; its right-hand side is ``A_f^T W^2 T g``, one sparse product.
    """

    def __init__(self, mask):
        h, w = mask.shape
        index = np.full(mask.shape, -1, dtype=np.int64)
        n = int(mask.sum())
        index[mask] = np.arange(n)
        flat = np.arange(h * w).reshape(h, w)
        rows, cols, vals, weights = [], [], [], []
        target_rows, target_cols, target_vals = [], [], []
        count = 0
        for axis, offset in ((1, 0), (0, h * w)):
            before = np.zeros_like(mask)
            after = np.zeros_like(mask)
            nxt = np.full_like(index, -1)
            prv = np.full_like(index, -1)
            if axis == 1:
                before[:, 1:], after[:, :-1] = mask[:, :-1], mask[:, 1:]
                nxt[:, :-1], prv[:, 1:] = index[:, 1:], index[:, :-1]
            else:
                before[1:, :], after[:-1, :] = mask[:-1, :], mask[1:, :]
                nxt[:-1, :], prv[1:, :] = index[1:, :], index[:-1, :]
            step = 1 if axis == 1 else w
            cases = [
                (mask & before & after, nxt, prv, 0.5),  # central
                (mask & after & ~before, nxt, index, 1.0),  # forward at the mask edge
                (mask & before & ~after, index, prv, 1.0),  # backward at the mask edge
            ]
            for where, plus, minus, coefficient in cases:
                m = int(where.sum())
                r = np.arange(count, count + m)
                rows += [r, r]
                cols += [plus[where], minus[where]]
                vals += [np.full(m, coefficient), np.full(m, -coefficient)]
                weights.append(np.ones(m))
                target_rows.append(r)
                target_cols.append(offset + flat[where])
                target_vals.append(np.ones(m))
                count += m
            # Coupling: every edge between masked neighbours, matched with the mean slope.
            edge = mask & after
            m = int(edge.sum())
            r = np.arange(count, count + m)
            rows += [r, r]
            cols += [nxt[edge], index[edge]]
            vals += [np.ones(m), -np.ones(m)]
            weights.append(np.full(m, _FOOTPRINT_COUPLING))
            target_rows += [r, r]
            target_cols += [offset + flat[edge], offset + flat[edge] + step]
            target_vals += [np.full(m, 0.5), np.full(m, 0.5)]
            count += m
        weight = np.concatenate(weights)
        a = scipy.sparse.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(count, n)
        )
        targets = scipy.sparse.csr_matrix(
            (np.concatenate(target_vals), (np.concatenate(target_rows), np.concatenate(target_cols))),
            shape=(count, 2 * h * w),
        )
        labels, self.components = scipy.ndimage.label(mask, structure=_FOUR)
        self.component = labels[mask] - 1
        self.mask = mask
        self.free = np.ones(n, dtype=bool)
        self.free[np.unique(self.component, return_index=True)[1]] = False
        a_free_t = (scipy.sparse.diags(weight) @ a[:, self.free]).T.tocsr()
        self.normal = (a_free_t @ a_free_t.T).tocsr()
        self.normal.sort_indices()
        self.rhs_operator = (a_free_t @ scipy.sparse.diags(weight) @ targets).tocsr()
        self.solver = None

    def with_solver(self):
        """This system, with its solver set up (factored, or its AMG hierarchy built)."""
        if self.normal.shape[0] > 0:
            direct = self.normal.shape[0] <= _FOOTPRINT_DIRECT_LIMIT
            self.solver = _SpdSolver(self.normal, "footprint normal matrix", direct=direct)
        return self

    def rhs(self, gc, gr):
        """The normal equations' right-hand side for the slopes ``(gc, gr)``."""
        return self.rhs_operator @ np.concatenate([gc.ravel(), gr.ravel()])

    def solve(self, gc, gr, tolerance):
        """Centred heights (H, W) float32 for the slopes, 0 outside the mask (after
        :meth:`with_solver`)."""
        z = np.zeros(self.free.size)
        if self.solver is not None:
            z[self.free] = self.solver.solve(self.rhs(gc, gr), tolerance)
        means = np.bincount(self.component, z, self.components) / np.bincount(self.component, minlength=self.components)
        z -= means[self.component]
        out = np.zeros(self.mask.shape, dtype=np.float32)
        out[self.mask] = z
        return out


# --------------------------------------------------------------------------- least squares


class _Problem:
    """The discrete functional of Quéau et al. over a mask, and its solvers.

    Unknowns are the masked pixels in raster order. Each pair of masked 4-neighbours
    (u, v), v after u, is an *edge*; it carries two residuals, forward
    ``z_v - z_u - t_f`` (slope at u) and backward ``z_v - z_u - t_b`` (slope at v), with
    weights ``w_f`` and ``w_b`` (1 for least squares). The normal equations are
    ``A z = b`` with A the graph Laplacian of edge weights ``w_f + w_b`` and
    ``b = D^T (w_f t_f + w_b t_b)``.
    """

    def __init__(self, mask, gc, gr):
        self.mask = mask
        h, w = mask.shape
        self.shape = (h, w)
        index = np.full((h, w), -1, dtype=np.int64)
        self.n = n = int(mask.sum())
        index[mask] = np.arange(n)
        self.index = index
        # Horizontal edges (i, j)-(i, j+1) and vertical edges (i, j)-(i+1, j).
        eh = mask[:, :-1] & mask[:, 1:]
        ev = mask[:-1, :] & mask[1:, :]
        self.eh, self.ev = eh, ev
        self.u = np.concatenate([index[:, :-1][eh], index[:-1, :][ev]])
        self.v = np.concatenate([index[:, 1:][eh], index[1:, :][ev]])
        self.t_f = np.concatenate([gc[:, :-1][eh], gr[:-1, :][ev]])
        self.t_b = np.concatenate([gc[:, 1:][eh], gr[1:, :][ev]])
        self.n_edges = self.u.size
        self.labels, self.n_components = scipy.ndimage.label(mask, structure=_FOUR)
        self.component = self.labels[mask] - 1
        self._build_structure()
        self._amg = None

    # --- sparse structure

    def _build_structure(self):
        """CSR structure of the pinned Laplacian, and where each edge's entries live in it.

        The Laplacian is singular, one constant per connected component: the first pixel
        of each component is pinned to 0 (its row and column become the identity's), which
        makes the system positive definite down to the coarsest AMG level. Row k holds, in
        increasing column order (raster order), the entries of its neighbours up and left,
        itself, then right and down: five slots per pixel, of which those without an edge
        (or with an edge to a pinned pixel) are left out.
        """
        mask, index = self.mask, self.index
        h, w = self.shape
        self.pin = np.unique(self.component, return_index=True)[1]
        pinned = np.zeros(self.n, dtype=bool)
        pinned[self.pin] = True
        self.pinned = pinned
        self.kept = ~(pinned[self.u] | pinned[self.v])
        free = np.zeros((h, w), dtype=bool)
        free[mask] = ~pinned
        eh = self.eh & free[:, :-1] & free[:, 1:]
        ev = self.ev & free[:-1, :] & free[1:, :]
        has = np.zeros((h, w, 5), dtype=bool)
        has[1:, :, 0] = ev  # up
        has[:, 1:, 1] = eh  # left
        has[..., 2] = True  # diagonal
        has[:, :-1, 3] = eh  # right
        has[:-1, :, 4] = ev  # down
        has = has[mask]  # (n, 5), rows in raster order
        itype = np.int32 if 5 * self.n < np.iinfo(np.int32).max else np.int64
        neighbour = np.zeros((h, w, 5), dtype=itype)
        neighbour[1:, :, 0] = index[:-1, :]
        neighbour[:, 1:, 1] = index[:, :-1]
        neighbour[..., 2] = index
        neighbour[:, :-1, 3] = index[:, 1:]
        neighbour[:-1, :, 4] = index[1:, :]
        neighbour = neighbour[mask]
        slot = np.cumsum(has.ravel(), dtype=itype).reshape(has.shape) - 1  # data position of each slot
        indptr = np.zeros(self.n + 1, dtype=itype)
        np.cumsum(has.sum(axis=1), out=indptr[1:])
        indices = neighbour[has]
        position = np.zeros((h, w, 5), dtype=itype)
        position[mask] = slot
        # Kept horizontal edges (u left, v right), then vertical ones (u above, v below),
        # in the order of self.u[self.kept] / self.v[self.kept].
        self.pos_uv = np.concatenate([position[:, :-1, 3][eh], position[:-1, :, 4][ev]])
        self.pos_vu = np.concatenate([position[:, 1:, 1][eh], position[1:, :, 0][ev]])
        self.pos_diag = slot[:, 2]
        self.indptr, self.indices = indptr, indices

    def matrix(self, edge_weight):
        """The pinned Laplacian with the given edge weights, as CSR."""
        data = np.empty(self.indices.size, dtype=np.float64)
        off = -edge_weight[self.kept]
        data[self.pos_uv] = off
        data[self.pos_vu] = off
        diag = np.bincount(self.u, edge_weight, self.n) + np.bincount(self.v, edge_weight, self.n)
        diag[self.pinned] = 1.0
        data[self.pos_diag] = diag
        a = scipy.sparse.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))
        a.has_sorted_indices = True
        return a

    def rhs(self, edge_target):
        """``D^T t`` for a (weighted) target per edge, 0 at the pinned pixels."""
        b = np.bincount(self.v, edge_target, self.n) - np.bincount(self.u, edge_target, self.n)
        b[self.pinned] = 0.0
        return b

    def differences(self, z):
        return z[self.v] - z[self.u]

    # --- solvers

    def solve_ls(self, tolerance, *, robust_start=False):
        """Least-squares heights. The solver of the mask's matrix is cached (see
        :func:`_cached`), except for the start of ``"mestimator"`` (`robust_start`), whose
        AMG hierarchy the re-weighted solves reuse."""
        if self.n_edges == 0:
            return np.zeros(self.n)
        b = self.rhs(self.t_f + self.t_b)
        if robust_start:
            solver = _SpdSolver(self.matrix(np.full(self.n_edges, 2.0)), "ls normal matrix", direct=False)
            self._amg = solver.amg
        else:
            solver = _cached(
                ("ls", _mask_key(self.mask)),
                lambda: _SpdSolver(
                    self.matrix(np.full(self.n_edges, 2.0)), "ls normal matrix", direct=self.n <= _LS_DIRECT_LIMIT
                ),
            )
        return self._project(solver.solve(b, tolerance))

    def solve_robust(self, z, robust_weight, iterations, tolerance):
        """IRLS from the least-squares heights `z`: `iterations` re-weighted solves.

        The intermediate solves stop at a looser tolerance (IRLS only needs their
        direction), the last one at `tolerance`. Each reuses the AMG hierarchy of the
        unweighted system, smoothing with the weighted matrix; when that needs too many
        iterations (strongly varying weights), the hierarchy is rebuilt for the current
        weights and kept for the next solves.
        """
        if self.n_edges == 0:
            return z
        amg = self._amg
        it = 0
        while it < iterations:
            last = it == iterations - 1
            d = self.differences(z)
            w_f, w_b = _robust_weights(np.concatenate([d - self.t_f, d - self.t_b]), robust_weight)
            a = self.matrix(w_f + w_b)
            b = self.rhs(w_f * self.t_f + w_b * self.t_b)
            z0 = z - z[self.pin][self.component]  # pinned pixels at 0
            inner = tolerance if last else max(tolerance, _IRLS_INNER_TOLERANCE)
            x, count, converged = _pcg(a, b, amg.with_fine_matrix(a), z0, inner, _REUSE_LIMIT)
            if not converged:
                amg = _AmgPreconditioner(a)
                x, more, converged = _pcg(a, b, amg, x, inner)
                count += more
            z = self._project(x)
            it += 1
            if count == 0 and not last:
                # Nothing moved at the loose tolerance: the next re-weightings would be
                # the same; go straight to the last, accurate solve.
                it = iterations - 1
        return z

    def _project(self, z):
        """Remove the mean of each connected component (the free constants)."""
        if self.n_components == 1:
            return z - z.mean()
        sums = np.bincount(self.component, z, self.n_components)
        counts = np.bincount(self.component, minlength=self.n_components)
        return z - (sums / counts)[self.component]

    def to_image(self, z):
        out = np.zeros(self.shape, dtype=np.float32)
        out[self.mask] = z
        return out


def _robust_weights(residuals, kind):
    """Per-residual IRLS weights for a robust scale 1.4826 MAD, split in two halves."""
    # The scale from a regular subsample of at most ~2^19 residuals: as good an estimate,
    # for a fraction of the two partial sorts on millions of residuals.
    sample = residuals[:: max(1, residuals.size >> 19)]
    scale = median_and_sigma(sample)[1]
    magnitude = np.abs(residuals)
    # Exact data have a zero MAD: keep the scale away from 0 (relative to the residuals).
    scale = max(scale, 1e-9 * float(magnitude.max()), 1e-300)
    if kind == "huber":
        # w = 1 for |r| <= k s, else k s / |r|.
        with np.errstate(divide="ignore"):
            w = np.divide(_HUBER_K * scale, magnitude, out=magnitude)
        np.minimum(w, 1.0, out=w)
    else:
        # w = 1 / (1 + (r / (k s))^2).
        w = np.multiply(magnitude, 1.0 / (_CAUCHY_K * scale), out=magnitude)
        np.square(w, out=w)
        w += 1.0
        np.reciprocal(w, out=w)
    half = residuals.size // 2
    return w[:half], w[half:]


class _SpdSolver:
    """One symmetric positive definite system, set up once and solved for many right-hand
    sides: when `direct`, by faer's sparse Cholesky factorisation
    (:class:`irtps._core.SparseCholesky`, exact to rounding), otherwise by conjugate
    gradients preconditioned with a pyamg hierarchy set up once.
    """

    def __init__(self, matrix, name, *, direct):
        self.matrix = matrix
        self.factor = None
        self.amg = None
        if direct:
            from irtps._core import SparseCholesky

            self.factor = SparseCholesky(
                matrix.indptr.astype(np.int64), matrix.indices.astype(np.int64), matrix.data, name
            )
        else:
            self.amg = _AmgPreconditioner(matrix)

    def solve(self, b, tolerance):
        """The solution of ``matrix x = b``; `tolerance` is the conjugate gradients' relative
        residual (the factorisation's solution is exact to rounding)."""
        if self.factor is not None:
            return self.factor.solve(b)
        x, _, _ = _pcg(self.matrix, b, self.amg, np.zeros(b.size), tolerance)
        return x


#: The last system set up (key -> solver or system), reused while the key is the same: the
#: IRT-PS passes integrate on one mask. One entry, so that a large factor does not outlive
#: the next integration on another mask; a lock, for batch workers running threads.
_LAST_SYSTEM: dict = {}
_LAST_SYSTEM_LOCK = threading.Lock()


def _cached(key, build):
    """The object built by ``build()`` for `key`, built only when the last key differs."""
    with _LAST_SYSTEM_LOCK:
        system = _LAST_SYSTEM.get(key)
        if system is None:
            system = build()
            _LAST_SYSTEM.clear()
            _LAST_SYSTEM[key] = system
    return system


def _mask_key(mask):
    """A key of the mask (its shape and a digest of its bits): the system's only input."""
    return mask.shape, hashlib.blake2b(np.packbits(mask).tobytes(), digest_size=16).digest()


def _dot(a, b):
    # einsum does not go through BLAS: on a busy machine the threaded BLAS dot of long
    # vectors can be orders of magnitude slower than this single-threaded reduction.
    return float(np.einsum("i,i->", a, b))


def _pcg(a, b, precondition, x0, tolerance, max_iterations=_MAX_PCG_ITERATIONS):
    """Preconditioned conjugate gradients for an SPD system.

    Returns the solution, the number of iterations (preconditioner calls) and whether
    ``||b - a x|| <= tolerance ||b||`` was reached.
    """
    b_norm = np.sqrt(_dot(b, b))
    if b_norm == 0.0:
        return np.zeros_like(b), 0, True
    x = x0.copy()
    r = b - a @ x
    if np.sqrt(_dot(r, r)) <= tolerance * b_norm:
        return x, 0, True
    z = precondition(r)
    p = z.copy()
    rz = _dot(r, z)
    for k in range(1, max_iterations + 1):
        ap = a @ p
        alpha = rz / _dot(p, ap)
        x += alpha * p
        r -= alpha * ap
        if np.sqrt(_dot(r, r)) <= tolerance * b_norm:
            return x, k, True
        z = precondition(r)
        rz_new = _dot(r, z)
        p *= rz_new / rz
        p += z
        rz = rz_new
    return x, max_iterations, False


class _AmgPreconditioner:
    """One symmetric V-cycle of a pyamg Ruge-Stuben hierarchy, without pyamg's overheads.

    The coarsest level is solved by a sparse LU factorization (the pinned system is
    positive definite), which needs no threaded BLAS: like :func:`_dot`, this keeps a
    busy machine's BLAS threads out of the inner loop.
    """

    def __init__(self, a, levels=None, coarse_solve=None):
        if levels is None:
            import pyamg
            import scipy.sparse.linalg

            ml = pyamg.ruge_stuben_solver(
                a.copy(),  # the matrices share their index arrays: pyamg gets its own
                interpolation=_INTERPOLATION,
                max_coarse=_MAX_COARSE,
                presmoother=_PRESMOOTHER,
                postsmoother=_POSTSMOOTHER,
                keep=False,
            )
            levels = []
            for level in ml.levels:
                level.A = level.A.tocsr()
                if hasattr(level, "P"):
                    level.P = level.P.tocsr()
                    level.R = level.R.tocsr()
                levels.append(level)
            coarse_solve = scipy.sparse.linalg.factorized(levels[-1].A.tocsc())
        self.levels = levels
        self.coarse_solve = coarse_solve
        self.fine = a

    def with_fine_matrix(self, a):
        """The same hierarchy, smoothing with `a` on the finest level."""
        if len(self.levels) == 1:  # a small system, solved directly: factorize `a` itself
            return _AmgPreconditioner(a)
        return _AmgPreconditioner(a, self.levels, self.coarse_solve)

    def __call__(self, b):
        return self._cycle(0, b)

    def _cycle(self, k, b):
        levels = self.levels
        if k == len(levels) - 1:
            return self.coarse_solve(b)
        a = self.fine if k == 0 else levels[k].A
        x = np.zeros_like(b)
        levels[k].presmoother(a, x, b)
        coarse = levels[k].R @ (b - a @ x)
        x += levels[k].P @ self._cycle(k + 1, coarse)
        levels[k].postsmoother(a, x, b)
        return x
