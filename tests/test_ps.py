"""Photometric stereo against ground truth: DiLiGenT, Mitsuba direct-only renders, synthetic."""

from pathlib import Path

import numpy as np
import pytest

import irtps
from irtps.errors import IrtpsError
from irtps.evaluate import angular_error_deg
from irtps.ps import photometric_stereo

DATA = Path(__file__).parent / "data"
SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason="needs the shared data sets (../shared)")


def _mean_error(data: irtps.Dataset, images: np.ndarray, robust: bool) -> float:
    fit = photometric_stereo(images, data.scene.light_directions, data.scene.light_irradiance, data.mask, robust=robust)
    return float(np.nanmean(angular_error_deg(fit.normals, data.gt.normal, data.mask)))


def test_small_diligent_ball_robust_beats_least_squares():
    data = irtps.load_dataset(DATA / "diligent_ball_small")
    plain, robust = _mean_error(data, data.images, False), _mean_error(data, data.images, True)
    assert robust < plain < 5.0
    assert robust < 3.5


@needs_shared
def test_diligent_ball_reaches_the_published_least_squares_level():
    data = irtps.load_dataset(SHARED / "diligent" / "ballPNG")
    assert _mean_error(data, data.images, robust=False) <= 4.30  # published LS baseline: 4.10
    assert _mean_error(data, data.images, robust=True) <= 4.30


@needs_shared
@pytest.mark.parametrize("scene, floor_deg", [("cap_cornell", 1.2), ("grooves_dark", 1.3)])
def test_mitsuba_direct_images_reach_the_floor(scene, floor_deg):
    data = irtps.load_dataset(SHARED / "mitsuba" / scene)
    assert _mean_error(data, data.gt.direct, robust=True) <= floor_deg


@needs_shared
@pytest.mark.parametrize("scene, classic_deg", [("cap_cornell", 7.4), ("grooves_dark", 14.8)])
def test_inter_reflections_bend_classic_ps_as_documented(scene, classic_deg):
    data = irtps.load_dataset(SHARED / "mitsuba" / scene)
    assert _mean_error(data, data.images, robust=True) == pytest.approx(classic_deg, abs=0.1)


def test_robust_mode_handles_cast_and_attached_shadows():
    data, _ = irtps.synthesize("cavity", size=48, lights=12, bounces=0, environment="none", seed=1)
    plain, robust = _mean_error(data, data.images, False), _mean_error(data, data.images, True)
    assert robust < 0.7 * plain
    assert robust < 1.3


def test_albedo_is_recovered_per_channel():
    data, _ = irtps.synthesize("relief", size=40, lights=8, bounces=0, environment="none", albedo="textured", seed=2)
    fit = photometric_stereo(data.images, data.scene.light_directions, data.scene.light_irradiance, data.mask)
    error = np.abs(fit.albedo - data.gt.albedo)[data.mask]
    assert np.median(error) < 0.01


def test_saturated_observations_are_dropped():
    lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8], [0, -0.6, 0.8]])
    normal = np.array([0.1, 0.05, 1.0]) / np.linalg.norm([0.1, 0.05, 1.0])
    images = (0.9 * np.clip(lights @ normal, 0, None))[:, None, None, None] * np.ones((5, 1, 1, 3))
    assert images[0].max() > 0.8 > images[1:].max()
    images[0] = np.minimum(images[0], 0.8)  # clipped by the sensor
    irradiance = np.full((5, 3), np.pi)
    clipped = photometric_stereo(images, lights, irradiance, robust=True, saturation=0.8)
    assert clipped.used[0, 0] == 4
    np.testing.assert_allclose(clipped.normals[0, 0], normal, atol=1e-5)
    fooled = photometric_stereo(images, lights, irradiance, robust=False)
    assert np.degrees(np.arccos(np.clip(fooled.normals[0, 0] @ normal, -1, 1))) > 0.1


@pytest.mark.parametrize(
    "directions, message",
    [
        ([[0, 0, 1], [0.6, 0, 0.8]], "at least 3"),
        ([[0, 0, 1], [0.6, 0, 0.8], [-0.6, 0, 0.8]], "coplanar"),
    ],
)
def test_unusable_lights_are_clear_errors(directions, message):
    k = len(directions)
    with pytest.raises(IrtpsError, match=message):
        photometric_stereo(np.ones((k, 2, 2, 3)), np.array(directions, float), np.ones((k, 3)))


def test_shape_mismatch_names_images():
    with pytest.raises(IrtpsError, match="images"):
        photometric_stereo(np.ones((3, 2, 2)), np.eye(3), np.ones((3, 3)))
