"""The re-rendering of a reconstruction: its residual, its noise and its shadows, against
analytic cases."""

import numpy as np
import pytest

from irtps import Camera, Floor, Light, Scene, render
from irtps.render.residual import compared_observations, render_with_residual

SIZE = 40


def _block_scene():
    """A 12×12 block, 6 high, on a floor, lit from +x and from −y at 45° and from above."""
    s = np.sqrt(0.5)
    lights = [Light(direction=d, irradiance=(np.pi,) * 3) for d in ([s, 0, s], [0, -s, s], [0, 0, 1])]
    scene = Scene(Camera(SIZE, SIZE, 1.0), lights, floor=Floor(0.0, (0.8, 0.8, 0.8)))
    mask = np.zeros((SIZE, SIZE), bool)
    mask[14:26, 14:26] = True
    height = np.where(mask, 6.0, 0.0)
    albedo = np.where(mask[..., None], 0.5, 0.0) * np.ones(3)
    return scene, height, albedo, mask


def test_the_rendering_casts_the_shadows_of_the_geometry():
    scene, height, albedo, mask = _block_scene()
    direct = render(scene, height, albedo, mask, bounces=1, samples=8).direct.sum(axis=-1)
    shadowed = direct <= 0.05 * direct.max(axis=0)
    # Light 0 comes from +x (growing column) at 45°: the block's side stands at the centre of
    # column 14 (contract §2), so the floor from x = 8 to 14 is in its shadow (columns 9-13
    # whole, column 8 half) and further left it is lit; nothing is in shadow from above.
    row = 20
    assert shadowed[0, row, 9:14].all() and not shadowed[0, row, :8].any()
    # Light 1 comes from −y, i.e. from growing rows (y grows upward): the same, above.
    assert shadowed[1, 9:14, row].all() and not shadowed[1, :8, row].any()
    assert not shadowed[2].any()
    assert not shadowed[:, mask].any()  # the block's flat top is lit by every light


def test_the_residual_is_lower_for_the_true_height_and_its_noise_shrinks_with_samples():
    scene, height, albedo, mask = _block_scene()
    images = render(scene, height, albedo, mask, bounces=2, samples=64, seed=3).images
    right = render_with_residual(scene, height, albedo, mask, images, bounces=2, samples=64).residual
    sunk = render_with_residual(scene, np.where(mask, 1.0, 0.0), albedo, mask, images, bounces=2, samples=64).residual
    assert right.surroundings < 0.5 * sunk.surroundings  # its shadows are in the wrong place
    few = render_with_residual(scene, height, albedo, mask, images, bounces=2, samples=4).residual
    assert 0 < right.noise < few.noise
    assert render_with_residual(scene, height, albedo, mask, images, bounces=2, samples=1).residual.noise == 0


@pytest.mark.parametrize("robust", [True, False])
def test_the_residual_compares_what_photometric_stereo_fits(robust):
    images = np.ones((4, 1, 2, 3), np.float32)
    images[0] = 2.0  # saturated
    images[3] *= 0.01  # dark
    kept = compared_observations(
        images, np.ones((4, 3)), np.array([[True, False]]), robust=robust, shadow_fraction=0.05, saturation=1.5
    )[..., 0]
    assert kept[:, 0, 1].tolist() == [False, True, True, True]  # around the object: not saturated
    assert kept[:, 0, 0].tolist() == [False, True, True, not robust]


@pytest.mark.parametrize("layout", ["C", "F", "strided"])
def test_the_cores_comparison_matches_numpy_in_any_memory_layout(layout):
    from irtps import _core

    rng = np.random.default_rng(3)
    lights, pixels = 5, 40
    direct, first, second = (rng.random((lights, pixels, 3), dtype=np.float32) for _ in range(3))
    frame = rng.random((lights, 2 * pixels, 3), dtype=np.float32)
    kept = rng.random((lights, 2 * pixels)) > 0.3
    observed, keep = np.ascontiguousarray(frame[:, ::2]), np.ascontiguousarray(kept[:, ::2])
    if layout == "F":
        observed, keep = np.asfortranarray(observed), np.asfortranarray(keep)
    elif layout == "strided":
        observed, keep = frame[:, ::2], kept[:, ::2]
    indirect, noise, sums = _core.compare_rendering(direct, [first, second], [3, 5], observed, keep)
    expected = (3 * first + 5 * second) / 8
    np.testing.assert_array_equal(indirect, expected)
    np.testing.assert_allclose(
        noise, np.square(first - second, dtype=np.float64).sum(axis=(0, 2)) * 15 / 64, rtol=1e-12
    )
    kept3 = np.broadcast_to(keep[..., None], observed.shape)
    for total, rendered in zip(sums[:1] + sums[2:], (direct + expected, direct + first, direct + second)):
        assert total == pytest.approx(float(np.abs(rendered - observed)[kept3].sum(dtype=np.float64)), rel=1e-9)
    assert sums[1] == pytest.approx(float(np.abs(observed)[kept3].sum(dtype=np.float64)), rel=1e-9)
    with pytest.raises(ValueError, match="keep"):
        _core.compare_rendering(direct, [first], [8], observed, keep[:, 1:])
    # The same pixels as a window of a longer list of observations.
    longer, kept_longer = np.concatenate([frame[:, :7], observed], axis=1), np.concatenate([kept[:, :7], keep], axis=1)
    assert _core.compare_rendering(direct, [first, second], [3, 5], longer, kept_longer, first=7)[2] == pytest.approx(
        sums, rel=1e-12
    )
    with pytest.raises(ValueError, match="observed"):
        _core.compare_rendering(direct, [first], [8], longer, kept_longer, first=8)
