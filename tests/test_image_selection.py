"""Leaving images out of a data set (`irtps.io.image_selection`, ``load_dataset(exclude_images=)``,
``irtps reconstruct --exclude-images``): which images a list names, that they are neither
read nor fitted, and what a run records (IRT-PS's estimates named after their images)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import refused
from irtps import (
    ArgumentError,
    Dataset,
    DatasetError,
    Reconstruction,
    exclude_images,
    load_dataset,
    reconstruct,
    save_dataset,
    save_reconstruction,
)
from irtps.batch.resume import _complete_indirect
from irtps.cli.main import main
from irtps.model.metrics import angular_error_deg
from irtps.io.image_selection import excluded_indices, exclusions_by_name, parse_image_list
from irtps.io.imageio import read_exr
from irtps.render.synth import synthesize

FIXTURE = Path(__file__).resolve().parent / "data" / "diligent_ball_small"
#: The fixture's images, as filenames.txt lists them.
NAMES = ["008.png", "009.png", "021.png", "041.png", "048.png", "052.png", "089.png", "096.png"]


@pytest.fixture
def ball(tmp_path):
    folder = tmp_path / "ball"
    shutil.copytree(FIXTURE, folder)
    return folder


@pytest.mark.parametrize(
    ("images", "dropped"),
    [
        ("8", [0]),
        ("008", [0]),
        ("1-9", [0, 1]),
        ("9 - 41", [1, 2, 3]),
        ("089.png", [6]),
        ("052", [5]),
        ("96,8,96", [0, 7]),
        (" 21 ,048.png", [2, 4]),
    ],
)
def test_numbers_ranges_and_names_select_the_images_they_name(images, dropped):
    assert excluded_indices(NAMES, images, where="ball") == dropped


def test_names_that_are_not_numbers_are_matched_whole():
    names = ["sphere_07.png", "sphere_7.png", "7.png", "left.exr", "right.exr", "top.exr"]
    assert excluded_indices(names, "sphere_07.png,left", where="rig") == [0, 3]
    assert excluded_indices(names, "7", where="rig") == [2]  # a number matches numbered names only


@pytest.mark.parametrize(
    ("images", "problem"),
    [
        ("", "empty item"),
        ("1-3,", "empty item"),
        ("20-1", "runs backwards; write 1-20"),
        ("9" * 5000, "an integer with 5000 digits; at most 40 are accepted"),
    ],
)
def test_a_malformed_list_is_refused_before_any_data_set(images, problem):
    with pytest.raises(ArgumentError, match=problem) as caught:
        parse_image_list(images)
    assert str(caught.value).startswith("exclude_images: ")
    with pytest.raises(ArgumentError, match=problem):
        exclude_images(load_dataset(FIXTURE), images)


def test_only_a_data_set_has_images_to_leave_out():
    with pytest.raises(ArgumentError, match="^dataset: expected a Dataset, got str$"):
        exclude_images("ballPNG", "1-20")


def test_a_list_must_name_images_of_the_data_set_and_leave_three():
    with pytest.raises(
        ArgumentError,
        match=r"^exclude_images: ball has no image numbered 1 to 5 \(the images: 008.png, 009.png, 021.png, ... 096.png\)$",
    ):
        excluded_indices(NAMES, "1-5", where="ball")
    with pytest.raises(ArgumentError, match="^exclude_images: ball has no image named 'missing.png'"):
        excluded_indices(NAMES, "8,missing.png", where="ball")
    with pytest.raises(
        ArgumentError,
        match="^exclude_images: leaving out 6 of the 8 images of ball leaves 2; photometric stereo needs at least 3",
    ):
        excluded_indices(NAMES, "8-52", where="ball")
    with pytest.raises(ArgumentError, match="^exclude_images: an integer with 5000 digits; at most 40 are accepted"):
        excluded_indices(NAMES, "1-" + "9" * 5000, where="ball")


def test_excluded_images_are_not_read(ball):
    (ball / "009.png").write_bytes((ball / "009.png").read_bytes()[:500])  # a file cut short
    with pytest.raises(DatasetError, match="009.png"):
        load_dataset(ball)
    data = load_dataset(ball, exclude_images="9")
    full = load_dataset(FIXTURE)
    assert data.names == tuple(NAMES[:1] + NAMES[2:]) and data.excluded_images == ("009.png",)
    np.testing.assert_array_equal(data.images, np.delete(full.images, 1, axis=0))
    np.testing.assert_array_equal(data.scene.light_directions, np.delete(full.scene.light_directions, 1, axis=0))
    np.testing.assert_array_equal(data.scene.light_irradiance, np.delete(full.scene.light_irradiance, 1, axis=0))


def test_leaving_out_in_memory_or_when_read_gives_the_same_data_set():
    full = load_dataset(FIXTURE)
    read = load_dataset(FIXTURE, exclude_images="21-48")
    left = exclude_images(full, "21-48")
    assert left.names == read.names == ("008.png", "009.png", "052.png", "089.png", "096.png")
    assert left.excluded_images == read.excluded_images == ("021.png", "041.png", "048.png")
    np.testing.assert_array_equal(left.images, read.images)
    assert left.scene == read.scene
    assert full.names == tuple(NAMES)  # the data set it came from is untouched


def test_the_irtps_layout_leaves_out_lights_and_their_direct_images(tmp_path):
    data, _ = synthesize("cap", size=16, lights=7, bounces=0, environment="none")
    save_dataset(data, tmp_path / "cap")
    read = load_dataset(tmp_path / "cap", exclude_images="000.exr,3-4")
    assert read.names == ("001.exr", "002.exr", "005.exr", "006.exr") and read.excluded_images == (
        "000.exr",
        "003.exr",
        "004.exr",
    )
    kept = [1, 2, 5, 6]
    np.testing.assert_allclose(read.images, data.images[kept], rtol=1e-6)
    np.testing.assert_allclose(read.gt.direct, data.gt.direct[kept], rtol=1e-6)
    assert read.scene.lights == tuple(data.scene.lights[k] for k in kept)
    assert exclude_images(read, "1").excluded_images == ("000.exr", "003.exr", "004.exr", "001.exr")


def test_a_data_set_in_memory_is_named_as_it_would_be_saved():
    data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    assert data.names == ("000.exr", "001.exr", "002.exr", "003.exr")
    with pytest.raises(DatasetError, match="image_names has 3 names, expected 4"):
        Dataset(scene=data.scene, images=data.images, mask=data.mask, image_names=("a", "b", "c"))


def test_a_faulty_image_left_out_no_longer_bends_the_normals():
    """An image lit 3x brighter than its light's recorded irradiance (a misfired flash) pulls
    the normals toward its light; without it, the fit of the other images is that of a
    data set that never had it."""
    data = load_dataset(FIXTURE)
    faulty = Dataset(
        scene=data.scene,
        images=data.images.copy(),
        mask=data.mask,
        gt=data.gt,
        source="faulty",
        saturation=None,
        image_names=data.names,
    )
    faulty.images[3] *= 3
    clean = reconstruct(exclude_images(data, "41"), robust="tukey", saturation=None)
    bent = reconstruct(faulty, robust="tukey", saturation=None)
    fixed = reconstruct(exclude_images(faulty, "041.png"), robust="tukey", saturation=None)
    error = {
        name: np.nanmean(angular_error_deg(result.normals, data.gt.normal, data.mask))
        for name, result in (("bent", bent), ("fixed", fixed), ("clean", clean))
    }
    assert error["bent"] > error["fixed"] + 1.0, error
    np.testing.assert_array_equal(fixed.normals, clean.normals)
    assert fixed.excluded_images == ("041.png",) and len(fixed.image_names) == 7


def test_the_command_records_and_prints_the_images_left_out(ball, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["reconstruct", str(ball), "--out", str(out), "--exclude-images", "8-9,096.png"]) == 0
    printed = capsys.readouterr().out
    assert "  5 of 8 images fitted; left out 008.png, 009.png, 096.png\n" in printed
    run = json.loads((out / "run.json").read_text())
    assert run["images"] == NAMES[2:7] and run["excluded_images"] == ["008.png", "009.png", "096.png"]
    assert main(["reconstruct", str(ball), "--out", str(tmp_path / "all")]) == 0
    run = json.loads((tmp_path / "all" / "run.json").read_text())
    assert run["images"] == NAMES and run["excluded_images"] == []


@pytest.mark.parametrize(
    ("images", "message"),
    [
        ("3-1", "--exclude-images: the range '3-1' runs backwards; write 1-3"),
        ("1-7", "--exclude-images: {ball} has no image numbered 1 to 7"),
        ("8-100", "--exclude-images: leaving out 8 of the 8 images of {ball} leaves 0"),
        ("9" * 5000, "--exclude-images: an integer with 5000 digits; at most 40 are accepted"),
    ],
)
def test_the_command_refuses_a_bad_list_and_writes_nothing(ball, tmp_path, capsys, images, message):
    out = tmp_path / "out"
    assert refused(["reconstruct", str(ball), "--out", str(out), "--exclude-images", images], capsys).startswith(
        f"irtps: error: {message.format(ball=ball)}"
    )
    assert not out.exists()


def _with_indirect(data, names):
    """A reconstruction of `data` whose IRT-PS estimate is image k's index k + 1 everywhere."""
    pixels = int(data.mask.sum())
    indirect = np.stack([np.full((pixels, 3), k + 1, np.float32) for k in range(len(names))])
    zeros = np.zeros(data.mask.shape, np.float32)
    return Reconstruction(
        normals=np.dstack([zeros, zeros, zeros + 1]),
        albedo=np.dstack([zeros + 0.5] * 3),
        height=zeros,
        mask=data.mask,
        flags=np.zeros(data.mask.shape, np.uint8),
        pixel_size=1.0,
        object_indirect=indirect,
        image_names=tuple(names),
    )


