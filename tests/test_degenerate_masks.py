"""Masks that make no surface (one pixel, no 2x2 block, a line one pixel wide): classic
photometric stereo fits them right, IRT-PS refuses them by name before any work, and a stray
pixel beside an object does not break IRT-PS."""

import shutil
import warnings
from pathlib import Path

import irtps
import numpy as np
import pytest
from irtps import _core
from irtps.model.metrics import angular_error_deg
from irtps.irt.interreflection import check_traceable
from irtps.render.surroundings import surroundings_light

from cli_helpers import refused

DATA = Path(__file__).parent / "data"
FIXTURES = {"ball": DATA / "diligent_ball_small", "cap": DATA / "mitsuba_small" / "cap_cornell"}


def _pixel(mask):
    rows, cols = np.nonzero(mask)
    return int(np.median(rows)), int(np.median(cols))


def _one_pixel(mask):
    new = np.zeros_like(mask)
    new[_pixel(mask)] = True
    return new


def _checkerboard(mask):
    return mask & (np.add.outer(np.arange(mask.shape[0]), np.arange(mask.shape[1])) % 2 == 0)


def _diagonal(mask):
    new = np.zeros_like(mask)
    row, col = _pixel(mask)
    for step in range(-6, 7):
        new[row + step, col + step] = True
    return new


def _row(mask):
    new = np.zeros_like(mask)
    row, col = _pixel(mask)
    new[row, col - 6 : col + 7] = True
    return new


DEGENERATE = {"one pixel": _one_pixel, "checkerboard": _checkerboard, "diagonal": _diagonal, "row": _row}


def _with_mask(tmp_path, fixture, shape):
    folder = tmp_path / fixture
    shutil.copytree(FIXTURES[fixture], folder)
    image, bits = _core.read_png(str(folder / "mask.png"))
    mask = (image[..., 0] if image.ndim == 3 else image) > 0.5
    new = shape(mask)
    values = new.astype(np.float32)
    _core.write_png(
        str(folder / "mask.png"),
        np.repeat(values[..., None], image.shape[2], axis=2) if image.ndim == 3 else values,
        bits,
    )
    return folder


@pytest.mark.parametrize("fixture", FIXTURES)
@pytest.mark.parametrize("shape", DEGENERATE)
def test_classic_ps_fits_a_degenerate_mask_as_the_whole_object(tmp_path, fixture, shape):
    whole = irtps.reconstruct(irtps.load_dataset(FIXTURES[fixture]), "ps", base_height="boundary")
    data = irtps.load_dataset(_with_mask(tmp_path, fixture, DEGENERATE[shape]))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        result = irtps.reconstruct(data, "ps", base_height="boundary")
    mask = data.mask
    assert np.isfinite(result.normals).all() and np.isfinite(result.height).all()
    # Each pixel's fit is its own: the same normal as in the fit of the whole object.
    assert angular_error_deg(result.normals, whole.normals, mask)[mask].max() < 1e-3


@pytest.mark.parametrize(("fixture", "error_deg"), [("ball", 1.5), ("cap", 0.1)])
def test_classic_ps_fits_one_pixel_as_its_true_normal(tmp_path, fixture, error_deg):
    data = irtps.load_dataset(_with_mask(tmp_path, fixture, _one_pixel))
    result = irtps.reconstruct(data, "ps")
    assert angular_error_deg(result.normals, data.gt.normal, data.mask)[data.mask].item() < error_deg


@pytest.mark.parametrize("fixture", FIXTURES)
@pytest.mark.parametrize("shape", DEGENERATE)
def test_irtps_refuses_a_mask_with_no_2x2_block_naming_it(tmp_path, capsys, fixture, shape):
    folder = _with_mask(tmp_path, fixture, DEGENERATE[shape])
    error = refused(
        ["reconstruct", str(folder), "--out", str(tmp_path / "out"), "--method", "irtps", "--quiet"], capsys
    )
    assert error.startswith(f"irtps: error: {folder / 'mask.png'}: no 2x2 block of object pixels: ")
    assert "--method ps" in error
    assert not (tmp_path / "out").exists()
    with pytest.raises(irtps.DatasetError, match=r"mask\.png: no 2x2 block"):
        irtps.reconstruct(irtps.load_dataset(folder), "irtps")


def test_a_data_set_in_memory_names_its_mask_field():
    data, _ = irtps.synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    data.mask = np.eye(16, dtype=bool)
    with pytest.raises(irtps.ArgumentError, match=r"^dataset\.mask: no 2x2 block"):
        irtps.reconstruct(data, "irtps")
    data.mask[:2, :2] = True
    check_traceable(data)


def test_a_pixel_no_triangle_touches_keeps_its_light():
    scene = irtps.Scene(
        irtps.Camera(10, 10, 1.0),
        [irtps.Light(direction=[0, 0, 1], irradiance=(np.pi,) * 3)],
        floor=irtps.Floor(height=0.0, albedo=(1.0, 1.0, 1.0)),
    )
    mask = np.zeros((10, 10), bool)
    mask[3:7, 3:7] = True
    mask[9, 9] = True  # a stray pixel, the last in row-major order: the floor fills its footprint in the reconstruction
    seen = surroundings_light(scene, np.where(mask, 10.0, 0.0), np.full((10, 10, 3), 0.5), mask)
    assert not seen.corrected[-1]
    assert seen.coverage(mask)[9, 9] == 1.0
    assert seen.corrected[:-1].any()


def test_irtps_with_stray_pixels_beside_the_object_gives_finite_results(tmp_path):
    def stray(mask):
        new = mask.copy()
        new[1, 1] = True
        rows, cols = np.nonzero(mask)
        for step in (1, 2, 3):
            new[rows.max() + step, cols.max() + step] = True
        return new

    data = irtps.load_dataset(_with_mask(tmp_path, "cap", stray))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        result = irtps.reconstruct(data, "irtps", iterations=1, samples=4)
    assert np.isfinite(result.albedo[data.mask]).all() and np.isfinite(result.normals[data.mask]).all()
    assert len(result.history) == 2


@pytest.mark.parametrize("fixture", FIXTURES)
@pytest.mark.parametrize("shape", DEGENERATE)
def test_the_command_prints_no_numpy_warning_on_a_degenerate_mask(tmp_path, capsys, fixture, shape):
    folder = _with_mask(tmp_path, fixture, DEGENERATE[shape])
    from irtps.cli.main import main

    assert main(["reconstruct", str(folder), "--out", str(tmp_path / "ps"), "--method", "ps"]) == 0
    printed = capsys.readouterr().err
    assert "Warning" not in printed, printed  # only irtps's own "irtps: warning: ..." lines
    assert all(line.startswith("irtps: warning: ") for line in printed.splitlines()), printed
