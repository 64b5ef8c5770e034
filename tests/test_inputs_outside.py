"""Inputs read from outside the data set folder, and folders that only look like outputs.

A data set's files need not be inside its folder: DiLiGenT's ``filenames.txt`` may list
``../other/009.png`` or an absolute path, and any folder or file of a data set may be a
symbolic link to another place. Every command that writes compares its --out with every
file and folder it reads, as the reader finds them (`irtps.io.dataset_files.dataset_inputs` and its
kin), so that --out can name none of them, with or without --force. And a folder of the
user's that merely holds a file named like one of our records (``index.html``,
``run.json`` ...) is not taken for an output of irtps.
"""

import json
import os
import random
import shutil
import sys
from pathlib import Path

import pytest
import scipy.io

from irtps import _core
from irtps._shared import guarded
from irtps.batch.cluster import local_cluster
from irtps.cli.main import main
from irtps.io.dataset import load_dataset, load_ground_truth, load_scene_object
from irtps.io.dataset_files import dataset_inputs, ground_truth_inputs, scene_object_inputs

from cli_helpers import refused, tree as _tree

DATA = Path(__file__).parent / "data"
BALL = DATA / "diligent_ball_small"  # DiLiGenT layout, 48x44, 8 lights, with Normal_gt.mat
MITSUBA = DATA / "mitsuba_small" / "cap_cornell"  # irtps layout with gt/, 96x96, 3 lights


@pytest.fixture(scope="module")
def scheduler():
    with local_cluster(1, processes=False) as client:
        yield client.scheduler.address


def _listed_outside(root):
    """A DiLiGenT data set whose filenames.txt lists one image as ../other/NAME and one by an
    absolute path, and whose Normal_gt.mat is a link to a file in another folder."""
    data = shutil.copytree(BALL, root / "data")
    names = (data / "filenames.txt").read_text().split()
    other, absolute, truth = root / "other", root / "abs", root / "truth"
    for folder in (other, absolute, truth):
        folder.mkdir()
    shutil.move(data / names[0], other / names[0])
    shutil.move(data / names[1], absolute / names[1])
    names[0], names[1] = f"../other/{names[0]}", str(absolute / names[1])
    (data / "filenames.txt").write_text("\n".join(names) + "\n")
    shutil.move(data / "Normal_gt.mat", truth / "Normal_gt.mat")
    (data / "Normal_gt.mat").symlink_to(truth / "Normal_gt.mat")
    return data, [other, absolute, truth]


def _linked_outside(root):
    """An irtps-layout data set whose images/ and gt/ are symbolic links to folders elsewhere."""
    data = shutil.copytree(MITSUBA, root / "data")
    pictures, truth = root / "pictures", root / "truth"
    shutil.move(data / "images", pictures)
    shutil.move(data / "gt", truth)
    (data / "images").symlink_to(pictures)
    (data / "gt").symlink_to(truth)
    return data, [pictures, truth]


LAYOUTS = {"listed": _listed_outside, "linked": _linked_outside}

