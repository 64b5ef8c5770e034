"""Normal integration: analytic surfaces with exact normals, the frame, robustness, errors."""

import numpy as np
import pytest
import scipy.ndimage

import irtps.geometry.footprint_integration
import irtps.geometry.integrate
import irtps.geometry.least_squares_integration
import irtps.geometry.sparse_solvers
from irtps.errors import IrtpsError
from irtps.geometry.boundary import mask_boundary, place_height
from irtps.geometry.integrate import integrate_normals
from irtps.geometry.surface import height_to_normals

N = 128  # image side (pixels)
S = 1.0 / N  # pixel size: the image spans [-0.5, 0.5] in x and y


def grid(n=N, s=None):
    """Pixel-centre coordinates of the contract: x right, y up (against the rows)."""
    s = 1.0 / n if s is None else s
    rows, cols = np.mgrid[0:n, 0:n].astype(float)
    x = (cols + 0.5 - n / 2) * s
    y = (n / 2 - rows - 0.5) * s
    return x, y


def normals_from_slopes(zx, zy):
    """Exact unit normals normalize(-dz/dx, -dz/dy, 1) from analytic slopes."""
    n = np.stack([-zx, -zy, np.ones_like(zx)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def sphere_cap(x, y, radius=0.6):
    z = np.sqrt(np.maximum(radius**2 - x**2 - y**2, 1e-12))
    return z - z.min(), np.stack([x, y, z], axis=-1) / radius


def tilted_plane(x, y, a=0.7, b=-0.4):
    return a * x + b * y, normals_from_slopes(np.full_like(x, a), np.full_like(x, b))


def sinusoid(x, y, amplitude=0.05, kx=2 * np.pi * 1.5, ky=2 * np.pi):
    z = amplitude * np.sin(kx * x) * np.cos(ky * y)
    zx = amplitude * kx * np.cos(kx * x) * np.cos(ky * y)
    zy = -amplitude * ky * np.sin(kx * x) * np.sin(ky * y)
    return z, normals_from_slopes(zx, zy)


def disc(x, y, radius=0.45, cx=0.0, cy=0.0):
    return (x - cx) ** 2 + (y - cy) ** 2 < radius**2


def ring(x, y):
    r2 = x**2 + y**2
    return (r2 < 0.46**2) & (r2 > 0.2**2)


def blob(x, y):
    """An irregular, non-convex blob: a smoothed random field, thresholded."""
    rng = np.random.default_rng(7)
    field = scipy.ndimage.gaussian_filter(rng.normal(size=x.shape), sigma=x.shape[0] / 12, mode="wrap")
    field -= 0.6 * field.std() * (x**2 + y**2) / 0.1  # keep it away from the border
    labels, count = scipy.ndimage.label(field > 0)
    largest = np.argmax(np.bincount(labels.ravel())[1:]) + 1
    return scipy.ndimage.binary_fill_holes(labels == largest)


def two_discs(x, y):
    return disc(x, y, 0.22, -0.24, 0.1) | disc(x, y, 0.18, 0.25, -0.2)


def relative_rmse(height, truth, mask):
    """RMSE over the mask after removing the best constant per 4-connected component,
    relative to the range of the truth."""
    labels, count = scipy.ndimage.label(mask)
    err = np.zeros(mask.sum())
    comp = labels[mask]
    diff = height[mask].astype(np.float64) - truth[mask]
    for k in range(1, count + 1):
        err[comp == k] = diff[comp == k] - diff[comp == k].mean()
    return float(np.sqrt(np.mean(err**2)) / np.ptp(truth[mask]))


SURFACES = {"sphere_cap": sphere_cap, "tilted_plane": tilted_plane, "sinusoid": sinusoid}
MASKS = {"disc": disc, "ring": ring, "blob": blob, "two_discs": two_discs}


@pytest.mark.parametrize("mask_name", list(MASKS))
@pytest.mark.parametrize("surface_name", list(SURFACES))
def test_ls_recovers_analytic_surfaces(surface_name, mask_name):
    x, y = grid()
    truth, normals = SURFACES[surface_name](x, y)
    mask = MASKS[mask_name](x, y)
    assert not mask.all() and mask.sum() > 1000
    height = integrate_normals(normals, mask, pixel_size=S)
    assert height.dtype == np.float32 and height.shape == mask.shape
    assert np.all(height[~mask] == 0)
    assert relative_rmse(height, truth, mask) < 0.005


def test_ls_is_centred_per_component():
    x, y = grid()
    truth, normals = sinusoid(x, y)
    mask = two_discs(x, y)
    height = integrate_normals(normals, mask, pixel_size=S)
    labels, count = scipy.ndimage.label(mask)
    assert count == 2
    for k in (1, 2):
        assert abs(height[labels == k].mean()) < 1e-6


def test_pixel_size_scales_heights():
    x, y = grid(64)
    truth, normals = sphere_cap(x, y)
    mask = disc(x, y)
    h1 = integrate_normals(normals, mask, pixel_size=1.0 / 64)
    h3 = integrate_normals(normals, mask, pixel_size=3.0 / 64)
    np.testing.assert_allclose(h3[mask], 3.0 * h1[mask], rtol=1e-4, atol=1e-6)


def test_frame_rising_right_and_up():
    """Heights rising with +x (columns) and with +y (toward row 0) come out so."""
    n = 64
    x, y = grid(n)
    truth = 0.5 * x + 0.3 * y + 0.2 * x * y
    normals = normals_from_slopes(0.5 + 0.2 * y, 0.3 + 0.2 * x)
    mask = disc(x, y)
    mid = n // 2
    for method, m in (("ls", mask), ("mestimator", mask), ("dct", None)):
        height = integrate_normals(normals, m, pixel_size=1.0 / n, method=method)
        assert height[mid, -8] > height[mid, 7] + 0.3, method  # right is higher
        assert height[7, mid] > height[-8, mid] + 0.2, method  # up (toward row 0) is higher
        keep = np.ones((n, n), bool) if m is None else m
        assert relative_rmse(height, truth, keep) < 0.005, method


@pytest.mark.parametrize("method", ["ls", "mestimator", "dct", "fc"])
def test_frame_peak_up_and_right(method):
    """A periodic bump peaking at x = +0.25, y = +0.25: in the upper-right quadrant."""
    n = 64
    x, y = grid(n)
    k = 2 * np.pi
    truth = np.cos(k * (x - 0.25)) + np.cos(k * (y - 0.25))
    normals = normals_from_slopes(-k * np.sin(k * (x - 0.25)), -k * np.sin(k * (y - 0.25)))
    height = integrate_normals(normals, None, pixel_size=1.0 / n, method=method)
    row, col = np.unravel_index(np.argmax(height), height.shape)
    assert (row, col) in [(15, 47), (15, 48), (16, 47), (16, 48)]  # x = 0.25, y = 0.25 +- half a pixel
    assert relative_rmse(height, truth, np.ones((n, n), bool)) < 0.005


def test_inverse_of_height_to_normals():
    """Round trip with the contract's own normals from heights (central differences)."""
    x, y = grid(96)
    truth, _ = sphere_cap(x, y)
    mask = blob(x, y)
    normals = height_to_normals(truth, mask, pixel_size=1.0 / 96)
    height = integrate_normals(normals, mask, pixel_size=1.0 / 96)
    assert relative_rmse(height, truth, mask) < 0.01


def gross_outliers(normals, fraction, seed):
    rng = np.random.default_rng(seed)
    bad = rng.random(normals.shape[:2]) < fraction
    v = rng.normal(size=normals.shape)
    v[..., 2] = np.abs(v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    out = normals.copy()
    out[bad] = v[bad]
    return out


@pytest.mark.parametrize("robust_weight", ["huber", "cauchy"])
def test_mestimator_beats_ls_on_outliers(robust_weight):
    x, y = grid()
    truth, normals = sphere_cap(x, y)
    mask = blob(x, y)
    noisy = gross_outliers(normals, 0.05, seed=3)
    ls = relative_rmse(integrate_normals(noisy, mask, pixel_size=S), truth, mask)
    robust = relative_rmse(
        integrate_normals(noisy, mask, pixel_size=S, method="mestimator", robust_weight=robust_weight), truth, mask
    )
    assert robust < 0.5 * ls
    assert robust < 0.005


def test_mestimator_on_clean_normals_matches_ls():
    x, y = grid()
    truth, normals = sinusoid(x, y)
    mask = ring(x, y)
    height = integrate_normals(normals, mask, pixel_size=S, method="mestimator")
    assert relative_rmse(height, truth, mask) < 0.005


def test_dct_full_rectangle_equals_ls():
    x, y = grid()
    truth = np.exp(-((x - 0.1) ** 2 + y**2) / 0.08) + 0.3 * x - 0.1 * y
    zx = -2 * (x - 0.1) / 0.08 * np.exp(-((x - 0.1) ** 2 + y**2) / 0.08) + 0.3
    zy = -2 * y / 0.08 * np.exp(-((x - 0.1) ** 2 + y**2) / 0.08) - 0.1
    normals = normals_from_slopes(zx, zy)
    full = np.ones(x.shape, bool)
    dct = integrate_normals(normals, None, pixel_size=S, method="dct")
    assert relative_rmse(dct, truth, full) < 0.005
    ls = integrate_normals(normals, full, pixel_size=S, method="ls", tolerance=1e-9)
    # Same functional, different solver.
    assert np.max(np.abs(dct - ls)) < 1e-4 * np.ptp(truth)
    assert abs(dct.mean()) < 1e-6


def test_fc_periodic_surface():
    x, y = grid()
    # Whole periods across the image (it spans 1 in x and y): periodic samples.
    truth = 0.05 * np.sin(2 * np.pi * 2 * x) * np.cos(2 * np.pi * y) + 0.03 * np.cos(2 * np.pi * 3 * y)
    zx = 0.05 * 2 * np.pi * 2 * np.cos(2 * np.pi * 2 * x) * np.cos(2 * np.pi * y)
    zy = -0.05 * 2 * np.pi * np.sin(2 * np.pi * 2 * x) * np.sin(2 * np.pi * y) - 0.03 * 2 * np.pi * 3 * np.sin(
        2 * np.pi * 3 * y
    )
    normals = normals_from_slopes(zx, zy)
    height = integrate_normals(normals, np.ones(x.shape, bool), pixel_size=S, method="fc")
    assert relative_rmse(height, truth, np.ones(x.shape, bool)) < 1e-4


@pytest.mark.parametrize("method", ["dct", "fc"])
def test_spectral_methods_need_full_rectangle(method):
    x, y = grid(32)
    _, normals = sphere_cap(x, y)
    with pytest.raises(IrtpsError, match="mask") as info:
        integrate_normals(normals, disc(x, y), method=method)
    assert isinstance(info.value, ValueError)


def test_grazing_and_backfacing_normals_stay_bounded():
    x, y = grid(64)
    truth, normals = sphere_cap(x, y)
    mask = disc(x, y)
    normals[20, 20] = [1.0, 0.0, 0.0]  # nz = 0
    normals[30, 40] = [0.0, -0.6, -0.8]  # facing away
    normals[40, 30] = [0.0, 0.0, 0.0]  # no normal at all
    height = integrate_normals(normals, mask, pixel_size=1.0 / 64, max_slope=5.0)
    assert np.all(np.isfinite(height))
    p, q = irtps.geometry.integrate.normals_to_gradients(normals, mask, max_slope=5.0)
    assert p[20, 20] == -5.0 and q[30, 40] == 5.0 and p[40, 30] == 0.0
    assert np.max(np.abs(p)) <= 5.0 and np.max(np.abs(q)) <= 5.0


def test_small_and_odd_masks():
    normals = np.zeros((6, 7, 3))
    normals[..., 2] = 1.0
    mask = np.zeros((6, 7), bool)
    mask[1, 1] = True  # an isolated pixel
    mask[3, 2:6] = True  # a one-pixel-wide line
    mask[5, 0] = True  # in the corner, touching the previous only diagonally
    height = integrate_normals(normals, mask)
    assert np.all(height == 0)
    height = integrate_normals(normals, mask, method="mestimator")
    assert np.all(height == 0)
    one = np.zeros((1, 1, 3))
    one[0, 0, 2] = 1.0
    assert integrate_normals(one).tolist() == [[0.0]]


def test_nan_outside_mask_is_ignored():
    x, y = grid(64)
    truth, normals = tilted_plane(x, y)
    mask = disc(x, y)
    normals[~mask] = np.nan
    height = integrate_normals(normals.astype(np.float32), mask, pixel_size=1.0 / 64)
    assert relative_rmse(height, truth, mask) < 0.005


def test_place_height():
    height = np.zeros((7, 9))
    mask = np.zeros((7, 9), bool)
    mask[1:6, 1:5] = True  # component A: boundary ring of 14 pixels around 2x3 interior... 3x2
    mask[0:3, 6:9] = True  # component B: touches the image border
    height[1:6, 1:5] = np.arange(20).reshape(5, 4) + 10.0
    height[0:3, 6:9] = 100.0
    height[1, 7] = 200.0  # B's only interior pixel
    boundary = mask_boundary(mask)
    assert boundary[1:6, 1:5].sum() == 14 and not boundary[2:5, 2:4].any()
    assert boundary[0:3, 6:9].sum() == 8 and not boundary[1, 7]

    placed = place_height(height, mask, base_height=2.5)
    assert placed.dtype == np.float32
    a = np.zeros_like(mask)
    a[1:6, 1:5] = True
    b = mask & ~a
    assert np.median(placed[a & boundary]) == pytest.approx(2.5)
    assert np.median(placed[b & boundary]) == pytest.approx(2.5)
    assert placed[1, 7] == pytest.approx(102.5)  # shapes kept, shifted
    np.testing.assert_allclose(placed[a] - height[a], placed[a][0] - height[a][0])
    assert np.all(placed[~mask] == 0)

    # One shift for the whole mask.
    whole = place_height(height, mask, per_component=False)
    assert np.median(whole[boundary]) == pytest.approx(0.0)
    np.testing.assert_allclose(whole[mask] - height[mask], whole[mask][0] - height[mask][0])


def test_place_height_after_integration():
    x, y = grid(64)
    truth, normals = sphere_cap(x, y)
    mask = disc(x, y)
    height = place_height(integrate_normals(normals, mask, pixel_size=1.0 / 64), mask, base_height=1.0)
    boundary = mask_boundary(mask)
    assert np.median(height[boundary]) == pytest.approx(1.0, abs=1e-6)
    # The cap's rim is at (nearly) constant height: it now sits at the base height.
    np.testing.assert_allclose(height[mask], truth[mask] - np.median(truth[boundary]) + 1.0, atol=2e-3)


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"normals": np.zeros((8, 8))}, "normals"),
        ({"normals": np.zeros((8, 8, 4))}, "normals"),
        ({"mask": np.ones((8, 9), bool)}, "mask"),
        ({"mask": np.zeros((8, 8), bool)}, "mask"),
        ({"method": "poisson"}, "method"),
        ({"method": "mestimator", "robust_weight": "tukey"}, "robust_weight"),
        ({"method": "mestimator", "iterations": -1}, "iterations"),
        ({"pixel_size": 0.0}, "pixel_size"),
        ({"pixel_size": float("nan")}, "pixel_size"),
        ({"max_slope": -1.0}, "max_slope"),
        ({"tolerance": 0.0}, "tolerance"),
    ],
)
def test_bad_inputs(kwargs, word):
    args = {"normals": np.dstack([np.zeros((8, 8)), np.zeros((8, 8)), np.ones((8, 8))]), "mask": np.ones((8, 8), bool)}
    args.update(kwargs)
    with pytest.raises(IrtpsError, match=word) as info:
        integrate_normals(args.pop("normals"), args.pop("mask"), **args)
    assert isinstance(info.value, ValueError)


