"""RTI folders (`irtps.io.rti`): a ``*.lp`` light position file and JPEG, PNG or TIFF images,
as dome users hold them; made here from the DiLiGenT ball cut, whose true normals and
calibrated result they are checked against."""

import json
import shutil
import warnings
from contextlib import contextmanager
from pathlib import Path, PureWindowsPath

import numpy as np
import pytest
import tifffile
from PIL import Image

import irtps
from irtps.cli.main import main
from irtps.io.dataset_files import dataset_inputs
from irtps.io.dataset_writer import save_dataset
from irtps.io.imageio import srgb_to_linear
from irtps.io.rti import load_rti
from irtps.render.synth import synthesize

BALL = Path(__file__).parent / "data" / "diligent_ball_small"


@contextmanager
def warnings_as_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error", irtps.IrtpsWarning)
        yield


def _to_srgb(linear):
    linear = np.clip(linear, 0, 1)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)


def _rti_folder(folder, *, names=None, suffix=".jpg", lines=None):
    """The ball cut as a dome user's folder: sRGB 8-bit images and ``ball.lp``."""
    data = irtps.load_dataset(BALL)
    folder.mkdir(parents=True)
    names = names or [f"ball_{k + 1:02d}{suffix}" for k in range(len(data.images))]
    for name, image in zip(names, data.images):
        Image.fromarray(np.rint(_to_srgb(image) * 255).astype(np.uint8)).save(
            folder / PureWindowsPath(name).name, quality=95
        )
    if lines is None:
        lines = [f"{name} {d[0]:.6f} {d[1]:.6f} {d[2]:.6f}" for name, d in zip(names, data.scene.light_directions)]
    (folder / "ball.lp").write_text(f"{len(data.images)}\n" + "\n".join(lines) + "\n")
    shutil.copy(BALL / "mask.png", folder / "mask.png")
    return data


def test_a_dome_folder_reconstructs_close_to_the_calibrated_result(tmp_path):
    data = _rti_folder(tmp_path / "dome")
    rti = irtps.load_dataset(tmp_path / "dome")
    assert not rti.irradiance_known and rti.saturation == 1.0
    assert rti.names == tuple(f"ball_{k + 1:02d}.jpg" for k in range(8))
    assert np.allclose(rti.scene.light_directions, data.scene.light_directions, atol=1e-5)
    with pytest.warns(irtps.IrtpsWarning, match="no light intensities given"):
        result = irtps.reconstruct(rti)
    calibrated = irtps.reconstruct(data)
    errors = [
        irtps.angular_error_deg(r.normals, data.gt.normal, data.mask)[data.mask].mean() for r in (calibrated, result)
    ]
    assert errors[1] < errors[0] + 1.0


