"""Batch runs on a local cluster of worker processes that lose workers, run as the command
in this process: a worker killed (SIGKILL) in the middle of a data set costs nothing but
time, and a data set that kills every worker that runs it fails alone.

The worker processes preload this file (`dask_setup`), which makes the task of a data set
named ``held`` wait in the middle until the test releases it, and that of one named
``poison`` kill its own worker once released: the kills are real, at a known point of the
task, and come once the client has received the results of the other data sets (Dask
counts a worker's death against every task the worker holds, a finished one whose result
has not reached the scheduler included)."""

import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

import pytest

import irtps.batch.run
import irtps.batch.task
from irtps.cli.main import main
from irtps.io.dataset_writer import save_dataset
from irtps.render.synth import synthesize

distributed = pytest.importorskip("distributed")
pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="kills worker processes with SIGKILL")

FLAGS = "IRTPS_TEST_BATCH_FLAGS"  # the folder through which the test and the hooked tasks talk
TIMEOUT = 60.0


def dask_setup(worker) -> None:
    """Hook the reconstructions of a worker process (a Dask preload) when `FLAGS` is set:
    ``held`` writes ``held-by-PID`` into the flags folder, then waits for ``release``;
    ``poison`` waits for ``release``, then kills its worker process."""
    flags = os.environ.get(FLAGS)
    if flags is None:
        return
    real = irtps.batch.task.load_and_reconstruct

    def load_and_reconstruct(source, **options):
        name = Path(source).name
        if name == "held":
            (Path(flags) / f"held-by-{os.getpid()}").touch()
        if name in ("held", "poison"):
            deadline = time.monotonic() + TIMEOUT
            while not (Path(flags) / "release").exists() and time.monotonic() < deadline:
                time.sleep(0.02)
        if name == "poison":
            os.kill(os.getpid(), signal.SIGKILL)
        return real(source, **options)

    irtps.batch.task.load_and_reconstruct = load_and_reconstruct


@pytest.fixture
def flags(tmp_path, monkeypatch):
    """The flags folder, and the local clusters of `irtps batch` with workers that preload this file."""
    folder = tmp_path / "flags"
    folder.mkdir()
    monkeypatch.setenv(FLAGS, str(folder))
    real = distributed.LocalCluster
    monkeypatch.setattr(
        distributed,
        "LocalCluster",
        lambda *args, preload=(), **kwargs: real(*args, preload=[*preload, __file__], **kwargs),
    )
    return folder


@pytest.fixture
def received(monkeypatch):
    """A function that waits until the client has received the results of the named data sets."""
    names, arrived = [], threading.Condition()
    real = irtps.batch.run._result_of

    def recording(future, name, source):
        outcome = real(future, name, source)
        with arrived:
            names.append(name)
            arrived.notify_all()
        return outcome

    monkeypatch.setattr(irtps.batch.run, "_result_of", recording)

    def wait_for(*expected):
        with arrived:
            if not arrived.wait_for(lambda: set(expected) <= set(names), timeout=TIMEOUT):
                raise TimeoutError(f"no result for {expected} in {TIMEOUT} s")

    return wait_for


