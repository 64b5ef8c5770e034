"""Atomic output: a file or folder appears complete or not at all.

Temporary files and folders are created next to their final place (same parent
folder, hence the same file system) under hidden names, then renamed into place.

Each write to ``NAME`` first creates a lock file ``.NAME.lock-TOKEN`` next to it and
holds an exclusive `fcntl.flock` on it until it ends. Its temporary file or folder is
``.NAME.tmp-TOKEN`` and, while it replaces an existing ``NAME``, the previous one is
moved aside to ``.NAME.old-TOKEN``; a write that ends, normally or by an exception,
removes all three. A write killed meanwhile (``kill -9``, power cut) leaves them
behind: the next write to the same ``NAME`` in the same folder removes the hidden
names whose lock is free (its owner is dead) or gone. A ``.NAME.old-TOKEN`` left that
way is renamed back to ``NAME`` if ``NAME`` is missing (the killed write had moved the
previous output aside but not put the new one in yet), so a failed write loses
nothing; a previous output being deleted is first renamed to the temporary name, so
a half-deleted one is never brought back. The hidden names of a write still running
are never touched.

Writes racing on the same ``NAME`` each use their own hidden names; the last one to
rename its output into place wins and none of them fails because of the others.
"""

from __future__ import annotations

import errno
import fcntl
import os
import re
import secrets
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import TypeVar

from irtps.errors import DatasetError
from irtps._shared.paths import exists

_T = TypeVar("_T")

# What ``os.rename`` of a folder raises when the target is taken: a non-empty folder
# (ENOTEMPTY, or EEXIST on some systems) or a file or symbolic link (ENOTDIR).
_TARGET_TAKEN = (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR)


@contextmanager
def atomic_output_dir(final_path: str | Path) -> Iterator[Path]:
    """Build a folder under a temporary name and move it into place on success.

    Parameters
    ----------
    final_path : str or pathlib.Path
        Where the folder must end up. Missing parent folders are created. An
        existing file or folder there is replaced, but only once the new folder
        is complete.

    Yields
    ------
    pathlib.Path
        An empty temporary folder next to ``final_path`` (hidden name
        ``.NAME.tmp-XXXXXXXX``) to write the content into.

    Raises
    ------
    DatasetError
        If the parent folder cannot be created or written to.

    Notes
    -----
    If the ``with`` body raises, the temporary folder is deleted, ``final_path``
    is left untouched and the exception propagates. Hidden names left next to
    ``final_path`` by a killed earlier write are cleaned up first (see the module
    documentation). Concurrent writes to the same ``final_path`` do not disturb
    each other: the last one to finish wins.
    """
    final = Path(final_path)
    with _writing(final) as token:
        temp = _hidden(final, "tmp", token)
        _create(temp, os.mkdir)
        try:
            yield temp
            _replace(temp, final, _hidden(final, "old", token))
        except BaseException:
            shutil.rmtree(temp, ignore_errors=True)
            raise


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write a file atomically: a temporary file in the same folder, then ``os.replace``.

    Parameters
    ----------
    path : str or pathlib.Path
        The file to write; missing parent folders are created.
    data : bytes

    Raises
    ------
    DatasetError
        If the parent folder cannot be created or written to.

    Notes
    -----
    The temporary file is ``.NAME.tmp-XXXXXXXX`` next to ``path``; those left by
    a killed earlier write are deleted, as by `atomic_output_dir`.
    """
    path = Path(path)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL
    with _writing(path) as token:
        temp = _hidden(path, "tmp", token)
        descriptor = _create(temp, lambda p: os.open(p, flags, 0o666))
        try:
            with os.fdopen(descriptor, "wb") as handle:
                handle.write(data)
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(temp, path)
        except BaseException:
            temp.unlink(missing_ok=True)
            raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write a UTF-8 text file atomically (see `atomic_write_bytes`).

    Parameters
    ----------
    path : str or pathlib.Path
    text : str
    """
    atomic_write_bytes(path, text.encode("utf-8"))