#: The commands that read a data set, and the layouts whose outside parts each reads.
READS = {
    "reconstruct": ["listed", "linked"],
    "render": ["linked"],
    "table": ["listed", "linked"],
    "batch": ["listed", "linked"],
    "report": ["listed", "linked"],
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A reconstruction of each layout's data set, for report (whose --truth is the data set)."""
    made = {}
    for kind, layout in LAYOUTS.items():
        root = tmp_path_factory.mktemp(f"run_{kind}")
        data, _ = layout(root)
        assert main(["reconstruct", str(data), "--out", str(root / "run"), "--quiet"]) == 0
        made[kind] = root / "run"
    return made


def _argv(command, data, out, scheduler, run):
    quick_table = ["--bounces", "1", "--iterations", "0", "--samples", "1", "--no-paper"]
    return {
        "reconstruct": ["reconstruct", str(data), "--out", str(out)],
        "render": ["render", str(data), "--out", str(out), "--bounces", "0", "--samples", "1"],
        "table": ["table", str(data), "--out", str(out), *quick_table],
        "report": ["report", str(run), "--truth", str(data), "--out", str(out)],
        "batch": ["batch", str(data), "--out", str(out), "--scheduler", scheduler],
    }[command] + ["--quiet"]


CASES = [(command, kind) for command, kinds in READS.items() for kind in kinds]


@pytest.mark.parametrize(("command", "kind"), CASES)
def test_out_naming_a_folder_read_from_outside_is_refused_even_with_force(
    command, kind, tmp_path, scheduler, runs, capsys
):
    data, outside = LAYOUTS[kind](tmp_path)
    if command in ("render", "report"):
        outside = [folder for folder in outside if folder.name == "truth"]  # they read the ground truth, no image
    before = _tree(tmp_path)
    for folder in outside:
        for force in ([], ["--force"]):
            err = refused([*_argv(command, data, folder, scheduler, runs.get(kind)), *force], capsys)
            assert err.startswith(f"irtps: error: --out {folder}: ") and " the input " in err, err
            assert "--force" not in err, err  # never advised: it would not help
            assert _tree(tmp_path) == before


@pytest.mark.parametrize(("command", "kind"), CASES)
def test_out_around_the_inputs_never_changes_what_is_read(command, kind, tmp_path, scheduler, runs, capsys):
    """The property: --out drawn around every part of a data set reached from outside its
    folder, through links and listed paths, with --force on and off: every file and link
    that was there before is there after, unchanged; a refusal is one line and writes
    nothing anywhere."""
    rng = random.Random(f"outside inputs, {command}, {kind}")
    starts = ["data", "other", "abs", "truth", "pictures", "to_truth", "data/gt", "data/images", "."]
    tails = ["", "out", "../out", "x/..", "Normal_gt.mat", "000.exr", "height.exr"]
    drawn = sorted({f"{rng.choice(starts)}/{rng.choice(tails)}".rstrip("/") for _ in range(60)})
    cases = [(path, rng.random() < 0.5) for path in drawn if not path.endswith("..") and path != "."][::4]
    refusals = 0
    for index, (relative, force) in enumerate(cases):
        root = tmp_path / f"case{index}"
        root.mkdir()
        data, _ = LAYOUTS[kind](root)
        (root / "to_truth").symlink_to(root / "truth")
        listed = {"render": scene_object_inputs, "report": ground_truth_inputs}.get(command, dataset_inputs)(data)
        inputs = [Path(path) for path in _resolved(listed)]
        before = _tree(root)
        read = {
            key for key in before if any(Path(os.path.realpath(root / key)).is_relative_to(path) for path in inputs)
        }
        status = main(
            [*_argv(command, data, root / relative, scheduler, runs.get(kind)), *(["--force"] if force else [])]
        )
        err = capsys.readouterr().err
        after = _tree(root)
        assert {key: before[key] for key in read}.items() <= after.items(), (relative, force, err)
        assert status in (0, 2), err
        if status == 2:
            refusals += 1
            assert err.startswith("irtps: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
            assert after == before, (relative, force)
    assert refusals > 0


# Every file a reader opens is among its listed inputs ----------------------------------


@pytest.fixture
def opened(monkeypatch):
    """The paths opened while the test runs: by Python (open) and by the Rust core (its
    readers are given paths)."""
    paths = []
    for name in ("read_exr", "read_png", "read_images"):
        real = getattr(_core, name)

        def record(first, *rest, real=real):
            paths.extend([first] if isinstance(first, str) else first)
            return real(first, *rest)

        monkeypatch.setattr(_core, name, record)
    real_open = open

    def python_open(file, *args, **kwargs):
        if isinstance(file, (str, os.PathLike)):
            paths.append(os.fspath(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(guarded, "open", python_open, raising=False)
    real_loadmat = scipy.io.loadmat

    def loadmat(file, *args, **kwargs):
        paths.append(os.fspath(file))
        return real_loadmat(file, *args, **kwargs)

    monkeypatch.setattr(scipy.io, "loadmat", loadmat)
    monkeypatch.setattr(sys.modules["irtps.io.imageio"], "open", python_open, raising=False)
    return paths


def _resolved(paths):
    return {os.path.realpath(path) for path in paths}


@pytest.mark.parametrize("kind", list(LAYOUTS))
def test_every_file_a_reader_opens_is_listed_as_its_input(kind, tmp_path, opened):
    data, _ = LAYOUTS[kind](tmp_path)
    load_dataset(data)
    assert opened and _resolved(opened) <= _resolved(dataset_inputs(data))
    opened.clear()
    load_ground_truth(data, (96, 96) if kind == "linked" else (44, 48))
    assert opened and _resolved(opened) <= _resolved(ground_truth_inputs(data))
    if kind == "linked":
        opened.clear()
        load_scene_object(data)
        assert opened and _resolved(opened) <= _resolved(scene_object_inputs(data))


def test_images_left_out_are_not_inputs(tmp_path):
    data, (other, absolute, _) = _listed_outside(tmp_path)
    inputs = _resolved(dataset_inputs(data, exclude_images="8-9"))  # the two images outside
    assert not any(path.startswith(str(other.resolve())) or path.startswith(str(absolute.resolve())) for path in inputs)


# Folders that only look like outputs of irtps ------------------------------------------


#: A user's folder holding a file named like a record of ours, and what else it holds.
DECOYS = {
    "a web site": ("index.html", "<html><head><title>My site</title></head></html>", "photo.jpg"),
    "another tool's run": ("run.json", '{"seed": 3, "lr": 0.001}', "weights.bin"),
    "a run.json of ours in name only": ("run.json", '{"format": "other.run/1"}', "cv.pdf"),
    "a table": ("table.json", "[1, 2]", "notes.txt"),
    "a batch": ("batch.json", '{"format": "irtps.batch/1"', "data.csv"),  # cut short
    "a rendering": ("gt/rendering.json", '{"irtps": "0.1.0"}', "scan.ply"),  # no format
}


@pytest.mark.parametrize("command", ["reconstruct", "synth", "demo", "table", "report", "batch", "render"])
@pytest.mark.parametrize("decoy", list(DECOYS))
def test_a_folder_with_a_record_name_but_not_our_record_is_not_replaced(
    command, decoy, tmp_path, scheduler, runs, capsys
):
    record, text, other = DECOYS[decoy]
    out = tmp_path / "mine"
    (out / record).parent.mkdir(parents=True)
    (out / record).write_text(text)
    (out / other).write_bytes(b"the user's work")
    source = MITSUBA if command == "render" else BALL
    argv = {
        "synth": [
            "synth",
            "cap",
            "--out",
            str(out),
            "--size",
            "8",
            "--lights",
            "3",
            "--bounces",
            "0",
            "--samples",
            "1",
            "--quiet",
        ],
        "demo": [
            "demo",
            "--out",
            str(out),
            "--size",
            "8",
            "--bounces",
            "1",
            "--iterations",
            "0",
            "--samples",
            "1",
            "--no-paper",
            "--quiet",
        ],
        "report": ["report", str(runs["listed"]), "--out", str(out), "--quiet"],
    }.get(command) or _argv(command, source, out, scheduler, None)
    before = _tree(tmp_path)
    err = refused(argv, capsys)
    assert f"--out {out}: is a folder with content that irtps did not write" in err, err
    assert _tree(tmp_path) == before


def test_each_output_carries_its_record_and_is_replaced_without_force(tmp_path, scheduler):
    quick = ["--bounces", "1", "--iterations", "0", "--samples", "1", "--no-paper", "--quiet"]
    commands = {
        "run.json": ["reconstruct", str(BALL), "--out", str(tmp_path / "run"), "--quiet"],
        "table.json": ["table", str(BALL), "--out", str(tmp_path / "table"), *quick],
        "batch.json": ["batch", str(BALL), "--out", str(tmp_path / "batch"), "--scheduler", scheduler, "--quiet"],
        "gt/rendering.json": [
            "synth",
            "cap",
            "--out",
            str(tmp_path / "synth"),
            "--size",
            "8",
            "--lights",
            "3",
            "--bounces",
            "0",
            "--samples",
            "1",
            "--quiet",
        ],
        "index.html": ["report", str(tmp_path / "run"), "--out", str(tmp_path / "report"), "--quiet"],
    }
    formats = {
        "run.json": "irtps.run/1",
        "table.json": "irtps.table/1",
        "batch.json": "irtps.batch/1",
        "gt/rendering.json": "irtps.rendering/1",
    }
    from irtps import __version__

    for record, argv in commands.items():
        for _ in range(2):  # the second run replaces the first's output, without --force
            assert main(argv) == 0, argv
        out = Path(argv[argv.index("--out") + 1])
        if record == "index.html":
            assert '<meta name="irtps-format" content="irtps.report/1">' in (out / record).read_text()
        else:
            stamp = json.loads((out / record).read_text())
            assert (stamp["format"], stamp["irtps"]) == (formats[record], __version__)
