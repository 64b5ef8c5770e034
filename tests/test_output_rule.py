"""Where --out may go, for every command that writes: never onto, into or around an input.

Each refused case must end with exit status 2 and one line ``irtps: error: --out ...``
with no traceback, and leave every file and link of the test's folder as it was. The
property test draws --out paths around a data set (the data set itself, inside it, above
it, beside it, through symbolic links to it or out of it) for every writing command, and
checks both ways: the data set is never changed, and exactly the paths that overlap an
input (as the system resolves them, or as the name that would be replaced) are refused.
"""

import json
import os
import random
import shutil
import socket
import stat
from pathlib import Path

import pytest

from irtps.batch.cluster import local_cluster
from irtps.cli.main import main

from cli_helpers import refused, tree as _tree

DATA = Path(__file__).parent / "data"
BALL = DATA / "diligent_ball_small"  # DiLiGenT layout, 48x44, 8 lights, with Normal_gt.mat
MITSUBA = DATA / "mitsuba_small" / "cap_cornell"  # contract layout with gt/, 96x96, 3 lights


@pytest.fixture(scope="module")
def scheduler():
    with local_cluster(1, processes=False) as client:
        yield client.scheduler.address


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A reconstruction of BALL, for report."""
    out = tmp_path_factory.mktemp("run") / "ball_run"
    assert main(["reconstruct", str(BALL), "--out", str(out), "--quiet"]) == 0
    return out


def _argv(command, data, out, scheduler, run):
    """The arguments of a quick run of `command` on data set `data` writing to `out`."""
    quick_table = ["--bounces", "1", "--iterations", "0", "--samples", "1", "--no-paper"]
    return {
        "reconstruct": ["reconstruct", str(data), "--out", str(out)],
        "render": ["render", str(data), "--out", str(out), "--bounces", "0", "--samples", "1"],
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
        ],
        "table": ["table", str(data), "--out", str(out), *quick_table],
        "report": ["report", str(run), "--truth", str(data), "--out", str(out)],
        "batch": ["batch", str(data), "--out", str(out), "--scheduler", scheduler],
        "demo": ["demo", "--out", str(out), "--size", "8", *quick_table],
    }[command] + ["--quiet"]


#: The data set each command reads (None: it reads none).
SOURCE = {
    "reconstruct": BALL,
    "render": MITSUBA,
    "synth": None,
    "table": BALL,
    "report": BALL,
    "batch": BALL,
    "demo": None,
}


def _refused(argv, capsys):
    err = refused(argv, capsys)
    assert err.startswith("irtps: error: --out "), err
    return err


# The cases, for every command that reads a data set -------------------------


#: For each command that reads a data set: one, and a part of it that --out must not replace.
INSIDE = {
    "reconstruct": (MITSUBA, "images"),  # the captured images
    "render": (MITSUBA, "gt"),  # the ground truth
    "table": (BALL, "Normal_gt.mat"),
    "report": (BALL, "sub"),
    "batch": (BALL, "sub"),
}


@pytest.mark.parametrize("command", list(INSIDE))
def test_out_inside_equal_to_or_holding_the_input_is_refused(command, tmp_path, scheduler, run, capsys):
    source, part = INSIDE[command]
    data = shutil.copytree(source, tmp_path / "data")
    (data / "sub").mkdir()
    before = _tree(tmp_path)
    for out, relation in ((data / part, "lies inside"), (data, "is"), (tmp_path, "holds")):
        err = _refused(_argv(command, data, out, scheduler, run), capsys)
        assert f"--out {out}: {relation} the input {data}" in err, err
        assert _tree(tmp_path) == before
    _refused([*_argv(command, data, data, scheduler, run), "--force"], capsys)  # --force never allows an input
    assert _tree(tmp_path) == before


def test_reconstruct_out_naming_the_scene_file_is_refused(tmp_path, capsys):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    before = _tree(tmp_path)
    err = _refused(["reconstruct", str(data), "--out", str(data / "scene.json"), "--quiet"], capsys)
    assert f"lies inside the input {data}" in err
    assert _tree(tmp_path) == before


def test_batch_out_holding_a_data_set_is_refused(tmp_path, scheduler, capsys):
    data = shutil.copytree(BALL, tmp_path / "runs" / "x")
    before = _tree(tmp_path)
    err = _refused(_argv("batch", data, tmp_path / "runs", scheduler, None), capsys)
    assert f"--out {tmp_path / 'runs'}: holds the input {data}" in err
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("command", list(SOURCE))
def test_an_existing_file_is_replaced_only_with_force(command, tmp_path, scheduler, run, capsys):
    data = shutil.copytree(SOURCE[command] or BALL, tmp_path / "data")
    out = tmp_path / "notes.txt"
    out.write_text("the user's notes")
    before = _tree(tmp_path)
    err = _refused(_argv(command, data, out, scheduler, run), capsys)
    assert "is an existing file; writing there would replace it: choose another path, or pass --force" in err
    assert _tree(tmp_path) == before
    assert main([*_argv(command, data, out, scheduler, run), "--force"]) == 0
    assert out.is_dir()


@pytest.mark.parametrize("command", list(SOURCE))
def test_a_folder_irtps_did_not_write_is_replaced_only_with_force(command, tmp_path, scheduler, run, capsys):
    data = shutil.copytree(SOURCE[command] or BALL, tmp_path / "data")
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "chapter1.tex").write_text("the user's work")
    before = _tree(tmp_path)
    err = _refused(_argv(command, data, out, scheduler, run), capsys)
    assert "is a folder with content that irtps did not write" in err and "pass --force" in err
    assert _tree(tmp_path) == before


def test_a_data_set_is_replaced_only_if_irtps_rendered_it(tmp_path, capsys):
    quick = ["--size", "8", "--lights", "3", "--bounces", "1", "--samples", "1", "--quiet"]
    assert main(["synth", "cap", "--out", str(tmp_path / "mine"), *quick]) == 0
    assert main(["synth", "relief", "--out", str(tmp_path / "mine"), *quick]) == 0  # its own output: replaced
    assert (
        main(
            [
                "render",
                str(tmp_path / "mine"),
                "--out",
                str(tmp_path / "mine2"),
                "--bounces",
                "0",
                "--samples",
                "1",
                "--quiet",
            ]
        )
        == 0
    )
    record = json.loads((tmp_path / "mine2" / "gt" / "rendering.json").read_text())
    assert record["command"] == "render" and record["source"] == str(tmp_path / "mine") and record["samples"] == 1
    captured = shutil.copytree(BALL, tmp_path / "captured")  # DiLiGenT layout
    elsewhere = shutil.copytree(MITSUBA, tmp_path / "mitsuba")  # rendered elsewhere, with gt/direct/
    contract = shutil.copytree(MITSUBA, tmp_path / "contract")  # captured, contract layout: no gt/direct
    shutil.rmtree(contract / "gt")
    before = _tree(tmp_path)
    for out in (captured, elsewhere, contract):
        err = _refused(["synth", "cap", "--out", str(out), *quick], capsys)
        assert "is a folder with content that irtps did not write" in err
        _refused(["render", str(tmp_path / "mine"), "--out", str(out), "--quiet"], capsys)
    assert _tree(tmp_path) == before


def test_a_symlink_loop_as_out_is_named(tmp_path, capsys):
    (tmp_path / "loop").symlink_to("loop")
    for out in (tmp_path / "loop", tmp_path / "loop" / "deeper"):
        err = _refused(["reconstruct", str(BALL), "--out", str(out), "--quiet"], capsys)
        assert f"--out {out}: is, or goes through, a symbolic-link loop" in err


@pytest.mark.parametrize("kind", ["fifo", "socket"])
def test_a_fifo_or_socket_as_out_is_never_replaced_even_with_force(kind, tmp_path, capsys):
    out = tmp_path / kind
    if kind == "fifo":
        os.mkfifo(out)
    else:
        listening = socket.socket(socket.AF_UNIX)
        listening.bind(str(out))
    for force in ([], ["--force"]):
        err = _refused(["reconstruct", str(BALL), "--out", str(out), "--quiet", *force], capsys)
        assert f"--out {out}: is a {'FIFO (named pipe)' if kind == 'fifo' else 'socket'}, not a folder" in err
        assert not stat.S_ISDIR(os.lstat(out).st_mode) and os.listdir(tmp_path) == [kind]


def test_a_newline_in_out_stays_on_one_line(tmp_path, capsys):
    data = shutil.copytree(BALL, tmp_path / "da\nta")
    err = _refused(["reconstruct", str(data), "--out", str(data / "out"), "--quiet"], capsys)
    assert "da\\nta/out: lies inside the input" in err


def test_rerunning_into_its_own_output_replaces_it(tmp_path):
    out = tmp_path / "out"
    for _ in range(2):
        assert main(["reconstruct", str(BALL), "--out", str(out), "--quiet"]) == 0
    assert main(["report", str(out), "--quiet"]) == 0
    assert main(["report", str(out), "--quiet"]) == 0  # out/report: inside the run, but no file report reads


# The property test --------------------------------------------------------------------


def _layout(root, source):
    """A data set with a folder and a link of the user's inside, and links around it."""
    data = shutil.copytree(source, root / "data")
    (data / "notes").mkdir()
    (root / "elsewhere").mkdir()
    (data / "to_elsewhere").symlink_to(root / "elsewhere")  # a link in the data set, out of it
    (root / "to_data").symlink_to(data)
    (root / "to_root").symlink_to(root)
    return data


