"""The data sets of a batch: the name of each one's output folder, the images it leaves out,
the intrinsics file that gives it a perspective camera and the light position file that
gives a folder of images its lights."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from irtps._shared.checks import check_path
from irtps._shared.paths import resolve_path
from irtps.batch.summary import SUMMARY_JSON, SUMMARY_MARKDOWN
from irtps.errors import ArgumentError
from irtps.io.image_selection import parse_image_list
from irtps.io.intrinsics import read_intrinsics
from irtps.io.rti import light_file_record

__all__ = ["dataset_exclusions", "dataset_intrinsics", "dataset_lights", "output_names"]


def output_names(paths: Sequence[str | Path]) -> list[str]:
    """Distinct output folder names for data set folders: their base names, with ``-2``,
    ``-3`` … added to repeats.

    Parameters
    ----------
    paths : sequence of str or pathlib.Path

    Returns
    -------
    list of str
        One name per path, in order; none is ``batch.json`` or ``batch.md``.

    Examples
    --------
    >>> output_names(["a/ball", "b/ball", "cap", "ball-2"])
    ['ball', 'ball-2', 'cap', 'ball-2-2']
    """
    taken = {SUMMARY_JSON, SUMMARY_MARKDOWN}
    names = []
    for path in paths:
        base = resolve_path(path).name
        name, suffix = base, 2
        while name in taken:
            name, suffix = f"{base}-{suffix}", suffix + 1
        taken.add(name)
        names.append(name)
    return names


def dataset_exclusions(
    exclude_images: str | Mapping[str, str | None] | None, names: list[str]
) -> dict[str, str | None]:
    """Each data set's list of images to leave out (`irtps.batch.run.reconstruct_many`'s
    ``exclude_images``), each list checked for form."""
    if exclude_images is None or isinstance(exclude_images, str):
        if exclude_images is not None:
            parse_image_list(exclude_images)
        return dict.fromkeys(names, exclude_images)
    if not isinstance(exclude_images, Mapping):
        raise ArgumentError(
            "exclude_images",
            f"expected a list of images or a mapping of data set names to lists, got {type(exclude_images).__name__}",
        )
    unknown = sorted(set(exclude_images) - set(names), key=str)
    if unknown:
        raise ArgumentError("exclude_images", f"{unknown[0]!r} is none of the data sets ({', '.join(names)})")
    for images in exclude_images.values():
        if images is not None:
            parse_image_list(images)
    return {name: exclude_images.get(name) for name in names}


def dataset_intrinsics(
    intrinsics: str | Path | Mapping[str, str | Path | None] | None, names: list[str]
) -> dict[str, str | None]:
    """Each data set's intrinsics file (`irtps.batch.run.reconstruct_many`'s ``intrinsics``),
    as an absolute path, each file read and checked (`irtps.io.intrinsics.read_intrinsics`,
    which raises a `DatasetError` naming it)."""
    files = _chosen_files("intrinsics", "a K.txt path", intrinsics, names)
    for path in {path for path in files.values() if path is not None}:
        read_intrinsics(path)
    return files


def dataset_lights(
    lights: str | Path | Mapping[str, str | Path | None] | None, names: list[str]
) -> dict[str, str | None]:
    """Each data set's light position file (`irtps.batch.run.reconstruct_many`'s ``lights``),
    as an absolute path, each file and the intensities beside it read
    (`irtps.io.rti.light_file_record`, which raises a `DatasetError` naming them)."""
    files = _chosen_files("lights", "a .lp path", lights, names)
    for path in {path for path in files.values() if path is not None}:
        light_file_record(path)
    return files


def _chosen_files(
    option: str, kind: str, files: str | Path | Mapping[str, str | Path | None] | None, names: list[str]
) -> dict[str, str | None]:
    """Each data set's file of `option`: one for all, or one (or None) per name; absolute."""
    if files is None or isinstance(files, (str, Path)):
        chosen: dict[str, str | Path | None] = dict.fromkeys(names, files)
    elif isinstance(files, Mapping):
        unknown = sorted(set(files) - set(names), key=str)
        if unknown:
            raise ArgumentError(option, f"{unknown[0]!r} is none of the data sets ({', '.join(names)})")
        chosen = {name: files.get(name) for name in names}
    else:
        raise ArgumentError(
            option, f"expected {kind} or a mapping of data set names to paths, got {type(files).__name__}"
        )
    return {
        name: None if path is None else str(resolve_path(check_path(f"{option}[{name!r}]", path)))
        for name, path in chosen.items()
    }