@contextmanager
def _writing(final: Path) -> Iterator[str]:
    """Clean up after dead writes to ``final``, then hold a new lock for one; yield its token.

    The caller must have removed its ``tmp`` and ``old`` names when the block ends; the
    lock file is then deleted and unlocked.
    """
    parent = _writable_parent(final)
    seen = _remove_stale(final)
    while True:
        token = secrets.token_hex(4)
        if token in seen:
            continue
        lock = _hidden(final, "lock", token)
        try:
            descriptor = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue
        except OSError as error:
            raise _not_writable(parent, error) from None
        try:
            held = _hold(descriptor, lock)
        except OSError as error:
            lock.unlink(missing_ok=True)
            os.close(descriptor)
            raise DatasetError(
                f"{parent}: cannot lock a file in the output folder ({error.strerror or error})"
            ) from None
        if held:
            break
        # A cleaner that opened the new file before the flock judged it stale and
        # deleted it (or is about to): try another token.
        os.close(descriptor)
    try:
        yield token
    finally:
        lock.unlink(missing_ok=True)
        os.close(descriptor)


def _remove_stale(final: Path) -> set[str]:
    """Remove the hidden names of dead writes to ``final``; return the tokens of all those seen."""
    pattern = re.compile(rf"\.{re.escape(final.name)}\.(?:tmp|old|lock)-([0-9a-f]{{8}})")
    try:
        with os.scandir(final.parent) as entries:
            tokens = {match[1] for entry in entries if (match := pattern.fullmatch(entry.name))}
    except OSError:
        return set()
    for token in tokens:
        lock = _hidden(final, "lock", token)
        try:
            descriptor = os.open(lock, os.O_RDWR)
        except FileNotFoundError:
            descriptor = None
        except OSError:
            continue  # another user's lock, say: its owner cannot be told dead
        try:
            stale = descriptor is None or _hold(descriptor, lock)
        except OSError:
            stale = False  # no locks on this file system: the owner cannot be told dead
        if stale:
            temp = _hidden(final, "tmp", token)
            _remove(temp)
            _restore(_hidden(final, "old", token), final, temp)
            _remove(lock)
        if descriptor is not None:
            os.close(descriptor)
    return tokens


def _hold(descriptor: int, lock: Path) -> bool:
    """Lock ``descriptor`` without waiting; True if that worked and ``lock`` is still its file.

    Raises `OSError` if the file system has no locks.
    """
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        named = os.stat(lock)
    except (BlockingIOError, FileNotFoundError):
        return False
    held = os.fstat(descriptor)
    return (held.st_dev, held.st_ino) == (named.st_dev, named.st_ino)


def _replace(new: Path, final: Path, old: Path) -> None:
    """Rename ``new`` to ``final``; an existing ``final`` is moved aside to ``old`` first, then deleted.

    Another write may put its own output at ``final`` or move it away between any two
    renames: then this one tries again, until ``new`` is in place.
    """
    try:
        while True:
            try:
                os.rename(new, final)
                break
            except OSError as error:
                if error.errno not in _TARGET_TAKEN:
                    raise
            _remove(old)  # an output moved aside in an earlier round, already replaced by another
            with suppress(FileNotFoundError):
                os.rename(final, old)
    except OSError as error:
        _restore(old, final, new)
        raise _not_writable(final.parent, error) from None
    _discard(old, new)


def _restore(old: Path, final: Path, trash: Path) -> None:
    """Rename ``old`` back to ``final`` if that is missing, otherwise discard it to ``trash``."""
    if not exists(final):
        with suppress(OSError):
            os.rename(old, final)
    if exists(final):
        _discard(old, trash)


def _discard(old: Path, trash: Path) -> None:
    """Delete ``old``, first renamed to the temporary name ``trash`` unless that is taken.

    A write killed while deleting then leaves a partial temporary, which the next one
    deletes, rather than a partial ``old``, which it could restore.
    """
    with suppress(OSError):
        os.rename(old, trash)
        old = trash
    _remove(old)


def _remove(path: Path) -> None:
    """Delete a file, link or folder tree if it exists, as far as possible."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with suppress(OSError):
            path.unlink(missing_ok=True)


def _hidden(final: Path, kind: str, token: str) -> Path:
    return final.parent / f".{final.name}.{kind}-{token}"


def _writable_parent(path: Path) -> Path:
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise DatasetError(f"{parent}: cannot create the output folder ({error.strerror or error})") from None
    return parent


def _create(path: Path, create: Callable[[Path], _T]) -> _T:
    """Return ``create(path)``; an `OSError` becomes a `DatasetError` naming the folder."""
    try:
        return create(path)
    except OSError as error:
        raise _not_writable(path.parent, error) from None


def _not_writable(parent: Path, error: OSError) -> DatasetError:
    return DatasetError(f"{parent}: the output folder is not writable ({error.strerror or error})")
