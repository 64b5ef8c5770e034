"""BiNI's iteration, re-stated for measurement beside irtps's integration (benches only).

Cao, Santo, Shi, Okura, Matsushita, Yagi: "Bilateral Normal Integration", ECCV 2022. BiNI is
GPL and is not a dependency; this is our own statement of its method, from the paper's
equations and the solver settings its documentation gives, so that ``depth_bench.py`` can
run it side by side on the same normals:

- unknowns: log depth per pixel (a pinhole camera K);
- four one-sided equations per pixel (up, down, right, left neighbour), each
  ``t_p (z_q - z_p) = -n_along`` with ``t_p = u n_up + v n_right + f n_in`` (u, v: the pixel's
  offset from the principal point, integer pixel centres; f: the focal length along the
  difference's axis);
- weights start at 1/2; after each solve, with ``d`` each equation's left side
  ``t_p (z_q - z_p)``, the "up" equation weighs ``sigmoid(k (d_down^2 - d_up^2))`` and the
  "down" one the rest (the same for right and left);
- each weighted system is solved by Jacobi-preconditioned conjugate gradients, warm-started
  from the last depth, until the residual is at most ``cg_tol`` times the right-hand side;
- the loop stops when the weighted energy changes by less than ``tol`` (relative) or after
  ``max_iter`` solves.

The conjugate-gradient stop matters: the re-weighting's fixed point depends on where each
inexact solve leaves the depth, so ``cg_tol`` changes the result (``depth_bench.py
--bini-tolerances``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: Neighbour offsets (row, column) and the sign that makes each a forward difference along
#: "up" (toward row 0) or "right" (toward the last column).
_DIRECTIONS = {"up": (-1, 0, 1.0), "down": (1, 0, -1.0), "right": (0, 1, 1.0), "left": (0, -1, -1.0)}


def _one_sided(mask: np.ndarray, slope_scale: np.ndarray, direction: str) -> sp.csr_matrix:
    """Rows ``slope_scale_p (z_q - z_p)`` (signed as a forward difference) for every pixel p
    whose neighbour q in `direction` is in `mask`; zero rows elsewhere."""
    d_row, d_col, sign = _DIRECTIONS[direction]
    height, width = mask.shape
    count = int(mask.sum())
    index = np.full(mask.shape, -1)
    index[mask] = np.arange(count)
    rows, cols = np.nonzero(mask)
    n_rows, n_cols = rows + d_row, cols + d_col
    inside = (n_rows >= 0) & (n_rows < height) & (n_cols >= 0) & (n_cols < width)
    inside[inside] = mask[n_rows[inside], n_cols[inside]]
    p = np.nonzero(inside)[0]
    q = index[n_rows[inside], n_cols[inside]]
    values = np.concatenate([sign * slope_scale[p], -sign * slope_scale[p]])
    return sp.csr_matrix((values, (np.concatenate([p, p]), np.concatenate([q, p]))), shape=(count, count))


def _jacobi_cg(
    matrix: sp.csr_matrix, rhs: np.ndarray, start: np.ndarray, max_iter: int, cg_tol: float
) -> tuple[np.ndarray, int]:
    """Conjugate gradients preconditioned by the diagonal, from `start`, until
    ``|r| <= cg_tol |rhs|`` (checked after each step); the solution and the steps taken."""
    inverse_diagonal = 1.0 / np.clip(matrix.diagonal(), 1e-5, None)
    x = start.copy()
    residual = rhs - matrix @ x
    preconditioned = inverse_diagonal * residual
    direction = preconditioned.copy()
    rz = residual @ preconditioned
    limit = cg_tol * cg_tol * (rhs @ rhs)
    steps = 0
    while steps < max_iter:
        product = matrix @ direction
        curvature = direction @ product
        if curvature == 0.0:
            break
        alpha = rz / curvature
        x += alpha * direction
        residual -= alpha * product
        steps += 1
        if residual @ residual <= limit:
            break
        preconditioned = inverse_diagonal * residual
        rz_next = residual @ preconditioned
        direction = preconditioned + (rz_next / rz) * direction
        rz = rz_next
    return x, steps


def bini_depth(
    normals: np.ndarray,
    mask: np.ndarray,
    K: np.ndarray,
    k: float = 2.0,
    max_iter: int = 150,
    tol: float = 1e-4,
    cg_tol: float = 1e-3,
    cg_max_iter: int = 5000,
) -> tuple[np.ndarray, int, int]:
    """Depth along the optical axis (up to scale; NaN outside `mask`) by BiNI's iteration.

    Parameters
    ----------
    normals : (H, W, 3) array
        Unit normals, x right, y up, z toward the camera (irtps's and DiLiGenT's frame).
    mask : (H, W) bool array
        The pixels to integrate.
    K : (3, 3) array
        Pinhole intrinsics in pixels (``cx`` a column, ``cy`` a row from the top).
    k, max_iter, tol, cg_tol, cg_max_iter
        BiNI's settings (its defaults).

    Returns
    -------
    depth : (H, W) array
    solves : int
        Weighted solves run.
    cg_steps : int
        Conjugate-gradient steps over all solves.
    """
    n_right = normals[mask][:, 0].astype(np.float64)
    n_up = normals[mask][:, 1].astype(np.float64)
    n_in = -normals[mask][:, 2].astype(np.float64)
    rows, cols = np.nonzero(mask)
    up_offset = K[1, 2] - rows
    right_offset = cols - K[0, 2]
    common = up_offset * n_up + right_offset * n_right
    vertical_scale = common + K[1, 1] * n_in
    horizontal_scale = common + K[0, 0] * n_in
    up, down = _one_sided(mask, vertical_scale, "up"), _one_sided(mask, vertical_scale, "down")
    right, left = _one_sided(mask, horizontal_scale, "right"), _one_sided(mask, horizontal_scale, "left")
    stacked = sp.vstack([up, down, right, left]).tocsr()
    stacked_t = stacked.T.tocsr()
    target = np.concatenate([-n_up, -n_up, -n_right, -n_right])
    count = int(mask.sum())
    weights = np.full(4 * count, 0.5)
    log_depth = np.zeros(count)
    energy = 0.5 * target @ target
    cg_steps = 0
    solves = 0
    for solves in range(1, max_iter + 1):
        normal_matrix = (stacked_t @ stacked.multiply(weights[:, None])).tocsr()
        log_depth, steps = _jacobi_cg(normal_matrix, stacked_t @ (weights * target), log_depth, cg_max_iter, cg_tol)
        cg_steps += steps
        d_up, d_down, d_right, d_left = up @ log_depth, down @ log_depth, right @ log_depth, left @ log_depth
        w_vertical = 0.5 * (1.0 + np.tanh(0.5 * k * (d_down**2 - d_up**2)))
        w_horizontal = 0.5 * (1.0 + np.tanh(0.5 * k * (d_left**2 - d_right**2)))
        weights = np.concatenate([w_vertical, 1.0 - w_vertical, w_horizontal, 1.0 - w_horizontal])
        previous, energy = energy, float(weights @ (stacked @ log_depth - target) ** 2)
        if abs(energy - previous) / previous < tol:
            break
    depth = np.full(mask.shape, np.nan)
    depth[mask] = np.exp(log_depth)
    return depth, solves, cg_steps