def test_nan_normals_inside_mask():
    normals = np.dstack([np.zeros((8, 8)), np.zeros((8, 8)), np.ones((8, 8))])
    normals[3, 4, 0] = np.nan
    with pytest.raises(IrtpsError, match="normals"):
        integrate_normals(normals, np.ones((8, 8), bool))
    mask = np.ones((8, 8), bool)
    mask[3, 4] = False
    assert np.all(np.isfinite(integrate_normals(normals, mask)))


def test_place_height_bad_inputs():
    with pytest.raises(IrtpsError, match="height"):
        place_height(np.zeros((3, 3, 3)))
    with pytest.raises(IrtpsError, match="mask"):
        place_height(np.zeros((3, 3)), np.ones((3, 4), bool))
    with pytest.raises(IrtpsError, match="mask"):
        place_height(np.zeros((3, 3)), np.zeros((3, 3), bool))
    with pytest.raises(IrtpsError, match="height"):
        place_height(np.full((3, 3), np.nan), np.ones((3, 3), bool))
    with pytest.raises(IrtpsError, match="base_height"):
        place_height(np.zeros((3, 3)), base_height=float("inf"))


def test_tiny_masks_match_direct_least_squares():
    """Systems small enough for a single AMG level (a direct solve) give the same heights."""
    x, y = grid(24)
    truth, normals = sinusoid(x, y)
    mask = disc(x, y)
    noisy = gross_outliers(normals, 0.05, seed=5)
    for method in ("ls", "mestimator"):
        height = integrate_normals(noisy, mask, pixel_size=1.0 / 24, method=method)
        assert np.all(np.isfinite(height)) and abs(height[mask].mean()) < 1e-6
    exact = integrate_normals(normals, mask, pixel_size=1.0 / 24)
    assert relative_rmse(exact, truth, mask) < 0.005


