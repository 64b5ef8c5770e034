"""Evaluation metrics: hand-computed cases, pixel selection, offset alignment and errors."""

import json

import numpy as np
import pytest
from irtps import GroundTruth, IrtpsError
from irtps.model.metrics import Metrics, angular_error_deg, error_maps, evaluate, format_metrics


def normal_map(*rows):
    """(1, N, 3) normals from N 3-vectors."""
    return np.array([rows], dtype=np.float64)


def tilted(degrees, azimuth_degrees=0.0):
    t, a = np.radians(degrees), np.radians(azimuth_degrees)
    return [np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)]


def test_a_known_ten_degree_tilt_gives_ten_degrees():
    size = (3, 4)
    gt = np.zeros((*size, 3))
    gt[..., :] = tilted(30.0, 45.0)
    # Rotate every true normal by 10 degrees about an axis perpendicular to it.
    axis = np.cross(gt[0, 0], [0.0, 0.0, 1.0])
    axis /= np.linalg.norm(axis)
    n, c, s = gt[0, 0], np.cos(np.radians(10.0)), np.sin(np.radians(10.0))
    rotated = n * c + np.cross(axis, n) * s + axis * np.dot(axis, n) * (1 - c)
    recon = np.broadcast_to(3.0 * rotated, gt.shape)  # length must not matter
    mask = np.ones(size, bool)
    angles = angular_error_deg(recon, gt, mask)
    assert angles.dtype == np.float32 and angles.shape == size
    np.testing.assert_allclose(angles, 10.0, atol=1e-4)
    metrics = evaluate(mask=mask, normals=recon, gt=GroundTruth(normal=gt))
    assert metrics.normal_mean_angular_deg == pytest.approx(10.0, abs=1e-4)
    assert metrics.normal_median_angular_deg == pytest.approx(10.0, abs=1e-4)
    assert metrics.pixels == 12


def test_angles_are_nan_outside_the_mask_and_where_the_truth_is_zero():
    gt = normal_map([0, 0, 1], [0, 0, 1], [0, 0, 0], [0, 0, np.nan])
    recon = normal_map([0, 0, 1], [1, 0, 0], [0, 0, 1], [0, 0, 1])
    angles = angular_error_deg(recon, gt, np.array([[False, True, True, True]]))
    assert np.isnan(angles[0, 0]) and np.isnan(angles[0, 2]) and np.isnan(angles[0, 3])
    assert angles[0, 1] == pytest.approx(90.0)


def test_opposite_and_zero_reconstructed_normals():
    gt = normal_map([0, 0, 1], [0, 0, 1])
    recon = normal_map([0, 0, -1], [0, 0, 0])
    angles = angular_error_deg(recon, gt, np.ones((1, 2), bool))
    np.testing.assert_allclose(angles, [[180.0, 90.0]])


def test_paper_normal_error_by_hand():
    gt = normal_map([0, 0, 1], [0, 0.6, 0.8], [0, 0, 1])
    recon = normal_map([0.6, 0, 0.8], [0, 0.6, 0.8], [0, 0.6, 0.8])
    m = evaluate(mask=np.ones((1, 3), bool), normals=recon, gt=GroundTruth(normal=gt))
    # |differences|: (0.6, 0, 0.2), (0, 0, 0), (0, 0.6, 0.2) -> means x 0.2, y 0.2, z 0.4/3.
    assert m.normal_component_error == pytest.approx((0.2 + 0.2 + 0.4 / 3) / 3, abs=1e-7)
    big = np.degrees(np.arccos(0.8))
    assert m.normal_mean_angular_deg == pytest.approx(2 * big / 3, abs=1e-4)
    assert m.normal_median_angular_deg == pytest.approx(big, abs=1e-4)


