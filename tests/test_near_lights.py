"""Photometric stereo under point lights near the object (contract §4b): each pixel's light
direction and irradiance at its own surface point, the fit pixel by pixel against analytic
images, the placement from the light's fall-off, and the shape settled from scratch on the
Mitsuba rig (tests/data/mitsuba_small/cap_rig, 3 of its 12 LEDs)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import irtps
from irtps import Camera, PointLight, Scene
from irtps.geometry.falloff_placement import falloff_placement
from irtps.model.options import OptionError
from irtps.model.scene import lights_at, stand_in_scene
from irtps.ps.fit import photometric_stereo

RIG = Path(__file__).parent / "data" / "mitsuba_small" / "cap_rig"
LEDS = [
    PointLight((20.0 * np.cos(a), 20.0 * np.sin(a), 30.0 + 5.0 * np.sin(3 * a)), (900.0, 800.0, 700.0))
    for a in np.linspace(0, 2 * np.pi, 6, endpoint=False)
]


def _lambert(normals, albedo, directions, irradiance):
    """(K, N, 3) images ρ E max(0, n·l) / π of normals (N, 3) under per-pixel lights (N, K, 3)."""
    cosine = np.clip(np.einsum("nki,ni->nk", directions, normals), 0.0, None)
    return np.transpose(albedo[:, None, :] * irradiance * cosine[..., None] / np.pi, (1, 0, 2))


def test_lights_at_a_point_follow_the_inverse_square_law():
    scene = Scene(Camera(4, 4, 1.0), [LEDS[0], irtps.Light((0.0, 0.0, 1.0), (1.0, 2.0, 3.0)), LEDS[1]])
    points = np.array([[0.0, 0.0, 0.0], [3.0, -2.0, 5.0]])
    directions, irradiance = lights_at(scene, points)
    offset = LEDS[0].position - points[1]
    np.testing.assert_allclose(directions[1, 0], offset / np.linalg.norm(offset))
    np.testing.assert_allclose(irradiance[1, 0], LEDS[0].intensity / (offset @ offset))
    np.testing.assert_array_equal(directions[:, 1], [[0, 0, 1], [0, 0, 1]])
    np.testing.assert_array_equal(irradiance[:, 1], [[1, 2, 3], [1, 2, 3]])


@pytest.mark.parametrize("robust", ["none", "threshold", "trim", "tukey", "lobe", "auto"])
def test_each_pixel_is_fitted_with_its_own_lights(robust):
    rng = np.random.default_rng(4)
    size = 6
    normals = rng.normal(size=(size * size, 3)) * [0.4, 0.4, 0.0] + [0.0, 0.0, 1.0]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    albedo = rng.uniform(0.2, 0.9, (size * size, 3))
    points = np.c_[rng.uniform(-5, 5, (size * size, 2)), rng.uniform(0, 4, size * size)]
    scene = Scene(Camera(size, size, 1.0), LEDS)
    directions, irradiance = lights_at(scene, points)
    images = _lambert(normals, albedo, directions, irradiance).reshape(len(LEDS), size, size, 3)
    fit = photometric_stereo(images, directions, irradiance, robust=robust)
    lit = np.einsum("nki,ni->nk", directions, normals).min(axis=1) > 0  # every LED lights it: exact
    cosine = (fit.normals.reshape(-1, 3)[lit] * normals[lit]).sum(axis=1)
    assert lit.sum() > 10 and np.degrees(np.arccos(np.clip(cosine, -1, 1))).max() < 0.05
    np.testing.assert_allclose(fit.albedo.reshape(-1, 3)[lit], albedo[lit], rtol=1e-3)
    if robust == "auto":  # matte: the lobe share of its pixels, fitted with their own lights, chooses Tukey
        assert fit.robust_used == "tukey" and fit.lobe_share is not None and fit.lobe_share < 0.5
    # The same lights taken as one distant light each (from the origin) miss the normals.
    distant = photometric_stereo(
        images, scene.nominal_light_directions, LEDS[0].intensity[None] / 900.0 * np.ones((6, 3)), robust="none"
    )
    off = (distant.normals.reshape(-1, 3)[lit] * normals[lit]).sum(axis=1)
    assert np.degrees(np.arccos(np.clip(off, -1, 1))).mean() > 1.0


def test_per_pixel_lights_of_the_wrong_shape_or_range_are_named():
    images = np.ones((6, 2, 2, 3))
    good = np.tile([0.0, 0.0, 1.0], (4, 6, 1))
    with pytest.raises(irtps.ArgumentError, match=r"^light_directions: "):
        photometric_stereo(images, good[:3], good)
    bad = good.copy()
    bad[2, 1, 0] = -1.0
    with pytest.raises(irtps.ArgumentError, match=r"^light_irradiance\[2, 1\]: channel 0 = -1"):
        photometric_stereo(images, good, bad)


def test_the_falloff_places_a_level_plate_at_its_height():
    size, height = 24, 7.5
    scene = Scene(Camera(size, size, 1.0), LEDS)
    mask = np.zeros((size, size), bool)
    mask[4:20, 4:20] = True
    points = scene.camera.surface_points(np.full((size, size), height))[mask]
    directions, irradiance = lights_at(scene, points)
    normals = np.tile([0.0, 0.0, 1.0], (mask.sum(), 1))
    images = np.zeros((len(LEDS), size, size, 3))
    images[:, mask] = _lambert(normals, np.full((mask.sum(), 3), 0.6), directions, irradiance)
    placement = falloff_placement(scene, np.zeros((size, size)), mask, images, robust="none")
    assert placement.source == "falloff"
    assert placement.base_height == pytest.approx(height, abs=0.02)


def test_the_rig_is_placed_and_fitted_from_scratch_on_its_direct_light():
    data = irtps.load_dataset(RIG)
    direct = dataclasses.replace(data, images=data.gt.direct)
    with pytest.warns(irtps.IrtpsWarning, match="orthographic camera"):
        result = irtps.reconstruct(direct, "ps")
    error = irtps.angular_error_deg(result.normals, data.gt.normal, data.mask)
    # Three LEDs fix each normal exactly; the mean is the shape's error, through the lights.
    assert np.mean(error[data.mask]) < 1.5
    assert result.placement.source == "falloff"
    assert np.abs(result.height - data.gt.height)[data.mask].mean() < 0.3


def test_reconstruct_writes_a_rig_from_the_command_line(tmp_path):
    from irtps.cli.main import main

    assert main(["reconstruct", str(RIG), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert (tmp_path / "out" / "normal.exr").is_file()


def test_the_surface_points_of_a_stand_in_project_to_their_pixel_centres():
    data = irtps.load_dataset(RIG)
    camera = data.scene.camera
    points = stand_in_scene(data.scene, "rig").camera.surface_points(data.gt.height)
    np.testing.assert_allclose(points[..., 2], data.gt.height, atol=1e-5)
    depth = camera.center_z - points[..., 2]
    u = camera.fx * points[..., 0] / depth + camera.cx
    v = -camera.fy * points[..., 1] / depth + camera.cy
    rows, columns = np.mgrid[: camera.height, : camera.width]
    np.testing.assert_allclose(u, columns + 0.5, atol=1e-6)
    np.testing.assert_allclose(v, rows + 0.5, atol=1e-6)


def test_three_lights_leave_the_height_to_the_fallback_and_say_why():
    scene = Scene(Camera(8, 8, 1.0), LEDS[:3])
    mask = np.ones((8, 8), bool)
    placement = falloff_placement(scene, np.zeros((8, 8)), mask, np.ones((3, 8, 8, 3)))
    assert placement.source == "boundary" and placement.base_height == 0.0
    assert "3 lights fit any height exactly" in placement.reason


def test_a_synthesized_rig_round_trips_and_irtps_removes_its_inter_reflections(tmp_path):
    data, _ = irtps.synthesize(
        "cap", size=40, lights=8, environment="light-box", lights_near=0.9, bounces=3, samples=64
    )
    assert isinstance(data.scene.environment, irtps.MeshEnvironment) and data.scene.floor is None
    assert data.scene.has_point_lights
    # The irradiance at the middle of the floor is that of the distant lights they stand for.
    np.testing.assert_allclose(lights_at(data.scene, np.zeros((1, 3)))[1], np.pi)
    irtps.save_dataset(data, tmp_path / "rig")
    assert irtps.load_dataset(tmp_path / "rig").scene == data.scene
    classic = irtps.reconstruct(data, "ps")
    result = irtps.reconstruct(data, "irtps")
    errors = [
        np.mean(irtps.angular_error_deg(r.normals, data.gt.normal, data.mask)[data.mask]) for r in (classic, result)
    ]
    assert errors[1] < 0.6 * errors[0], errors
    assert result.placement.source == "falloff"


def test_absurd_near_lights_are_refused_by_name():
    with pytest.raises(OptionError, match=r"^lights_near: 0.01 is out of range"):
        irtps.synthesize("cap", size=16, lights=3, lights_near=0.01)


def test_the_report_draws_the_rig_around_the_object(tmp_path):
    from irtps.report.build import build_report

    out = tmp_path / "out"
    irtps.save_reconstruction(irtps.reconstruct(irtps.load_dataset(RIG), "ps"), out, source=str(RIG))
    report = build_report(out)
    rig = next(figure for figure in report.figures if figure.name == "rig")
    assert rig.png.startswith(b"\x89PNG") and "point lights" in rig.caption


def test_auto_chooses_the_lobe_mode_for_a_glossy_object_under_near_lights():
    rng = np.random.default_rng(8)
    count = 400
    normals = rng.normal(size=(count, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, 1.0]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    points = np.c_[rng.uniform(-4, 4, (count, 2)), np.zeros(count)]
    lights = [
        PointLight((12.0 * np.cos(a), 12.0 * np.sin(a), 10.0 + 4 * np.cos(2 * a)), (600.0,) * 3)
        for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ]
    directions, irradiance = lights_at(Scene(Camera(20, 20, 1.0), lights), points)
    half = directions + [0.0, 0.0, 1.0]
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    cosine = np.clip(np.einsum("nki,ni->nk", directions, normals), 0.0, None)
    lobe = 0.4 + 3.0 * np.clip(np.einsum("nki,ni->nk", half, normals), 0.0, None) ** 16
    images = np.transpose(irradiance * (cosine * lobe)[..., None] / np.pi, (1, 0, 2)).reshape(16, 20, 20, 3)
    fit = photometric_stereo(images, directions, irradiance, robust="auto")
    assert fit.robust_used == "lobe" and fit.lobe_share > 0.5


def test_the_residual_covers_the_visible_environment_of_a_rig():
    from irtps.render.residual import render_with_residual

    data = irtps.load_dataset(RIG)
    scene, height, albedo, mask = irtps.load_scene_object(RIG)
    right = render_with_residual(scene, height, albedo, mask, data.images, bounces=2, samples=16).residual
    dark = render_with_residual(scene, height, albedo, mask, 0.5 * data.images, bounces=2, samples=16).residual
    # The true scene explains its light box within the Monte-Carlo noise; halved images do not.
    assert right.surroundings is not None and right.surroundings < 0.15
    assert dark.surroundings > 0.5