def _v_grooves_on_a_disc(size=160):
    rows, cols = np.mgrid[0:size, 0:size].astype(float)
    mask = (rows - size / 2) ** 2 + (cols - size / 2) ** 2 < (0.45 * size) ** 2
    height = 20 + 10 * np.abs(((cols / 10.0) % 2) - 1) + 0.02 * rows
    return height, mask


def test_footprint_integration_keeps_creases_that_least_squares_blunts():
    from irtps.geometry.surface import height_to_normals

    height, mask = _v_grooves_on_a_disc()
    normals = height_to_normals(height, mask)  # the footprint-mean (central-difference) normals

    def relative_rmse(z):
        d = (z - height)[mask]
        return np.sqrt(((d - d.mean()) ** 2).mean()) / np.ptp(height[mask])

    footprint = relative_rmse(integrate_normals(normals, mask, method="footprint"))
    least_squares = relative_rmse(integrate_normals(normals, mask, method="ls"))
    assert footprint < 0.005
    assert footprint < 0.5 * least_squares  # 0.38x with the coupling of 0.3 that keeps large objects stable


def test_footprint_integration_of_a_smooth_surface_with_two_parts():
    from irtps.geometry.surface import height_to_normals

    rows, cols = np.mgrid[0:96, 0:96].astype(float)
    mask = ((rows - 30) ** 2 + (cols - 30) ** 2 < 20**2) | ((rows - 66) ** 2 + (cols - 66) ** 2 < 22**2)
    height = 5 * np.sin(cols / 9) + 3 * np.cos(rows / 7)
    z = integrate_normals(height_to_normals(height, mask), mask, method="footprint")
    labels, count = scipy.ndimage.label(mask)
    assert count == 2
    for part in (1, 2):
        d = (z - height)[labels == part]
        assert np.sqrt(((d - d.mean()) ** 2).mean()) < 0.005 * np.ptp(height[mask])


