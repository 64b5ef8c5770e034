"""The symmetric positive definite solvers of the least-squares normal integrations: faer's
sparse Cholesky factorisation or conjugate gradients preconditioned with an algebraic
multigrid V-cycle (pyamg), set up once and kept for the next integration on the same mask.
"""

from __future__ import annotations

import hashlib
import threading

import numpy as np

# Size below which the AMG hierarchy stops coarsening (then a sparse LU).
_MAX_COARSE = 300
# Ruge-Stuben interpolation: "direct" sets up faster than "classical" on these
# Laplacians, for one or two more conjugate-gradient iterations, which cost less than the
# set-up saves (docs/benchmarks.md, Normal integration).
_INTERPOLATION = "direct"
_MAX_PCG_ITERATIONS = 1000
_PRESMOOTHER = ("gauss_seidel", {"sweep": "symmetric"})
_POSTSMOOTHER = ("gauss_seidel", {"sweep": "symmetric"})


class SpdSolver:
    """One symmetric positive definite system, set up once and solved for many right-hand
    sides: when `direct`, by faer's sparse Cholesky factorisation
    (:class:`irtps._core.SparseCholesky`, exact to rounding), otherwise by conjugate
    gradients preconditioned with a pyamg hierarchy set up once.

    The factor wins from the second solve on (the IRT-PS passes), but its fill-in grows
    faster than the system (AMD ordering), and a single solve (classic PS) is slower by the
    factor on large masks: the integrations factor their systems up to a size (the
    ``_LS_DIRECT_LIMIT`` and ``_FOOTPRINT_DIRECT_LIMIT`` of
    `irtps.geometry.least_squares_integration` and `irtps.geometry.footprint_integration`),
    where the later passes are its gain and the kept factor stays small beside the images,
    and set pyamg up once beyond (figures: docs/benchmarks.md, Normal integration).
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
            self.amg = AmgPreconditioner(matrix)

    def solve(self, b, tolerance):
        """The solution of ``matrix x = b``; `tolerance` is the conjugate gradients' relative
        residual (the factorisation's solution is exact to rounding)."""
        if self.factor is not None:
            return self.factor.solve(b)
        x, _, _ = pcg(self.matrix, b, self.amg, np.zeros(b.size), tolerance)
        return x


#: The last system set up (key -> solver or system), reused while the key is the same: the
#: IRT-PS passes integrate on one mask. One entry, so that a large factor does not outlive
#: the next integration on another mask; a lock, for batch workers running threads.
_LAST_SYSTEM: dict = {}
_LAST_SYSTEM_LOCK = threading.Lock()


def cached(key, build):
    """The object built by ``build()`` for `key`, built only when the last key differs."""
    with _LAST_SYSTEM_LOCK:
        system = _LAST_SYSTEM.get(key)
        if system is None:
            system = build()
            _LAST_SYSTEM.clear()
            _LAST_SYSTEM[key] = system
    return system


def mask_key(mask):
    """A key of the mask (its shape and a digest of its bits): the system's only input."""
    return mask.shape, hashlib.blake2b(np.packbits(mask).tobytes(), digest_size=16).digest()


def _dot(a, b):
    # einsum does not go through BLAS: on a busy machine the threaded BLAS dot of long
    # vectors can be orders of magnitude slower than this single-threaded reduction.
    return float(np.einsum("i,i->", a, b))


def pcg(a, b, precondition, x0, tolerance, max_iterations=_MAX_PCG_ITERATIONS):
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


class AmgPreconditioner:
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
            return AmgPreconditioner(a)
        return AmgPreconditioner(a, self.levels, self.coarse_solve)

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
