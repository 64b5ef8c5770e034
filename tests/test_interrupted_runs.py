"""Interrupted runs, through the ``irtps`` command as a user would: Ctrl-C, SIGTERM or a
full disk while the outputs are written leave the previous output as it was, and no
partial output."""

import signal
import subprocess
import sys
from pathlib import Path

import pytest
from irtps import DatasetError, _core
from irtps.cli.main import main

from cli_helpers import interruptible, snapshot

DATA = Path(__file__).parent / "data"
MITSUBA = DATA / "mitsuba_small" / "cap_cornell"  # 96x96, 3 lights, floor and Cornell box
BALL = DATA / "diligent_ball_small"  # DiLiGenT layout, 48x44, 8 lights, 16-bit PNG


EARLIER_RUN = '{"format": "irtps.run/1", "earlier": true}'


@pytest.fixture
def previous_output(tmp_path):
    """An output folder from an earlier run, which a failed run must leave as it is."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text(EARLIER_RUN)
    return out


def _fail_on_third_exr(monkeypatch, error):
    real, calls = _core.write_exr, []

    def write_exr(path, array, compression="zip"):
        calls.append(path)
        if len(calls) == 3:
            raise error
        real(path, array, compression)

    monkeypatch.setattr(_core, "write_exr", write_exr)
    return calls


def test_ctrl_c_while_writing_leaves_the_previous_output(tmp_path, previous_output, monkeypatch, capsys):
    calls = _fail_on_third_exr(monkeypatch, KeyboardInterrupt())
    assert main(["reconstruct", str(BALL), "--out", str(previous_output), "--quiet"]) == 130
    assert len(calls) == 3 and calls[0].startswith(str(tmp_path / ".out.tmp-"))
    assert capsys.readouterr().err == "irtps: interrupted; no partial output was left\n"
    assert snapshot(tmp_path) == {"out/run.json": EARLIER_RUN.encode()}


def test_a_full_disk_while_writing_leaves_the_previous_output(tmp_path, previous_output, monkeypatch, capsys):
    full = DatasetError(
        "out/normal.exr: could not write OpenEXR (No space left on device (os error 28))"
    )  # as the core says it
    calls = _fail_on_third_exr(monkeypatch, full)
    assert main(["reconstruct", str(BALL), "--out", str(previous_output), "--quiet"]) == 2
    assert len(calls) == 3
    assert capsys.readouterr().err == f"irtps: error: {full}\n"
    assert snapshot(tmp_path) == {"out/run.json": EARLIER_RUN.encode()}


@pytest.mark.parametrize("signum, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_killed_process_leaves_the_previous_output(tmp_path, previous_output, signum, status):
    command = [
        sys.executable,
        "-m",
        "irtps.cli",
        "render",
        str(MITSUBA),
        "--out",
        str(previous_output),
        "--samples",
        "8192",
    ]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=interruptible)
    assert process.stderr.read(1)  # the progress bar has started: rendering is under way
    process.send_signal(signum)
    _, err = process.communicate(timeout=120)
    assert process.returncode == status
    assert b"irtps: interrupted; no partial output was left\n" in err
    assert b"Traceback" not in err
    assert snapshot(tmp_path) == {"out/run.json": EARLIER_RUN.encode()}
