"""Unknown light strengths (semi-calibrated photometric stereo): estimated from the images,
against the strengths that made them (a rendered sphere) and against DiLiGenT's own
``light_intensities.txt`` (a cut of the ball)."""

import dataclasses
import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

import irtps
from irtps.model.scene import with_emission
from irtps.ps.semi_calibrated import estimate_light_intensities
from irtps.render.synth import synthesize
from irtps.report.build import write_report

BALL = Path(__file__).parent / "data" / "diligent_ball_small"


def _sphere(strengths, size=64, lights=12, seed=0):
    """Images of a Lambertian sphere of varied colour under `strengths` (K, 3), with attached
    shadows, and its directions and mask."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[-1 : 1 : size * 1j, -1 : 1 : size * 1j]
    mask = x**2 + y**2 < 0.9
    normals = np.dstack([x, y, np.sqrt(np.clip(1 - x**2 - y**2, 0, None))])
    angles = rng.uniform(0, 2 * np.pi, lights)
    tilt = rng.uniform(0.2, 0.6, lights)
    directions = np.c_[tilt * np.cos(angles), tilt * np.sin(angles), np.sqrt(1 - tilt**2)]
    albedo = 0.3 + 0.5 * rng.random((size, size, 3))
    shading = np.clip(normals @ directions.T, 0, None).transpose(2, 0, 1)[..., None]
    return strengths[:, None, None] * albedo * shading, directions, mask


def test_the_strengths_that_made_the_images_come_back():
    rng = np.random.default_rng(3)
    strengths = rng.uniform(0.7, 1.3, (12, 1)) * rng.uniform(0.9, 1.1, (12, 3))
    images, directions, mask = _sphere(strengths)
    found = estimate_light_intensities(images, directions, mask)
    assert np.abs(found / (strengths / np.median(strengths, axis=0)) - 1).max() < 1e-6


def test_highlights_and_saturated_pixels_do_not_move_them():
    rng = np.random.default_rng(4)
    strengths = rng.uniform(0.7, 1.3, (12, 1)) * np.ones(3)
    images, directions, mask = _sphere(strengths)
    # A bright highlight at a third of the pixels in each image, some of them clipped.
    spots = rng.random(images.shape[:3]) < 0.02
    images[spots] += 2.0
    found = estimate_light_intensities(images, directions, mask, saturation=2.5)
    assert np.abs(found / (strengths / np.median(strengths, axis=0)) - 1).max() < 0.01


def test_too_few_pixels_lit_by_every_light_is_named():
    strengths = np.ones((12, 3))
    images, directions, mask = _sphere(strengths)
    images[:6, :-6] = 0  # half the lights reach only the last rows, outside the sphere
    with pytest.raises(irtps.ArgumentError, match=r"^images: \d+ pixels are lit by every light"):
        estimate_light_intensities(images, directions, mask)
    with pytest.raises(irtps.ArgumentError, match="^light_directions: 3 lights"):
        estimate_light_intensities(images[:3], directions[:3], mask)


def test_a_diligent_folder_without_intensities_is_estimated_and_recorded(tmp_path):
    folder = shutil.copytree(BALL, tmp_path / "ball")
    calibrated = irtps.reconstruct(irtps.load_dataset(folder))
    (folder / "light_intensities.txt").unlink()
    data = irtps.load_dataset(folder)
    assert not data.irradiance_known
    with pytest.warns(irtps.IrtpsWarning, match="no light intensities given: estimated from the images"):
        result = irtps.reconstruct(data)
    given = np.loadtxt(BALL / "light_intensities.txt")
    assert np.abs(result.estimated_irradiance / (given / np.median(given, axis=0)) - 1).max() < 0.1
    error = [
        irtps.angular_error_deg(r.normals, data.gt.normal, data.mask)[data.mask].mean() for r in (calibrated, result)
    ]
    assert abs(error[1] - error[0]) < 0.5
    assert calibrated.estimated_irradiance is None
    irtps.save_reconstruction(result, tmp_path / "out")
    record = json.loads((tmp_path / "out" / "run.json").read_text())
    assert np.allclose(record["estimated_irradiance"], result.estimated_irradiance, atol=1e-5)


def test_a_capture_that_cannot_fix_them_names_the_data_set():
    data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    data.irradiance_known = False
    for k in range(4):  # each light leaves a quarter of the columns in shadow
        data.images[k, :, 4 * k : 4 * k + 4] = 0.0
    with pytest.raises(irtps.DatasetError, match="no light intensities given, and 0 pixels are lit by every light"):
        irtps.reconstruct(data)


def test_the_report_says_the_strengths_were_estimated(tmp_path):
    folder = shutil.copytree(BALL, tmp_path / "ball")
    (folder / "light_intensities.txt").unlink()
    with pytest.warns(irtps.IrtpsWarning):
        result = irtps.reconstruct(irtps.load_dataset(folder))
    irtps.save_reconstruction(result, tmp_path / "out")
    page = write_report(tmp_path / "out").read_text()
    assert "The lights&#x27; strengths were not given: estimated from the images" in page  # HTML-escaped


def test_irtps_finds_the_scale_of_estimated_strengths_and_removes_the_inter_reflections():
    """Estimated strengths are relative (the median light's is 1): IRT-PS must find their
    scale from the images before it can render the inter-reflections, as for DiLiGenT's."""
    data, _ = synthesize("cap", size=48, lights=8, environment="cornell", seed=1)
    equal = tuple(with_emission(light, np.ones(3)) for light in data.scene.lights)
    unknown = dataclasses.replace(data, scene=dataclasses.replace(data.scene, lights=equal), irradiance_known=False)
    settings = {"bounces": 2, "samples": 16, "seed": 0}
    errors = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irtps.IrtpsWarning)
        for name, dataset in (("known", data), ("unknown", unknown)):
            result = irtps.reconstruct(dataset, "irtps", **settings)
            errors[name] = irtps.evaluate(mask=data.mask, normals=result.normals, gt=data.gt).normal_mean_angular_deg
        classic = irtps.reconstruct(unknown)
    errors["classic"] = irtps.evaluate(mask=data.mask, normals=classic.normals, gt=data.gt).normal_mean_angular_deg
    assert result.albedo_scale.source == "images" and result.chosen > 0
    # Most of what IRT-PS removes with the strengths given.
    closed = (errors["classic"] - errors["unknown"]) / (errors["classic"] - errors["known"])
    assert closed > 0.8, errors
