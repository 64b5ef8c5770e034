"""Paths that cannot be read as what they should be, run through the ``irtps`` command.

A directory, a FIFO, a symlink loop or a broken symlink where a data set has a file (an
image, ``mask.png``, ``scene.json``, ``filenames.txt``, ``Normal_gt.mat``, ``gt/*.exr``)
must be named with what it is, not called "missing"; an optional file (``mask.png``,
``gt/``, ``Normal_gt.mat``) that is there in such a form is an error, not "absent", for
``reconstruct`` and ``render`` alike; a data folder that is a symlink loop is named as one.
Each ends with exit status 2 and one line ``irtps: error: PATH: PROBLEM``, no traceback,
no output, the data set unchanged, and no FIFO ever opened (so nothing blocks).
"""

import json
import os
import shutil
import stat
import threading
import time
from pathlib import Path

import pytest
from irtps.batch.cluster import local_cluster
from irtps.cli.main import main
from irtps._shared.paths import file_problem, folder_problem, optional_file, resolve_path

from cli_helpers import refused

DATA = Path(__file__).parent / "data"
MITSUBA = DATA / "mitsuba_small" / "cap_cornell"  # 96x96, 3 lights, gt/, mask.png
BALL = DATA / "diligent_ball_small"  # DiLiGenT layout, 8 lights, 16-bit PNG
BALL_IMAGE_6 = (BALL / "filenames.txt").read_text().split()[5]  # listed on line 6

# What replaces a file, and how the error must describe it.
KINDS = {
    "directory": "a directory, not a file",
    "fifo": "a FIFO (named pipe), not a regular file",
    "symlink loop": "a symlink loop",
    "broken symlink": "a broken symlink (to nowhere.exr)",
}

# (command, fixture, the file replaced, what follows the description in the message)
TARGETS = {
    "image": ("reconstruct", "mitsuba", "images/001.exr", " (scene.json has 3 lights, one image each)"),
    "mask (reconstruct)": ("reconstruct", "mitsuba", "mask.png", ""),
    "mask (render)": ("render", "mitsuba", "mask.png", ""),
    "scene.json (reconstruct)": ("reconstruct", "mitsuba", "scene.json", ""),
    "scene.json (render)": ("render", "mitsuba", "scene.json", ""),
    "true height (render)": ("render", "mitsuba", "gt/height.exr", " (rendering needs the true height and albedo)"),
    "true normals": ("reconstruct", "mitsuba", "gt/normal.exr", ""),
    "direct-light image": ("reconstruct", "mitsuba", "gt/direct/002.exr", " (scene.json has 3 lights, one image each)"),
    "image (table)": ("table", "mitsuba", "images/000.exr", " (scene.json has 3 lights, one image each)"),
    "DiLiGenT filenames.txt": ("reconstruct", "ball", "filenames.txt", " (a DiLiGenT folder needs"),
    "DiLiGenT light_directions.txt": ("reconstruct", "ball", "light_directions.txt", " (a DiLiGenT folder needs"),
    "DiLiGenT image": ("reconstruct", "ball", BALL_IMAGE_6, " (listed on line 6 of filenames.txt)"),
    "DiLiGenT mask": ("reconstruct", "ball", "mask.png", ""),
    "DiLiGenT Normal_gt.mat": ("reconstruct", "ball", "Normal_gt.mat", ""),
}


