"""Helpers shared by the tests that run the ``irtps`` command as a user would."""

import os
import signal
from pathlib import Path

from irtps import _core
from irtps.cli.main import main


def refused(argv, capsys) -> str:
    """Run the command; check exit status 2, nothing on stdout and one clean error line on
    stderr (no traceback); return that line."""
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith("irtps: error: ") and captured.err.count("\n") == 1, captured.err
    assert "Traceback" not in captured.err
    return captured.err


def saturate(folder, images=6):
    """Set a 6x6 patch of the object to the PNG maximum in the first `images` images of a
    DiLiGenT-layout data set (216 saturated observations for 6 images)."""
    for name in (folder / "filenames.txt").read_text().split()[:images]:
        image, bits = _core.read_png(str(folder / name))
        image[20:26, 20:26] = 1.0
        _core.write_png(str(folder / name), image, bits)


def interruptible() -> None:
    """In a child process before it runs the command: Ctrl-C (SIGINT) back to its default.
    A shell starts background jobs with SIGINT ignored (a CI script launched with ``&``),
    a program keeps an ignored signal ignored, and the tests that press Ctrl-C would then
    see the command run on."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def tree(root) -> dict:
    """Every file's bytes and every link's target under `root` (links not followed): what a
    run must leave as it was."""
    state = {}
    for folder, folders, files in os.walk(root):
        for name in folders + files:
            path = Path(folder) / name
            key = str(path.relative_to(root))
            if path.is_symlink():
                state[key] = ("link", os.readlink(path))
            elif path.is_file():
                state[key] = ("file", path.read_bytes())
            else:
                state[key] = ("folder", None)
    return state


def snapshot(folder):
    """Every file under `folder`, by its relative path, with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}