def test_each_indirect_estimate_is_named_after_its_image(tmp_path):
    data = exclude_images(load_dataset(FIXTURE), "9,41")
    save_reconstruction(_with_indirect(data, data.names), tmp_path / "out")
    files = sorted(path.name for path in (tmp_path / "out" / "indirect").iterdir())
    assert files == ["008.exr", "021.exr", "048.exr", "052.exr", "089.exr", "096.exr"]
    assert read_exr(tmp_path / "out" / "indirect" / "021.exr")[data.mask].max() == 2  # the second image fitted
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert _complete_indirect(tmp_path / "out" / "indirect", run["images"])
    assert not _complete_indirect(tmp_path / "out" / "indirect", NAMES)  # not the images of this run


def test_indirect_estimates_are_numbered_where_names_would_not_do(tmp_path):
    data = load_dataset(FIXTURE)
    names = [f"{side}/{k}.png" for k in range(4) for side in ("left", "right")]  # stems repeat
    save_reconstruction(_with_indirect(data, names), tmp_path / "out")
    assert sorted(path.name for path in (tmp_path / "out" / "indirect").iterdir()) == [f"{k:03d}.exr" for k in range(8)]


def test_lists_for_many_data_sets_go_to_every_one_or_to_the_one_named():
    names = ["ballPNG", "bearPNG", "rig", "rig=old"]
    assert exclusions_by_name([], names) == dict.fromkeys(names)
    assert exclusions_by_name(["96", "bearPNG=1-20", "bearPNG=37"], names) == {
        "ballPNG": "96",
        "bearPNG": "96,1-20,37",
        "rig": "96",
        "rig=old": "96",
    }
    # A name with "=" in it: the longest name the entry starts with.
    assert exclusions_by_name(["rig=old=3", "rig=4"], names) == {
        "ballPNG": None,
        "bearPNG": None,
        "rig": "4",
        "rig=old": "3",
    }


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ("bear=1-20", "exclude_images: 'bear=1-20' names no data set (the data sets: ballPNG, bearPNG)"),
        ("bearPNG=5-1", "exclude_images: the range '5-1' runs backwards; write 1-5"),
        ("bearPNG=", "exclude_images: '' has an empty item"),
    ],
)
def test_a_list_for_a_data_set_that_is_not_there_or_malformed_is_refused(entry, message):
    with pytest.raises(ArgumentError) as caught:
        exclusions_by_name([entry], ["ballPNG", "bearPNG"])
    assert str(caught.value).startswith(message)


