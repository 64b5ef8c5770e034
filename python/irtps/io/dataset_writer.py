"""Writing a data set folder in the irtps layout (`save_dataset`), atomically; `irtps.io.dataset`
reads it back.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path, PurePosixPath

import numpy as np

from irtps._shared.atomic import atomic_output_dir
from irtps._shared.checks import check_finite, check_instance, check_path
from irtps._shared.records import RENDERING, stamp
from irtps.errors import ArgumentError, DatasetError
from irtps.io.dataset_files import GT_FOLDER, IMAGES_FOLDER, MASK_FILE, SCENE_FILE
from irtps.io.imageio import write_exr, write_png
from irtps.model.data import Dataset, GroundTruth, image_file_name
from irtps.model.scene import write_scene

#: The record of how irtps rendered a data set (`save_dataset`'s ``rendering``).
RENDERING_RECORD = "gt/rendering.json"


def save_dataset(
    dataset: Dataset,
    path: str | Path,
    *,
    extra: Mapping[str, np.ndarray] | None = None,
    rendering: Mapping | None = None,
) -> None:
    """Write a data set folder in the irtps layout, atomically.

    Writes ``scene.json``, ``images/000.exr`` ..., ``mask.png`` (8-bit, 0 or 255)
    and, when present, ``gt/height.exr`` (Y), ``gt/normal.exr``, ``gt/albedo.exr``,
    ``gt/depth.exr`` (Y; an unknown depth, NaN, is written as 0, as outside the mask: no
    point a camera sees has depth 0) and ``gt/direct/000.exr`` .... An existing folder at
    ``path`` is replaced only once everything is written.

    Parameters
    ----------
    dataset : Dataset
    path : str or pathlib.Path
    extra : mapping of str to numpy.ndarray, optional
        More EXR files to write in the same transaction: a relative POSIX path
        ending in ``.exr`` (e.g. ``"gt/bounce1/000.exr"``) to a (H, W) or
        (H, W, 3) array. It must not name one of the files above.
    rendering : mapping, optional
        How the images were rendered (e.g. bounces, samples, seed), written with the irtps
        version as ``gt/rendering.json``: the data set's provenance, by which irtps also
        knows a folder it may replace (`irtps._shared.records.written_by_irtps`).

    Raises
    ------
    DatasetError
        If the data set breaks the contract (shapes, non-finite values, scene); nothing is
        written then.
    ArgumentError
        If ``extra`` is malformed; nothing is written then.
    """
    check_instance("dataset", dataset, Dataset)
    path = check_path("path", path)
    dataset.check_shapes()
    if not dataset.mask.any():
        raise DatasetError("Dataset.mask is empty: a data set needs at least one object pixel")
    extra = dict(extra or {})
    _check_extra(extra)
    for k, image in enumerate(dataset.images):
        check_finite(f"Dataset.images[{k}]", image, error=DatasetError)
    for name, files in _gt_files(dataset.gt).items():
        for relative, array in files:
            check_finite(f"Dataset.gt.{name} ({relative})", array, error=DatasetError)
    with atomic_output_dir(path) as out:
        write_scene(dataset.scene, out / SCENE_FILE)
        (out / IMAGES_FOLDER).mkdir()
        for k, image in enumerate(dataset.images):
            write_exr(out / IMAGES_FOLDER / image_file_name(k), image)
        write_png(out / MASK_FILE, dataset.mask.astype(np.float32), bit_depth=8)
        for files in _gt_files(dataset.gt).values():
            for relative, array in files:
                _write_new_exr(out, relative, array)
        for relative, array in extra.items():
            _write_new_exr(out, relative, array)
        if rendering is not None:
            record = out / RENDERING_RECORD
            record.parent.mkdir(exist_ok=True)
            record.write_text(json.dumps({**stamp(RENDERING), **rendering}, indent=2) + "\n", encoding="utf-8")


def _gt_files(gt: GroundTruth | None) -> dict[str, list[tuple[str, np.ndarray]]]:
    """The EXR files of the ground truth, by part: relative path and array."""
    if gt is None:
        return {}
    files = {}
    for name in ("height", "normal", "albedo", "depth"):
        value = getattr(gt, name)
        if value is not None:
            known = np.where(np.isnan(value), np.float32(0.0), value) if name == "depth" else value
            files[name] = [(f"{GT_FOLDER}/{name}.exr", known)]
    if gt.direct is not None:
        files["direct"] = [(f"{GT_FOLDER}/direct/{image_file_name(k)}", image) for k, image in enumerate(gt.direct)]
    return files


def _check_extra(extra: dict) -> None:
    for relative, array in extra.items():
        if not isinstance(relative, str):
            raise ArgumentError("extra", f"keys must be relative paths (str), got {relative!r}")
        path = PurePosixPath(relative)
        if path.is_absolute() or "\\" in relative or ".." in path.parts or path.suffix != ".exr":
            raise ArgumentError(
                "extra", f"{relative!r} must be a relative POSIX path inside the data set ending in .exr"
            )
        shape = np.shape(array)
        if not (len(shape) == 2 or (len(shape) == 3 and shape[2] == 3)):
            raise ArgumentError("extra", f"{relative!r} has shape {shape}, expected (H, W) or (H, W, 3)")


def _write_new_exr(out: Path, relative: str, array: np.ndarray) -> None:
    target = out / relative
    if target.exists():
        raise ArgumentError("extra", f"{relative!r} would overwrite a file of the data set")
    target.parent.mkdir(parents=True, exist_ok=True)
    write_exr(target, array)