def _in_background(function):
    """Run ``function`` in a thread (the command runs in the main thread, which handles signals)."""
    thread = threading.Thread(target=function)
    thread.start()
    return thread


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Tiny data sets (classic PS takes milliseconds) named as the hooks expect."""
    folder = tmp_path_factory.mktemp("data")
    dataset, _ = synthesize("cap", size=8, lights=6, bounces=0, environment="none")
    for name in ("cap", "held", "poison", "ball"):
        save_dataset(dataset, folder / name)
    return folder


def _wait_for(found):
    deadline = time.monotonic() + TIMEOUT
    while not (result := found()):
        if time.monotonic() > deadline:
            raise TimeoutError("the hooked task did not start")
        time.sleep(0.02)
    return result


def _summary(out: Path) -> dict:
    return {entry["name"]: entry for entry in json.loads((out / "batch.json").read_text())["datasets"]}


def test_a_worker_killed_in_the_middle_of_a_data_set_loses_nothing(data, flags, received, tmp_path, capsys):
    killed = []

    def kill_the_first_holder_then_release():
        try:
            first = _wait_for(lambda: sorted(flags.glob("held-by-*")))[0]
            received("cap", "ball")
            killed.append(int(first.name.removeprefix("held-by-")))
            os.kill(killed[0], signal.SIGKILL)
            _wait_for(lambda: [path for path in flags.glob("held-by-*") if path != first])  # running again
        finally:
            (flags / "release").touch()

    controller = _in_background(kill_the_first_holder_then_release)
    out = tmp_path / "out"
    status = main(
        ["batch", str(data / "cap"), str(data / "ball"), str(data / "held"), "--out", str(out), "--workers", "2"]
    )
    controller.join()
    printed = capsys.readouterr().out
    assert status == 0 and len(killed) == 1
    summary = _summary(out)
    assert {name: (entry["status"], entry["lost_workers"]) for name, entry in summary.items()} == {
        "cap": ("ok", 0),
        "held": ("ok", 1),
        "ball": ("ok", 0),
    }
    assert (
        summary["held"]["metrics"] == summary["cap"]["metrics"] == summary["ball"]["metrics"]
    )  # the same data set thrice
    assert summary["held"]["metrics"]["normal_mean_angular_deg"] < 20
    held_by = sorted(int(path.name.removeprefix("held-by-")) for path in flags.glob("held-by-*"))
    assert len(held_by) == 2 and killed[0] in held_by  # ran twice, in two processes
    assert "| held | ok (1 worker lost) |" in printed and "3 data sets reconstructed" in printed
    assert sorted(path.name for path in out.iterdir()) == [
        "ball",
        "batch.json",
        "batch.md",
        "cap",
        "held",
    ]  # no leftover of the killed task
    assert json.loads((out / "held" / "run.json").read_text())["source"] == str(data / "held")


def test_a_data_set_that_kills_every_worker_fails_alone(data, flags, received, tmp_path, capsys):
    def release_once_the_others_are_back():
        try:
            received("cap", "ball")
        finally:
            (flags / "release").touch()

    controller = _in_background(release_once_the_others_are_back)
    out = tmp_path / "out"
    # One worker, which starts the data sets in the order given: the poison waits for cap
    # and ball, then kills the worker each time it runs.
    status = main(
        [
            "batch",
            str(data / "cap"),
            str(data / "ball"),
            str(data / "poison"),
            "--out",
            str(out),
            "--workers",
            "1",
            "--quiet",
        ]
    )
    controller.join()
    assert status == 2
    summary = _summary(out)
    assert {name: (entry["status"], entry["lost_workers"]) for name, entry in summary.items()} == {
        "cap": ("ok", 0),
        "ball": ("ok", 0),
        "poison": ("failed", 4),
    }
    assert summary["poison"]["error"] == (
        "KilledWorker: each of the 4 workers that ran it died (killed, e.g. out of memory); Dask gave up on it (distributed.scheduler.allowed-failures = 3)"
    )
    assert "| poison | failed (4 workers lost) |" in capsys.readouterr().out
    assert sorted(path.name for path in out.iterdir()) == ["ball", "batch.json", "batch.md", "cap"]


def test_data_sets_waiting_for_a_worker_are_not_charged_with_its_deaths(data, flags, tmp_path):
    (flags / "release").touch()  # the poison kills its worker as soon as it runs
    out = tmp_path / "out"
    # More data sets than twice the worker threads: the scheduler holds back those that wait
    # (but cap, sent to the worker with the poison before there were three, may be charged
    # with the first death; with Dask's default worker saturation, it was charged with all four).
    status = main(
        [
            "batch",
            str(data / "poison"),
            str(data / "cap"),
            str(data / "ball"),
            "--out",
            str(out),
            "--workers",
            "1",
            "--quiet",
        ]
    )
    assert status == 2
    summary = _summary(out)
    assert {name: entry["status"] for name, entry in summary.items()} == {"poison": "failed", "cap": "ok", "ball": "ok"}
    assert (summary["poison"]["lost_workers"], summary["ball"]["lost_workers"]) == (4, 0) and summary["cap"][
        "lost_workers"
    ] <= 1
