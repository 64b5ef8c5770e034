"""Leaving images out of a data set: a capture's faulty ones (a light that misfired, an image
taken as the object moved, a file that cannot be read) or those a benchmark sets aside
(DiLiGenT bear's first 20).

A list of images is a text of items separated by commas: a number (``37``) or a range of
numbers (``1-20``) names the images whose file name is that number (``001.png`` …
``020.png`` in the DiLiGenT layout, ``000.exr`` … in the irtps layout); any other item
names the image of that file name, with or without its extension (``sphere_07.png``).
`exclude_images` leaves them out of a data set in memory; `irtps.load_dataset` takes the
same list and does not read them at all.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from typing import NamedTuple
from pathlib import PurePosixPath

from irtps.model.data import Dataset
from irtps.errors import ArgumentError
from irtps._shared.by_name import entry_target
from irtps._shared.guarded import MAX_DIGITS, parse_int
from irtps.model.scene import MIN_LIGHTS

__all__ = [
    "ImageSelection",
    "exclude_images",
    "excluded_indices",
    "exclusions_by_name",
    "format_image_names",
    "format_images_fitted",
    "parse_image_list",
    "select_images",
]

_NUMBER = re.compile(r"\d+")
_RANGE = re.compile(r"(\d+)\s*-\s*(\d+)")
#: An example of the list, for error messages.
_EXAMPLE = "1-20,37,sphere_07.png"


def parse_image_list(images: str) -> tuple[str, ...]:
    """The items of a list of images, checked for form (not against any data set).

    Parameters
    ----------
    images : str
        Items separated by commas: numbers, ranges ``A-B`` of numbers, file names.

    Returns
    -------
    tuple of str
        The items, stripped of spaces.

    Raises
    ------
    ArgumentError
        Naming ``exclude_images``: not a text, an empty item, a range that runs backwards,
        a number of more than `irtps._shared.guarded.MAX_DIGITS` digits.

    Examples
    --------
    >>> parse_image_list("1-20, 37,sphere_07.png")
    ('1-20', '37', 'sphere_07.png')
    >>> parse_image_list("20-1")
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: exclude_images: the range '20-1' runs backwards; write 1-20
    """
    if not isinstance(images, str):
        raise ArgumentError(
            "exclude_images", f"expected a list of images such as {_EXAMPLE!r}, got {type(images).__name__}"
        )
    items = tuple(item.strip() for item in images.split(","))
    for item in items:
        if not item:
            raise ArgumentError(
                "exclude_images",
                f"{images!r} has an empty item; expected items separated by commas, such as {_EXAMPLE!r}",
            )
        span = _numbers(item)
        if span is not None and span[0] > span[1]:
            raise ArgumentError("exclude_images", f"the range {item!r} runs backwards; write {span[1]}-{span[0]}")
    return items


def excluded_indices(names: Sequence[str], images: str, *, where: str) -> list[int]:
    """The indices, into `names`, of the images that a list of images names.

    Parameters
    ----------
    names : sequence of str
        Every image's file name, in the data set's order.
    images : str
        The list (`parse_image_list`).
    where : str
        The data set, for error messages.

    Returns
    -------
    list of int
        Sorted, each once.

    Raises
    ------
    ArgumentError
        Naming ``exclude_images``: a malformed list (`parse_image_list`), an item that names
        none of the images (naming `where` and the item), or a list that leaves fewer than 3
        images.

    Examples
    --------
    >>> names = [f"{k:03d}.png" for k in range(1, 97)]
    >>> excluded_indices(names, "1-3,096.png", where="bearPNG")
    [0, 1, 2, 95]
    >>> excluded_indices(names, "97", where="bearPNG")
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: exclude_images: bearPNG has no image named '97' (the images: 001.png, 002.png, 003.png, ... 096.png)
    """
    items = parse_image_list(images)
    stems = [PurePosixPath(name).stem for name in names]
    numbers = [int(stem) if _NUMBER.fullmatch(stem) and len(stem) <= MAX_DIGITS else None for stem in stems]
    chosen: set[int] = set()
    for item in items:
        span = _numbers(item)
        hits = [
            k
            for k, (name, stem, number) in enumerate(zip(names, stems, numbers, strict=True))
            if item in (name, stem) or _within(number, span)
        ]
        if not hits:
            what = f"numbered {span[0]} to {span[1]}" if span is not None and span[0] != span[1] else f"named {item!r}"
            raise ArgumentError(
                "exclude_images", f"{where} has no image {what} (the images: {format_image_names(names)})"
            )
        chosen.update(hits)
    kept = len(names) - len(chosen)
    if kept < MIN_LIGHTS:
        raise ArgumentError(
            "exclude_images",
            f"leaving out {len(chosen)} of the {len(names)} images of {where} leaves {kept}; photometric stereo needs at least {MIN_LIGHTS}",
        )
    return sorted(chosen)


def exclusions_by_name(entries: Sequence[str], names: Sequence[str]) -> dict[str, str | None]:
    """Each data set's list of images to leave out, from lists given for many data sets at once
    (``irtps batch`` and ``irtps table``): ``LIST`` for every data set, ``NAME=LIST`` for the
    data set named ``NAME``; a data set's lists are joined.

    Parameters
    ----------
    entries : sequence of str
        The lists, each ``LIST`` or ``NAME=LIST`` (``NAME`` the longest of `names` that the
        entry starts with, followed by ``=``).
    names : sequence of str
        The data sets' names (`irtps.batch.plan.output_names`).

    Returns
    -------
    dict
        Name -> the joined list (`parse_image_list`'s form), or None when nothing is left out.

    Raises
    ------
    ArgumentError
        For a malformed list, or an entry with ``=`` that starts with none of `names` (checked
        before anything is read).

    Examples
    --------
    >>> exclusions_by_name(["96", "bearPNG=1-20"], ["ballPNG", "bearPNG"])
    {'ballPNG': '96', 'bearPNG': '96,1-20'}
    >>> exclusions_by_name(["bear=1-20"], ["ballPNG", "bearPNG"])
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: exclude_images: 'bear=1-20' names no data set (the data sets: ballPNG, bearPNG)
    """
    lists: dict[str, list[str]] = {name: [] for name in names}
    for entry in entries:
        name, images = entry_target(entry, names)
        if name is not None:
            targets = [name]
        elif "=" in entry:
            raise ArgumentError("exclude_images", f"{entry!r} names no data set (the data sets: {', '.join(names)})")
        else:
            targets = list(names)
        parse_image_list(images)
        for target in targets:
            lists[target].append(images)
    return {name: ",".join(images) if images else None for name, images in lists.items()}


def _numbers(item: str) -> tuple[int, int] | None:
    """The numbers from and to which an item of a list names images, if it is a number or a
    range of them."""
    if span := _RANGE.fullmatch(item):
        return parse_int(span[1], "exclude_images"), parse_int(span[2], "exclude_images")
    return (parse_int(item, "exclude_images"),) * 2 if _NUMBER.fullmatch(item) else None


class ImageSelection(NamedTuple):
    """The images of a data set that a list leaves in, and those it leaves out."""

    #: Indices of the images kept, in order.
    kept: list[int]
    #: Their names.
    names: tuple[str, ...]
    #: The names of those left out.
    excluded: tuple[str, ...]


def select_images(names: Sequence[str], images: str | None, *, where: str) -> ImageSelection:
    """The images that remain when a list (`excluded_indices`; None: none) leaves some out.

    Examples
    --------
    >>> select_images(["001.png", "002.png", "003.png", "004.png"], "2", where="rig")
    ImageSelection(kept=[0, 2, 3], names=('001.png', '003.png', '004.png'), excluded=('002.png',))
    """
    dropped = set() if images is None else set(excluded_indices(names, images, where=where))
    kept = [k for k in range(len(names)) if k not in dropped]
    return ImageSelection(kept, tuple(names[k] for k in kept), tuple(names[k] for k in sorted(dropped)))


def _within(number: int | None, span: tuple[int, int] | None) -> bool:
    """Whether an image numbered `number` (None: not numbered) is in `span`."""
    return number is not None and span is not None and span[0] <= number <= span[1]


def exclude_images(dataset: Dataset, images: str) -> Dataset:
    """The data set without the images that a list of images names.

    Parameters
    ----------
    dataset : Dataset
    images : str
        Items separated by commas: numbers and ranges of numbers (``1-20``) match the
        images whose file name is that number (`Dataset.names`), other items a file name
        with or without its extension.

    Returns
    -------
    Dataset
        A new data set: its images, lights, names and direct-light ground truth without
        those; ``excluded_images`` adds their names.

    Raises
    ------
    ArgumentError
        If `dataset` is not a `Dataset`; as `excluded_indices` for `images`, naming
        ``dataset.source``.

    Examples
    --------
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=6, bounces=0, environment="none")
    >>> fewer = exclude_images(data, "0-1")
    >>> len(fewer.scene.lights), fewer.names, fewer.excluded_images
    (4, ('002.exr', '003.exr', '004.exr', '005.exr'), ('000.exr', '001.exr'))
    """
    if not isinstance(dataset, Dataset):
        raise ArgumentError("dataset", f"expected a Dataset, got {type(dataset).__name__}")
    selection = select_images(dataset.names, images, where=dataset.source or "the data set")
    gt = dataset.gt
    if gt is not None and gt.direct is not None:
        gt = dataclasses.replace(gt, direct=gt.direct[selection.kept])
    return dataclasses.replace(
        dataset,
        scene=dataclasses.replace(dataset.scene, lights=tuple(dataset.scene.lights[k] for k in selection.kept)),
        images=dataset.images[selection.kept],
        gt=gt,
        image_names=selection.names,
        excluded_images=dataset.excluded_images + selection.excluded,
    )


def format_image_names(names: Sequence[str], shown: int = 3) -> str:
    """A short list of image names: all of a few, else the first `shown` and the last.

    Examples
    --------
    >>> format_image_names(["001.png", "002.png"])
    '001.png, 002.png'
    >>> format_image_names([f"{k:03d}.png" for k in range(1, 21)])
    '001.png, 002.png, 003.png, ... 020.png'
    """
    if len(names) <= shown + 1:
        return ", ".join(names)
    return f"{', '.join(names[:shown])}, ... {names[-1]}"


def format_images_fitted(fitted: int, excluded: Sequence[str]) -> str:
    """How many images a fit used, and which were left out.

    Examples
    --------
    >>> format_images_fitted(76, [f"{k:03d}.png" for k in range(1, 21)])
    '76 of 96 images fitted; left out 001.png, 002.png, 003.png, ... 020.png'
    >>> format_images_fitted(96, [])
    '96 images fitted'
    """
    if not excluded:
        return f"{fitted} images fitted"
    return f"{fitted} of {fitted + len(excluded)} images fitted; left out {format_image_names(excluded)}"