def test_table_leaves_out_the_images_named_for_each_data_set(ball, tmp_path, capsys):
    other = shutil.copytree(ball, tmp_path / "other")
    out = tmp_path / "table"
    argv = [
        "table",
        str(ball),
        str(other),
        "--out",
        str(out),
        "--bounces",
        "1",
        "--iterations",
        "1",
        "--samples",
        "4",
        "--no-paper",
        "--quiet",
    ]
    assert main([*argv, "--exclude-images", "96", "--exclude-images", "other=8-9"]) == 0
    printed = capsys.readouterr().out
    table = json.loads((out / "table.json").read_text())
    assert table["excluded_images"] == {"ball": ["096.png"], "other": ["008.png", "009.png", "096.png"]}
    assert (
        "ball: 7 of 8 images fitted; left out 096.png\nother: 5 of 8 images fitted; left out 008.png, 009.png, 096.png\n"
        in printed
    )
    assert (out / "table.md").read_text() in printed
    # Each column is the reconstruction of the data set without those images.
    expected = reconstruct(load_dataset(other, exclude_images="8-9,96"), method="ps")
    truth = load_dataset(other).gt
    error = float(np.nanmean(angular_error_deg(expected.normals, truth.normal, expected.mask)))
    assert table["datasets"]["other"]["PS"]["normal_mean_angular_deg"] == pytest.approx(error)
    assert table["datasets"]["ball"]["PS"]["normal_mean_angular_deg"] != pytest.approx(error)
    assert "names no data set" in refused([*argv[:5], "--exclude-images", "bal=1"], capsys)
