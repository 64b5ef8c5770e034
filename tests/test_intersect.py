"""`Renderer.intersect`, the batch closest-hit query: distances against analytic geometry,
the same answers on one thread and on all, and clear errors for bad input."""

import numpy as np
import pytest

from irtps import _core
from irtps.model.scene import Floor


def flat_renderer(n: int = 16, height: float = 2.0, floor: float = 0.0) -> _core.Renderer:
    """An all-masked n×n plane at `height` (pixel size 1) over a floor at `floor`."""
    z = np.full((n, n), height, dtype=np.float32)
    mask = np.ones((n, n), dtype=bool)
    albedo = np.full((n, n, 3), 0.5, dtype=np.float32)
    lights = np.array([[0.0, 0.0, 1.0]], dtype=np.float32)
    return _core.Renderer(
        z, mask, albedo, 1.0, lights, np.ones((1, 3), dtype=np.float32), floor=Floor(floor, (0.5, 0.5, 0.5))
    )


def test_rays_down_onto_a_plane_hit_at_its_height_and_rays_up_miss():
    renderer = flat_renderer(height=2.0)
    rng = np.random.default_rng(0)
    count = 5000
    xy = rng.uniform(-7.0, 7.0, size=(count, 2))
    origins = np.column_stack([xy, np.full(count, 10.0)]).astype(np.float32)
    tilt = rng.uniform(-0.3, 0.3, size=(count, 2))
    down = np.column_stack([tilt, -np.ones(count)])
    down /= np.linalg.norm(down, axis=1, keepdims=True)
    t, triangle = renderer.intersect(origins, down.astype(np.float32), threads=1)
    # The plane z = 2 is met after (10 − 2) / |d_z|; pixel centres span ±7.5.
    expected = 8.0 / -down[:, 2]
    landing = xy + down[:, :2] * expected[:, None]
    inside = np.all(np.abs(landing) < 7.4, axis=1)
    assert inside.sum() > 4000
    assert np.all(triangle[inside] >= 0)
    np.testing.assert_allclose(t[inside], expected[inside], rtol=1e-5)
    up = down * np.array([1.0, 1.0, -1.0])
    t_up, triangle_up = renderer.intersect(origins, up.astype(np.float32), threads=1)
    assert np.all(triangle_up == -1) and np.all(np.isinf(t_up))


def test_one_thread_and_all_threads_give_the_same_hits():
    renderer = flat_renderer(n=24, height=1.5)
    rng = np.random.default_rng(1)
    count = 20_000  # several parallel tasks
    origins = np.column_stack([rng.uniform(-14, 14, size=(count, 2)), rng.uniform(0.5, 6.0, size=count)]).astype(
        np.float32
    )
    directions = rng.normal(size=(count, 3))
    directions = (directions / np.linalg.norm(directions, axis=1, keepdims=True)).astype(np.float32)
    t1, id1 = renderer.intersect(origins, directions, threads=1)
    t_all, id_all = renderer.intersect(origins, directions)
    t2, id2 = renderer.intersect(origins, directions, threads=2)
    assert (id1 >= 0).sum() > count // 4
    np.testing.assert_array_equal(id1, id_all)
    np.testing.assert_array_equal(t1, t_all)
    np.testing.assert_array_equal(id1, id2)


def test_mismatched_rows_are_an_error_naming_the_argument():
    renderer = flat_renderer()
    with pytest.raises(ValueError, match="directions"):
        renderer.intersect(np.zeros((3, 3), np.float32), np.zeros((2, 3), np.float32))


def test_fortran_ordered_rays_are_read_row_by_row():
    # numpy lends a Fortran-ordered array as one block of x, then y, then z: the core must
    # not take it for rows.
    renderer = flat_renderer(height=2.0)
    origins = np.array([[0.0, 0.0, 10.0], [1.0, -1.0, 10.0], [3.0, 2.0, 10.0]], dtype=np.float32)
    down = np.tile(np.array([0.0, 0.0, -1.0], dtype=np.float32), (3, 1))
    t_c, _ = renderer.intersect(origins, down, threads=1)
    t_f, _ = renderer.intersect(np.asfortranarray(origins), np.asfortranarray(down), threads=1)
    np.testing.assert_allclose(t_c, 8.0, rtol=1e-6)
    np.testing.assert_array_equal(t_f, t_c)
