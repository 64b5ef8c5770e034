"""The ``"ls"`` and ``"mestimator"`` normal integrations: the discrete functional of Quéau,
Durou & Aujol over a mask, solved by least squares or by iteratively re-weighted least
squares (for :func:`irtps.geometry.integrate.integrate_normals`).
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage
import scipy.sparse

from irtps.geometry.boundary import FOUR_CONNECTED
from irtps.geometry.sparse_solvers import AmgPreconditioner, SpdSolver, cached, mask_key, pcg
from irtps.ps.robust_stats import median_and_sigma

# Tuning constants giving 95 % efficiency on Gaussian residuals (in units of the scale).
_HUBER_K = 1.345
_CAUCHY_K = 2.385
# Tolerance of the intermediate IRLS solves; more than _REUSE_LIMIT iterations with the
# unweighted hierarchy and the hierarchy is rebuilt for the weighted matrix.
IRLS_INNER_TOLERANCE = 1e-3
_REUSE_LIMIT = 25
#: Largest ``"ls"`` systems (unknowns) factored rather than solved by AMG-PCG
#: (`irtps.geometry.sparse_solvers.SpdSolver`); ``"mestimator"``'s matrix changes with every
#: re-weighting and is always solved by AMG-PCG.
_LS_DIRECT_LIMIT = 100_000


class LeastSquaresProblem:
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
        self.labels, self.n_components = scipy.ndimage.label(mask, structure=FOUR_CONNECTED)
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
        :func:`irtps.geometry.sparse_solvers.cached`), except for the start of ``"mestimator"`` (`robust_start`), whose
        AMG hierarchy the re-weighted solves reuse."""
        if self.n_edges == 0:
            return np.zeros(self.n)
        b = self.rhs(self.t_f + self.t_b)
        if robust_start:
            solver = SpdSolver(self.matrix(np.full(self.n_edges, 2.0)), "ls normal matrix", direct=False)
            self._amg = solver.amg
        else:
            solver = cached(
                ("ls", mask_key(self.mask)),
                lambda: SpdSolver(
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
            inner = tolerance if last else max(tolerance, IRLS_INNER_TOLERANCE)
            x, count, converged = pcg(a, b, amg.with_fine_matrix(a), z0, inner, _REUSE_LIMIT)
            if not converged:
                amg = AmgPreconditioner(a)
                x, more, converged = pcg(a, b, amg, x, inner)
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
