"""Maps turned into display images: normal encoding, albedo and light scaling, hillshade, cropping."""

import numpy as np
import pytest

from irtps.report.display import BACKGROUND, albedo_to_rgb, hillshade, normal_to_rgb, object_window, radiance_to_rgb
from irtps.errors import ArgumentError


def _srgb(value):
    return 1.055 * value ** (1 / 2.4) - 0.055


def test_normal_encoding_of_known_normals():
    normals = np.array(
        [[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]], [[0.6, 0.0, 0.8], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]]
    )
    mask = np.array([[True, True, True], [True, True, False]])
    rgb = normal_to_rgb(normals, mask)
    np.testing.assert_allclose(rgb[0, 0], [0.5, 0.5, 1.0])  # facing the camera: light blue
    np.testing.assert_allclose(rgb[0, 1], [1.0, 0.5, 0.5])  # facing right: red
    np.testing.assert_allclose(rgb[0, 2], [0.5, 0.0, 0.5])  # facing down: no green
    np.testing.assert_allclose(rgb[1, 0], [0.8, 0.5, 0.9])
    np.testing.assert_allclose(rgb[1, 2], [BACKGROUND] * 3)  # outside the mask, whatever the normal


def test_reflectance_albedo_is_shown_unscaled_and_srgb_encoded():
    albedo = np.zeros((2, 2, 3))
    albedo[..., 0], albedo[..., 1], albedo[..., 2] = 0.8, 0.4, 0.2
    mask = np.array([[True, True], [True, False]])
    rgb, scale = albedo_to_rgb(albedo, mask)
    assert scale == 1.0
    np.testing.assert_allclose(rgb[0, 0], _srgb(np.array([0.8, 0.4, 0.2])), rtol=1e-6)
    np.testing.assert_allclose(rgb[1, 1], [BACKGROUND] * 3)


def test_relative_albedo_brighter_than_white_is_scaled_keeping_its_colour():
    rng = np.random.default_rng(1)
    albedo = rng.uniform(1.0, 3.0, size=(20, 20, 1)) * np.array([1.0, 0.5, 0.25])
    mask = np.ones((20, 20), bool)
    rgb, scale = albedo_to_rgb(albedo, mask)
    assert scale == pytest.approx(1.0 / np.percentile(albedo, 99))
    assert (rgb[..., 0] >= 1.0).mean() == pytest.approx(0.03, abs=0.02)  # only the top percent is clipped
    unclipped = rgb[..., 0] < 1.0
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose((linear[..., 1] / linear[..., 0])[unclipped], 0.5, rtol=1e-4)


def test_radiance_is_exposed_so_its_99th_percentile_is_white():
    radiance = np.linspace(0.0, 0.01, 300).reshape(10, 10, 3)
    mask = np.ones((10, 10), bool)
    rgb, scale = radiance_to_rgb(radiance, mask)
    assert scale == pytest.approx(1.0 / np.percentile(radiance, 99))
    assert rgb.max() == 1.0 and rgb.min() == 0.0
    dark, _ = radiance_to_rgb(np.zeros((2, 2, 3)), np.ones((2, 2), bool))
    assert (dark == 0).all()  # nothing to expose: stays black


def test_hillshade_of_planes_matches_their_angle_to_the_light():
    mask = np.ones((8, 8), bool)
    rows, cols = np.mgrid[0:8, 0:8].astype(float)
    assert hillshade(np.zeros((8, 8)), mask)[4, 4, 0] == pytest.approx(np.sin(np.radians(45)))
    # A plane rising toward the lower right faces the upper left, where the light is.
    # Its normal is (-0.5, 0.5, 1) / |.|, the light's direction (-0.5, 0.5, sqrt(0.5)).
    facing = 0.5 * cols + 0.5 * rows
    expected = (0.25 + 0.25 + np.sqrt(0.5)) / np.sqrt(1.5)
    assert hillshade(facing, mask)[4, 4, 0] == pytest.approx(expected, abs=1e-6)
    assert hillshade(facing, mask)[4, 4, 0] > hillshade(-facing, mask)[4, 4, 0]
    # The pixel size sets the slopes: a finer grid makes the same heights steeper and darker.
    assert hillshade(-facing, mask, pixel_size=0.5)[4, 4, 0] < hillshade(-facing, mask, pixel_size=2.0)[4, 4, 0]


def test_hillshade_outline_of_a_plateau_casts_no_false_cliff():
    mask = np.zeros((10, 10), bool)
    mask[2:8, 2:8] = True
    height = np.where(mask, 5.0, 0.0)
    shade = hillshade(height, mask)
    np.testing.assert_allclose(shade[mask], np.sin(np.radians(45)), rtol=1e-6)
    np.testing.assert_allclose(shade[~mask], BACKGROUND)


def test_object_window_is_the_box_with_a_margin_inside_the_image():
    mask = np.zeros((50, 80), bool)
    mask[0:10, 60:80] = True
    rows, cols = object_window(mask, margin=0.1)
    assert (rows.start, rows.stop, cols.start, cols.stop) == (0, 12, 58, 80)
    assert mask[rows, cols].sum() == mask.sum()


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            lambda: normal_to_rgb(np.zeros((2, 3, 3)), np.ones((2, 2), bool)),
            "normals: shape (2, 3, 3), expected (2, 2, 3) to match the mask",
        ),
        (
            lambda: albedo_to_rgb(np.full((2, 2, 3), np.nan), np.ones((2, 2), bool)),
            "albedo: non-finite value nan at row 0, column 0",
        ),
        (lambda: radiance_to_rgb(np.zeros((2, 2, 3)), np.zeros((2, 2), bool)), "mask: empty"),
        (
            lambda: hillshade(np.zeros((2, 2)), np.ones((2, 2), bool), pixel_size=0),
            "pixel_size: expected a positive finite number, got 0",
        ),
        (
            lambda: hillshade(np.zeros((3, 2)), np.ones((2, 2), bool)),
            "height: shape (3, 2), expected (2, 2) to match the mask",
        ),
    ],
)
def test_bad_input_names_the_argument(call, message):
    with pytest.raises(ArgumentError) as caught:
        call()
    assert str(caught.value).startswith(message)