def test_paper_albedo_error_by_hand_without_rescaling():
    gt = np.array([[[0.5, 0.5, 0.5], [0.2, 0.4, 0.6]]])
    recon = np.array([[[0.4, 0.5, 0.8], [0.2, 0.1, 0.6]]])
    m = evaluate(mask=np.ones((1, 2), bool), albedo=recon, gt=GroundTruth(albedo=gt))
    # |differences|: (0.1, 0, 0.3), (0, 0.3, 0) -> per channel (0.05, 0.15, 0.15).
    np.testing.assert_allclose(m.albedo_error_rgb, (0.05, 0.15, 0.15), atol=1e-7)
    assert m.albedo_error == pytest.approx(0.35 / 3, abs=1e-7)
    # A reconstruction off by a global scale is reported as it is, not rescaled.
    scaled = evaluate(mask=np.ones((1, 2), bool), albedo=2 * gt, gt=GroundTruth(albedo=gt))
    assert scaled.albedo_error == pytest.approx(gt.mean(), abs=1e-7)


def test_paper_height_error_and_median_alignment_by_hand():
    gt = np.array([[1.0, 2.0], [3.0, 4.0]])
    recon = gt + np.array([[2.0, 2.0], [2.0, 1.0]])  # differences gt - recon: -2, -2, -2, -1
    m = evaluate(mask=np.ones((2, 2), bool), height=recon, gt=GroundTruth(height=gt))
    assert m.height_error == pytest.approx(1.75)
    assert m.height_offset == pytest.approx(-2.0)  # the median, not the mean (-1.75)
    assert m.height_error_aligned == pytest.approx(0.25)
    # RMSE after removing the mean difference -1.75: sqrt((3 * 0.25^2 + 0.75^2) / 4).
    assert m.height_rmse_aligned == pytest.approx(np.sqrt(0.75 / 4))


def test_offset_alignment_removes_a_constant_exactly():
    rng = np.random.default_rng(1)
    gt = GroundTruth(height=rng.uniform(0.0, 5.0, (6, 7)))
    mask = np.ones((6, 7), bool)
    recon = gt.height.astype(np.float64) - 3.25
    m = evaluate(mask=mask, height=recon, gt=gt)
    assert m.height_error == pytest.approx(3.25)
    assert m.height_offset == pytest.approx(3.25)
    assert m.height_error_aligned == pytest.approx(0.0, abs=1e-12)
    assert m.height_rmse_aligned == pytest.approx(0.0, abs=1e-12)
    maps = error_maps(mask=mask, height=recon, gt=gt)
    np.testing.assert_allclose(maps.height_aligned, 0.0, atol=1e-12)


def test_base_height_shifts_the_truth_for_the_unaligned_error_only():
    gt = GroundTruth(height=np.array([[0.0, 1.0, 2.0]]))
    recon = gt.height + 0.5  # world z, with the truth measured from a base at 0.5
    mask = np.ones((1, 3), bool)
    m = evaluate(mask=mask, height=recon, gt=gt, base_height=0.5)
    assert m.height_error == pytest.approx(0.0) and m.height_offset == pytest.approx(0.0)
    unshifted = evaluate(mask=mask, height=recon, gt=gt)
    assert unshifted.height_error == pytest.approx(0.5)
    assert unshifted.height_error_aligned == pytest.approx(0.0)


def test_pixels_outside_the_mask_or_without_true_normal_are_ignored():
    # Pixel 0: good. Pixel 1: outside the mask. Pixel 2: true normal zero. Pixel 3: true normal NaN.
    gt = GroundTruth(
        normal=normal_map([0, 0, 1], [0, 0, 1], [0, 0, 0], [np.nan, 0, 1]),
        albedo=np.full((1, 4, 3), 0.5),
        height=np.array([[1.0, 1.0, 1.0, 1.0]]),
    )
    mask = np.array([[True, False, True, True]])
    recon_normals = normal_map(tilted(10.0), [1, 0, 0], [1, 0, 0], [1, 0, 0])
    recon_albedo = np.array([[[0.6, 0.6, 0.6], [9, 9, 9], [9, 9, 9], [9, 9, 9]]])
    recon_height = np.array([[1.5, np.nan, 100.0, 100.0]])  # NaN outside the evaluated pixels is fine
    m = evaluate(mask=mask, normals=recon_normals, albedo=recon_albedo, height=recon_height, gt=gt)
    assert m.pixels == 1
    assert m.normal_mean_angular_deg == pytest.approx(10.0, abs=1e-4)
    assert m.albedo_error == pytest.approx(0.1)
    assert m.height_error == pytest.approx(0.5)
    maps = error_maps(mask=mask, normals=recon_normals, albedo=recon_albedo, height=recon_height, gt=gt)
    for name in ("angular_deg", "albedo", "height_aligned"):
        values = getattr(maps, name)
        assert values.dtype == np.float32 and values.shape == (1, 4)
        assert np.isnan(values[0, 1:]).all(), name
        assert np.isfinite(values[0, 0]), name


