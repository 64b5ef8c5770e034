"""Files given for many data sets at once (``irtps batch`` and ``irtps table``): one for every
data set, or ``NAME=FILE`` for the data set named ``NAME``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from irtps.errors import ArgumentError

__all__ = ["entry_target", "files_by_name"]


def entry_target(entry: str, names: Sequence[str]) -> tuple[str | None, str]:
    """The data set an entry ``NAME=VALUE`` is for and its value: ``NAME`` the longest of
    `names` that the entry starts with, followed by ``=``; (None, `entry`) when none is.

    Examples
    --------
    >>> entry_target("bearPNG=1-20", ["bear", "bearPNG"])
    ('bearPNG', '1-20')
    >>> entry_target("K.txt", ["bearPNG"])
    (None, 'K.txt')
    """
    matches = [name for name in names if entry.startswith(name + "=")]
    if not matches:
        return None, entry
    name = max(matches, key=len)
    return name, entry[len(name) + 1 :]


def files_by_name(option: str, entries: Sequence[str], names: Sequence[str]) -> dict[str, Path | None]:
    """Each data set's file of a command-line option given for many data sets at once: ``FILE``
    for every data set, ``NAME=FILE`` for the data set named ``NAME``, which takes it instead.

    Parameters
    ----------
    option : str
        The option's name, for errors (``"intrinsics"``, ``"lights"``).
    entries : sequence of str
        The files, each a path or ``NAME=`` and a path (`entry_target`).
    names : sequence of str
        The data sets' names, those of their output folders.

    Returns
    -------
    dict
        Name -> the file (not read yet), or None for a data set that none is given for.

    Raises
    ------
    ArgumentError
        Naming `option`: two files for every data set, or two for one ``NAME``.

    Examples
    --------
    >>> files_by_name("lights", ["rig.lp", "bearPNG=bear.lp"], ["ballPNG", "bearPNG"])
    {'ballPNG': PosixPath('rig.lp'), 'bearPNG': PosixPath('bear.lp')}
    >>> files_by_name("lights", [], ["ballPNG"])
    {'ballPNG': None}
    """
    every: Path | None = None
    named: dict[str, Path] = {}
    for entry in entries:
        name, file = entry_target(entry, names)
        if name is None:
            if every is not None:
                raise ArgumentError(option, f"{entry!r} and {str(every)!r} are both for every data set: give one")
            every = Path(file)
        elif name in named:
            raise ArgumentError(option, f"{name} is given two files, {str(named[name])!r} and {entry!r}")
        else:
            named[name] = Path(file)
    return {name: named.get(name, every) for name in names}
