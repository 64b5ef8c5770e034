"""Lines of numbers in the text files irtps reads (DiLiGenT's light lists, ``K.txt``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from irtps._shared.guarded import parse_float
from irtps.errors import ArgumentError, DatasetError

__all__ = ["three_numbers"]


def three_numbers(path: Path, number: int, line: str) -> list[float]:
    """The three finite numbers of line `number` of the file at `path`, separated by blanks or
    commas.

    Raises
    ------
    DatasetError
        ``"PATH: line N: PROBLEM"``: something that is not a number (`parse_float`), not three
        of them, or one that is not finite.

    Examples
    --------
    >>> three_numbers(Path("K.txt"), 3, "0, 0, 1")
    [0.0, 0.0, 1.0]
    >>> three_numbers(Path("K.txt"), 1, "28.8 0 12 0")
    Traceback (most recent call last):
    ...
    irtps.errors.DatasetError: K.txt: line 1: expected 3 numbers, got 4
    """
    fields = line.replace(",", " ").split()
    try:
        row = [parse_float(field, "field") for field in fields]
    except ArgumentError:
        raise DatasetError(f"{path}: line {number}: expected 3 numbers, got {line!r}") from None
    if len(row) != 3:
        raise DatasetError(f"{path}: line {number}: expected 3 numbers, got {len(row)}")
    if not all(np.isfinite(row)):
        raise DatasetError(f"{path}: line {number}: non-finite value in {line!r}")
    return row
