"""How each image agrees with the fit (`irtps.ps.image_agreement`): exact on Lambertian renders,
a faulty image's factor and a shifted image's spread on a real object, what a run prints and
records; ``correct_brightness``, which scales each light by its image's brightness."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from irtps import ArgumentError, angular_error_deg, load_dataset, reconstruct, synthesize
from irtps.cli.main import main
from irtps.ps.image_agreement import MIN_PIXELS, ImageAgreement, format_image_agreement, image_agreement

FIXTURE = Path(__file__).resolve().parent / "data" / "diligent_ball_small"


@pytest.fixture(scope="module")
def cap():
    data, _ = synthesize("cap", size=48, lights=8, bounces=0, environment="none", seed=3)
    return data


def _agreement(data, images=None, mask=None):
    scene = data.scene
    return image_agreement(
        data.images if images is None else images,
        scene.light_directions,
        scene.light_irradiance,
        data.gt.normal,
        data.gt.albedo,
        data.mask if mask is None else mask,
    )


def test_a_lambertian_render_against_its_true_shape_agrees_everywhere(cap):
    agreement = _agreement(cap)
    np.testing.assert_allclose(agreement.brightness, 1.0, atol=1e-3)
    assert np.all(agreement.spread < 0.005), agreement.spread  # the render's own facets


def test_an_image_off_by_a_factor_shows_that_factor_and_no_spread(cap):
    images = cap.images.copy()
    images[2] *= 0.7
    images[5] *= 1.25
    expected = np.ones(8)
    expected[[2, 5]] = 0.7, 1.25
    agreement = _agreement(cap, images)
    np.testing.assert_allclose(agreement.brightness, expected, atol=1e-3)
    assert np.all(agreement.spread < 0.005), agreement.spread


def test_an_image_with_noise_spreads_by_the_noise(cap):
    """Multiplicative noise of 5 % (lognormal) in one image: its spread is about 0.05 (a
    little more: the cap's rim pixels, partly the dark beyond the object, fall far below the
    fit and leave fewer pixels about the median), the others' stays at the render's own."""
    images = cap.images.copy()
    images[4] *= np.exp(np.random.default_rng(0).normal(0, 0.05, images.shape[1:3]))[..., None]
    agreement = _agreement(cap, images)
    assert 0.045 < agreement.spread[4] < 0.065 and np.all(np.delete(agreement.spread, 4) < 0.005), agreement.spread
    assert abs(agreement.brightness[4] - 1) < 0.01


def test_an_image_that_lights_too_few_pixels_well_has_no_figures(cap):
    mask = np.zeros_like(cap.mask)
    mask[24, 24 : 24 + MIN_PIXELS - 1] = True  # fewer pixels than any image needs
    agreement = _agreement(cap, mask=mask)
    assert np.isnan(agreement.brightness).all() and np.isnan(agreement.spread).all()
    assert format_image_agreement(cap.names, agreement) == [
        "images' agreement with the fit: no image has enough well-lit pixels"
    ]


def test_bad_arguments_are_named(cap):
    scene = cap.scene
    with pytest.raises(ArgumentError, match="^albedo: "):
        image_agreement(
            cap.images, scene.light_directions, scene.light_irradiance, cap.gt.normal, cap.gt.albedo[:, :3], cap.mask
        )
    with pytest.raises(ArgumentError, match="^mask: empty"):
        _agreement(cap, mask=np.zeros_like(cap.mask))
    with pytest.raises(ArgumentError, match="^sample: 0 is not a positive integer$"):
        image_agreement(
            cap.images, scene.light_directions, scene.light_irradiance, cap.gt.normal, cap.gt.albedo, cap.mask, sample=0
        )


@pytest.mark.filterwarnings("ignore:.*saturated")
@pytest.mark.parametrize("faulty", [0, 3, 7])
def test_a_real_image_too_bright_stands_out_after_a_robust_fit(faulty):
    """DiLiGenT ball (8 of its images): one made 1.5x too bright shows 1.4-1.6 while the
    others stay within 5 % of the median image, so it is the first one printed."""
    data = load_dataset(FIXTURE)
    data = dataclasses.replace(data, images=data.images.copy())
    data.images[faulty] *= 1.5
    result = reconstruct(data)
    brightness = result.image_agreement.brightness
    assert 1.4 < brightness[faulty] < 1.6, brightness
    assert np.all(np.abs(np.delete(brightness, faulty) - 1) < 0.05), brightness
    line = format_image_agreement(result.image_names, result.image_agreement)[0]
    assert line.split("farthest ")[1].startswith(f"{data.names[faulty]} 1.")


@pytest.mark.filterwarnings("ignore:.*saturated")
def test_a_real_image_taken_as_the_object_moved_spreads_wider():
    """DiLiGenT ball: an image shifted by 3 pixels keeps its brightness within 10 % but
    spreads at least twice as wide as any other."""
    data = load_dataset(FIXTURE)
    data = dataclasses.replace(data, images=data.images.copy())
    data.images[5] = np.roll(data.images[5], 3, axis=1)
    agreement = reconstruct(data).image_agreement
    assert agreement.spread[5] > 2 * np.delete(agreement.spread, 5).max(), agreement.spread
    assert abs(agreement.brightness[5] - 1) < 0.1
    assert format_image_agreement(data.names, agreement)[1].split("widest ")[1].startswith("052.png")


def test_irtps_measures_the_images_against_classic_photometric_stereo():
    """Inter-reflections add light to every image, by how much depends on the light: the
    agreement is measured against pass 0's fit, of the images as they are, whatever pass
    IRT-PS returns."""
    data, _ = synthesize("cavity", size=32, lights=6, bounces=2, environment="cornell", samples=16, seed=2)
    classic = reconstruct(data)
    corrected = reconstruct(data, "irtps", iterations=1, samples=8)
    assert corrected.chosen == 1  # not classic photometric stereo's fit
    np.testing.assert_array_equal(corrected.image_agreement.brightness, classic.image_agreement.brightness)
    np.testing.assert_array_equal(corrected.image_agreement.spread, classic.image_agreement.spread)
    assert np.all(np.abs(classic.image_agreement.brightness - 1) < 0.05), classic.image_agreement.brightness


def test_the_lines_name_the_farthest_and_widest_images():
    agreement = ImageAgreement(np.array([0.5, 1.0, np.nan]), np.array([0.01, 0.2, np.nan]))
    assert format_image_agreement(["a.png", "b.png", "c.png"], agreement, shown=1) == [
        "images' brightness against the fit: 0.50 to 1.00 of the median image's; farthest a.png 0.50 (1 image with too few well-lit pixels)",
        "images' spread about the fit: 1.0 to 20.0 % a pixel; widest b.png 20.0 %",
    ]
    with pytest.raises(ArgumentError, match="^agreement: 3 images' figures for 2 names$"):
        format_image_agreement(["a.png", "b.png"], agreement)


def test_a_recorded_agreement_reads_back_and_a_malformed_one_is_refused():
    agreement = ImageAgreement(np.array([1.0, np.nan]), np.array([0.02, np.nan]))
    record = json.loads(json.dumps(agreement.to_dict()))
    assert record == {"brightness": [1.0, None], "spread": [0.02, None]}
    back = ImageAgreement.from_dict(record)
    np.testing.assert_array_equal(back.brightness, agreement.brightness)
    for bad in (
        {"brightness": [1.0]},
        {"brightness": [1.0], "spread": [0.1, 0.2]},
        {"brightness": "x", "spread": "y"},
        [1.0],
    ):
        with pytest.raises(ArgumentError, match="^image_agreement: "):
            ImageAgreement.from_dict(bad)


def test_the_command_prints_and_records_how_each_image_agrees(tmp_path, capsys):
    assert main(["reconstruct", str(FIXTURE), "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "  images' brightness against the fit: 0.97 to 1.02 of the median image's; farthest " in printed
    assert "  images' spread about the fit: " in printed
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    figures = run["image_agreement"]
    assert len(figures["brightness"]) == len(figures["spread"]) == len(run["images"]) == 8
    assert all(0.95 < value < 1.05 for value in figures["brightness"])
    assert all(0 < value < 0.05 for value in figures["spread"])


@pytest.mark.filterwarnings("ignore:.*saturated")
def test_correcting_the_brightness_takes_a_wrong_irradiance_out_of_the_fit():
    """DiLiGenT ball (8 images), image 4 made 1.5x too bright: --correct-brightness scales its
    light by about that, so that the image then agrees with the fit and the error falls
    most of the way back to the sound data's."""
    data = load_dataset(FIXTURE)
    faulty = dataclasses.replace(data, images=data.images.copy())
    faulty.images[3] *= 1.5

    def error(result):
        return np.nanmean(angular_error_deg(result.normals, data.gt.normal, data.mask))

    sound, kept, corrected = reconstruct(data), reconstruct(faulty), reconstruct(faulty, correct_brightness=True)
    assert sound.irradiance_factors is None and kept.irradiance_factors is None
    assert 1.4 < corrected.irradiance_factors[3] < 1.6 and np.all(
        np.abs(np.delete(corrected.irradiance_factors, 3) - 1) < 0.05
    )
    assert np.all(np.abs(corrected.image_agreement.brightness - 1) < 0.01), corrected.image_agreement.brightness
    assert error(corrected) < error(sound) + 0.25 < error(kept), (error(sound), error(kept), error(corrected))
    assert "brightness_correction" in corrected.timings and "brightness_correction" not in kept.timings


def test_a_sound_render_needs_no_correction(cap):
    result = reconstruct(cap, correct_brightness=True)
    np.testing.assert_allclose(result.irradiance_factors, 1.0, atol=2e-3)


def test_the_command_prints_and_records_the_correction(tmp_path, capsys):
    assert main(["reconstruct", str(FIXTURE), "--out", str(tmp_path / "out"), "--correct-brightness"]) == 0
    printed = capsys.readouterr().out
    assert (
        "  irradiance scaled by each image's brightness against a first fit: 0.97 to 1.02 (--correct-brightness)\n"
        in printed
    )
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert run["parameters"]["correct_brightness"] is True and len(run["irradiance_factors"]) == 8
    assert main(["reconstruct", str(FIXTURE), "--out", str(tmp_path / "plain"), "--quiet"]) == 0
    assert json.loads((tmp_path / "plain" / "run.json").read_text())["irradiance_factors"] is None