def test_non_finite_true_height_or_albedo_excludes_the_pixel():
    gt = GroundTruth(height=np.array([[1.0, np.inf]]), albedo=np.array([[[0.5] * 3, [0.5, np.nan, 0.5]]]))
    m = evaluate(mask=np.ones((1, 2), bool), height=np.array([[2.0, 0.0]]), albedo=np.zeros((1, 2, 3)), gt=gt)
    assert m.pixels == 1
    assert m.height_error == pytest.approx(1.0)
    assert m.albedo_error == pytest.approx(0.5)


def test_error_maps_average_to_the_metrics():
    rng = np.random.default_rng(3)
    size = (5, 6)
    mask = rng.uniform(size=size) > 0.3
    normal = rng.normal(size=(*size, 3))
    normal[..., 2] = np.abs(normal[..., 2]) + 0.1
    gt = GroundTruth(normal=normal, albedo=rng.uniform(size=(*size, 3)), height=rng.uniform(size=size))
    recon = {
        "normals": gt.normal + rng.normal(scale=0.1, size=(*size, 3)),
        "albedo": gt.albedo + rng.normal(scale=0.1, size=(*size, 3)),
        "height": gt.height + rng.normal(scale=0.1, size=size),
    }
    m = evaluate(mask=mask, gt=gt, **recon)
    maps = error_maps(mask=mask, gt=gt, **recon)
    assert m.pixels == mask.sum()
    assert np.nanmean(maps.angular_deg.astype(float)) == pytest.approx(m.normal_mean_angular_deg, rel=1e-5)
    assert np.nanmedian(maps.angular_deg.astype(float)) == pytest.approx(m.normal_median_angular_deg, rel=1e-5)
    assert np.nanmean(maps.albedo.astype(float)) == pytest.approx(m.albedo_error, rel=1e-5)
    assert np.nanmean(maps.height_aligned.astype(float)) == pytest.approx(m.height_error_aligned, rel=1e-5)
    np.testing.assert_array_equal(np.isnan(maps.albedo), ~mask)


def test_missing_pieces_give_none():
    size = (2, 2)
    mask = np.ones(size, bool)
    gt = GroundTruth(normal=np.dstack([np.zeros(size), np.zeros(size), np.ones(size)]))
    m = evaluate(mask=mask, normals=gt.normal, albedo=np.zeros((*size, 3)), height=np.zeros(size), gt=gt)
    assert m.normal_mean_angular_deg == pytest.approx(0.0, abs=1e-3) and m.normal_component_error == 0.0
    for name in (
        "albedo_error",
        "albedo_error_rgb",
        "height_error",
        "height_error_aligned",
        "height_rmse_aligned",
        "height_offset",
    ):
        assert getattr(m, name) is None, name
    no_normals = evaluate(mask=mask, height=np.zeros(size), gt=gt)
    assert no_normals.normal_mean_angular_deg is None and no_normals.normal_component_error is None
    nothing = evaluate(mask=mask, normals=gt.normal, gt=None)
    assert nothing == Metrics(pixels=4)
    maps = error_maps(mask=mask, height=np.zeros(size), gt=gt)
    assert maps.angular_deg is None and maps.albedo is None and maps.height_aligned is None


def test_an_empty_selection_gives_no_metrics():
    gt = GroundTruth(height=np.ones((2, 2)))
    m = evaluate(mask=np.zeros((2, 2), bool), height=np.ones((2, 2)), gt=gt)
    assert m == Metrics(pixels=0)