def test_sparse_cholesky_solves_a_grid_laplacian():
    """The core's factor-once Cholesky solves a known SPD system for several right-hand sides."""
    import scipy.sparse

    from irtps._core import SparseCholesky

    n = 30
    path = scipy.sparse.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    laplacian = (scipy.sparse.kronsum(path, path) + 0.01 * scipy.sparse.eye(n * n)).tocsr()
    laplacian.sort_indices()
    factor = SparseCholesky(laplacian.indptr.astype(np.int64), laplacian.indices.astype(np.int64), laplacian.data)
    assert factor.dim == n * n and factor.factor_len >= laplacian.nnz // 2
    rng = np.random.default_rng(0)
    for _ in range(3):
        x = rng.normal(size=n * n)
        np.testing.assert_allclose(factor.solve(laplacian @ x), x, rtol=0, atol=1e-9)


def test_sparse_cholesky_errors_name_the_input():
    import scipy.sparse

    from irtps._core import SparseCholesky
    from irtps.errors import ArgumentError

    indefinite = scipy.sparse.diags([-np.ones(9), np.ones(10), -np.ones(9)], [-1, 0, 1]).tocsr()
    with pytest.raises(ArgumentError, match="^normal_matrix: matrix is not positive definite"):
        SparseCholesky(
            indefinite.indptr.astype(np.int64), indefinite.indices.astype(np.int64), indefinite.data, "normal_matrix"
        )
    with pytest.raises(ArgumentError, match="^a: indptr"):
        SparseCholesky(np.array([0, 5], np.int64), np.array([0], np.int64), np.array([1.0]), "a")
    factor = SparseCholesky(np.array([0, 1], np.int64), np.array([0], np.int64), np.array([4.0]))
    with pytest.raises(ArgumentError, match="^b:"):
        factor.solve(np.ones(2))


