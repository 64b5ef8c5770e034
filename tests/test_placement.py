"""Placement from the images (contract §6), the residual without ground truth, and IRT-PS
returning its best pass: against synthesized scenes whose true base height is known."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

import irtps
from irtps.cli.main import main
from irtps.errors import IrtpsWarning
from irtps.model.options import OptionError, ReconstructOptions
from irtps.render.placement import estimate_placement
from irtps.render.synth import SHAPES, synthesize

BALL = Path(__file__).parent / "data" / "diligent_ball_small"  # 48x44, 8 lights, no floor


def _boundary_median(data):
    mask = data.mask
    return float(np.median(data.gt.height[mask & ~ndimage.binary_erosion(mask)]))


def _surroundings(environment):
    """(environment, floor) of `synthesize`: a Cornell box, or a bare floor."""
    return (environment, None) if environment == "cornell" else ("none", True)


@pytest.mark.parametrize("environment", ["cornell", "floor only"])
@pytest.mark.parametrize(
    "shape, base", [("pedestal", 4.0), ("pedestal", 12.0), ("cap", 1.0), ("cap", 6.0), ("relief", 6.0)]
)
def test_the_estimate_is_the_true_base_for_the_true_shape(shape, base, environment):
    env, floor = _surroundings(environment)
    data, _ = synthesize(
        shape, size=48, lights=8, bounces=1, samples=32, base=base, environment=env, floor=floor, seed=2
    )
    true = _boundary_median(data)
    assert true == pytest.approx(base, abs=1e-4)
    relief = np.where(data.mask, data.gt.height - true, 0.0)
    placement = estimate_placement(data.scene, relief, data.gt.albedo, data.mask, data.images, bounces=1)
    assert placement.source == "images"
    assert abs(placement.base_height - true) <= 0.01 * data.gt.height.max()


@pytest.mark.parametrize("size", [192, 201])
def test_a_large_image_is_placed_from_coarse_blocks_as_well(size):
    # 192 is compared in 2x2 blocks, 201 in 3x3 blocks after cropping one pixel a side.
    data, _ = synthesize("pedestal", size=size, lights=8, bounces=1, samples=8, base=0.1 * size)
    true = _boundary_median(data)
    relief = np.where(data.mask, data.gt.height - true, 0.0)
    placement = estimate_placement(data.scene, relief, data.gt.albedo, data.mask, data.images, bounces=1)
    assert placement.source == "images" and placement.floor_pixels < (size // 2) ** 2
    assert abs(placement.base_height - true) <= 0.02 * data.gt.height.max()  # measured 0.2 % and 1.4 %


@pytest.mark.parametrize("environment", ["cornell", "floor only"])
@pytest.mark.parametrize("shape, base", [("pedestal", 4.0), ("pedestal", 12.0), ("cavity", 10.0)])
def test_irtps_places_a_raised_object_within_3_percent_of_its_height(shape, base, environment):
    # From the reconstructed (not the true) shape, over seeds 0-2 of these six scenes the
    # error was -2.7 % to +0.8 % of the height with the Tukey fit (-2.3 % to +0.6 % with the
    # threshold fit), mostly below: the reconstructed relief is flatter than the true one.
    env, floor = _surroundings(environment)
    data, _ = synthesize(shape, size=48, lights=8, bounces=2, samples=32, base=base, environment=env, floor=floor)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # IRT-PS improves on classic PS here: no warning
        result = irtps.reconstruct(data, "irtps", bounces=2, samples=64, iterations=4)
    assert result.placement.source == "images"
    assert abs(result.placement.base_height - _boundary_median(data)) <= 0.03 * data.gt.height.max()


def test_the_residual_falls_as_the_error_falls():
    data, _ = synthesize("pedestal", size=48, lights=8, bounces=2, samples=32, base=8.0)
    runs = {
        base: irtps.reconstruct(data, "irtps", bounces=2, samples=64, iterations=3, base_height=base, early_stop=False)
        for base in ("auto", "boundary", 16.0)
    }
    errors = {base: run.history[run.chosen].metrics["normal_mean_angular_deg"] for base, run in runs.items()}
    residuals = {base: run.history[run.chosen].residual["object"] for base, run in runs.items()}
    # A wrong placement (on the floor, or 8 too high) explains the images worse and is worse.
    for wrong in ("boundary", 16.0):
        assert residuals["auto"] < residuals[wrong] and errors["auto"] < errors[wrong]
        assert runs[wrong].history[0].residual["surroundings"] > runs["auto"].history[0].residual["surroundings"]
    history = runs["auto"].history
    assert history[0].residual["object"] > 2 * history[runs["auto"].chosen].residual["object"]
    assert (
        history[0].metrics["normal_mean_angular_deg"]
        > history[runs["auto"].chosen].metrics["normal_mean_angular_deg"] + 2
    )


@pytest.mark.parametrize("shape", ["cavity", "grooves", "pedestal"])
def test_an_object_that_fills_the_frame_is_placed_by_the_walls_light_on_it(shape):
    # No floor pixel in view: the estimate comes from the object's own pixels, which the
    # walls and floor light differently at each height, from the true shape and the albedo
    # photometric stereo fits (too bright where inter-reflections add light: refitted).
    data, _ = synthesize(shape, size=40, lights=8, bounces=2, samples=32, fill=True)
    assert data.mask.all()
    true = _boundary_median(data)
    relief = np.where(data.mask, data.gt.height - true, 0.0)
    fitted = irtps.photometric_stereo(data.images, data.scene.light_directions, data.scene.light_irradiance)
    albedo = np.clip(fitted.albedo, 0.0, 1.0)  # as IRT-PS renders it
    placement = estimate_placement(data.scene, relief, albedo, data.mask, data.images, bounces=2)
    assert placement.source == "object" and placement.object_pixels == 40 * 40
    assert placement.reason == "the mask covers the whole image: no floor is visible"
    assert abs(placement.base_height - true) <= 0.05 * data.gt.height.max()


def test_irtps_on_an_object_that_fills_a_cornell_box_beats_its_fallback_placement():
    data, _ = synthesize("cavity", size=40, lights=8, bounces=2, samples=32, fill=True)
    estimated = irtps.reconstruct(data, "irtps", bounces=2, samples=32, iterations=3)
    assert estimated.placement.source == "object"
    assert abs(estimated.placement.base_height - _boundary_median(data)) <= 0.05 * data.gt.height.max()
    fallback = irtps.reconstruct(data, "irtps", bounces=2, samples=32, iterations=3, base_height="boundary")
    error = {
        name: irtps.evaluate(mask=r.mask, normals=r.normals, gt=data.gt).normal_mean_angular_deg
        for name, r in (("estimated", estimated), ("fallback", fallback))
    }
    assert error["estimated"] < 0.5 * error["fallback"], error


def test_without_anything_around_a_filling_object_the_fallback_says_why():
    data, _ = synthesize("relief", size=32, lights=6, bounces=1, samples=8, fill=True, environment="none")
    placement = irtps.reconstruct(data).placement
    assert placement.source == "boundary" and "the scene has no floor" in placement.reason


def test_without_a_floor_the_fallback_is_used_and_recorded(tmp_path):
    data, _ = synthesize("cavity", size=32, lights=6, environment="none", floor=False, bounces=1, samples=8)
    result = irtps.reconstruct(data)
    assert result.placement.source == "boundary" and "no floor" in result.placement.reason
    assert _boundary_median(data) > 5 and result.placement.base_height == 0.0  # nothing fixes it
    folder = tmp_path / "data"
    irtps.save_dataset(data, folder)
    assert main(["reconstruct", str(folder), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    placement = json.loads((tmp_path / "out" / "run.json").read_text())["placement"]
    assert placement["source"] == "boundary" and "no floor" in placement["reason"]


def test_a_given_or_boundary_placement_is_used_as_it_is():
    data, _ = synthesize("pedestal", size=40, lights=6, bounces=1, samples=8, base=6.0)
    given = irtps.reconstruct(data, base_height=2.5)
    assert given.placement.source == "given"
    boundary = irtps.reconstruct(data, base_height="boundary")
    assert boundary.placement.source == "boundary" and boundary.placement.reason is None
    edge = data.mask & ~ndimage.binary_erosion(data.mask)
    assert np.median(given.height[edge]) == pytest.approx(2.5, abs=1e-4)
    assert np.median(boundary.height[edge]) == pytest.approx(0.0, abs=1e-4)


def test_irtps_returns_classic_ps_with_a_warning_when_no_pass_explains_the_images_better():
    data = irtps.load_dataset(BALL)  # a real glossy ball: the Lambertian re-rendering cannot do better
    classic = irtps.reconstruct(data)
    with pytest.warns(IrtpsWarning, match="no pass explained the images better than classic photometric stereo"):
        # Without the early stop, which keeps classic PS before rendering pass 1 here.
        result = irtps.reconstruct(data, "irtps", iterations=2, samples=16, early_stop=False)
    assert result.chosen == 0 and result.indirect is None
    np.testing.assert_array_equal(result.normals, classic.normals)


@pytest.mark.parametrize("value", ["high", float("nan"), None, [1.0]])
def test_a_base_height_that_is_not_a_number_auto_or_boundary_is_refused(value):
    with pytest.raises(OptionError, match="base_height: .* is not a finite number, auto or boundary"):
        ReconstructOptions(base_height=value)


def test_synth_places_every_shape_at_the_base_asked_for_and_refuses_one_below_the_floor():
    for shape in SHAPES:
        data, _ = synthesize(shape, size=32, lights=3, bounces=0, base=20.0)
        assert _boundary_median(data) == pytest.approx(20.0, abs=1e-4) and data.gt.height[data.mask].min() >= 0
    with pytest.raises(OptionError, match="base: 0 puts part of the pedestal below the floor"):
        synthesize("pedestal", size=32, lights=3, bounces=0, base=0.0)
