"""Reading data set folders: `load_dataset` detects the layout and reads a folder in the irtps
layout (``scene.json``, contract ``irtps.scene/1``) or the DiLiGenT layout
(`irtps.io.diligent`); `load_ground_truth` and `load_scene_object` read only the parts that
evaluating and rendering need. The files each reads are found by `irtps.io.dataset_files`;
`irtps.io.dataset_writer` writes the irtps layout. The data classes, `Dataset` and
`GroundTruth`, are `irtps.model.data`'s.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from irtps._shared.checks import check_finite, check_integer, check_path
from irtps._shared.paths import check_folder
from irtps.errors import ArgumentError, DatasetError
from irtps.io.dataset_files import (
    SCENE_FILE,
    TruthFiles,
    dataset_layout,
    ground_truth_files,
    irtps_files,
    scene_object_files,
)
from irtps.io.diligent import load_diligent, load_diligent_ground_truth
from irtps.io.rti import load_rti
from irtps.io.image_selection import parse_image_list
from irtps.io.intrinsics import Intrinsics, read_intrinsics, with_intrinsics
from irtps.io.imageio import (
    ENCODINGS,
    check_stack_memory,
    clip_negative,
    format_size,
    png_saturation,
    read_exr,
    read_image,
    read_images,
    read_mask,
    srgb_to_linear,
)
from irtps.model.data import Dataset, GroundTruth
from irtps.model.scene import Scene

_HEIGHT_CHANNEL_TOLERANCE = 1e-6


def load_dataset(
    path: str | Path,
    *,
    ground_truth: bool = True,
    exclude_images: str | None = None,
    intrinsics: str | Path | None = None,
    encoding: str | None = None,
    lights: str | Path | None = None,
) -> Dataset:
    """Read a data set folder, in the irtps layout, the DiLiGenT layout or as an RTI folder
    (`irtps.io.rti`: a ``*.lp`` file and its images, the lights' strengths unknown).

    Parameters
    ----------
    path : str or pathlib.Path
        A folder holding ``scene.json`` (irtps layout), ``light_directions.txt``
        (DiLiGenT layout) or one ``*.lp`` file (RTI).
    ground_truth : bool
        Also read the ground truth (``gt/``, or DiLiGenT's ``Normal_gt.mat``) when present.
    exclude_images : str, optional
        Images to leave out, not read (`irtps.io.image_selection`): numbers and ranges of
        numbers that match the images' numbered file names (``"1-20,37"``), or file names.
    intrinsics : str or pathlib.Path, optional
        A ``K.txt`` (`irtps.io.intrinsics`): the data set's camera is then the perspective
        camera of those intrinsics (`irtps.io.intrinsics.with_intrinsics`), whatever the
        folder says.
    encoding : {"srgb", "linear"}, optional
        How the images' values map to light, whatever the layout's default: linear for the
        irtps and DiLiGenT layouts (their contract), by bit depth in an RTI folder (8-bit
        sRGB, else linear). ``"srgb"`` applies to PNG, JPEG and TIFF images only.
    lights : str or pathlib.Path, optional
        A light position file (``*.lp``, as ``irtps calibrate`` writes it) kept outside the
        folder: `path` is then read as an RTI folder with those lights (`irtps.io.rti`), the
        images the file names found in it, the strengths from the ``light_intensities.txt``
        beside the file (unknown without one). Nothing needs copying into the folder.

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
        z > 0, an unknown format; naming the intrinsics file (read before any image), one
        that is not a usable intrinsic matrix or whose principal point lies far outside
        the data set's images (`irtps.model.camera.intrinsics_problem`).
    ArgumentError
        Naming ``exclude_images``: malformed (checked before anything is read), an item
        that names no image, or fewer than 3 images left. Naming ``lights``: given for a
        folder in the irtps or the DiLiGenT layout, whose lights are their own.
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
    if encoding is not None and encoding not in ENCODINGS:
        raise ArgumentError("encoding", f"{encoding!r} is not one of {', '.join(ENCODINGS)}")
    camera = None if intrinsics is None else read_intrinsics(check_path("intrinsics", intrinsics))
    lights = None if lights is None else check_path("lights", lights)
    folder = check_folder(path)
    layout = dataset_layout(folder, lights)
    if layout == "rti":
        dataset = load_rti(folder, exclude_images=exclude_images, encoding=encoding, lights=lights)
    elif layout == "irtps":
        dataset, camera = _load_irtps(folder, ground_truth, exclude_images, camera), None  # its camera set
    else:
        dataset = load_diligent(folder, ground_truth=ground_truth, exclude_images=exclude_images)
    if encoding == "srgb" and layout != "rti":
        _decode_srgb(dataset)
    return dataset if camera is None else dataclasses.replace(dataset, scene=with_intrinsics(dataset.scene, camera))


def _decode_srgb(dataset: Dataset) -> None:
    """Linearise the images of `dataset`, read as they are stored, from sRGB, in place."""
    for name in dataset.names:
        if not name.lower().endswith(".png"):
            raise ArgumentError("encoding", f"'srgb' applies to PNG, JPEG and TIFF images; {name} is stored linear")
    for image in dataset.images:  # one at a time: no float64 copy of the whole stack
        image[...] = srgb_to_linear(image)


def _load_irtps(folder: Path, ground_truth: bool, exclude_images: str | None, camera: Intrinsics | None) -> Dataset:
    files = irtps_files(folder, ground_truth, exclude_images)
    scene = files.scene if camera is None else with_intrinsics(files.scene, camera)
    paths = files.images
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


def load_ground_truth(
    path: str | Path, size: tuple[int, int], *, lights: str | Path | None = None
) -> GroundTruth | None:
    """Read only the ground truth of a data set folder, without decoding its images.

    The direct-light images of ``gt/direct/`` are left out: this is what evaluating a
    reconstruction needs.

    Parameters
    ----------
    path : str or pathlib.Path
        A data set folder (irtps or DiLiGenT layout).
    size : tuple of int
        The (H, W) the ground truth must have (the reconstruction's).
    lights : str or pathlib.Path, optional
        The light position file the folder was read with (`load_dataset`): a folder of
        images, which holds no ground truth.

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
    layout = dataset_layout(folder, None if lights is None else check_path("lights", lights))
    if layout == "diligent":
        return load_diligent_ground_truth(folder, (size[0], size[1]))
    if layout == "rti":
        return None  # an RTI folder holds no ground truth
    scene, truth = ground_truth_files(folder)
    camera_size = (scene.camera.height, scene.camera.width)
    if camera_size != tuple(size):
        raise DatasetError(
            f"{folder / SCENE_FILE}: camera size {format_size(camera_size)} differs from the reconstruction's ({format_size(size)})"
        )
    return None if truth is None else _read_ground_truth(truth, camera_size)


def _checked_image_size(size) -> tuple[int, int]:
    """`size` as (H, W), two positive integers."""
    if isinstance(size, (str, bytes)) or np.ndim(size) != 1 or len(size) != 2:
        raise ArgumentError("size", f"expected (H, W), two positive integers, got {size!r:.60}")
    return check_integer("size[0]", size[0], 1), check_integer("size[1]", size[1], 1)


def _read_ground_truth(files: TruthFiles, size: tuple[int, int]) -> GroundTruth | None:
    """The ground truth in `files`, None if there is none."""
    parts = {
        "height": None if files.height is None else read_height_map(files.height, size),
        "normal": None if files.normal is None else read_normal_map(files.normal, size),
        "albedo": None if files.albedo is None else read_albedo_map(files.albedo, size),
        "depth": None if files.depth is None else read_height_map(files.depth, size, "depth map"),
    }
    if files.direct:
        check_stack_memory(files.direct, size)
        parts["direct"] = _checked_size(files.direct[0], read_images(files.direct), size)
    if all(part is None for part in parts.values()):
        return None
    return GroundTruth(**parts)


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
    files = scene_object_files(check_folder(check_path("path", path)))
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


def read_height_map(path: Path, size: tuple[int, int], what: str = "height map") -> np.ndarray:
    """A finite (H, W) height map (or another map of one value a pixel, `what`: the depth map
    of ``gt/depth.exr``) of size ``size`` from an EXR file (Y, or R = G = B).

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
                f"{path}: R, G and B differ (by up to {spread:g}); a {what} needs R = G = B or a single Y channel"
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
