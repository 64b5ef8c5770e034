"""The one rule for every command that writes: where its output may go.

An output folder is written atomically (`irtps._shared.atomic`): built under a hidden name next to
it, then renamed over whatever had the name. So the name must not be, hold, or lie inside
anything the command reads, compared both as the paths resolve through symlinks and as the
name that is replaced (its folder resolved, the name itself not, for a symbolic link
replaced is a path lost); and it must not be something of the user's that is not an output
of irtps: an existing file, or a folder with other content.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from irtps.errors import IrtpsError
from irtps._shared.paths import file_problem, folder_problem
from irtps._shared.records import written_by_irtps

__all__ = ["OutputError", "check_output", "escaped"]

#: What is at an output path that is never replaced, even with ``--force``: a program may be
#: reading or listening there, and a device is the system's (as `_kind` names them).
_NEVER_REPLACED = ("a FIFO", "a socket", "a device")


class OutputError(IrtpsError, ValueError):
    """An output path that would destroy an input or something else of the user's."""


def check_output(out: str | Path, inputs: Iterable[str | Path], *, force: bool = False, option: str = "--out") -> None:
    """Refuse an output path that writing there would lose something by.

    Parameters
    ----------
    out : str or pathlib.Path
        Where the command will write (a folder replaced as a whole).
    inputs : iterable of str or pathlib.Path
        Every file or folder the command reads.
    force : bool
        Replace an existing file, or a folder that is not `written_by_irtps`, all the same.
    option : str
        The option's name, for messages.

    Raises
    ------
    OutputError
        Naming the option and the path: `out` is a symbolic-link loop; it is, holds or lies
        inside an input; it is a FIFO, a socket or a device (even with `force`); it is an
        existing file (without `force`) or something else that is not a folder; it is a folder with content that is not `irtps._shared.records.written_by_irtps` (without
        `force`).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     check_output(folder + "/data/out", [folder + "/data"])
    Traceback (most recent call last):
    ...
    irtps._shared.output_rule.OutputError: --out .../data/out: lies inside the input .../data; writing there would change it: choose a folder outside the input
    """
    shown = escaped(out)
    if Path(out).name in ("", ".", ".."):
        raise OutputError(f"{option} {shown}: ends in '.' or '..': name the output folder itself")
    kind = _kind(Path(out), option, shown)
    if kind is None:
        _check_ancestor(Path(out), option, shown)
    out_paths = _both_paths(out)
    for source in inputs:
        for in_path in _both_paths(source):
            for out_path in out_paths:
                relation = _relation(out_path, in_path)
                if relation is not None:
                    raise OutputError(
                        f"{option} {shown}: {relation} the input {escaped(source)}; writing there would "
                        f"{'delete' if relation != 'lies inside' else 'change'} it: choose a folder outside the input"
                    )
    if kind is not None and kind.startswith(_NEVER_REPLACED):
        raise OutputError(
            f"{option} {shown}: is {kind}, not a folder: choose another path (--force never replaces one)"
        )
    if kind is None or force:
        return
    if kind == "file":
        raise OutputError(
            f"{option} {shown}: is an existing file; writing there would replace it: choose another path, or pass --force"
        )
    if kind != "folder":
        raise OutputError(f"{option} {shown}: is {kind}, not a folder: choose another path")
    if _names(Path(out), option, shown) and not written_by_irtps(out):
        raise OutputError(
            f"{option} {shown}: is a folder with content that irtps did not write; writing there would replace it: "
            "choose a new or empty folder, or pass --force"
        )


def _kind(path: Path, option: str, shown: str) -> str | None:
    """What is at `path`: None (nothing), "folder", "file", or what else (`irtps._shared.paths`)."""
    problem = folder_problem(path, missing="")
    if problem is None:
        return "folder"
    if problem == "a symlink loop":
        raise OutputError(f"{option} {shown}: is, or goes through, a symbolic-link loop")
    if not problem:
        return None
    if problem != "not a folder":
        return problem
    problem = file_problem(path)
    return "file" if problem is None or problem.startswith("not readable") else problem.split(",")[0]


def _check_ancestor(path: Path, option: str, shown: str) -> None:
    """Refuse a path whose nearest existing ancestor is not a folder that can be written into."""
    ancestor = Path(os.path.abspath(path)).parent
    while not os.path.lexists(ancestor) and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    problem = folder_problem(ancestor)
    if problem is not None:
        raise OutputError(f"{option} {shown}: cannot be made: {escaped(ancestor)} is {problem}")


def _names(folder: Path, option: str, shown: str) -> list[str]:
    try:
        return os.listdir(folder)
    except OSError as error:
        raise OutputError(f"{option} {shown}: cannot be listed ({error.strerror or error})") from None


def _both_paths(path: str | Path) -> tuple[str, str]:
    """The path fully resolved through symbolic links, and as the name that a rename would
    replace: its folder resolved, its last part as it is. (``..`` is resolved where it
    stands, after the links before it, as the system does: never by cutting text.)"""
    text = os.fspath(path)
    parent, name = os.path.split(text.rstrip(os.sep) or text)
    resolved = os.path.realpath(text)
    if name in ("", ".", ".."):
        return resolved, resolved
    return resolved, os.path.join(os.path.realpath(parent or os.curdir), name)


def _relation(out: str, source: str) -> str | None:
    """How `out` overlaps `source`: "is", "holds", "lies inside", or None."""
    if out == source:
        return "is"
    common = os.path.commonpath([out, source])
    if common == out:
        return "holds"
    if common == source:
        return "lies inside"
    return None


def escaped(path: str | Path) -> str:
    """A path (or a message) as one printable line: control characters and undecodable bytes
    escaped as in a Python string literal.

    Examples
    --------
    >>> print(escaped("scans/a\\nb"))
    scans/a\\nb
    """
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in os.fspath(path))
