"""What is wrong with a path that irtps cannot read: the words of its error messages.

A file that irtps reads must be a readable regular file (a symlink to one is fine). When
it is not, `file_problem` says why in a few words ("missing", "a directory, not a file",
"a FIFO (named pipe), not a regular file", "a symlink loop", ...), and `check_file`
raises `DatasetError` naming the path, e.g.
``"data/images/001.exr: a directory, not a file (scene.json has 3 lights, one image each)"``.
Only `os.stat` and `os.lstat` are used: nothing is opened, so a FIFO never blocks.

An optional file (``mask.png``, ``gt/height.exr``, ``Normal_gt.mat``) is absent only when
nothing at all is at its path; `optional_file` raises for anything else that is not a
readable regular file (a directory, a FIFO, a broken symlink).
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from irtps.errors import DatasetError

MISSING = "missing"
"""The problem of a file path with nothing at it."""

NO_DATA_SET_FOLDER = "no such data set folder"
"""The problem of a data set folder path with nothing at it."""

INVALID_NAME = "not a valid path (it holds a NUL character)"
"""The problem of a path that no file can have."""


def file_problem(path: str | Path) -> str | None:
    """Why ``path`` cannot be read as a file, or None if it is a readable regular file.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    str or None
        ``"missing"``, ``"a broken symlink (to TARGET)"``, ``"a symlink loop"``,
        ``"a directory, not a file"``, ``"a FIFO (named pipe), not a regular file"``,
        ``"a socket, not a regular file"``, ``"a device, not a regular file"``,
        ``"not readable (permission denied)"``, ``"cannot be read (REASON)"`` or
        ``"not a valid path (it holds a NUL character)"``.

    Examples
    --------
    >>> file_problem("/")
    'a directory, not a file'
    >>> file_problem("/no/such/file")
    'missing'
    """
    try:
        mode = os.stat(path).st_mode
    except OSError as error:
        return _stat_problem(path, error, MISSING)
    except ValueError:  # a NUL character: no file can have such a name
        return INVALID_NAME
    if stat.S_ISREG(mode):
        return None if os.access(path, os.R_OK) else "not readable (permission denied)"
    if stat.S_ISDIR(mode):
        return "a directory, not a file"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe), not a regular file"
    if stat.S_ISSOCK(mode):
        return "a socket, not a regular file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device, not a regular file"
    return "not a regular file"


def folder_problem(path: str | Path, missing: str = NO_DATA_SET_FOLDER) -> str | None:
    """Why ``path`` cannot be read as a folder, or None if it is a readable folder.

    Parameters
    ----------
    path : str or pathlib.Path
    missing : str
        The problem when nothing is at ``path`` (by default ``"no such data set folder"``).

    Returns
    -------
    str or None
        ``missing``, ``"a broken symlink (to TARGET)"``, ``"a symlink loop"``,
        ``"not a folder"``, ``"not readable (permission denied)"``,
        ``"cannot be read (REASON)"`` or ``"not a valid path (it holds a NUL character)"``.
    """
    try:
        mode = os.stat(path).st_mode
    except OSError as error:
        return _stat_problem(path, error, missing)
    except ValueError:
        return INVALID_NAME
    if not stat.S_ISDIR(mode):
        return "not a folder"
    return None if os.access(path, os.R_OK | os.X_OK) else "not readable (permission denied)"


def exists(path: str | Path) -> bool:
    """Whether anything at all is at ``path``: a file, a folder, a FIFO, even a broken symlink.

    Unlike `pathlib.Path.exists`, a symlink loop or a broken symlink exists.
    """
    return os.path.lexists(path)


def check_file(path: str | Path, context: str | None = None) -> Path:
    """``path`` if it is a readable regular file; else raise `DatasetError` naming it.

    Parameters
    ----------
    path : str or pathlib.Path
    context : str, optional
        Added in parentheses, e.g. ``"scene.json has 3 lights, one image each"``.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    DatasetError
        ``"PATH: PROBLEM (CONTEXT)"`` with a problem of `file_problem`.
    """
    problem = file_problem(path)
    if problem is not None:
        raise DatasetError(_message(path, problem, context))
    return Path(path)


def optional_file(path: str | Path, context: str | None = None) -> bool:
    """Whether an optional file is there to read: False only when nothing is at ``path``.

    Raises
    ------
    DatasetError
        When something is at ``path`` that is not a readable regular file (a directory, a
        FIFO, a broken symlink, a symlink loop ...), as `check_file`.
    """
    if not exists(path):
        return False
    check_file(path, context)
    return True


def check_folder(
    path: str | Path,
    missing: str = NO_DATA_SET_FOLDER,
    context: str | None = None,
    error: type[Exception] = DatasetError,
) -> Path:
    """``path`` if it is a readable folder; else raise ``error`` (`DatasetError`) naming it.

    Parameters
    ----------
    path : str or pathlib.Path
    missing : str
        The problem when nothing is at ``path``.
    context : str, optional
        Added in parentheses.
    error : type
        The exception type to raise.

    Returns
    -------
    pathlib.Path
    """
    problem = folder_problem(path, missing)
    if problem is not None:
        raise error(_message(path, problem, context))
    return Path(path)


def optional_folder(path: str | Path, context: str | None = None) -> bool:
    """Whether an optional folder (``gt/``) is there: False only when nothing is at ``path``.

    Raises
    ------
    DatasetError
        When something is at ``path`` that is not a readable folder.
    """
    if not exists(path):
        return False
    check_folder(path, MISSING, context)
    return True


def resolve_path(path: str | Path) -> Path:
    """`pathlib.Path.resolve`, but a path that cannot be resolved (a symlink loop) is made
    absolute instead of raising ``RuntimeError``, so that the reader reports it.

    Examples
    --------
    >>> resolve_path("/tmp/../tmp") == Path("/tmp").resolve()
    True
    """
    try:
        return Path(path).resolve()
    except (RuntimeError, OSError, ValueError):  # a loop; a NUL character
        return Path(os.path.abspath(path))


def _stat_problem(path: str | Path, error: OSError, missing: str) -> str:
    if error.errno == errno.ELOOP:
        return "a symlink loop"
    if error.errno in (errno.ENOENT, errno.ENOTDIR):
        if os.path.islink(path):
            try:
                return f"a broken symlink (to {os.readlink(path)})"
            except OSError:
                return "a broken symlink"
        return missing
    if error.errno in (errno.EACCES, errno.EPERM):
        return "not readable (permission denied)"
    return f"cannot be read ({error.strerror or error})"


def _message(path: str | Path, problem: str, context: str | None) -> str:
    return f"{path}: {problem}" if context is None else f"{path}: {problem} ({context})"
