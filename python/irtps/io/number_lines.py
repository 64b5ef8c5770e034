"""Lines of numbers in the text files irtps reads (DiLiGenT's light lists, ``K.txt``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from irtps._shared.guarded import parse_float, read_text
from irtps.errors import ArgumentError, DatasetError
from irtps.model.scene import irradiance_problem

__all__ = ["check_intensities", "three_number_lines", "three_numbers"]


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


def three_number_lines(path: Path) -> tuple[np.ndarray, list[int]]:
    """Three finite numbers per non-blank line of a text file (`three_numbers`): a float64
    (N, 3) array and the lines' 1-based numbers.

    Raises
    ------
    DatasetError
        As `three_numbers`, naming the file and the line.
    """
    rows, numbers = [], []
    for number, line in enumerate(read_text(path).splitlines(), start=1):
        if line.strip():
            rows.append(three_numbers(path, number, line.strip()))
            numbers.append(number)
    return np.array(rows, dtype=np.float64).reshape(-1, 3), numbers


def check_intensities(path: Path, intensities: np.ndarray, lines: list[int]) -> None:
    """Refuse a line of light intensities (``light_intensities.txt``) with a negative value or
    one out of the core's range (`irtps.model.scene.irradiance_problem`).

    Raises
    ------
    DatasetError
        ``"PATH: line N: PROBLEM"``.
    """
    for row, line in zip(intensities, lines, strict=True):
        if (row < 0.0).any():
            raise DatasetError(f"{path}: line {line}: light intensities must not be negative, got {row.tolist()}")
        problem = irradiance_problem(row)
        if problem is not None:
            raise DatasetError(f"{path}: line {line}: light intensity {problem}")
