"""Each image's brightness against the fit (`irtps.image_brightness`): exact on Lambertian
renders, the factor of a faulty image on a real one, and what a run prints and records."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from irtps import ArgumentError, load_dataset, reconstruct, synthesize
from irtps.cli import main
from irtps.image_brightness import MIN_PIXELS, format_image_brightness, image_brightness

FIXTURE = Path(__file__).resolve().parent / "data" / "diligent_ball_small"


@pytest.fixture(scope="module")
def cap():
    data, _ = synthesize("cap", size=48, lights=8, bounces=0, environment="none", seed=3)
    return data


def _brightness(data, normals, albedo, images=None, mask=None):
    scene = data.scene
    return image_brightness(data.images if images is None else images, scene.light_directions, scene.light_irradiance, normals, albedo, data.mask if mask is None else mask)


def test_a_lambertian_render_against_its_true_shape_is_one_everywhere(cap):
    brightness = _brightness(cap, cap.gt.normal, cap.gt.albedo)
    np.testing.assert_allclose(brightness, 1.0, atol=1e-3)


def test_an_image_off_by_a_factor_shows_that_factor(cap):
    images = cap.images.copy()
    images[2] *= 0.7
    images[5] *= 1.25
    expected = np.ones(8)
    expected[[2, 5]] = 0.7, 1.25
    np.testing.assert_allclose(_brightness(cap, cap.gt.normal, cap.gt.albedo, images), expected, atol=1e-3)


def test_an_image_that_lights_too_few_pixels_well_has_no_brightness(cap):
    mask = np.zeros_like(cap.mask)
    mask[24, 24 : 24 + MIN_PIXELS - 1] = True  # fewer pixels than any image needs
    assert np.isnan(_brightness(cap, cap.gt.normal, cap.gt.albedo, mask=mask)).all()


def test_bad_arguments_are_named(cap):
    with pytest.raises(ArgumentError, match="^albedo: "):
        _brightness(cap, cap.gt.normal, cap.gt.albedo[:, :3])
    with pytest.raises(ArgumentError, match="^mask: empty"):
        _brightness(cap, cap.gt.normal, cap.gt.albedo, mask=np.zeros_like(cap.mask))


@pytest.mark.filterwarnings("ignore:.*saturated")
@pytest.mark.parametrize("faulty", [0, 3, 7])
def test_a_faulty_real_image_stands_out_after_a_robust_fit(faulty):
    """DiLiGenT ball (8 of its images): one made 1.5x too bright shows 1.4-1.6 while the
    others stay within 5 % of the median image, so it is the first one printed."""
    data = load_dataset(FIXTURE)
    data = dataclasses.replace(data, images=data.images.copy())
    data.images[faulty] *= 1.5
    result = reconstruct(data)
    brightness = result.image_brightness
    assert 1.4 < brightness[faulty] < 1.6, brightness
    assert np.all(np.abs(np.delete(brightness, faulty) - 1) < 0.05), brightness
    assert format_image_brightness(result.image_names, brightness).split("farthest ")[1].startswith(f"{data.names[faulty]} 1.")


def test_the_line_names_the_farthest_images_and_those_without_a_value():
    line = format_image_brightness(["a.png", "b.png", "c.png"], [0.5, 1.0, float("nan")], shown=1)
    assert line == "images' brightness against the fit: 0.50 to 1.00 of the median image's (1 image without enough well-lit pixels); farthest a.png 0.50"
    assert format_image_brightness(["a.png"], [float("nan")]) == "images' brightness against the fit: no image has enough well-lit pixels"
    with pytest.raises(ArgumentError, match="^brightness: 1 values for 2 images$"):
        format_image_brightness(["a.png", "b.png"], [1.0])


def test_the_command_prints_and_records_each_image_brightness(tmp_path, capsys):
    assert main(["reconstruct", str(FIXTURE), "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "  images' brightness against the fit: 0.97 to 1.02 of the median image's; farthest " in printed
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert len(run["image_brightness"]) == len(run["images"]) == 8
    assert all(0.95 < value < 1.05 for value in run["image_brightness"])


def test_irtps_measures_the_images_against_classic_photometric_stereo():
    """Inter-reflections add light to every image, by how much depends on the light: the
    brightness is measured against pass 0's fit, of the images as they are, whatever pass
    IRT-PS returns."""
    data, _ = synthesize("cavity", size=32, lights=6, bounces=2, environment="cornell", samples=16, seed=2)
    classic = reconstruct(data)
    corrected = reconstruct(data, "irtps", iterations=1, samples=8)
    assert corrected.chosen == 1  # not classic photometric stereo's fit
    np.testing.assert_array_equal(corrected.image_brightness, classic.image_brightness)
    assert np.all(np.abs(classic.image_brightness - 1) < 0.05), classic.image_brightness
