"""Batch runs on a local cluster of worker processes, run as a real command: an interrupted
batch ends with one line and leaves no process and no partial output; the warnings of
the workers are printed like those of a local run."""

import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from irtps.io.dataset_writer import save_dataset
from irtps.render.synth import synthesize

from cli_helpers import interruptible, saturate

pytest.importorskip("distributed")
pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the process table in /proc")

DATA = Path(__file__).parent / "data"
INTERRUPTED = "irtps: interrupted; no partial output was left"
TINY_KEPT_CLASSIC_PS = re.compile(r"irtps: warning: tiny: IRT-PS: [^\n]*the result is classic photometric stereo's")


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    """A tiny data set (a fraction of a second with --samples 2048) and a small one that
    takes many seconds with --samples 2048 (a 32x32 cap in a Cornell box)."""
    folder = tmp_path_factory.mktemp("data")
    tiny, _ = synthesize("cap", size=8, lights=6, bounces=0, environment="none")
    save_dataset(tiny, folder / "tiny")
    slow, _ = synthesize("cap", size=32, lights=6, bounces=0)
    save_dataset(slow, folder / "slow")
    return folder


class _Command:
    """``python -m irtps.cli ARGS`` in a session of its own, its stderr read as it comes."""

    def __init__(self, *args):
        command = [sys.executable, "-m", "irtps.cli", *map(str, args)]
        self.process = subprocess.Popen(
            command,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            bufsize=0,
            start_new_session=True,
            preexec_fn=interruptible,
        )
        self._err, self._out, self._lock = [], [], threading.Lock()
        self._readers = [
            threading.Thread(target=self._read, args=(stream, chunks), daemon=True)
            for stream, chunks in ((self.process.stderr, self._err), (self.process.stdout, self._out))
        ]
        for reader in self._readers:
            reader.start()

    def _read(self, stream, chunks):
        while chunk := os.read(stream.fileno(), 65536):
            with self._lock:
                chunks.append(chunk)

    @property
    def err(self) -> str:
        with self._lock:
            return b"".join(self._err).decode()

    def wait_until(self, done) -> None:
        """Until `done()` holds, the command still running (with a guard against hanging if
        it never does)."""
        deadline = time.monotonic() + 300
        while not done():
            assert self.process.poll() is None, self.err
            assert time.monotonic() < deadline, self.err
            time.sleep(0.05)

    def finish(self) -> tuple[int, str, str]:
        """Its exit status, stdout and stderr, once every process holding them has closed them."""
        status = self.process.wait(timeout=300)
        for reader in self._readers:
            reader.join(timeout=300)
        with self._lock:
            return status, b"".join(self._out).decode(), b"".join(self._err).decode()

    def live_processes(self) -> list[str]:
        """The processes of its session that are still running (not zombies): waits a little
        for the last ones to exit, then lists them."""
        deadline = time.monotonic() + 60
        while (alive := _session_processes(self.process.pid)) and time.monotonic() < deadline:
            time.sleep(0.1)
        return alive


def _session_processes(session: int) -> list[str]:
    alive = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:  # gone meanwhile
            continue
        fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) ": state, ppid, pgrp, session
        if int(fields[3]) == session and fields[0] not in "ZX":
            alive.append(f"{entry.name} {fields[0]} {command}")
    return alive


def _messages(err: str) -> list[str]:
    """The lines of stderr without the progress bar: pieces between carriage returns and
    newlines, blanks (the cleared bar) and the bar's states (``batch: ...``) left out."""
    return [piece.strip() for piece in re.split(r"[\r\n]", err) if piece.strip() and not piece.startswith("batch:")]


