"""The ``"footprint"`` normal integration: least squares on central differences, the slopes
photometric stereo measures, set up once per mask (for
:func:`irtps.geometry.integrate.integrate_normals`).
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage
import scipy.sparse

from irtps.geometry.boundary import FOUR_CONNECTED
from irtps.geometry.sparse_solvers import SpdSolver, cached, mask_key

#: Weight of the forward differences that couple odd and even pixels in ``"footprint"``.
#: Central differences leave the odd and even pixels free to drift apart: a weaker coupling
#: let a pixel-scale ripple grow (pixels came out locally concave, then bright with false
#: inter-reflections inside IRT-PS); this one keeps the ripple down and creases still sharp
#: (docs/benchmarks.md, Normal integration).
_FOOTPRINT_COUPLING = 0.3
#: Largest ``"footprint"`` systems (unknowns) factored rather than solved by AMG-PCG
#: (`irtps.geometry.sparse_solvers.SpdSolver`): its factor's fill-in is larger than ``"ls"``'s.
_FOOTPRINT_DIRECT_LIMIT = 100_000


def integrate_footprint(mask, gc, gr, tolerance):
    """Least squares on central differences (one-sided at the mask edge), weakly coupled."""
    system = cached(("footprint", mask_key(mask)), lambda: FootprintSystem(mask).with_solver())
    return system.solve(gc, gr, tolerance)


class FootprintSystem:
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
        labels, self.components = scipy.ndimage.label(mask, structure=FOUR_CONNECTED)
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
            self.solver = SpdSolver(self.normal, "footprint normal matrix", direct=direct)
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
