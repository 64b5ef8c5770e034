"""Data sets in the DiLiGenT layout (a small committed crop of ballPNG, and the real one)."""

import shutil
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from irtps import DatasetError, _core, load_dataset, save_dataset
from irtps.io.diligent import load_diligent

FIXTURE = Path(__file__).resolve().parent / "data" / "diligent_ball_small"
SHARED = Path(__file__).resolve().parents[1].parent / "shared"
BALL = SHARED / "data" / "diligent" / "ballPNG"
needs_shared = pytest.mark.skipif(not BALL.is_dir(), reason="shared DiLiGenT data not available")

LIGHT_COUNT, HEIGHT, WIDTH = 8, 44, 48


@pytest.fixture
def ball(tmp_path):
    """A writable copy of the fixture folder."""
    return Path(shutil.copytree(FIXTURE, tmp_path / "ball"))


def _lines(path):
    return path.read_text().splitlines()


def test_fixture_loads_with_scene_built_from_the_text_files():
    dataset = load_diligent(FIXTURE)
    assert dataset.images.shape == (LIGHT_COUNT, HEIGHT, WIDTH, 3)
    assert dataset.images.dtype == np.float32
    scene = dataset.scene
    assert (scene.camera.width, scene.camera.height, scene.camera.pixel_size) == (WIDTH, HEIGHT, 1.0)
    assert scene.floor is None and scene.environment is None
    listed = np.loadtxt(FIXTURE / "light_directions.txt")
    np.testing.assert_allclose(scene.light_directions, listed, atol=1e-4)
    np.testing.assert_allclose(np.linalg.norm(scene.light_directions, axis=1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(scene.light_irradiance, np.loadtxt(FIXTURE / "light_intensities.txt"))
    assert dataset.mask.dtype == bool and 0 < dataset.mask.sum() < HEIGHT * WIDTH
    assert dataset.source == str(FIXTURE)


def test_ground_truth_normals_come_from_normal_gt_mat():
    dataset = load_diligent(FIXTURE)
    normal = dataset.gt.normal
    assert normal.shape == (HEIGHT, WIDTH, 3) and normal.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(normal[dataset.mask], axis=1), 1.0, atol=1e-5)
    assert np.all(normal[~dataset.mask] == 0.0)
    assert dataset.gt.height is None and dataset.gt.direct is None
    assert load_diligent(FIXTURE, ground_truth=False).gt is None


def test_normals_use_the_irtps_frame_y_up():
    normal = load_diligent(FIXTURE).gt.normal
    rows, columns = np.nonzero(np.linalg.norm(normal, axis=2))
    middle_column = (columns.min() + columns.max()) // 2
    middle_row = (rows.min() + rows.max()) // 2
    assert normal[rows.min() + 1, middle_column, 1] > 0.5
    assert normal[rows.max() - 1, middle_column, 1] < -0.5
    assert normal[middle_row, columns.min() + 1, 0] < -0.5
    assert normal[middle_row, columns.max() - 1, 0] > 0.5


def test_lambertian_fit_matches_the_ground_truth_normals():
    dataset = load_diligent(FIXTURE)
    shading = (dataset.images / dataset.scene.light_irradiance[:, None, None, :]).mean(axis=3)
    normal = dataset.gt.normal
    inner = dataset.mask & (normal[..., 2] > 0.8)
    observed = shading[:, inner]
    solution, *_ = np.linalg.lstsq(dataset.scene.light_directions, observed, rcond=None)
    fitted = solution.T / np.linalg.norm(solution.T, axis=1, keepdims=True)
    error_deg = np.degrees(np.arccos(np.clip(np.sum(fitted * normal[inner], axis=1), -1.0, 1.0)))
    assert np.median(error_deg) < 5.0


def test_images_keep_their_16_bits():
    values = load_diligent(FIXTURE).images * 65535.0
    np.testing.assert_allclose(values, np.round(values), atol=0.02)
    assert np.any(np.round(values) % 257 != 0)


def test_load_dataset_detects_the_diligent_layout():
    dataset = load_dataset(FIXTURE)
    np.testing.assert_array_equal(dataset.images, load_diligent(FIXTURE).images)
    assert dataset.gt.normal is not None


def test_images_follow_the_order_of_filenames_txt(ball):
    original = load_diligent(ball)
    for name in ("filenames.txt", "light_directions.txt", "light_intensities.txt"):
        (ball / name).write_text("\n".join(reversed(_lines(ball / name))) + "\n\n")
    reordered = load_diligent(ball)
    np.testing.assert_array_equal(reordered.images, original.images[::-1])
    np.testing.assert_array_equal(reordered.scene.light_directions, original.scene.light_directions[::-1])


def test_nearly_unit_directions_are_renormalised(ball):
    lines = _lines(ball / "light_directions.txt")
    lines[0] = " ".join(str(1.005 * float(v)) for v in lines[0].split())
    (ball / "light_directions.txt").write_text("\n".join(lines) + "\n")
    directions = load_diligent(ball).scene.light_directions
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-12)


