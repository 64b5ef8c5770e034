"""One guarded reader for every JSON file and every integer that irtps parses.

Python's own parsers fail in ways that do not name the input: ``json.loads`` raises
`RecursionError` on deeply nested text and `ValueError` on an integer past the interpreter's
4,300-digit conversion limit, and ``int()`` does the same for a command-line value. The
functions here bound what they accept before parsing (the size of a file, the depth of its
nesting, the digits of a number) and turn every failure into one error line that names the
file (and the line and column) or the option.

`read_json` reads ``scene.json``, ``run.json``, ``table.json``, ``batch.json`` and
``gt/rendering.json``; `read_text` the DiLiGenT text files; `parse_int` every integer given on
the command line or in a list of images; `parse_float` every other number given on the command
line or in a DiLiGenT text file. Numbers are written in ASCII decimal digits: Python's own
``float()`` and ``int()`` also take ``1_000`` (as 1000) and digits of other scripts (``٣``).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from irtps.errors import ArgumentError, DatasetError, IrtpsError
from irtps._shared.paths import MISSING, file_problem

__all__ = [
    "MAX_DEPTH",
    "MAX_DIGITS",
    "MAX_TEXT_BYTES",
    "parse_float",
    "parse_int",
    "parse_json",
    "read_json",
    "read_text",
    "shown",
]

#: The largest text file read: far above any scene, record or light list (96 lights take
#: 4 kB), far below what would exhaust memory.
MAX_TEXT_BYTES = 64 * 1024 * 1024
#: The deepest nesting of arrays and objects accepted in a JSON file (ours nest 5 deep).
MAX_DEPTH = 64
#: The most digits of a number (sign and exponent aside): a float64 holds 17 significant
#: digits and no count irtps uses needs more than 20.
MAX_DIGITS = 40

_FLOAT = re.compile(
    r"[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf|infinity|nan)", flags=re.ASCII | re.IGNORECASE
)
_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_NUMBER_DIGITS = re.compile(r"\d")
_BRACKETS = re.compile(r"[\[\]{}]")


def read_text(path: str | Path, *, error: type[IrtpsError] = DatasetError, max_bytes: int = MAX_TEXT_BYTES) -> str:
    """The UTF-8 text of a file, read only if it is a regular file of at most `max_bytes`.

    A byte-order mark at its start (as Windows editors write) is not part of the text.

    Parameters
    ----------
    path : str or pathlib.Path
    error : type
        The exception raised, `DatasetError` by default.
    max_bytes : int

    Returns
    -------
    str

    Raises
    ------
    error
        ``"PATH: PROBLEM"``: missing, not a regular file (checked before opening: a FIFO
        would block), larger than `max_bytes`, unreadable, not UTF-8.

    Examples
    --------
    >>> read_text("/no/such/file")
    Traceback (most recent call last):
    ...
    irtps.errors.DatasetError: /no/such/file: missing
    """
    problem = file_problem(path)
    if problem is not None:
        raise error(f"{path}: {problem}")
    try:
        with open(path, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except FileNotFoundError:
        raise error(f"{path}: {MISSING}") from None
    except OSError as failure:
        raise error(f"{path}: cannot be read ({failure.strerror or failure})") from None
    if len(data) > max_bytes:
        raise error(f"{path}: larger than {max_bytes // (1024 * 1024)} MiB: not a file irtps reads")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as failure:
        raise error(f"{path}: not UTF-8 text (byte {failure.start})") from None


def read_json(path: str | Path, *, error: type[IrtpsError] = DatasetError, unique_keys: bool = True) -> Any:
    """Parse a JSON file with `parse_json`, read by `read_text`.

    Parameters
    ----------
    path : str or pathlib.Path
    error : type
        The exception raised, `DatasetError` by default.
    unique_keys : bool
        Refuse an object that repeats a key (JSON's own parsers keep the last).

    Returns
    -------
    object
        The parsed value.

    Raises
    ------
    error
        As `read_text` and `parse_json`, naming `path`.
    """
    return parse_json(read_text(path, error=error), str(path), error=error, unique_keys=unique_keys)


def parse_json(text: str, source: str, *, error: type[IrtpsError] = DatasetError, unique_keys: bool = True) -> Any:
    """Parse JSON text, bounded: nesting up to `MAX_DEPTH`, numbers up to `MAX_DIGITS` digits.

    Parameters
    ----------
    text : str
    source : str
        What the text is (a file's path), the start of every error message.
    error : type
        The exception raised.
    unique_keys : bool
        Refuse an object that repeats a key.

    Returns
    -------
    object

    Raises
    ------
    error
        ``"SOURCE: PROBLEM"``: invalid JSON (with the line and column), nested too deeply,
        a number with too many digits, a repeated key, ``NaN`` or ``Infinity`` (not JSON).

    Examples
    --------
    >>> parse_json('{"a": [1, 2.5]}', "x.json")
    {'a': [1, 2.5]}
    >>> parse_json("[" * 100 + "]" * 100, "x.json")
    Traceback (most recent call last):
    ...
    irtps.errors.DatasetError: x.json: arrays and objects nested 100 deep; at most 64 are accepted
    >>> parse_json('{"width": ' + "9" * 5000 + "}", "x.json")
    Traceback (most recent call last):
    ...
    irtps.errors.DatasetError: x.json: line 1, column 11: a number with 5000 digits; at most 40 are accepted
    """
    depth = _nesting(text)
    if depth > MAX_DEPTH:
        raise error(f"{source}: arrays and objects nested {depth} deep; at most {MAX_DEPTH} are accepted")

    def number(kind: type):
        def parse(literal: str):
            digits = len(_NUMBER_DIGITS.findall(literal.split("e")[0].split("E")[0]))
            if digits > MAX_DIGITS:
                raise _Refused(literal, f"a number with {digits} digits; at most {MAX_DIGITS} are accepted")
            return kind(literal)

        return parse

    def constant(name: str):
        raise _Refused(name, f"{name} is not a JSON number")

    def pairs(items: list[tuple[str, object]]) -> dict:
        obj: dict = {}
        for key, value in items:
            if unique_keys and key in obj:
                raise _Refused(None, f"duplicate key {key!r} in a JSON object")
            obj[key] = value
        return obj

    try:
        return json.loads(
            text, parse_int=number(int), parse_float=number(float), parse_constant=constant, object_pairs_hook=pairs
        )
    except json.JSONDecodeError as failure:
        raise error(f"{source}: invalid JSON at line {failure.lineno}, column {failure.colno}: {failure.msg}") from None
    except _Refused as refused:
        raise error(f"{source}: {_place(text, refused.literal)}{refused.problem}") from None
    except RecursionError:  # not reached with MAX_DEPTH far below the interpreter's limit
        raise error(f"{source}: nested too deeply") from None


def parse_int(text: str, name: str) -> int:
    """An integer written in decimal digits (an optional sign, nothing else), bounded.

    Parameters
    ----------
    text : str
    name : str
        What the text is (an argument's or an option's name), the start of every message.

    Returns
    -------
    int

    Raises
    ------
    ArgumentError
        ``"NAME: PROBLEM"`` for anything but an integer of at most `MAX_DIGITS` digits.

    Examples
    --------
    >>> parse_int(" 12 ", "size")
    12
    >>> parse_int("1" * 5000, "size")
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: size: an integer with 5000 digits; at most 40 are accepted
    """
    stripped = text.strip()
    if not re.fullmatch(r"[+-]?[0-9]+", stripped, flags=re.ASCII):
        raise ArgumentError(name, f"expected an integer, got {shown(stripped)}")
    digits = len(stripped.lstrip("+-"))
    if digits > MAX_DIGITS:
        raise ArgumentError(name, f"an integer with {digits} digits; at most {MAX_DIGITS} are accepted")
    return int(stripped)


def parse_float(text: str, name: str) -> float:
    """A number written in decimal digits (``-1.5e-3``, ``.5``, ``inf``, ``nan``), bounded.

    Parameters
    ----------
    text : str
    name : str
        What the text is (an option's name), the start of every message.

    Returns
    -------
    float
        Possibly ``inf`` or ``nan``: the caller says whether those are allowed.

    Raises
    ------
    ArgumentError
        ``"NAME: PROBLEM"`` for anything else (``1_000``, ``0x10``, ``٣``), or a number of more
        than `MAX_DIGITS` digits before its exponent.

    Examples
    --------
    >>> parse_float(" -1.5e-3 ", "saturation")
    -0.0015
    >>> parse_float("1_0", "saturation")
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: saturation: expected a number, got '1_0'
    """
    stripped = text.strip()
    if not _FLOAT.fullmatch(stripped):
        raise ArgumentError(name, f"expected a number, got {shown(stripped)}")
    digits = len(_NUMBER_DIGITS.findall(stripped.split("e")[0].split("E")[0]))
    if digits > MAX_DIGITS:
        raise ArgumentError(name, f"a number with {digits} digits; at most {MAX_DIGITS} are accepted")
    return float(stripped)


class _Refused(Exception):
    """A value the hooks of `parse_json` refuse: its literal (to find its place) and why."""

    def __init__(self, literal: str | None, problem: str) -> None:
        super().__init__(problem)
        self.literal = literal
        self.problem = problem


def _nesting(text: str) -> int:
    """The deepest nesting of brackets and braces outside strings (of well-formed JSON)."""
    depth = deepest = 0
    for character in _BRACKETS.findall(_STRING.sub("", text)):
        if character in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif character in "]}":
            depth -= 1
    return deepest


def _place(text: str, literal: str | None) -> str:
    """``"line L, column C: "`` of the first occurrence of `literal` outside strings, or ""."""
    if literal is None:
        return ""
    blanked = _STRING.sub(lambda match: " " * len(match.group()), text)
    at = blanked.find(literal)
    if at < 0:
        return ""
    line = blanked.count("\n", 0, at) + 1
    column = at - (blanked.rfind("\n", 0, at) + 1) + 1
    return f"line {line}, column {column}: "


def shown(value: object, limit: int = 40) -> str:
    """A value read from a file or the command line, for a message: its `repr`, of a text at
    most `limit` characters of it (a field of a JSON file may be megabytes long).

    Examples
    --------
    >>> shown("x" * 100)
    "'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx...'"
    >>> shown([0] * 100, limit=12)
    '[0, 0, 0,...'
    """
    if isinstance(value, str):
        return repr(value if len(value) <= limit else value[: limit - 3] + "...")
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
