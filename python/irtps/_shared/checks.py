"""Checks of the arguments of irtps's public functions, shared by every module (as
scikit-image's ``skimage._shared`` checks).

Each check returns the argument as the code goes on to use it, or raises
`irtps.errors.ArgumentError` (an `irtps.IrtpsError` and a `ValueError`) whose message starts
with the argument's name. Data read from a file are checked the same way with
``error=DatasetError`` and the file as the name.
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Callable, Sequence
from itertools import dropwhile
from pathlib import Path
from typing import TypeVar

import numpy as np

from irtps.errors import ArgumentError, IrtpsError

F = TypeVar("F", bound=Callable)


def check_array(
    name: str,
    value,
    shape: tuple[int | None, ...],
    *,
    match: str | None = None,
    dtype: type | None = np.float64,
    copy: bool = True,
    nonempty: bool = False,
) -> np.ndarray:
    """`value` as an array of `shape` (None: any length on that axis), converted to `dtype`
    (None: kept as it is; a float type: refused unless `value` holds real numbers); a copy
    unless `copy` is False and `value` is already of `dtype`. With `nonempty`, no axis may
    have length 0. A `numpy.ma` array with masked entries is refused (numpy's conversion
    would use their hidden values); one without is taken as its data.

    Examples
    --------
    >>> check_array("albedo", [[0.5, 0.5, 0.5]], (None, 3)).shape
    (1, 3)
    >>> check_array("albedo", [0.5, 0.5], (None, 3), match="the vertices")
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: albedo: shape (2,), expected (N, 3) to match the vertices
    >>> check_array("height", np.zeros((0, 4)), (None, None), nonempty=True)
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: height: shape (0, 4) is empty: expected (H, W) with every length at least 1
    """
    if isinstance(value, (str, bytes)):
        raise ArgumentError(
            name, f"expected an array of shape {_shape_text(shape)}, got {type(value).__name__} {value!r:.40}"
        )
    if np.ma.is_masked(value):
        raise ArgumentError(
            name,
            "a masked array with masked entries: their values would be used as they are; fill them, or leave pixels out with the mask argument",
        )
    array = np.asarray(value)
    if array.ndim != len(shape) or any(want is not None and have != want for have, want in zip(array.shape, shape)):
        expected = _shape_text(shape)
        raise ArgumentError(name, f"shape {array.shape}, expected {expected}" + (f" to match {match}" if match else ""))
    if nonempty and array.size == 0:
        raise ArgumentError(
            name, f"shape {array.shape} is empty: expected {_shape_text(shape)} with every length at least 1"
        )
    if dtype is None:
        return array
    if (
        np.issubdtype(dtype, np.floating)
        and not (np.issubdtype(array.dtype, np.number) or array.dtype == bool)
        or np.iscomplexobj(array)
    ):
        raise ArgumentError(name, f"expected real numbers, got dtype {array.dtype}")
    return array.astype(dtype, copy=copy)


def _shape_text(shape: tuple[int | None, ...]) -> str:
    """A shape with its free axes named as the docs name them: (N, 3), (H, W), (K, H, W, 3)."""
    free = len(shape) - len(tuple(dropwhile(lambda want: want is None, shape)))
    names = ["K", "H", "W"][-free:] if free >= 2 else ["N"] * free
    parts = [*names, *("N" if want is None else str(want) for want in shape[free:])]
    return "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"


def check_mask(
    mask, shape: tuple[int, int] | None = None, *, match: str | None = None, name: str = "mask", nonempty: bool = False
) -> np.ndarray:
    """`mask` as a bool (H, W) array: of `shape` if given (that of the array named by
    `match`; None is then every pixel), with a pixel set if `nonempty`.

    Examples
    --------
    >>> check_mask([[1, 0]]).tolist()
    [[True, False]]
    >>> check_mask([[0, 0]], nonempty=True)
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: mask: empty (no pixel set)
    """
    if mask is None and shape is not None:
        return np.ones(shape, dtype=bool)
    mask = check_array(
        name, mask, (None, None) if shape is None else tuple(shape), match=match, dtype=bool, nonempty=True
    )
    if nonempty and not mask.any():
        raise ArgumentError(name, "empty (no pixel set)")
    return mask


def check_image(name: str, value, mask: np.ndarray, *, channels: int | None = 3, finite: bool = True) -> np.ndarray:
    """`value` as a float64 map of the mask's size, (H, W, `channels`) or (H, W) for
    ``channels=None``, finite on the mask's pixels if `finite`.

    Examples
    --------
    >>> mask = np.array([[True, False]])
    >>> check_image("height", [[1.0, np.inf]], mask, channels=None).shape
    (1, 2)
    >>> check_image("albedo", np.zeros((1, 3, 3)), mask)
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: albedo: shape (1, 3, 3), expected (1, 2, 3) to match the mask
    """
    image = check_array(name, value, mask.shape if channels is None else (*mask.shape, channels), match="the mask")
    if finite:
        check_finite(name, image, mask)
    return image


def check_finite(
    name: str | Path,
    array: np.ndarray,
    where: np.ndarray | None = None,
    *,
    unit: str = "pixel",
    error: type[IrtpsError] = ArgumentError,
) -> None:
    """Refuse a NaN or an infinity in `array` (at the pixels `where` is set, if given),
    naming the first: by row and column for an image (``unit="pixel"``), else by its index
    along the first axis (e.g. ``unit="vertex"``).

    ``error=DatasetError`` names a file read as `name`.

    Examples
    --------
    >>> check_finite("height", np.array([[0.0, np.nan]]))
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: height: non-finite value nan at row 0, column 1
    >>> check_finite("height", np.array([[0.0, np.nan]]), where=np.array([[True, False]]))
    """
    bad = ~np.isfinite(array)
    if where is not None:
        bad &= where.reshape(where.shape + (1,) * (array.ndim - where.ndim))
    if not bad.any():
        return
    index = tuple(np.argwhere(bad)[0])
    place = f"row {index[0]}, column {index[1]}" if unit == "pixel" else f"{unit} {index[0]}"
    message = f"non-finite value {array[index]} at {place}"
    if error is ArgumentError:
        raise ArgumentError(str(name), message)
    raise error(f"{name}: {message}")


def check_images_finite(name: str, images: np.ndarray, mask: np.ndarray) -> None:
    """Refuse a NaN or an infinity in images (K, H, W, C) at the pixels `mask` (H, W) sets,
    naming the first by its image, row and column; two passes over the images and no copy
    when every value is finite.

    Examples
    --------
    >>> images = np.zeros((2, 1, 2, 3)); images[1, 0, 1, 2] = np.nan
    >>> check_images_finite("images", images, np.array([[True, True]]))
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: images[1]: non-finite value nan at row 0, column 1
    >>> check_images_finite("images", images, np.array([[True, False]]))
    """
    if images.size == 0 or (np.isfinite(images.min()) and np.isfinite(images.max())):
        return
    for k, image in enumerate(images):
        check_finite(f"{name}[{k}]", image, mask)


def check_positive(name: str, value) -> float:
    """`value` as a float, refused unless it is a positive finite number.

    Examples
    --------
    >>> check_positive("pixel_size", 0)
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: pixel_size: expected a positive finite number, got 0
    """
    number = check_number(name, value, what="a positive finite number")
    if not number > 0:
        raise ArgumentError(name, f"expected a positive finite number, got {value!r}")
    return number


def check_number(name: str, value, *, what: str = "a finite number") -> float:
    """`value` as a float, refused unless it is a finite number (a text or a bool is not one,
    even ``"0.1"``).

    Examples
    --------
    >>> check_number("base_height", "high")
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: base_height: expected a finite number, got 'high'
    >>> check_number("shadow_fraction", "0.1")
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: shadow_fraction: expected a finite number, got '0.1'
    """
    if isinstance(value, (str, bytes, bool, np.bool_)):
        raise ArgumentError(name, f"expected {what}, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ArgumentError(name, f"expected {what}, got {value!r}") from None
    if not np.isfinite(number):
        raise ArgumentError(name, f"expected {what}, got {value!r}")
    return number


def check_instance(name: str, value, kind: type):
    """`value`, refused unless it is a `kind`.

    Examples
    --------
    >>> check_instance("dataset", {"images": []}, tuple)
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: dataset: expected a tuple, got dict
    """
    if not isinstance(value, kind):
        raise ArgumentError(name, f"expected a {kind.__name__}, got {type(value).__name__}")
    return value


def check_integer(name: str, value, minimum: int) -> int:
    """`value` as an int, refused unless it is an integer (not a bool, not a text) of at
    least `minimum`.

    Examples
    --------
    >>> check_integer("stride", "2", 1)
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: stride: expected an integer of at least 1, got '2'
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ArgumentError(name, f"expected an integer of at least {minimum}, got {value!r}")
    return int(value)


