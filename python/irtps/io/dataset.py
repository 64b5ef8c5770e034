"""Data set folders: `load_dataset` detects the layout and reads a folder in the irtps layout
(``scene.json``, contract ``irtps.scene/1``) or the DiLiGenT layout (`irtps.io.diligent`);
`save_dataset` writes the irtps layout. The data classes, `Dataset` and `GroundTruth`, are
`irtps.model.data`'s.
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Mapping
from pathlib import Path, PurePosixPath
from typing import NamedTuple

import numpy as np

from irtps._shared.checks import check_finite, check_instance, check_integer, check_path
from irtps._shared.atomic import atomic_output_dir
from irtps.model.data import Dataset, GroundTruth, image_file_name
from irtps.io.diligent import (
    diligent_ground_truth_inputs,
    diligent_image_names,
    diligent_inputs,
    load_diligent,
    load_diligent_ground_truth,
)
from irtps.errors import ArgumentError, DatasetError
from irtps.io.image_selection import ImageSelection, parse_image_list, select_images
from irtps.io.imageio import (
    check_stack_memory,
    clip_negative,
    format_size,
    png_saturation,
    read_exr,
    read_image,
    read_images,
    read_mask,
    write_exr,
    write_png,
)
from irtps._shared.paths import check_file, check_folder, exists, folder_problem, optional_file, optional_folder
from irtps._shared.records import RENDERING, stamp
from irtps.model.scene import Scene, load_scene, write_scene

SCENE_FILE = "scene.json"
MASK_FILE = "mask.png"
IMAGES_FOLDER = "images"
GT_FOLDER = "gt"
DILIGENT_MARKER = "light_directions.txt"

_NUMBERED_IMAGE = re.compile(r"\d{3,}\.(exr|png)", re.IGNORECASE)
_HEIGHT_CHANNEL_TOLERANCE = 1e-6


def load_dataset(path: str | Path, *, ground_truth: bool = True, exclude_images: str | None = None) -> Dataset:
    """Read a data set folder, in the irtps layout or the DiLiGenT layout.

    Parameters
    ----------
    path : str or pathlib.Path
        A folder holding ``scene.json`` (irtps layout) or ``light_directions.txt``
        (DiLiGenT layout).
    ground_truth : bool
        Also read the ground truth (``gt/``, or DiLiGenT's ``Normal_gt.mat``) when present.
    exclude_images : str, optional
        Images to leave out, not read (`irtps.io.image_selection`): numbers and ranges of
        numbers that match the images' numbered file names (``"1-20,37"``), or file names.

    Returns
    -------
    Dataset
        Negative pixel values of the images are clipped to 0. When every image is a
        PNG file, ``saturation`` is 1.0. ``image_names`` holds the file names read,
        ``excluded_images`` those left out.

    Raises
    ------
    DatasetError
        Naming the file and the problem: missing files, a path that is not a readable
        regular file (a directory, a FIFO, a symlink loop or a broken symlink; an
        optional file such as ``mask.png`` is absent only when nothing is at its path),
        an image count that is not the number of lights, sizes that disagree,
        non-finite pixels, too few lights, a light that is not a unit vector with
        z > 0, an unknown format.
    ArgumentError
        Naming ``exclude_images``: malformed (checked before anything is read), an item
        that names no image, or fewer than 3 images left.
    IrtpsError
        If decoding the images would need more memory than is available (checked from
        the first image's header before decoding any), naming the images' folder.

    Warns
    -----
    IrtpsWarning
        Naming the first image with negative values, if any.
    """
    path = check_path("path", path)
    if exclude_images is not None:
        parse_image_list(exclude_images)
    folder = check_folder(path)
    if _layout(folder) == "diligent":
        return load_diligent(folder, ground_truth=ground_truth, exclude_images=exclude_images)
    return _load_irtps(folder, ground_truth, exclude_images)


def dataset_image_names(path: str | Path) -> tuple[str, ...]:
    """The file names of every image of a data set folder, in its order, without reading
    them: what a list of images to leave out (`irtps.io.image_selection`) is matched against.

    Raises
    ------
    DatasetError
        As `load_dataset`, for a folder that is not a data set or whose images are missing.

    Examples
    --------
    >>> import tempfile
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_dataset(data, folder + "/cap")
    ...     dataset_image_names(folder + "/cap")
    ('000.exr', '001.exr', '002.exr', '003.exr')
    """
    folder = check_folder(path)
    if _layout(folder) == "diligent":
        return diligent_image_names(folder)
    scene = load_scene(folder / SCENE_FILE)
    return tuple(image.name for image in _numbered_images(folder / IMAGES_FOLDER, len(scene.lights)))


def _not_a_dataset(folder: Path) -> DatasetError:
    return DatasetError(
        f"{folder}: not a data set: it holds neither {SCENE_FILE} (irtps layout) "
        f"nor {DILIGENT_MARKER} (DiLiGenT layout)"
    )


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
    and, when present, ``gt/height.exr`` (Y), ``gt/normal.exr``, ``gt/albedo.exr``
    and ``gt/direct/000.exr`` .... An existing folder at ``path`` is replaced only
    once everything is written.

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


def load_ground_truth(path: str | Path, size: tuple[int, int]) -> GroundTruth | None:
    """Read only the ground truth of a data set folder, without decoding its images.

    The direct-light images of ``gt/direct/`` are left out: this is what evaluating a
    reconstruction needs.

    Parameters
    ----------
    path : str or pathlib.Path
        A data set folder (irtps or DiLiGenT layout).
    size : tuple of int
        The (H, W) the ground truth must have (the reconstruction's).

    Returns
    -------
    GroundTruth or None
        None when the folder holds no ground truth.

    Raises
    ------
    DatasetError
        Naming the file: not a data set, a camera of another size, malformed ground truth.
    ArgumentError
        If `path` is not a path or `size` not two positive integers.
    """
    size = _checked_image_size(size)
    folder = check_folder(check_path("path", path))
    if _layout(folder) == "diligent":
        return load_diligent_ground_truth(folder, (size[0], size[1]))
    scene, truth = _ground_truth_files(folder)
    camera_size = (scene.camera.height, scene.camera.width)
    if camera_size != tuple(size):
        raise DatasetError(
            f"{folder / SCENE_FILE}: camera size {format_size(camera_size)} differs from the reconstruction's ({format_size(size)})"
        )
    return None if truth is None else _read_ground_truth(truth, camera_size)


def _ground_truth_files(folder: Path) -> tuple[Scene, _TruthFiles | None]:
    """The scene of a data set folder in the irtps layout, and its ground-truth maps."""
    scene = load_scene(folder / SCENE_FILE)
    return scene, _truth_files(folder / GT_FOLDER, len(scene.lights), direct=False)


def dataset_inputs(path: str | Path, *, ground_truth: bool = True, exclude_images: str | None = None) -> list[Path]:
    """Every file and folder that `load_dataset` reads, found by the code that reads them
    (the small files that list the rest are read; no image is decoded).

    What a command that writes compares its output with (`irtps._shared.output_rule`): an image
    listed from outside the data set folder, or a folder of it that is a symbolic link to
    another place, is read all the same.

    Parameters
    ----------
    path, ground_truth, exclude_images
        As for `load_dataset`.

    Returns
    -------
    list of pathlib.Path
        The data set folder, then the files and folders read, as the reader names them
        (symbolic links not resolved).

    Raises
    ------
    DatasetError, ArgumentError
        As `load_dataset`, for what is found wrong without decoding an image.

    Examples
    --------
    >>> import tempfile
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=3, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_dataset(data, folder + "/cap")
    ...     [path.relative_to(folder).as_posix() for path in dataset_inputs(folder + "/cap")][:6]
    ['cap', 'cap/scene.json', 'cap/images', 'cap/images/000.exr', 'cap/images/001.exr', 'cap/images/002.exr']
    """
    if exclude_images is not None:
        parse_image_list(exclude_images)
    folder = check_folder(check_path("path", path))
    if _layout(folder) == "diligent":
        return diligent_inputs(folder, ground_truth=ground_truth, exclude_images=exclude_images)
    return _irtps_files(folder, ground_truth, exclude_images).paths()


def ground_truth_inputs(path: str | Path) -> list[Path]:
    """Every file and folder that `load_ground_truth` reads (see `dataset_inputs`).

    Raises
    ------
    DatasetError
        As `load_ground_truth`, for what is found wrong without decoding a map.
    """
    folder = check_folder(check_path("path", path))
    if _layout(folder) == "diligent":
        return diligent_ground_truth_inputs(folder)
    _, truth = _ground_truth_files(folder)
    return [folder, folder / SCENE_FILE, *([] if truth is None else truth.paths())]


def is_data_set(path: str | Path) -> bool:
    """Whether `path` is a folder that holds a data set's marker file (``scene.json``, or
    DiLiGenT's ``light_directions.txt``); what it holds is not read.

    Examples
    --------
    >>> is_data_set("/")
    False
    """
    return folder_problem(path) is None and (exists(Path(path) / SCENE_FILE) or exists(Path(path) / DILIGENT_MARKER))


def _layout(folder: Path) -> str:
    """``"irtps"`` or ``"diligent"``: the layout of a data set folder, told by its marker file."""
    if exists(folder / SCENE_FILE):
        return "irtps"
    if exists(folder / DILIGENT_MARKER):
        return "diligent"
    raise _not_a_dataset(folder)


class _TruthFiles(NamedTuple):
    """The ground-truth files of a data set folder in the irtps layout that are there to read."""

    folder: Path
    height: Path | None
    normal: Path | None
    albedo: Path | None
    #: The direct-light images of the lights kept (none when they are not read).
    direct: list[Path]

    def paths(self) -> list[Path]:
        maps = [path for path in (self.height, self.normal, self.albedo) if path is not None]
        return [self.folder, *maps, *self.direct]


class _IrtpsFiles(NamedTuple):
    """What reading a data set folder in the irtps layout reads, found (and ``scene.json``
    parsed) without decoding an image."""

    scene_file: Path
    #: The scene, with the lights of the images kept.
    scene: Scene
    images: list[Path]
    selection: ImageSelection
    mask: Path | None
    truth: _TruthFiles | None

    def paths(self) -> list[Path]:
        mask = [] if self.mask is None else [self.mask]
        truth = [] if self.truth is None else self.truth.paths()
        return [
            self.scene_file.parent,
            self.scene_file,
            self.scene_file.parent / IMAGES_FOLDER,
            *self.images,
            *mask,
            *truth,
        ]


def _irtps_files(folder: Path, ground_truth: bool, exclude_images: str | None) -> _IrtpsFiles:
    scene = load_scene(folder / SCENE_FILE)
    paths = _numbered_images(folder / IMAGES_FOLDER, len(scene.lights))
    selection = select_images([path.name for path in paths], exclude_images, where=str(folder))
    kept = dataclasses.replace(scene, lights=tuple(scene.lights[k] for k in selection.kept))
    mask = _optional_path(folder / MASK_FILE)
    truth = _truth_files(folder / GT_FOLDER, len(scene.lights), selection.kept) if ground_truth else None
    return _IrtpsFiles(folder / SCENE_FILE, kept, [paths[k] for k in selection.kept], selection, mask, truth)


def _checked_image_size(size) -> tuple[int, int]:
    """`size` as (H, W), two positive integers."""
    if isinstance(size, (str, bytes)) or np.ndim(size) != 1 or len(size) != 2:
        raise ArgumentError("size", f"expected (H, W), two positive integers, got {size!r:.60}")
    return check_integer("size[0]", size[0], 1), check_integer("size[1]", size[1], 1)


def _load_irtps(folder: Path, ground_truth: bool, exclude_images: str | None) -> Dataset:
    files = _irtps_files(folder, ground_truth, exclude_images)
    scene, paths = files.scene, files.images
    size = (scene.camera.height, scene.camera.width)
    check_stack_memory(paths, size)
    images = read_images(paths)
    if images.shape[1:3] != size:
        raise DatasetError(
            f"{paths[0]}: size {format_size(images.shape[1:3])} does not match "
            f"the camera in {SCENE_FILE} ({format_size(size)})"
        )
    clip_negative(paths, images)
    mask = read_mask(files.mask, size) if files.mask is not None else np.ones(size, dtype=bool)
    gt = None if files.truth is None else _read_ground_truth(files.truth, size)
    saturation = png_saturation(paths)
    selection = files.selection
    return Dataset(
        scene=scene,
        images=images,
        mask=mask,
        gt=gt,
        source=str(folder),
        saturation=saturation,
        image_names=selection.names,
        excluded_images=selection.excluded,
    )


def _numbered_images(folder: Path, count: int) -> list[Path]:
    """``folder/000.exr`` (or ``.png``) ... for ``count`` lights; no more, no fewer."""
    context = f"{SCENE_FILE} has {count} lights, one image each"
    check_folder(folder, missing="missing folder", context=context)
    paths = []
    for k in range(count):
        candidates = [folder / image_file_name(k, suffix) for suffix in (".exr", ".png")]
        present = [candidate for candidate in candidates if exists(candidate)]
        if not present:
            raise DatasetError(f"{candidates[0]}: missing ({context})")
        if len(present) > 1:
            raise DatasetError(f"{folder}: both {present[0].name} and {present[1].name} exist; keep one")
        paths.append(check_file(present[0], context))
    numbered = sorted(entry.name for entry in folder.iterdir() if _NUMBERED_IMAGE.fullmatch(entry.name))
    if len(numbered) > count:
        unexpected = sorted(set(numbered) - {path.name for path in paths})
        raise DatasetError(
            f"{folder}: {len(numbered)} images for {count} lights in {SCENE_FILE} ({unexpected[0]} has no light)"
        )
    return paths


def _truth_files(folder: Path, count: int, kept: list[int] | None = None, direct: bool = True) -> _TruthFiles | None:
    """The ground-truth files in `folder`, if it is there: the maps present and, with
    `direct`, the direct-light images of the lights `kept` (default all `count`)."""
    if not optional_folder(folder):
        return None
    height, normal, albedo = (_optional_path(folder / f"{name}.exr") for name in ("height", "normal", "albedo"))
    direct_paths: list[Path] = []
    if direct and optional_folder(folder / "direct"):
        direct_paths = _numbered_images(folder / "direct", count)
        direct_paths = direct_paths if kept is None else [direct_paths[k] for k in kept]
    return _TruthFiles(folder, height, normal, albedo, direct_paths)


def _read_ground_truth(files: _TruthFiles, size: tuple[int, int]) -> GroundTruth | None:
    """The ground truth in `files`, None if there is none."""
    parts = {
        "height": None if files.height is None else read_height_map(files.height, size),
        "normal": None if files.normal is None else read_normal_map(files.normal, size),
        "albedo": None if files.albedo is None else read_albedo_map(files.albedo, size),
    }
    if files.direct:
        check_stack_memory(files.direct, size)
        parts["direct"] = _checked_size(files.direct[0], read_images(files.direct), size)
    if all(part is None for part in parts.values()):
        return None
    return GroundTruth(**parts)


def _optional_path(path: Path) -> Path | None:
    """`path` if an optional file is there to read, None if nothing is at it (`optional_file`)."""
    return path if optional_file(path) else None


def read_height_map(path: Path, size: tuple[int, int]) -> np.ndarray:
    """A finite (H, W) height map of size ``size`` from an EXR file (Y, or R = G = B).

    Raises
    ------
    DatasetError
        Naming ``path``: unreadable, non-finite, channels that differ, another size.
    """
    height = read_exr(path)
    check_finite(path, height, error=DatasetError)
    if height.ndim == 3:
        spread = float(np.ptp(height, axis=2).max())
        if spread > _HEIGHT_CHANNEL_TOLERANCE * max(1.0, float(np.abs(height).max())):
            raise DatasetError(
                f"{path}: R, G and B differ (by up to {spread:g}); a height map needs R = G = B or a single Y channel"
            )
        height = np.ascontiguousarray(height[:, :, 0])
    return _checked_size(path, height, size)


def read_normal_map(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """A finite (H, W, 3) normal map (R, G, B = nx, ny, nz) from an EXR file.

    Raises
    ------
    DatasetError
        Naming ``path``: unreadable, a single channel, non-finite, not of size ``size``
        (when given).
    """
    normal = read_exr(path)
    if normal.ndim != 3:
        raise DatasetError(f"{path}: has a single Y channel; a normal map needs R, G, B = nx, ny, nz")
    check_finite(path, normal, error=DatasetError)
    return normal if size is None else _checked_size(path, normal, size)


def read_albedo_map(path: Path, size: tuple[int, int]) -> np.ndarray:
    """A finite (H, W, 3) RGB albedo map of size ``size`` (a Y channel is replicated).

    Raises
    ------
    DatasetError
        Naming ``path``: unreadable, non-finite, another size.
    """
    return _checked_size(path, read_image(path), size)


def _checked_size(path: Path, array: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``array`` (an image or a stack of images) if its image size is ``size`` (H, W)."""
    if _image_size(array.shape) != tuple(size):
        raise DatasetError(
            f"{path}: size {format_size(_image_size(array.shape))} does not match the images ({format_size(size)})"
        )
    return array


def _image_size(shape: tuple[int, ...]) -> tuple[int, int]:
    """(H, W) of an image shape (H, W), (H, W, 3) or a stack shape (K, H, W, 3)."""
    return (shape[1], shape[2]) if len(shape) == 4 else (shape[0], shape[1])


def _gt_files(gt: GroundTruth | None) -> dict[str, list[tuple[str, np.ndarray]]]:
    """The EXR files of the ground truth, by part: relative path and array."""
    if gt is None:
        return {}
    files = {}
    for name in ("height", "normal", "albedo"):
        value = getattr(gt, name)
        if value is not None:
            files[name] = [(f"{GT_FOLDER}/{name}.exr", value)]
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


def load_scene_object(path: str | Path) -> tuple[Scene, np.ndarray, np.ndarray, np.ndarray]:
    """Read what rendering a data set folder needs: its scene and its true object.

    Parameters
    ----------
    path : str or pathlib.Path
        A folder with ``scene.json``, ``gt/height.exr``, ``gt/albedo.exr`` and optionally
        ``mask.png`` (absent: every pixel; anything else at that path that is not a
        readable file is an error, as for `load_dataset`). Images are not needed.

    Returns
    -------
    (Scene, height, albedo, mask)
        float32 (H, W) heights, float32 (H, W, 3) albedo, bool (H, W) mask.

    Raises
    ------
    DatasetError
        Naming the missing or malformed file, e.g. an albedo outside [0, 1] in the mask.
    ArgumentError
        If `path` is not a path.
    """
    files = _scene_object_files(check_folder(check_path("path", path)))
    scene, albedo_path = files.scene, files.albedo
    size = (scene.camera.height, scene.camera.width)
    height = read_height_map(files.height, size)
    albedo = read_albedo_map(albedo_path, size)
    mask = read_mask(files.mask, size) if files.mask is not None else np.ones(size, dtype=bool)
    outside = (albedo < 0.0) | (albedo > 1.0)
    outside[~mask] = False
    if outside.any():
        row, column, channel = np.argwhere(outside)[0]
        raise DatasetError(
            f"{albedo_path}: albedo {albedo[row, column, channel]:g} at row {row}, column {column} of the mask is outside [0, 1]"
        )
    return scene, height, albedo, mask


class _SceneObjectFiles(NamedTuple):
    """What `load_scene_object` reads, found (and ``scene.json`` parsed) without decoding a map."""

    scene: Scene
    height: Path
    albedo: Path
    mask: Path | None

    def paths(self) -> list[Path]:
        folder = self.height.parent.parent
        return [
            folder,
            folder / SCENE_FILE,
            self.height.parent,
            self.height,
            self.albedo,
            *([] if self.mask is None else [self.mask]),
        ]


def _scene_object_files(folder: Path) -> _SceneObjectFiles:
    scene = load_scene(folder / SCENE_FILE)
    height, albedo = folder / GT_FOLDER / "height.exr", folder / GT_FOLDER / "albedo.exr"
    for required in (height, albedo):
        check_file(required, "rendering needs the true height and albedo")
    return _SceneObjectFiles(scene, height, albedo, _optional_path(folder / MASK_FILE))


def scene_object_inputs(path: str | Path) -> list[Path]:
    """Every file and folder that `load_scene_object` reads (see `dataset_inputs`).

    Raises
    ------
    DatasetError
        As `load_scene_object`, for what is found wrong without decoding a map.
    """
    return _scene_object_files(check_folder(check_path("path", path))).paths()
