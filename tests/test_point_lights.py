"""Point lights in the renderer (contract §4b), through the core's bindings: the
inverse-square law in world units, and named errors."""

import numpy as np
import pytest

from irtps import _core
from irtps.errors import ArgumentError

SIZE = 16


def _renderer(light_positions, pixel_size=0.5, intensity=(10.0, 20.0, 30.0), lights=None):
    """A level plate of 0.5 albedo at height 0; `lights` directions (default one per row of
    `light_positions`, straight up)."""
    count = len(light_positions) if lights is None else lights
    return _core.Renderer(
        np.zeros((SIZE, SIZE), np.float32),
        np.ones((SIZE, SIZE), bool),
        np.full((SIZE, SIZE, 3), 0.5, np.float32),
        pixel_size,
        np.tile(np.float32([0, 0, 1]), (count, 1)),
        np.tile(np.float32(intensity), (count, 1)),
        light_positions=np.asarray(light_positions, np.float32),
    )


def _footprint_mean(position, intensity, row, col, pixel_size):
    """ρ I cos θ / (π r²) over pixel (row, col) of the level plate at height 0, by a 32 x 32
    grid (ρ = 0.5)."""
    offsets = (np.arange(32) + 0.5) / 32
    x = (col + offsets[None, :] - SIZE / 2) * pixel_size
    y = (SIZE / 2 - row - offsets[:, None]) * pixel_size
    d = np.stack(np.broadcast_arrays(position[0] - x, position[1] - y, np.full_like(x * y, position[2])), -1)
    r2 = (d**2).sum(-1)
    return 0.5 * intensity * (d[..., 2] / np.sqrt(r2) / (np.pi * r2)).mean()


def test_a_point_light_falls_off_with_the_square_of_the_world_distance():
    position = np.array([1.0, -2.0, 6.0])
    renderer = _renderer([position])
    direct = renderer.render_rows(0, SIZE, 0, 1, 256, 0, True)[0, 0]
    for row, col in [(1, 1), (5, 9), (12, 3)]:
        expected = _footprint_mean(position, np.array([10.0, 20.0, 30.0]), row, col, 0.5)
        np.testing.assert_allclose(direct[row, col], expected, rtol=5e-3)


def test_nan_rows_keep_distant_lights_and_rows_must_match_the_lights():
    mixed = _renderer([[np.nan] * 3, [1.0, -2.0, 6.0]])
    direct = mixed.render_rows(0, SIZE, 0, 1, 16, 0, True)[0]
    # The distant light straight above: E cos 0 ρ / π on every interior pixel.
    straight_above = np.broadcast_to(0.5 * np.float32([10, 20, 30]) / np.pi, (8, 8, 3))
    np.testing.assert_allclose(direct[0, 4:12, 4:12], straight_above, rtol=1e-5)
    assert not np.allclose(direct[1, 5, 5], direct[1, 10, 10])  # the point light's falls off
    with pytest.raises(ArgumentError, match="light_positions: 1 rows for 2 lights"):
        _renderer([[0.0, 0.0, 5.0]], lights=2)
    with pytest.raises(ArgumentError, match=r"lights\[0\]\.position"):
        _renderer([[0.0, np.inf, 5.0]])