def test_the_command_line_detects_the_folder_and_lists_what_it_reads(tmp_path):
    _rti_folder(tmp_path / "dome")
    names = {path.name for path in dataset_inputs(tmp_path / "dome")}
    assert {"dome", "ball.lp", "mask.png", "ball_01.jpg", "ball_08.jpg"} <= names
    assert main(["reconstruct", str(tmp_path / "dome"), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert (tmp_path / "out" / "normal.png").stat().st_size > 0


def test_paths_written_on_another_machine_are_found_beside_the_lp_file(tmp_path):
    names = [f"C:\\dome\\capture\\ball_{k + 1:02d}.jpg" for k in range(8)]
    _rti_folder(tmp_path / "dome", names=names)
    assert irtps.load_dataset(tmp_path / "dome").names[0] == "ball_01.jpg"


LP_FAULTS = {
    "count": (lambda lines: lines[:-1], r"ball\.lp: line 1 counts 8 images, but 7 lines follow"),
    "not unit": (
        lambda lines: [lines[0].rsplit(maxsplit=3)[0] + " 0.5 0 0.5", *lines[1:]],
        "line 2: light direction is not a unit vector",
    ),
    "away": (lambda lines: [lines[0].rsplit(maxsplit=3)[0] + " 0 0 -1", *lines[1:]], "line 2: light direction "),
    "malformed": (lambda lines: ["ball_01.jpg 0 0", *lines[1:]], "line 2: expected 'filename x y z'"),
    "twice": (lambda lines: [lines[0], lines[0], *lines[2:]], "line 3: ball_01.jpg is listed again"),
    "missing": (lambda lines: ["ball_99.jpg 0 0 1", *lines[1:]], "ball_99.jpg"),
}


@pytest.mark.parametrize("fault", sorted(LP_FAULTS))
def test_a_faulty_lp_file_is_one_named_error(fault, tmp_path):
    data = irtps.load_dataset(BALL)
    lines = [
        f"ball_{k + 1:02d}.jpg {d[0]:.6f} {d[1]:.6f} {d[2]:.6f}" for k, d in enumerate(data.scene.light_directions)
    ]
    edit, message = LP_FAULTS[fault]
    _rti_folder(tmp_path / "dome", lines=edit(lines))
    with pytest.raises(irtps.DatasetError, match=message):
        irtps.load_dataset(tmp_path / "dome")


def test_two_lp_files_are_refused(tmp_path):
    _rti_folder(tmp_path / "dome")
    shutil.copy(tmp_path / "dome" / "ball.lp", tmp_path / "dome" / "other.lp")
    with pytest.raises(irtps.DatasetError, match="2 light position files"):
        irtps.load_dataset(tmp_path / "dome")


def test_bit_depth_chooses_the_encoding_and_encoding_overrides_it(tmp_path):
    _rti_folder(tmp_path / "dome", suffix=".png")
    code = np.asarray(Image.open(tmp_path / "dome" / "ball_01.png"), dtype=np.float64) / 255
    srgb = load_rti(tmp_path / "dome").images[0]
    assert np.allclose(srgb, srgb_to_linear(code), atol=1e-6)
    linear = load_rti(tmp_path / "dome", encoding="linear").images[0]
    assert np.allclose(linear, code, atol=1e-6)
    with pytest.raises(irtps.ArgumentError, match="^encoding: 'gamma' is not one of srgb, linear$"):
        load_rti(tmp_path / "dome", encoding="gamma")


def test_float_and_16_bit_tiff_images_are_linear(tmp_path):
    data = _rti_folder(tmp_path / "dome")
    for k, image in enumerate(data.images):
        (tmp_path / "dome" / f"ball_{k + 1:02d}.jpg").unlink()
        tifffile.imwrite(tmp_path / "dome" / f"ball_{k + 1:02d}.jpg", image, photometric="rgb")  # misnamed
    with pytest.raises(irtps.DatasetError, match="cannot be read as a JPEG image"):
        load_rti(tmp_path / "dome")
    lp = tmp_path / "dome" / "ball.lp"
    lp.write_text(lp.read_text().replace(".jpg", ".tif"))
    for k, image in enumerate(data.images):
        path = tmp_path / "dome" / f"ball_{k + 1:02d}.tif"
        tifffile.imwrite(path, image if k % 2 else np.rint(image * 65535).astype(np.uint16), photometric="rgb")
    read = load_rti(tmp_path / "dome")
    assert np.allclose(read.images, data.images, atol=1 / 65535)
    assert read.saturation is None  # float images do not clip at a known code


def test_encoding_overrides_any_layout_and_is_recorded(tmp_path, capsys):
    _rti_folder(tmp_path / "dome")
    assert (
        main(["reconstruct", str(tmp_path / "dome"), "--out", str(tmp_path / "out"), "--quiet", "--encoding", "linear"])
        == 0
    )
    assert json.loads((tmp_path / "out" / "run.json").read_text())["encoding"] == "linear"
    # DiLiGenT's 16-bit PNG files are linear by its layout; read as sRGB when asked.
    linear, srgb = (irtps.load_dataset(BALL, encoding=encoding) for encoding in (None, "srgb"))
    assert np.allclose(srgb.images, srgb_to_linear(linear.images), atol=1e-6)
    # The irtps layout's EXR images are linear floats: sRGB does not apply.
    data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    save_dataset(data, tmp_path / "cap")
    argv = ["reconstruct", str(tmp_path / "cap"), "--out", str(tmp_path / "cap_out"), "--encoding", "srgb"]
    capsys.readouterr()
    assert main(argv) == 2
    assert capsys.readouterr().err.startswith("irtps: error: --encoding: 'srgb' applies to PNG, JPEG and TIFF images")
    assert not (tmp_path / "cap_out").exists()


def test_light_intensities_beside_the_lp_file_are_the_lights_strengths(tmp_path):
    data = _rti_folder(tmp_path / "dome")
    given = data.scene.light_irradiance
    (tmp_path / "dome" / "light_intensities.txt").write_text("".join(f"{r} {g} {b}\n" for r, g, b in given))
    rti = irtps.load_dataset(tmp_path / "dome", exclude_images="ball_02.jpg")
    assert rti.irradiance_known and rti.scene.relative_irradiance
    assert np.allclose(rti.scene.light_irradiance, np.delete(given, 1, axis=0))
    assert tmp_path / "dome" / "light_intensities.txt" in dataset_inputs(tmp_path / "dome")
    with warnings_as_errors():
        irtps.reconstruct(rti)  # nothing to estimate, nothing to warn about


@pytest.mark.parametrize(
    "text, message",
    [
        ("1 1 1\n" * 7, r"light_intensities\.txt: 7 lines, but ball\.lp lists 8 images"),
        ("1 1 1\n" * 7 + "1 -1 1\n", r"light_intensities\.txt: line 8: light intensities must not be negative"),
        ("1 1 1\n" * 7 + "1 1\n", r"light_intensities\.txt: line 8: expected 3 numbers, got 2"),
    ],
)
def test_bad_light_intensities_are_named(tmp_path, text, message):
    _rti_folder(tmp_path / "dome")
    (tmp_path / "dome" / "light_intensities.txt").write_text(text)
    with pytest.raises(irtps.DatasetError, match=message):
        irtps.load_dataset(tmp_path / "dome")