@pytest.mark.parametrize("method", ["ls", "footprint"])
def test_same_mask_reuses_the_factorisation_and_matches_conjugate_gradients(method, monkeypatch):
    """A second integration on the same mask reuses the system; the factor's heights equal
    those of pyamg-preconditioned conjugate gradients to the solver's tolerance."""
    x, y = grid(64)
    truth, normals = sinusoid(x, y)
    mask = disc(x, y)
    irtps.geometry.sparse_solvers._LAST_SYSTEM.clear()
    built = []
    original = irtps.geometry.sparse_solvers.SpdSolver.__init__

    def counting(self, matrix, name, *, direct):
        built.append(direct)
        original(self, matrix, name, direct=direct)

    monkeypatch.setattr(irtps.geometry.sparse_solvers.SpdSolver, "__init__", counting)
    first = integrate_normals(normals, mask, pixel_size=1 / 64, method=method)
    second = integrate_normals(normals[:, ::-1] * [-1, 1, 1], mask, pixel_size=1 / 64, method=method)
    assert built == [True]  # one factorisation for both
    assert not np.allclose(first, second)  # a new right-hand side, not a cached answer
    monkeypatch.setattr(irtps.geometry.least_squares_integration, "_LS_DIRECT_LIMIT", 0)
    monkeypatch.setattr(irtps.geometry.footprint_integration, "_FOOTPRINT_DIRECT_LIMIT", 0)
    irtps.geometry.sparse_solvers._LAST_SYSTEM.clear()
    iterative = integrate_normals(normals, mask, pixel_size=1 / 64, method=method, tolerance=1e-10)
    assert built == [True, False]
    np.testing.assert_allclose(first, iterative, rtol=0, atol=1e-5 * np.ptp(first[mask]))
    assert relative_rmse(first, truth, mask) < 0.01