def _replace(path: Path, kind: str) -> None:
    """Put `kind` at `path` in place of whatever is there."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif os.path.lexists(path):
        path.unlink()
    if kind == "directory":
        path.mkdir()
        (path / "inside.txt").write_text("a folder in place of a file")
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "symlink loop":
        os.symlink(path.name, path)
    elif kind == "broken symlink":
        os.symlink("nowhere.exr", path)
    else:
        raise AssertionError(kind)


def _snapshot(folder: Path) -> dict:
    """Every entry under `folder` without following symlinks or opening FIFOs: its type and
    its bytes (regular files) or target (symlinks)."""
    entries = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            path = Path(root) / name
            mode = os.lstat(path).st_mode
            if stat.S_ISLNK(mode):
                entries[str(path)] = ("link", os.readlink(path))
            elif stat.S_ISREG(mode):
                entries[str(path)] = ("file", path.read_bytes())
            else:
                entries[str(path)] = (stat.S_IFMT(mode),)
    return entries


class _FifoWatch:
    """Notices whether anything opens a FIFO for reading (which would block), and unblocks it."""

    def __init__(self, fifo: Path) -> None:
        self.fifo, self.opened, self._stop = fifo, False, threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def _watch(self) -> None:
        while not self._stop.is_set():
            try:
                descriptor = os.open(self.fifo, os.O_WRONLY | os.O_NONBLOCK)  # succeeds only with a reader
            except OSError:
                time.sleep(0.005)
                continue
            self.opened = True
            os.close(descriptor)  # the reader sees end of file instead of blocking for ever

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def _argv(command: str, data: Path, out: Path) -> list[str]:
    if command == "table":
        return ["table", str(data), "--quiet"]
    return [command, str(data), "--out", str(out), "--quiet"]


@pytest.mark.parametrize("kind", list(KINDS))
@pytest.mark.parametrize("target", list(TARGETS))
def test_a_file_that_is_not_a_regular_file_is_named_for_what_it_is(target, kind, tmp_path, capsys):
    command, fixture, relative, context = TARGETS[target]
    data = shutil.copytree({"mitsuba": MITSUBA, "ball": BALL}[fixture], tmp_path / "data")
    path = data / relative
    _replace(path, kind)
    out = tmp_path / "out"
    before = _snapshot(tmp_path)
    if kind == "fifo":
        with _FifoWatch(path) as watch:
            err = refused(_argv(command, data, out), capsys)
        assert not watch.opened, f"{path} was opened: reading a FIFO blocks"
    else:
        err = refused(_argv(command, data, out), capsys)
    assert f"{path}: {KINDS[kind]}{context}" in err, err
    assert "missing" not in err
    assert _snapshot(tmp_path) == before  # data set untouched, no output, no temporary folder
    assert not out.exists()


@pytest.mark.parametrize("command", ["reconstruct", "render"])
def test_a_mask_that_is_a_folder_is_refused_by_render_and_reconstruct_alike(command, tmp_path, capsys):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    _replace(data / "mask.png", "directory")
    err = refused(_argv(command, data, tmp_path / "out"), capsys)
    assert err == f"irtps: error: {data / 'mask.png'}: a directory, not a file\n"


def test_an_absent_mask_still_means_every_pixel(tmp_path, capsys):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    (data / "mask.png").unlink()
    out = tmp_path / "out"
    assert main(["render", str(data), "--out", str(out), "--bounces", "0", "--samples", "1", "--quiet"]) == 0
    assert main(["reconstruct", str(data), "--out", str(tmp_path / "ps"), "--quiet"]) == 0


def test_a_gt_folder_that_is_a_file_is_an_error_not_absent(tmp_path, capsys):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    shutil.rmtree(data / "gt" / "direct")
    (data / "gt" / "direct").write_text("a file in place of a folder")
    err = refused(_argv("reconstruct", data, tmp_path / "out"), capsys)
    assert f"{data / 'gt' / 'direct'}: not a folder" in err


def test_an_images_folder_that_is_a_symlink_loop(tmp_path, capsys):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    _replace(data / "images", "symlink loop")
    err = refused(_argv("reconstruct", data, tmp_path / "out"), capsys)
    assert f"{data / 'images'}: a symlink loop (scene.json has 3 lights, one image each)" in err


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads every file")
def test_an_unreadable_image_says_permission_denied(tmp_path, capsys):
    data = shutil.copytree(MITSUBA, tmp_path / "data")
    (data / "images" / "001.exr").chmod(0)
    err = refused(_argv("reconstruct", data, tmp_path / "out"), capsys)
    assert f"{data / 'images' / '001.exr'}: not readable (permission denied)" in err


# A data folder that is a symlink loop -------------------------------------------------


@pytest.fixture
def loop(tmp_path):
    path = tmp_path / "loop"
    os.symlink("loop", path)
    return path


@pytest.mark.parametrize("command", ["reconstruct", "render", "table"])
def test_a_data_folder_that_is_a_symlink_loop(command, loop, tmp_path, capsys):
    err = refused(_argv(command, loop, tmp_path / "out"), capsys)
    assert err == f"irtps: error: {loop}: a symlink loop\n"
    assert os.readlink(loop) == "loop" and sorted(p.name for p in tmp_path.iterdir()) == ["loop"]


def test_evaluate_against_a_ground_truth_folder_that_is_a_symlink_loop(loop, tmp_path, capsys):
    reconstruction = tmp_path / "ps"
    assert main(["reconstruct", str(BALL), "--out", str(reconstruction), "--quiet"]) == 0
    capsys.readouterr()
    err = refused(["evaluate", str(reconstruction), "--gt", str(loop)], capsys)
    assert err == f"irtps: error: {loop}: a symlink loop\n"


@pytest.mark.parametrize("kind", ["loop", "fifo", "missing"])
def test_report_of_a_reconstruction_folder_that_is_not_one(kind, tmp_path, capsys):
    path = tmp_path / kind
    if kind == "loop":
        os.symlink(kind, path)
    elif kind == "fifo":
        os.mkfifo(path)
    problem = {"loop": "a symlink loop", "fifo": "not a folder", "missing": "no such reconstruction folder"}[kind]
    assert refused(["report", str(path), "--quiet"], capsys) == f"irtps: error: {path}: {problem}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ([] if kind == "missing" else [kind])


@pytest.fixture(scope="module")
def cluster():
    with local_cluster(1, processes=False) as client:
        yield client


def test_batch_reports_a_data_folder_that_is_a_symlink_loop_as_failed(cluster, loop, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["batch", str(loop), "--out", str(out), "--scheduler", cluster.scheduler.address, "--quiet"]) == 2
    printed = capsys.readouterr()
    assert printed.err == f"irtps: error: 1 of 1 data sets failed (see {out / 'batch.md'})\n"
    assert printed.out == (out / "batch.md").read_text()  # the summary table
    (entry,) = json.loads((out / "batch.json").read_text())["datasets"]
    assert entry["status"] == "failed" and entry["error"] == f"{loop}: a symlink loop"
    assert f"{loop}: a symlink loop" in (out / "batch.md").read_text()


# The helpers themselves ------------------------------------------------------------------


def test_the_helpers_describe_each_kind_of_path(tmp_path):
    for kind, description in KINDS.items():
        path = tmp_path / kind.replace(" ", "_")
        _replace(path, kind)
        assert file_problem(path) == description
    (tmp_path / "file").write_text("x")
    assert file_problem(tmp_path / "file") is None
    assert file_problem(tmp_path / "absent") == "missing"
    assert file_problem(tmp_path / "file" / "below") == "missing"
    assert folder_problem(tmp_path) is None
    assert folder_problem(tmp_path / "file") == "not a folder"
    assert folder_problem(tmp_path / "absent") == "no such data set folder"
    assert folder_problem(tmp_path / "symlink_loop") == "a symlink loop"
    assert folder_problem(tmp_path / "broken_symlink") == "a broken symlink (to nowhere.exr)"
    assert file_problem("/dev/null") == "a device, not a regular file"
    assert file_problem("a\0b") == folder_problem("a\0b") == "not a valid path (it holds a NUL character)"
    assert optional_file(tmp_path / "absent") is False and optional_file(tmp_path / "file") is True
    assert resolve_path(tmp_path / "symlink_loop") == tmp_path / "symlink_loop"
    assert resolve_path(tmp_path / "file") == (tmp_path / "file").resolve()