def test_text_files_from_windows_editors_load_the_same(ball):
    """A byte-order mark and CRLF line ends, as Notepad writes them, change nothing."""
    original = load_diligent(ball)
    for name in ("filenames.txt", "light_directions.txt", "light_intensities.txt"):
        path = ball / name
        path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes().replace(b"\n", b"\r\n"))
    edited = load_diligent(ball)
    assert edited.image_names == original.image_names
    assert edited.scene == original.scene


def test_saved_in_the_irtps_layout_it_loads_back_the_same(ball, tmp_path):
    dataset = load_diligent(ball)
    save_dataset(dataset, tmp_path / "converted")
    converted = load_dataset(tmp_path / "converted")
    assert converted.scene == dataset.scene
    np.testing.assert_array_equal(converted.images, dataset.images)
    np.testing.assert_array_equal(converted.mask, dataset.mask)
    np.testing.assert_array_equal(converted.gt.normal, dataset.gt.normal)


def _edit_line(path, number, text):
    lines = _lines(path)
    lines[number - 1] = text
    path.write_text("\n".join(lines) + "\n")


def _keep_lines(folder, count):
    for name in ("filenames.txt", "light_directions.txt", "light_intensities.txt"):
        (folder / name).write_text("\n".join(_lines(folder / name)[:count]) + "\n")


def _second_image(folder):
    return folder / _lines(folder / "filenames.txt")[1]