@pytest.mark.parametrize(
    "name, arguments",
    [
        ("normals", {"normals": np.zeros((2, 3, 3))}),
        ("albedo", {"albedo": np.zeros((2, 2))}),
        ("height", {"height": np.zeros((3, 2))}),
        ("gt.normal", {"gt": GroundTruth(normal=np.zeros((2, 2, 4)))}),
        ("gt.albedo", {"gt": GroundTruth(albedo=np.zeros((2, 3, 3)))}),
        ("gt.height", {"gt": GroundTruth(height=np.zeros((2, 2, 1)))}),
        ("mask", {"mask": np.ones((2, 2, 1), bool)}),
    ],
)
def test_shape_mismatches_raise_naming_the_argument(name, arguments):
    call = {"mask": np.ones((2, 2), bool), "gt": GroundTruth()}
    call.update(arguments)
    with pytest.raises(IrtpsError, match=rf"^{name}: shape"):
        evaluate(**call)
    with pytest.raises(IrtpsError, match=rf"^{name}: shape"):
        error_maps(**call)


def test_angular_error_shape_mismatches_raise_naming_the_argument():
    good = np.zeros((2, 2, 3))
    with pytest.raises(IrtpsError, match="^normals: shape"):
        angular_error_deg(np.zeros((2, 2)), good, np.ones((2, 2), bool))
    with pytest.raises(IrtpsError, match="^normals_gt: shape"):
        angular_error_deg(good, np.zeros((3, 2, 3)), np.ones((2, 2), bool))
    with pytest.raises(IrtpsError, match="^mask: shape"):
        angular_error_deg(good, good, np.ones(4, bool))


def test_a_non_finite_reconstruction_on_an_evaluated_pixel_raises():
    gt = GroundTruth(height=np.ones((1, 2)))
    with pytest.raises(IrtpsError, match="^height: non-finite value nan at row 0, column 1$"):
        evaluate(mask=np.ones((1, 2), bool), height=np.array([[1.0, np.nan]]), gt=gt)


def test_to_dict_is_json_ready_and_format_metrics_reads_well():
    gt = GroundTruth(albedo=np.full((1, 2, 3), 0.5), height=np.array([[1.0, 2.0]]))
    m = evaluate(mask=np.ones((1, 2), bool), albedo=np.full((1, 2, 3), 0.25), height=np.array([[1.0, 2.5]]), gt=gt)
    data = json.loads(json.dumps(m.to_dict()))
    assert data["pixels"] == 2 and data["normal_mean_angular_deg"] is None
    assert data["albedo_error_rgb"] == pytest.approx([0.25, 0.25, 0.25])
    assert data["height_error"] == pytest.approx(0.25)
    assert set(data) >= {
        "normal_mean_angular_deg",
        "normal_median_angular_deg",
        "normal_component_error",
        "albedo_error",
        "albedo_error_rgb",
        "height_error",
        "height_error_aligned",
        "height_rmse_aligned",
        "pixels",
    }
    text = format_metrics(m)
    lines = text.splitlines()
    assert lines[0].split() == ["pixels", "evaluated", "2"]
    assert "n/a" in lines[1] and "albedo error (paper)      0.25  (R 0.25, G 0.25, B 0.25)" in text
    assert "height error (paper)      0.25" in text


def test_irtps_evaluate_refuses_a_normal_map_that_is_not_unit_on_the_mask(tmp_path, capsys):
    import shutil
    from pathlib import Path

    from irtps import _core
    from irtps.cli.main import main

    from cli_helpers import refused

    ball = Path(__file__).parent / "data" / "diligent_ball_small"
    out = tmp_path / "ball"
    assert main(["reconstruct", str(ball), "--out", str(out), "--quiet"]) == 0
    assert main(["evaluate", str(out), "--gt", str(ball), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["normal_mean_angular_deg"] < 5
    zero = tmp_path / "zero"
    shutil.copytree(out, zero)
    normals = _core.read_exr(str(zero / "normal.exr"))
    _core.write_exr(str(zero / "normal.exr"), np.zeros_like(normals))
    error = refused(["evaluate", str(zero), "--gt", str(ball)], capsys)
    assert error.startswith(f"irtps: error: {zero / 'normal.exr'}: the normal at row ")
    assert "has length 0, not 1" in error
