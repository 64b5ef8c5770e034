"""The renderer against analytic truth: Lambert's law, a form factor, albedo scaling."""

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest

from irtps import Camera, CornellBox, Light, Scene, render
from irtps.errors import IrtpsError
from irtps.model.scene import MAX_PIXEL_SIZE, MIN_PIXEL_SIZE
from irtps.render.synth import synthesize

PI = np.pi


def _lights(*directions, irradiance=(PI, PI, PI)):
    return tuple(Light(direction=np.asarray(d) / np.linalg.norm(d), irradiance=irradiance) for d in directions)


def test_unshadowed_plane_follows_lamberts_law_exactly():
    size = 12
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float32)
    height = 0.3 * cols - 0.2 * rows + 5.0  # dz/dx = 0.3, dz/dy = +0.2 (y grows upward)
    normal = np.array([-0.3, -0.2, 1.0]) / np.linalg.norm([-0.3, -0.2, 1.0])
    albedo = np.array([0.9, 0.5, 0.2], np.float32)
    irradiance = (2.0, 3.0, 4.0)
    scene = Scene(Camera(size, size, 1.0), _lights([0, 0, 1], [0.5, 0.3, 0.8], [-0.4, 0.1, 0.9], irradiance=irradiance))
    out = render(
        scene, height, np.broadcast_to(albedo, (size, size, 3)), np.ones((size, size), bool), bounces=0, samples=16
    )
    inner = (slice(1, -1), slice(1, -1))  # border pixels' footprints reach past the object
    for k, light in enumerate(scene.lights):
        expected = albedo * np.asarray(irradiance) * max(0.0, float(normal @ light.direction)) / PI
        np.testing.assert_allclose(out.direct[k][inner], np.broadcast_to(expected, (size - 2, size - 2, 3)), rtol=2e-6)


def _point_to_wall_form_factor(px, py, wall_x, y_range, z_range, n=600):
    """Differential form factor from an up-facing point to a wall facing +x (midpoint rule)."""
    y = np.linspace(*y_range, n + 1)
    z = np.linspace(*z_range, n + 1)
    yc, zc = (y[:-1] + y[1:]) / 2, (z[:-1] + z[1:]) / 2
    yy, zz = np.meshgrid(yc, zc, indexing="ij")
    dx, dy, dz = wall_x - px, yy - py, zz
    r2 = dx**2 + dy**2 + dz**2
    cos_point, cos_wall = dz / np.sqrt(r2), -dx / np.sqrt(r2)
    return float((cos_point * cos_wall / r2).sum() * (y[1] - y[0]) * (z[1] - z[0]) / PI)


def test_one_bounce_matches_a_numerically_integrated_form_factor():
    # A flat plate (z = 0) in a box whose only non-black wall is the left one; the light
    # reaches that wall unshadowed, so bounce 1 on the plate is rho_p * L_wall * F(p -> wall).
    size, half, top = 16, 12.0, 8.0
    rho_plate, rho_wall = 0.7, 0.6
    black = (0.0, 0.0, 0.0)
    box = CornellBox((-half, half), (-half, half), top, (rho_wall,) * 3, black, black, black)
    light = _lights([0.5, 0.0, 1.0])
    scene = Scene(Camera(size, size, 1.0), light, floor=None, environment=box)
    out = render(
        scene,
        np.zeros((size, size)),
        np.full((size, size, 3), rho_plate),
        np.ones((size, size), bool),
        bounces=1,
        samples=4096,
        seed=3,
    )
    wall_radiance = rho_wall * PI * light[0].direction[0] / PI
    xs, ys = scene.camera.pixel_centers()
    for row, col in [(8, 1), (8, 8), (3, 12), (12, 5)]:
        px, py = xs[row, col], ys[row, col]
        expected = rho_plate * wall_radiance * _point_to_wall_form_factor(px, py, -half, (-half, half), (0.0, top))
        assert out.bounces[0, 0, row, col, 0] == pytest.approx(expected, rel=0.03), (row, col)


def test_bounce_b_scales_with_albedo_to_the_power_b_plus_one():
    # Everything has the same albedo, so with the same seed every path is the same and the
    # b-th bounce scales exactly as albedo^(b+1).
    size = 24
    cols = np.arange(size, dtype=np.float32)
    height = np.broadcast_to(4.0 + 3.0 * np.abs((cols % 8) - 4.0) / 4.0 * 2.0, (size, size)).copy()
    scene = Scene(Camera(size, size, 1.0), _lights([0.3, 0.2, 0.9], [-0.5, 0.0, 0.85], [0.0, -0.4, 0.9]))
    mask = np.ones((size, size), bool)
    low = render(scene, height, np.full((size, size, 3), 0.4), mask, bounces=3, samples=32, seed=1)
    high = render(scene, height, np.full((size, size, 3), 0.8), mask, bounces=3, samples=32, seed=1)
    for b in range(3):
        lit = low.bounces[b] > 1e-6
        assert lit.mean() > 0.3
        np.testing.assert_allclose(high.bounces[b][lit] / low.bounces[b][lit], 2.0 ** (b + 2), rtol=1e-4)
    energy = [float(high.bounces[b].sum()) for b in range(3)]
    assert energy[0] > energy[1] > energy[2] > 0