MALFORMED = {
    "missing filenames.txt": (lambda f: (f / "filenames.txt").unlink(), "filenames.txt: missing"),
    "light_intensities.txt a folder": (
        lambda f: ((f / "light_intensities.txt").unlink(), (f / "light_intensities.txt").mkdir()),
        "light_intensities.txt: ",
    ),
    "line counts disagree": (
        lambda f: (f / "light_directions.txt").write_text("\n".join(_lines(f / "light_directions.txt")[:7]) + "\n"),
        "light_directions.txt: 7 lines, but filenames.txt lists 8 images",
    ),
    "non-unit direction": (
        lambda f: _edit_line(f / "light_directions.txt", 3, "0 0.9 1.2"),
        "light_directions.txt: line 3: light direction is not a unit vector (norm 1.5)",
    ),
    "downward light": (
        lambda f: _edit_line(f / "light_directions.txt", 2, "0 0.6 -0.8"),
        "light_directions.txt: line 2: light direction must point toward the camera side (z > 0)",
    ),
    "text instead of numbers": (
        lambda f: _edit_line(f / "light_directions.txt", 4, "0 zero 1"),
        "light_directions.txt: line 4: expected 3 numbers, got '0 zero 1'",
    ),
    "a number with an underscore": (
        lambda f: _edit_line(f / "light_intensities.txt", 2, "1_2.5 1 1"),
        "light_intensities.txt: line 2: expected 3 numbers, got '1_2.5 1 1'",
    ),
    "digits of another script": (
        lambda f: _edit_line(f / "light_directions.txt", 1, "0 0 \u0661"),
        "light_directions.txt: line 1: expected 3 numbers, got '0 0 \u0661'",
    ),
    "an image listed twice": (
        lambda f: _edit_line(f / "filenames.txt", 3, "./" + _lines(f / "filenames.txt")[0]),
        "filenames.txt: line 3 lists './008.png' again (line 1 lists it): each image goes with one light",
    ),
    "two numbers": (
        lambda f: _edit_line(f / "light_intensities.txt", 6, "1 1"),
        "light_intensities.txt: line 6: expected 3 numbers, got 2",
    ),
    "NaN intensity": (
        lambda f: _edit_line(f / "light_intensities.txt", 1, "nan 1 1"),
        "light_intensities.txt: line 1: non-finite value",
    ),
    "negative intensity": (
        lambda f: _edit_line(f / "light_intensities.txt", 5, "1 -1 1"),
        "light_intensities.txt: line 5: light intensities must not be negative",
    ),
    "too few lights": (lambda f: _keep_lines(f, 2), "filenames.txt: 2 images: photometric stereo needs at least 3"),
    "missing image": (lambda f: _second_image(f).unlink(), "missing (listed on line 2 of filenames.txt)"),
    "image of another size": (
        lambda f: _core.write_png(str(_second_image(f)), np.zeros((HEIGHT, WIDTH + 1, 3), np.float32), 16),
        f"size {WIDTH + 1}x{HEIGHT} differs from",
    ),
    "corrupt image": (lambda f: _second_image(f).write_bytes(b"broken"), "not a readable PNG file"),
    "mask of another size": (
        lambda f: _core.write_png(str(f / "mask.png"), np.ones((HEIGHT + 2, WIDTH), np.float32), 8),
        f"mask.png: size {WIDTH}x{HEIGHT + 2} does not match the images ({WIDTH}x{HEIGHT})",
    ),
    "wrong variable in Normal_gt.mat": (
        lambda f: scipy.io.savemat(f / "Normal_gt.mat", {"N": np.zeros((HEIGHT, WIDTH, 3))}),
        "Normal_gt.mat: no variable 'Normal_gt' (found ['N'])",
    ),
    "normals of another size": (
        lambda f: scipy.io.savemat(f / "Normal_gt.mat", {"Normal_gt": np.zeros((HEIGHT, 5, 3))}),
        f"Normal_gt.mat: size 5x{HEIGHT} does not match the images ({WIDTH}x{HEIGHT})",
    ),
    "normals not RGB": (
        lambda f: scipy.io.savemat(f / "Normal_gt.mat", {"Normal_gt": np.zeros((HEIGHT, WIDTH))}),
        "Normal_gt.mat: Normal_gt has shape",
    ),
    "corrupt Normal_gt.mat": (
        lambda f: (f / "Normal_gt.mat").write_bytes(b"broken"),
        "Normal_gt.mat: not a readable MATLAB file",
    ),
    "complex Normal_gt.mat": (
        lambda f: scipy.io.savemat(f / "Normal_gt.mat", {"Normal_gt": np.full((HEIGHT, WIDTH, 3), 1 + 1j)}),
        "Normal_gt.mat: Normal_gt holds complex128 values, expected real numbers",
    ),
}


@pytest.mark.parametrize("name", list(MALFORMED))
def test_malformed_diligent_folder_is_rejected_naming_the_file(ball, name):
    damage, expected = MALFORMED[name]
    damage(ball)
    with pytest.raises(DatasetError) as info:
        load_dataset(ball)
    message = str(info.value)
    assert message.startswith(str(ball)), message
    assert expected in message, message


def test_running_out_of_memory_reading_normal_gt_mat_does_not_blame_the_file(ball, monkeypatch):
    def out_of_memory(path):
        raise MemoryError("Unable to allocate 1.00 GiB")

    monkeypatch.setattr(scipy.io, "loadmat", out_of_memory)
    with pytest.raises(MemoryError, match="Unable to allocate"):
        load_dataset(ball)


@needs_shared
def test_real_ball_loads_and_matches_the_fixture():
    dataset = load_diligent(BALL)
    assert dataset.images.shape == (96, 512, 612, 3)
    assert dataset.gt.normal.shape == (512, 612, 3)
    assert dataset.mask.sum() > 10000
    fixture = load_diligent(FIXTURE)
    names = _lines(BALL / "filenames.txt")
    first = names.index(_lines(FIXTURE / "filenames.txt")[0])
    crop = dataset.images[first, 176:352, 212:404].reshape(HEIGHT, 4, WIDTH, 4, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(fixture.images[0], crop, atol=0.5 / 65535 + 1e-6)
