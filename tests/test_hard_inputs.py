"""Hard inputs, run through the ``irtps`` command as a user would.

Every malformed input must end with exit status 2 and one line ``irtps: error: ...``
naming the offending file or field, no traceback, and no output: neither OUT nor a
temporary folder is left behind (the fixtures are damaged by tests/damage.py). Inputs
accepted on purpose (negative, saturated pixels) keep their documented behaviour.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from irtps import _core
from irtps.cli.main import main

from cli_helpers import saturate, snapshot
from damage import (
    ball_image,
    claim_exr_size,
    claim_png_size,
    coplanar_diligent,
    edit_exr,
    edit_run_text,
    edit_scene,
    edit_scene_text,
    light_directions,
    out_under_a_file,
    rename_exr_channel,
    replace_line,
    set_pixels,
    truncate,
    two_lights,
    write_png,
)

DATA = Path(__file__).parent / "data"
MITSUBA = DATA / "mitsuba_small" / "cap_cornell"  # 96x96, 3 lights, floor and Cornell box
BALL = DATA / "diligent_ball_small"  # DiLiGenT layout, 48x44, 8 lights, 16-bit PNG
SIZE = 96


# The matrix ------------------------------------------------------------------------
#
# Each case: (command, fixture, damage, extra arguments, expected parts of the message).
# fixture is "mitsuba" or "ball" (a copy of that fixture to damage), "reconstruction"
# (a reconstruction of BALL, for evaluate) or None (then the data argument names a path
# that does not exist). {data} in a message stands for the data argument, {tmp} for the
# test's temporary folder. An "--out" in the extra arguments may be a callable of tmp_path.

CASES = {
    # wrong or missing files
    "no such data folder": ("reconstruct", None, None, [], ["{tmp}/nowhere: no such data set folder"]),
    "data is a file": (
        "reconstruct",
        None,
        lambda f: f.write_text("a file, not a folder"),
        [],
        ["{data}: not a folder"],
    ),
    "neither layout": (
        "reconstruct",
        "mitsuba",
        lambda f: (f / "scene.json").rename(f / "scene.txt"),
        [],
        ["{data}: not a data set: it holds neither scene.json", "nor light_directions.txt"],
    ),
    "missing image": (
        "reconstruct",
        "mitsuba",
        lambda f: (f / "images" / "001.exr").unlink(),
        [],
        ["{data}/images/001.exr: missing (scene.json has 3 lights, one image each)"],
    ),
    "image without a light": (
        "reconstruct",
        "mitsuba",
        lambda f: shutil.copy(f / "images" / "000.exr", f / "images" / "003.exr"),
        [],
        ["{data}/images: 4 images for 3 lights in scene.json (003.exr has no light)"],
    ),
    "render without true height": (
        "render",
        "mitsuba",
        lambda f: (f / "gt" / "height.exr").unlink(),
        [],
        ["{data}/gt/height.exr: missing (rendering needs the true height and albedo)"],
    ),
    "listed DiLiGenT image missing": (
        "reconstruct",
        "ball",
        lambda f: ball_image(f, 5).unlink(),
        [],
        ["{data}/052.png: missing (listed on line 6 of filenames.txt)"],
    ),
    "evaluate without albedo.exr": (
        "evaluate",
        "reconstruction",
        lambda f: (f / "albedo.exr").unlink(),
        ["--gt", str(BALL)],
        ["{data}/albedo.exr: no such file"],
    ),
    # mismatched sizes
    "image of another size": (
        "reconstruct",
        "mitsuba",
        lambda f: _core.write_exr(str(f / "images" / "002.exr"), np.ones((8, 8, 3), np.float32)),
        [],
        ["{data}/images/002.exr: size 8x8 differs from {data}/images/000.exr (96x96)"],
    ),
    "camera disagrees with images": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s["camera"].update(width=95)),
        [],
        ["{data}/images/000.exr: size 96x96 does not match the camera in scene.json (95x96)"],
    ),
    "mask of another size": (
        "render",
        "mitsuba",
        lambda f: write_png(f / "mask.png", np.ones((SIZE, SIZE + 1))),
        [],
        ["{data}/mask.png: size 97x96 does not match the images (96x96)"],
    ),
    "reconstruction parts of different sizes": (
        "evaluate",
        "reconstruction",
        lambda f: _core.write_exr(str(f / "height.exr"), np.zeros((5, 5), np.float32)),
        ["--gt", str(BALL)],
        ["{data}/height.exr: size 5x5 does not match"],
    ),
    # NaN / Inf pixels
    "NaN pixel": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_exr(f / "images" / "001.exr", set_pixels(np.nan)),
        [],
        ["{data}/images/001.exr: non-finite value NaN at row 3, column 4"],
    ),
    "infinite true height": (
        "render",
        "mitsuba",
        lambda f: edit_exr(f / "gt" / "height.exr", set_pixels(np.inf)),
        [],
        ["{data}/gt/height.exr: non-finite value inf at row 3, column 4"],
    ),
    "NaN reconstructed normals": (
        "evaluate",
        "reconstruction",
        lambda f: edit_exr(f / "normal.exr", set_pixels(np.nan)),
        ["--gt", str(BALL)],
        ["{data}/normal.exr: non-finite value nan at row 3, column 4"],
    ),
    # black images, albedo out of range
    "every image black": (
        "reconstruct",
        "mitsuba",
        lambda f: [edit_exr(f / "images" / f"{k:03d}.exr", set_pixels(0.0, ...)) for k in range(3)],
        [],
        ["{data}: every image is black on the object"],
    ),
    "true albedo above 1": (
        "render",
        "mitsuba",
        lambda f: edit_exr(f / "gt" / "albedo.exr", set_pixels(1.5, (48, 50))),
        [],
        ["{data}/gt/albedo.exr: albedo 1.5 at row 48, column 50 of the mask is outside [0, 1]"],
    ),
    # too few or coplanar lights
    "two lights": ("reconstruct", "mitsuba", two_lights, [], ["{data}/scene.json: lights has 2 lights"]),
    "coplanar lights": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_scene(f, light_directions([0.6, 0.0, 0.8], [-0.6, 0.0, 0.8], [0.0, 0.0, 1.0])),
        [],
        ["{data}: lights: directions are (nearly) coplanar"],
    ),
    "coplanar DiLiGenT lights": (
        "reconstruct",
        "ball",
        coplanar_diligent,
        [],
        ["{data}: lights: directions are (nearly) coplanar"],
    ),
    "light without irradiance": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s["lights"][1].update(irradiance=[0.0, 0.0, 0.0])),
        [],
        ["{data}: lights[1].irradiance: must be positive in every channel"],
    ),
    # irradiance whose products overflow float32 (a RuntimeWarning once, then a wrong error)
    "overflowing DiLiGenT intensity": (
        "reconstruct",
        "ball",
        lambda f: replace_line(f / "light_intensities.txt", 2, "1e308 1e308 1e308"),
        [],
        [
            "{data}/light_intensities.txt: line 2: light intensity has channel 0 = 1e+308, out of range: expected 0 or a number from 1e-09 to 1e+09"
        ],
    ),
    "vanishing DiLiGenT intensity": (
        "reconstruct",
        "ball",
        lambda f: replace_line(f / "light_intensities.txt", 1, "1 1e-40 1"),
        ["--method", "irtps"],
        ["{data}/light_intensities.txt: line 1: light intensity has channel 1 = 1e-40, out of range"],
    ),
    "overflowing scene irradiance": (
        "render",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s["lights"][2].update(irradiance=[1.0, 1e308, 1.0])),
        [],
        ["{data}/scene.json: lights[2].irradiance has channel 1 = 1e+308, out of range"],
    ),
    # non-unit or downward light directions
    "non-unit light direction": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s["lights"][1].update(direction=[0.0, 0.0, 1.1])),
        [],
        ["{data}/scene.json: lights[1].direction is not a unit vector (norm 1.1)"],
    ),
    "downward light": (
        "render",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s["lights"][2].update(direction=[0.0, 0.6, -0.8])),
        [],
        ["{data}/scene.json: lights[2].direction must point toward the camera side (z > 0)"],
    ),
    # z > 0 as a float64 but 0 as the core's float32 (the core refused it without the file)
    "light grazing below float32": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s["lights"][0].update(direction=[1.0, 0.0, 1e-50])),
        [],
        [
            "{data}/scene.json: lights[0].direction must point toward the camera side (z > 0), got z = 1e-50, which is 0 in float32"
        ],
    ),
    "DiLiGenT light grazing below float32": (
        "reconstruct",
        "ball",
        lambda f: replace_line(f / "light_directions.txt", 3, "0 1 1e-300"),
        [],
        [
            "{data}/light_directions.txt: line 3: light direction must point toward the camera side (z > 0), got z = 1e-300, which is 0"
        ],
    ),
    # empty mask
    "empty mask": (
        "reconstruct",
        "mitsuba",
        lambda f: write_png(f / "mask.png", np.zeros((SIZE, SIZE))),
        [],
        ["{data}/mask.png: the mask is empty"],
    ),
    "empty reconstruction mask": (
        "evaluate",
        "reconstruction",
        lambda f: write_png(f / "mask.png", np.zeros((44, 48))),
        ["--gt", str(BALL)],
        ["{data}/mask.png: the mask is empty"],
    ),
    # corrupt EXR / PNG
    "EXR of garbage": (
        "reconstruct",
        "mitsuba",
        lambda f: (f / "images" / "000.exr").write_bytes(bytes(range(256)) * 16),
        [],
        ["{data}/images/000.exr: not a readable OpenEXR file"],
    ),
    "truncated EXR": (
        "reconstruct",
        "mitsuba",
        lambda f: truncate(f / "images" / "001.exr", 20_000),
        [],
        ["{data}/images/001.exr: not a readable OpenEXR file"],
    ),
    "EXR with other channels": (
        "render",
        "mitsuba",
        lambda f: rename_exr_channel(f / "gt" / "albedo.exr", b"R", b"S"),
        [],
        ["{data}/gt/albedo.exr: channels", "expected R, G, B (optionally A) or a single Y"],
    ),
    "truncated 16-bit PNG": (
        "reconstruct",
        "ball",
        lambda f: truncate(ball_image(f, 1), 3000),
        [],
        ["{data}/009.png: corrupt PNG data"],
    ),
    # wrong JSON
    "camera width as a string": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s["camera"].update(width="96")),
        [],
        ["{data}/scene.json: camera.width must be a positive integer, got the string '96'"],
    ),
    "lights as an object": (
        "render",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s.update(lights={"0": s["lights"][0]})),
        [],
        ["{data}/scene.json: lights must be an array, got an object"],
    ),
    # a string field of megabytes, shown in part: still one short line
    "scene format of 10 million characters": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s.update(format="x" * 10_000_000)),
        [],
        ["{data}/scene.json: format is 'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx...': unknown format"],
    ),
    "unknown field of a million characters": (
        "render",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s["camera"].update({"y" * 1_000_000: 1})),
        [],
        ["{data}/scene.json: camera has an unknown field 'yyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyy...'"],
    ),
    "scene.json not JSON": (
        "reconstruct",
        "mitsuba",
        lambda f: (f / "scene.json").write_text('{"format": "irtps.scene/1",\n  "camera": }'),
        [],
        ["{data}/scene.json: invalid JSON at line 2, column 13"],
    ),
    "scene.json not UTF-8": (
        "reconstruct",
        "mitsuba",
        lambda f: (f / "scene.json").write_bytes(b'{"format": "\xff\xfe"}'),
        [],
        ["{data}/scene.json: not UTF-8 text"],
    ),
    "scene.json nested too deeply": (
        "reconstruct",
        "mitsuba",
        lambda f: (f / "scene.json").write_text("[" * 100_000),
        [],
        ["{data}/scene.json: arrays and objects nested 100000 deep; at most 64 are accepted"],
    ),
    # numbers and nesting past what Python's own parsers take (int digits, recursion)
    "camera width of 5000 digits": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_scene_text(f, lambda text: text.replace('"width": 96', '"width": ' + "9" * 5000)),
        [],
        ["{data}/scene.json: line ", ": a number with 5000 digits; at most 40 are accepted"],
    ),
    "render: camera width of 5000 digits": (
        "render",
        "mitsuba",
        lambda f: edit_scene_text(f, lambda text: text.replace('"width": 96', '"width": ' + "9" * 5000)),
        [],
        ["{data}/scene.json: line ", ": a number with 5000 digits"],
    ),
    "run.json pixel size of 5000 digits": (
        "report",
        "reconstruction",
        lambda f: edit_run_text(f, lambda text: text.replace('"pixel_size": 1.0', '"pixel_size": ' + "9" * 5000)),
        [],
        ["{data}/run.json: line ", ": a number with 5000 digits"],
    ),
    "run.json nested deeply": (
        "report",
        "reconstruction",
        lambda f: (f / "run.json").write_text('{"format": "irtps.run/1", "x": ' + "[" * 50_000 + "]" * 50_000 + "}"),
        [],
        ["{data}/run.json: arrays and objects nested 50001 deep; at most 64 are accepted"],
    ),
    "--exclude-images of 5000 digits": (
        "reconstruct",
        "ball",
        None,
        ["--exclude-images", "9" * 5000],
        ["--exclude-images: an integer with 5000 digits; at most 40 are accepted"],
    ),
    "--exclude-images out of range": (
        "reconstruct",
        "ball",
        None,
        ["--exclude-images", "200-300"],
        ["--exclude-images: {data} has no image numbered 200 to 300"],
    ),
    "table: --exclude-images of 5000 digits": (
        "table",
        "ball",
        None,
        ["--exclude-images", "1-" + "9" * 5000],
        ["--exclude-images: an integer with 5000 digits"],
    ),
    "batch: --exclude-images of 5000 digits": (
        "batch",
        "ball",
        None,
        ["--exclude-images", "data=" + "9" * 5000, "--workers", "1"],
        ["--exclude-images: an integer with 5000 digits"],
    ),
    # absurd sizes
    "absurd camera": (
        "render",
        "mitsuba",
        lambda f: ((f / "mask.png").unlink(), edit_scene(f, lambda s: s["camera"].update(width=10**7, height=10**7))),
        [],
        ["{data}/scene.json: camera size 10000000x10000000 exceeds the largest supported image"],
    ),
    "EXR header claiming an absurd size": (
        "reconstruct",
        "mitsuba",
        lambda f: claim_exr_size(f / "images" / "002.exr", 1 << 20, 1 << 20),
        [],
        ["{data}/images/002.exr: size 1048576x1048576 exceeds the largest supported image"],
    ),
    "PNG header claiming an absurd size": (
        "reconstruct",
        "ball",
        lambda f: claim_png_size(ball_image(f, 2), 10_000, 10_000),
        [],
        ["{data}/021.png: corrupt PNG: its header claims 10000x10000 pixels, more than its"],
    ),
    "absurd pixel size": (
        "reconstruct",
        "mitsuba",
        lambda f: edit_scene(f, lambda s: s["camera"].update(pixel_size=1e308)),
        [],
        ["{data}/scene.json: camera.pixel_size 1e+308 is out of range: expected a number from 1e-09 to 1e+09"],
    ),
    "absurd base height": (
        "reconstruct",
        "mitsuba",
        None,
        ["--base-height", "1e308"],
        ["--base-height: 1e+308 is out of range for this data set: expected at most 1e+06 pixel sizes"],
    ),
    "absurd synthetic size": (
        "synth",
        None,
        None,
        ["cap", "--size", "1000000"],
        ["--size: 1000000 is out of range: expected an integer from 8 to 11585"],
    ),
    "no samples": (
        "render",
        "mitsuba",
        None,
        ["--samples", "0"],
        ["--samples: 0 is out of range: expected an integer from 1 to 1048576"],
    ),
    "saturation not a number": (
        "reconstruct",
        "mitsuba",
        None,
        ["--saturation", "nan"],
        ["--saturation: nan is not a finite number above 0"],
    ),
    # unwritable or dangerous output folders
    "output under a file": (
        "reconstruct",
        "mitsuba",
        None,
        ["--out", out_under_a_file],
        ["--out {tmp}/blocker/out: cannot be made: {tmp}/blocker is not a folder"],
    ),
    "output is the input": (
        "reconstruct",
        "mitsuba",
        None,
        ["--out", lambda tmp: tmp / "data"],
        ["--out {tmp}/data: is the input {tmp}/data; writing there would delete it"],
    ),
    "output holds the input": (
        "render",
        "mitsuba",
        None,
        ["--out", lambda tmp: tmp],
        ["--out {tmp}: holds the input {tmp}/data; writing there would delete it"],
    ),
}


@pytest.fixture(scope="module")
def reconstruction(tmp_path_factory):
    out = tmp_path_factory.mktemp("reconstruction") / "ball"
    assert main(["reconstruct", str(BALL), "--out", str(out), "--quiet"]) == 0
    return out


def _prepare(name, tmp_path, reconstruction):
    """The argument list of case `name`, its damaged data folder and its output folder."""
    command, fixture, damage, extra, _ = CASES[name]
    data = tmp_path / ("data" if fixture else "nowhere")
    if fixture:
        source = {"mitsuba": MITSUBA, "ball": BALL, "reconstruction": reconstruction}[fixture]
        shutil.copytree(source, data)
    if damage:
        damage(data)
    extra = [str(value(tmp_path)) if callable(value) else value for value in extra]
    out = Path(extra[extra.index("--out") + 1]) if "--out" in extra else tmp_path / "out"
    if command == "evaluate":
        return [command, str(data), *extra], data, None
    if command == "synth":
        return [command, *extra, "--out", str(out), "--quiet"], data, out
    outside = [] if "--out" in extra else ["--out", str(out)]
    return [command, str(data), *extra, *outside, "--quiet"], data, out


def test_the_matrix_has_at_least_30_cases():
    assert len(CASES) >= 30


@pytest.mark.parametrize("name", list(CASES))
def test_malformed_input_is_a_clear_error_with_no_output(name, tmp_path, reconstruction, capsys):
    argv, data, out = _prepare(name, tmp_path, reconstruction)
    before = snapshot(tmp_path)
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith("irtps: error: ") and captured.err.count("\n") == 1, captured.err
    assert len(captured.err) < 1000, captured.err[:1000]
    for part in CASES[name][4]:
        assert part.format(data=data, tmp=tmp_path) in captured.err, captured.err
    assert "Traceback" not in captured.err
    assert snapshot(tmp_path) == before  # no output, no temporary folder, inputs untouched
    if out is not None and out not in (data, tmp_path):
        assert not out.exists()


@pytest.mark.parametrize("name", ["truncated EXR", "scene.json nested too deeply", "absurd camera"])
def test_a_real_process_exits_2_without_traceback(name, tmp_path, reconstruction):
    argv, data, out = _prepare(name, tmp_path, reconstruction)
    result = subprocess.run([sys.executable, "-m", "irtps.cli", *argv], capture_output=True, text=True, check=False)
    assert result.returncode == 2
    assert result.stderr.startswith("irtps: error: ")
    assert str(data) in result.stderr
    assert "Traceback" not in result.stderr + result.stdout
    assert not out.exists()


def test_running_out_of_memory_is_a_clear_error(tmp_path, monkeypatch, capsys):
    def allocate(path, **options):
        raise MemoryError("Unable to allocate 90.9 TiB for an array with shape (10000000, 10000000)")

    monkeypatch.setattr(sys.modules["irtps.irt.reconstruct"], "load_dataset", allocate)
    assert main(["reconstruct", str(BALL), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == (
        "irtps: error: not enough memory (Unable to allocate 90.9 TiB for an array with shape (10000000, 10000000))\n"
    )
    assert list(tmp_path.iterdir()) == []


# Inputs accepted on purpose ---------------------------------------------------------


def test_negative_pixels_are_clipped_to_zero_with_a_warning(tmp_path, capsys):
    data, clipped = tmp_path / "data", tmp_path / "clipped"
    shutil.copytree(MITSUBA, data)
    shutil.copytree(MITSUBA, clipped)
    edit_exr(data / "images" / "001.exr", set_pixels(-0.25, (slice(40, 50), slice(40, 50))))
    edit_exr(clipped / "images" / "001.exr", set_pixels(0.0, (slice(40, 50), slice(40, 50))))
    assert main(["reconstruct", str(data), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    warning = capsys.readouterr().err
    assert warning == f"irtps: warning: {data}/images/001.exr: 300 negative values (down to -0.25) clipped to 0\n"
    assert main(["reconstruct", str(clipped), "--out", str(tmp_path / "reference"), "--quiet"]) == 0
    for name in ("normal.exr", "albedo.exr", "height.exr"):
        assert (tmp_path / "out" / name).read_bytes() == (tmp_path / "reference" / name).read_bytes(), name


FULL_FIT = "full fit kept (too few non-coplanar lit observations)"


def test_saturated_png_pixels_are_left_out_and_flagged(tmp_path, reconstruction, capsys):
    data, out = tmp_path / "data", tmp_path / "out"
    shutil.copytree(BALL, data)
    saturate(data)
    assert main(["reconstruct", str(data), "--out", str(out), "--quiet"]) == 0
    assert capsys.readouterr().err == (
        f"irtps: warning: {data}: 216 observations in 6 images are saturated (a channel at or above 1); "
        "left out of the fit\n"
    )
    run = json.loads((out / "run.json").read_text())
    assert run["parameters"]["saturation"] == 1.0
    # 2 unsaturated lights are too few: the 36 pixels of the patch keep the full fit, flagged
    unsaturated = json.loads((reconstruction / "run.json").read_text())
    assert run["flags"][FULL_FIT] == unsaturated["flags"][FULL_FIT] + 36


def test_saturated_png_pixels_are_reported_when_not_robust(tmp_path, capsys):
    data = tmp_path / "data"
    shutil.copytree(BALL, data)
    saturate(data)
    assert main(["reconstruct", str(data), "--out", str(tmp_path / "out"), "--robust", "none", "--quiet"]) == 0
    assert capsys.readouterr().err.endswith(
        "are saturated (a channel at or above 1); used as they are (robust mode none)\n"
    )