@pytest.mark.parametrize(
    "signum, whole_group, status",
    [
        (signal.SIGINT, True, 130),
        (signal.SIGINT, False, 130),
        (signal.SIGTERM, False, 143),
        (signal.SIGTERM, True, 143),
    ],
    ids=[
        "ctrl-c (whole process group)",
        "SIGINT to the command",
        "SIGTERM to the command",
        "SIGTERM to the whole process group",
    ],
)
def test_an_interrupted_batch_prints_one_line_and_leaves_no_worker_and_no_partial_output(
    datasets, tmp_path, signum, whole_group, status
):
    inputs = tmp_path / "in"
    shutil.copytree(datasets / "tiny", inputs / "tiny")
    for name in ("slow", "slow-b", "slow-c"):
        shutil.copytree(datasets / "slow", inputs / name)
    out = tmp_path / "out"
    data = [inputs / "missing", inputs / "tiny", inputs / "slow", inputs / "slow-b", inputs / "slow-c"]
    command = _Command("batch", *data, "--out", out, "--method", "irtps", "--samples", "2048", "--workers", "2")
    # the missing and the tiny data set are done (the tiny one's warning printed and its output
    # in place; the bar may skip its "2/5" when both end within its refresh interval): both
    # workers are on slow ones (seconds each)
    command.wait_until(lambda: TINY_KEPT_CLASSIC_PS.search(command.err) and (out / "tiny").is_dir())
    if whole_group:  # as a terminal does: the workers are signalled too
        os.killpg(command.process.pid, signum)
    else:
        command.process.send_signal(signum)
    returncode, printed, err = command.finish()
    assert returncode == status, err
    assert printed == ""
    assert err.endswith(f"\r{INTERRUPTED}\n")
    # No traceback, no Dask log, no leaked semaphore warning: only the tiny data set's warning
    # (it has no inter-reflection, so IRT-PS keeps classic PS and says so) and the interrupt.
    warning, last = _messages(err)
    assert TINY_KEPT_CLASSIC_PS.fullmatch(warning) and last == INTERRUPTED, err
    assert command.live_processes() == []  # no worker, no resource tracker left running
    # complete output folders only: the tiny one, written before the interrupt, and no temporary
    assert sorted(path.name for path in out.iterdir()) == ["tiny"]
    written = sorted(path.name for path in (out / "tiny").iterdir())
    assert {"normal.exr", "albedo.exr", "height.exr", "mask.png", "run.json"} <= set(written) and not any(
        name.startswith(".") for name in written
    )


def test_a_ctrl_c_while_the_workers_start_is_one_line_too(datasets, tmp_path):
    inputs = tmp_path / "in"
    shutil.copytree(datasets / "slow", inputs / "slow")
    out = tmp_path / "out"
    command = _Command(
        "batch", inputs / "slow", "--out", out, "--method", "irtps", "--samples", "2048", "--workers", "2"
    )
    # the worker processes exist and are importing (a second or more) before they set themselves up
    deadline = time.monotonic() + 300
    while sum("spawn_main" in line for line in _session_processes(command.process.pid)) < 2:
        assert command.process.poll() is None and time.monotonic() < deadline, command.err
        time.sleep(0.01)
    os.killpg(command.process.pid, signal.SIGINT)
    returncode, printed, err = command.finish()
    assert returncode == 130, err
    assert printed == "" and _messages(err) == [INTERRUPTED], err  # no worker's KeyboardInterrupt traceback
    assert command.live_processes() == []
    assert not out.exists() or list(out.iterdir()) == []


def test_the_warnings_of_worker_processes_are_printed_like_a_local_runs(tmp_path):
    data = shutil.copytree(DATA / "diligent_ball_small", tmp_path / "in" / "ball")
    saturate(data)
    out = tmp_path / "out"
    command = _Command("batch", data, "--out", out, "--workers", "1", "--quiet")
    returncode, printed, err = command.finish()
    assert returncode == 0, err
    assert (
        err
        == f"irtps: warning: ball: {data}: 216 observations in 6 images are saturated (a channel at or above 1); left out of the fit\n"
    )
    assert "| ball | ok |" in printed
    assert command.live_processes() == []