#: Starting points of a drawn --out, relative to the test's folder, and what may follow.
STARTS = ["data", "data/notes", "data/to_elsewhere", "to_data", "to_root", "to_root/data", ".", "elsewhere", "sibling"]
TAILS = ["", "out", "out/deeper", "notes", "../out", "../data", "to_elsewhere/../out"]


def _draw(rng):
    start, tail = rng.choice(STARTS), rng.choice(TAILS)
    text = start if not tail else f"{start}/{tail}"
    return None if text.rstrip("/").endswith("..") or text == "." else text


def _expected_refusal(root, relative, data, reads_data):
    """Whether the rule refuses --out root/relative, worked out with pathlib."""
    out = root / relative
    targets = [out.resolve(), out.parent.resolve() / out.name]
    inputs = [data.resolve()] if reads_data else []
    if any(t == i or t.is_relative_to(i) or i.is_relative_to(t) for t in targets for i in inputs):
        return True
    if out.exists() and not out.is_dir():
        return True
    if out.is_dir() and any(out.iterdir()):  # no existing folder of the layout is an output of irtps
        return True
    return False


@pytest.mark.parametrize("command", list(SOURCE))
def test_random_out_paths_never_change_the_data_set_and_only_overlaps_are_refused(
    command, tmp_path, scheduler, run, capsys
):
    rng = random.Random(f"out paths for {command}")
    drawn = {path for path in (_draw(rng) for _ in range(200)) if path is not None}
    cases = sorted(drawn)[:: max(1, len(drawn) // 14)]  # about 14 paths, spread over the kinds
    refused_count = 0
    for index, relative in enumerate(cases):
        root = tmp_path / f"case{index}"
        root.mkdir()
        data = _layout(root, SOURCE[command] or BALL)
        expected = _expected_refusal(root, relative, data, SOURCE[command] is not None)
        before = _tree(data)
        everything = _tree(root)
        status = main(_argv(command, data, root / relative, scheduler, run))
        err = capsys.readouterr().err
        assert status == (2 if expected else 0), (relative, err)
        after = _tree(data)  # the data set's own entries: links in it not followed
        if SOURCE[command] is not None:
            assert after == before, relative
        else:
            assert before.items() <= after.items(), relative  # not an input: new entries only
        if expected:
            refused_count += 1
            assert err.startswith("irtps: error: --out ") and "Traceback" not in err, err
            assert _tree(root) == everything, relative  # nothing written anywhere
    assert 0 < refused_count < len(cases)  # both kinds drawn