def check_path(name: str, value) -> Path:
    """`value` as a `pathlib.Path`: a str, a bytes path (decoded as `os.fsdecode` does) or an
    `os.PathLike`; refused if it is anything else or empty.

    Examples
    --------
    >>> check_path("path", b"data/ball")
    PosixPath('data/ball')
    >>> check_path("path", 3)
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: path: expected a path (str, bytes or os.PathLike), got int 3
    """
    if isinstance(value, (str, bytes, os.PathLike)):
        try:
            text = os.fsdecode(value)
        except TypeError:  # an os.PathLike whose __fspath__ gives neither str nor bytes
            text = ""
        if text:
            return Path(text)
    raise ArgumentError(name, f"expected a path (str, bytes or os.PathLike), got {type(value).__name__} {value!r:.60}")


def check_choice(name: str, value, choices) -> None:
    """Refuse `value` unless it is one of `choices`.

    Examples
    --------
    >>> check_choice("robust", "huber", ("tukey", "none"))
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: robust: unknown 'huber'; expected one of tukey, none
    """
    if value not in choices:
        raise ArgumentError(name, f"unknown {value!r}; expected one of {', '.join(map(str, choices))}")


def document_choices(**choices: Sequence[str]) -> Callable[[F], F]:
    """Write into the decorated function's docstring the choices of each argument named, from
    the very sequence the code checks: its ``name : ...`` parameter line becomes
    ``name : {"a", "b"}``.

    Examples
    --------
    >>> @document_choices(mode=("fast", "exact"))
    ... def solve(mode):
    ...     '''Parameters
    ...     ----------
    ...     mode : str
    ...     '''
    >>> [line.strip() for line in solve.__doc__.splitlines() if line.strip().startswith("mode")]
    ['mode : {"fast", "exact"}']
    """

    def decorate(function: F) -> F:
        doc = function.__doc__ or ""
        for name, values in choices.items():
            listed = "{" + ", ".join(f'"{value}"' for value in values) + "}"
            line = rf"^(\s*{re.escape(name)} : ).*$"
            doc, count = re.subn(
                line, functools.partial(_replace_value, listed=listed), doc, count=1, flags=re.MULTILINE
            )
            if count != 1:
                raise TypeError(f"{function.__qualname__}: its docstring has no parameter line for {name!r}")
        function.__doc__ = doc
        return function

    return decorate


def _replace_value(match: re.Match[str], listed: str) -> str:
    """A numpydoc parameter line `match` with its type replaced by `listed`."""
    return match.group(1) + listed
