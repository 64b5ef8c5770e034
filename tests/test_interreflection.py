"""IRT-PS: the loop removes inter-reflections where there are some and changes nothing else."""

import json

import numpy as np
import pytest

import irtps
from irtps.cli.main import main
from irtps.errors import IrtpsError
from irtps.irt.interreflection import remove_interreflections


@pytest.fixture(scope="module")
def grooves():
    data, _ = irtps.synthesize("grooves", size=40, lights=10, environment="none", bounces=4, samples=128, seed=4)
    return data


def _error(result):
    return result.history[result.chosen].metrics["normal_mean_angular_deg"]


def test_irtps_removes_most_of_the_inter_reflection_error(grooves):
    floor = irtps.evaluate(
        mask=grooves.mask,
        normals=irtps.photometric_stereo(
            grooves.gt.direct, grooves.scene.light_directions, grooves.scene.light_irradiance, grooves.mask
        ).normals,
        gt=grooves.gt,
    ).normal_mean_angular_deg
    result = remove_interreflections(grooves, bounces=3, iterations=4, samples=128)
    classic = result.history[0].metrics["normal_mean_angular_deg"]
    assert classic > floor + 2.0  # the scene has strong inter-reflection
    closed = (classic - _error(result)) / (classic - floor)
    assert closed > 0.6
    residuals = [step.residual["object"] for step in result.history]
    assert result.chosen > 0 and residuals[result.chosen] == min(residuals) < 0.5 * residuals[0]
    assert result.indirect.shape == (len(grooves.images), grooves.mask.sum(), 3) and (result.indirect >= 0).all()


def test_irtps_leaves_a_scene_without_inter_reflection_alone():
    data, _ = irtps.synthesize("cap", size=32, lights=8, environment="none", floor=False, bounces=0, seed=1)
    result = remove_interreflections(data, bounces=3, iterations=2, samples=32)
    assert abs(_error(result) - result.history[0].metrics["normal_mean_angular_deg"]) <= 0.1
    assert result.indirect is None or np.abs(result.indirect).max() == 0.0  # nothing was subtracted


def test_reconstruct_cli_writes_indirect_images_and_history(tmp_path, grooves):
    data = tmp_path / "grooves"
    irtps.save_dataset(grooves, data)
    out = tmp_path / "out"
    assert (
        main(
            [
                "reconstruct",
                str(data),
                "--out",
                str(out),
                "--method",
                "irtps",
                "--iterations",
                "2",
                "--samples",
                "32",
                "--quiet",
            ]
        )
        == 0
    )
    assert sorted(p.name for p in (out / "indirect").iterdir()) == [f"{k:03d}.exr" for k in range(10)]
    run = json.loads((out / "run.json").read_text())
    assert run["parameters"]["method"] == "irtps" and run["parameters"]["integration"] == "footprint"
    assert [step["index"] for step in run["history"]] == [0, 1, 2]
    assert (
        run["history"][0]["metrics"]["normal_mean_angular_deg"]
        > run["history"][-1]["metrics"]["normal_mean_angular_deg"]
    )


@pytest.mark.parametrize(
    "argument, value", [("bounces", 0), ("relaxation", 2.0), ("update", "sideways"), ("iterations", -1)]
)
def test_bad_settings_are_named(grooves, argument, value):
    with pytest.raises(IrtpsError, match=argument):
        remove_interreflections(grooves, **{argument: value})


def test_footprint_normals_of_a_plane_are_its_normal():
    rows, cols = np.mgrid[0:6, 0:7].astype(float)
    height = 0.5 * cols - 0.25 * rows  # dz/dx = 0.5, dz/dy = +0.25 (y grows against rows)
    n = irtps.geometry.surface.footprint_normals(height, np.ones((6, 7), bool), pixel_size=1.0)
    expected = np.array([-0.5, -0.25, 1.0]) / np.linalg.norm([-0.5, -0.25, 1.0])
    np.testing.assert_allclose(n[1:-1, 1:-1], np.broadcast_to(expected, (4, 5, 3)), atol=1e-12)


def test_surface_albedo_undoes_the_crease_bias_of_photometric_stereo(grooves):
    fit = irtps.photometric_stereo(
        grooves.gt.direct, grooves.scene.light_directions, grooves.scene.light_irradiance, grooves.mask
    )
    mask, truth = grooves.mask, grooves.gt.albedo
    inner = mask & ~np.isnan(fit.albedo[..., 0])
    fitted_bias = np.mean(fit.albedo[inner] - truth[inner])
    corrected = irtps.geometry.surface.surface_albedo(
        fit.albedo, grooves.gt.height, mask, grooves.scene.camera.pixel_size
    )
    corrected_bias = np.mean(corrected[inner] - truth[inner])
    assert fitted_bias < -0.02  # crease pixels read dark
    assert abs(corrected_bias) < 0.6 * abs(fitted_bias)  # the rest: cast shadows in the narrow grooves


def test_a_reconstruction_gives_its_inter_reflection_estimate_as_images_and_saves_them(tmp_path):
    data, _ = irtps.synthesize("grooves", size=24, lights=6, environment="none", bounces=2, samples=16, seed=3)
    result = irtps.reconstruct(data, "irtps", bounces=2, iterations=2, samples=16, early_stop=False)
    assert result.chosen > 0
    frames, mask = result.indirect, data.mask
    assert frames.shape == data.images.shape and frames.dtype == np.float32
    np.testing.assert_array_equal(frames[:, mask], result.object_indirect)
    assert not frames[:, ~mask].any() and frames[:, mask].max() > 0
    irtps.save_reconstruction(result, tmp_path / "out")
    np.testing.assert_array_equal(irtps.io.imageio.read_exr(tmp_path / "out" / "indirect" / "004.exr"), frames[4])