def test_same_seed_same_images_whatever_the_thread_count(tmp_path):
    script = (
        "import numpy as np, sys; from irtps.render.synth import synthesize; "
        "d, r = synthesize('grooves', size=24, lights=3, bounces=2, samples=16, seed=5, environment='none'); "
        "np.save(sys.argv[1], r.bounces)"
    )
    results = []
    for threads in ("1", "2"):
        path = tmp_path / f"t{threads}.npy"
        env = dict(os.environ, RAYON_NUM_THREADS=threads)
        subprocess.run([sys.executable, "-c", script, str(path)], check=True, env=env)
        results.append(np.load(path))
    np.testing.assert_array_equal(results[0], results[1])


def test_bad_arguments_raise_named_errors():
    scene = Scene(Camera(8, 8, 1.0), _lights([0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8]))
    flat = (np.zeros((8, 8)), np.full((8, 8, 3), 0.5), np.ones((8, 8), bool))
    with pytest.raises(IrtpsError, match="samples"):
        render(scene, *flat, samples=0)
    with pytest.raises(IrtpsError, match="height"):
        render(scene, np.zeros((7, 8)), *flat[1:])
    with pytest.raises(IrtpsError, match="albedo"):
        render(scene, flat[0], np.full((8, 8, 3), 1.5), flat[2])


def test_sparse_indirect_estimate_is_exact_where_rendered_and_close_elsewhere():
    from scipy import ndimage

    from irtps.render.renderer import render_indirect
    from irtps.render.synth import synthesize

    data, _ = synthesize("cap", size=32, lights=4, environment="cornell", bounces=0, seed=3)
    height, albedo = data.gt.height, data.gt.albedo
    full = render_indirect(data.scene, height, albedo, data.mask, bounces=2, samples=64, seed=7)
    sparse = render_indirect(data.scene, height, albedo, data.mask, bounces=2, samples=64, seed=7, stride=2)
    rows, cols = np.indices(data.mask.shape)
    edge = data.mask & ~ndimage.binary_erosion(data.mask)
    # Every pixel's paths depend only on (seed, pixel): rendered pixels match the full render.
    shift_row, shift_col = np.random.default_rng(7).integers(0, 2, size=2)
    rendered = data.mask & ((((rows - shift_row) % 2 == 0) & ((cols - shift_col) % 2 == 0)) | edge)
    np.testing.assert_array_equal(sparse[:, rendered], full[:, rendered])
    filled = data.mask & ~rendered
    assert filled.sum() > 0.5 * data.mask.sum()
    # Against a low-noise reference, the interpolated pixels are about as good as rendered ones.
    reference = render_indirect(data.scene, height, albedo, data.mask, bounces=2, samples=1024, seed=1)

    def error(estimate):
        return np.abs(estimate[:, filled] - reference[:, filled]).mean() / reference[:, filled].mean()

    assert error(sparse) < 1.2 * error(full)
    assert (sparse[:, ~data.mask] == 0).all()


def _scaled(scene, height, factor, lift):
    """`scene` and `height` at `factor` times their size, raised by `lift` pixel sizes."""
    size = scene.camera.pixel_size * factor
    z = lambda h: h * factor + lift * size  # noqa: E731
    box = scene.environment
    moved = dataclasses.replace(
        scene,
        camera=dataclasses.replace(scene.camera, pixel_size=size),
        floor=dataclasses.replace(scene.floor, height=z(scene.floor.height)),
        environment=dataclasses.replace(
            box, x=tuple(v * factor for v in box.x), y=tuple(v * factor for v in box.y), z_top=z(box.z_top)
        ),
    )
    return moved, z(np.float64(height))


@pytest.mark.parametrize("pixel_size", [MIN_PIXEL_SIZE, 1e-3, 1e3, 1e7, MAX_PIXEL_SIZE])
def test_direct_light_is_the_same_at_every_accepted_scale(pixel_size):
    # A direct-light rendering is unitless: the same object at another scale renders the same.
    # Issue 44: from a pixel size of about 3e7 the images went black.
    data, _ = synthesize("cap", size=16, lights=3, bounces=0, environment="cornell", floor=True)
    render_at = lambda scene, height: render(scene, height, data.gt.albedo, data.mask, bounces=0, samples=4).direct  # noqa: E731
    truth = render_at(*_scaled(data.scene, data.gt.height, 1.0 / data.scene.camera.pixel_size, 0.0))
    assert truth[:, data.mask].mean() > 0.3
    for lift in (0.0, -1e3):  # heights and floor 1000 pixel sizes below 0: float32 keeps them to 2^-14
        image = render_at(*_scaled(data.scene, data.gt.height, pixel_size / data.scene.camera.pixel_size, lift))
        np.testing.assert_allclose(image, truth, atol=1e-3, err_msg=f"lift {lift}")
