"""Atomic output: a file or folder appears complete or not at all.

Temporary files and folders are created next to their final place (same parent
folder, hence the same file system) under hidden names, then renamed into place.
"""

from __future__ import annotations

import os
import secrets
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from irtps.errors import DatasetError


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
    is left untouched and the exception propagates.
    """
    final = Path(final_path)
    parent = _writable_parent(final)
    temp, _ = _create_unique(parent, f".{final.name}.tmp-", os.mkdir)
    try:
        yield temp
        _replace(temp, final)
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
    """
    path = Path(path)
    parent = _writable_parent(path)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL
    temp, descriptor = _create_unique(parent, f".{path.name}.tmp-", lambda p: os.open(p, flags, 0o666))
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


def _writable_parent(path: Path) -> Path:
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise DatasetError(f"{parent}: cannot create the output folder ({error.strerror or error})") from None
    return parent


def _create_unique(parent: Path, prefix: str, create: Callable[[Path], object]) -> tuple[Path, object]:
    """Call ``create`` on a fresh hidden name in ``parent``; return the name and the result."""
    while True:
        candidate = parent / f"{prefix}{secrets.token_hex(4)}"
        try:
            return candidate, create(candidate)
        except FileExistsError:
            continue
        except OSError as error:
            raise DatasetError(f"{parent}: the output folder is not writable ({error.strerror or error})") from None


def _replace(new: Path, final: Path) -> None:
    """Rename ``new`` to ``final``; an existing ``final`` is moved aside first, then deleted."""
    if not final.exists() and not final.is_symlink():
        os.rename(new, final)
        return
    old, _ = _create_unique(final.parent, f".{final.name}.old-", lambda p: os.rename(final, p))
    try:
        os.rename(new, final)
    except BaseException:
        os.rename(old, final)
        raise
    if old.is_dir() and not old.is_symlink():
        shutil.rmtree(old, ignore_errors=True)
    else:
        old.unlink(missing_ok=True)
