"""Reading data sets in the DiLiGenT layout.

A DiLiGenT folder holds the images listed in ``filenames.txt`` (16-bit PNG), one
line per image in ``light_directions.txt`` (x right, y up, z toward the camera:
the irtps frame) and ``light_intensities.txt`` (RGB), ``mask.png``, optionally the
camera's intrinsics ``K.txt`` (`irtps.io.intrinsics`: the folder is then perspective) and, for
evaluation, ``Normal_gt.mat`` (variable ``Normal_gt``, (H, W, 3)) and ``depth_gt.npz``
(variable ``depth_gt``, (H, W): depth along the optical axis in millimetres, NaN where
unknown).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import NamedTuple

import numpy as np
import scipy.io

from irtps.model.data import Dataset, GroundTruth
from irtps._shared.checks import check_finite
from irtps.errors import DatasetError
from irtps._shared.guarded import read_text
from irtps.io.image_selection import ImageSelection, select_images
from irtps.io.imageio import check_stack_memory, format_size, png_saturation, read_images, read_mask
from irtps.io.intrinsics import INTRINSICS_FILE, Intrinsics, read_intrinsics, with_intrinsics
from irtps.io.number_lines import check_intensities, three_number_lines
from irtps._shared.paths import check_file, check_folder, optional_file
from irtps.model.scene import MIN_LIGHTS, Camera, Light, Scene, upward_problem

FILENAMES_FILE = "filenames.txt"
DIRECTIONS_FILE = "light_directions.txt"
INTENSITIES_FILE = "light_intensities.txt"
MASK_FILE = "mask.png"
NORMALS_FILE = "Normal_gt.mat"
NORMALS_VARIABLE = "Normal_gt"
DEPTH_FILE = "depth_gt.npz"
DEPTH_VARIABLE = "depth_gt"

UNIT_TOLERANCE = 1e-2
"""How far the norm of a listed light direction may be from 1; within it, it is renormalised."""

#: What a missing list's error says.
_NEEDED = f"a DiLiGenT folder needs {FILENAMES_FILE} and {DIRECTIONS_FILE} ({INTENSITIES_FILE} if it has one)"


def load_diligent(path: str | Path, *, ground_truth: bool = True, exclude_images: str | None = None) -> Dataset:
    """Read a data set folder in the DiLiGenT layout.

    Parameters
    ----------
    path : str or pathlib.Path
    ground_truth : bool
        Also read the normals of ``Normal_gt.mat`` and the depth of ``depth_gt.npz`` when
        the files are present.
    exclude_images : str, optional
        Images to leave out, not read (`irtps.io.image_selection`): ``"1-20"`` for
        ``001.png`` … ``020.png``, or file names as ``filenames.txt`` lists them.

    Returns
    -------
    Dataset
        Images in ``filenames.txt`` order, read at full bit depth and divided by
        ``2^bits - 1``. Each light's irradiance is its line of
        ``light_intensities.txt``; without that file, 1 for every light and
        `Dataset.irradiance_known` False (`irtps.reconstruct` then estimates the lights'
        strengths from the images). The camera is orthographic with the images'
        size and ``pixel_size`` 1, or, when the folder holds a ``K.txt``, perspective with
        those intrinsics and its optical centre at ``(0, 0, sqrt(fx * fy))``, where a pixel
        at the object's base is 1 wide (`irtps.io.intrinsics.with_intrinsics`); there is
        no floor and no environment.
        ``saturation`` is 1.0: a PNG value of ``2^bits - 1`` is clipped.
        ``mask.png`` is optional (absent means every pixel; anything else at that path
        that is not a readable file is an error).

    Raises
    ------
    DatasetError
        Naming the file (and line) and the problem: a missing file or one that is
        not a readable regular file (a directory, a FIFO, a symlink loop), line counts
        that disagree, a ``K.txt`` that is not a usable intrinsic matrix for the images
        (`irtps.io.intrinsics.read_intrinsics`, `irtps.io.intrinsics.with_intrinsics`), a
        ``depth_gt.npz`` without a real (H, W) ``depth_gt`` of positive or NaN values, an image listed twice, a direction that is not a unit vector (beyond 1e-2) or
        has z <= 0, a negative intensity or one out of range
        (`irtps.model.scene.irradiance_problem`), fewer than 3 lights, images of
        different sizes or with non-finite values.
    ArgumentError
        Naming ``exclude_images``: malformed, an item that names no image, or fewer than 3
        images left.
    IrtpsError
        If decoding the images would need more memory than is available (checked from
        the first image's header and the image count, before decoding any).

    Notes
    -----
    With the irradiance E taken from ``light_intensities.txt``, the contract's
    image model ``L = rho * E * (n . l) / pi`` makes irtps albedos pi times
    DiLiGenT's convention ``I = rho * e * (n . l)``.
    """
    folder = check_folder(path)
    files = _diligent_files(folder, ground_truth, exclude_images)
    image_paths, selection = files.images, files.selection
    check_stack_memory(image_paths, where=folder / FILENAMES_FILE)
    images = read_images(image_paths)
    size = images.shape[1:3]
    mask = read_mask(files.mask, size) if files.mask is not None else np.ones(size, dtype=bool)
    gt = _ground_truth(files.normals, files.depth, size)
    scene = Scene(
        camera=Camera(width=size[1], height=size[0], pixel_size=1.0),
        lights=files.lights,
        relative_irradiance=True,  # light_intensities.txt: relative RGB intensities
    )
    if files.intrinsics is not None:
        scene = with_intrinsics(scene, files.intrinsics)
    saturation = png_saturation(image_paths)
    return Dataset(
        scene=scene,
        images=images,
        mask=mask,
        gt=gt,
        source=str(folder),
        saturation=saturation,
        image_names=selection.names,
        excluded_images=selection.excluded,
        irradiance_known=files.irradiance_known,
    )


class _DiligentFiles(NamedTuple):
    """What reading a DiLiGenT folder reads, found (and its three lists parsed) without
    decoding an image."""

    folder: Path
    #: The lights of the images kept.
    lights: tuple[Light, ...]
    images: list[Path]
    selection: ImageSelection
    mask: Path | None
    normals: Path | None
    intrinsics: Intrinsics | None
    depth: Path | None

    #: Whether the folder has ``light_intensities.txt`` (else every light's is 1, unknown).
    irradiance_known: bool

    def paths(self) -> list[Path]:
        listed = (FILENAMES_FILE, DIRECTIONS_FILE) + ((INTENSITIES_FILE,) if self.irradiance_known else ())
        lists = [self.folder / name for name in listed]
        camera = [] if self.intrinsics is None else [self.intrinsics.source]
        optional = [path for path in (self.mask, self.normals, self.depth) if path is not None]
        return [self.folder, *lists, *camera, *self.images, *optional]


def _diligent_files(folder: Path, ground_truth: bool, exclude_images: str | None) -> _DiligentFiles:
    names, name_lines = _read_filenames(folder / FILENAMES_FILE)
    directions, direction_lines = _read_table(folder / DIRECTIONS_FILE)
    irradiance_known = optional_file(folder / INTENSITIES_FILE)
    if irradiance_known:
        intensities, intensity_lines = _read_table(folder / INTENSITIES_FILE)
    else:  # unknown: estimated by `irtps.reconstruct`
        intensities, intensity_lines = np.ones((len(directions), 3)), list(direction_lines)
    for other, table in ((DIRECTIONS_FILE, directions), (INTENSITIES_FILE, intensities)):
        if len(table) != len(names):
            raise DatasetError(f"{folder / other}: {len(table)} lines, but {FILENAMES_FILE} lists {len(names)} images")
    if len(names) < MIN_LIGHTS:
        raise DatasetError(
            f"{folder / FILENAMES_FILE}: {len(names)} images: photometric stereo needs at least {MIN_LIGHTS}"
        )
    directions = _unit_directions(folder / DIRECTIONS_FILE, directions, direction_lines)
    check_intensities(folder / INTENSITIES_FILE, intensities, intensity_lines)
    selection = select_images(names, exclude_images, where=str(folder))
    image_paths = [folder / names[k] for k in selection.kept]
    for image_path, line in zip(image_paths, [name_lines[k] for k in selection.kept], strict=True):
        check_file(image_path, f"listed on line {line} of {FILENAMES_FILE}")
    lights = tuple(Light(direction=directions[k], irradiance=intensities[k]) for k in selection.kept)
    mask = folder / MASK_FILE if optional_file(folder / MASK_FILE) else None
    normals, depth = (
        folder / name if ground_truth and optional_file(folder / name) else None for name in (NORMALS_FILE, DEPTH_FILE)
    )
    intrinsics = read_intrinsics(folder / INTRINSICS_FILE) if optional_file(folder / INTRINSICS_FILE) else None
    return _DiligentFiles(folder, lights, image_paths, selection, mask, normals, intrinsics, depth, irradiance_known)


def diligent_inputs(path: str | Path, *, ground_truth: bool = True, exclude_images: str | None = None) -> list[Path]:
    """Every file and folder that `load_diligent` reads, found by the code that reads them:
    the folder, its three lists, its ``K.txt`` when present, the images listed (wherever they
    are) but those left out, the mask and the true normals and depth when present.

    Raises
    ------
    DatasetError, ArgumentError
        As `load_diligent`, for what is found wrong without decoding an image.
    """
    return _diligent_files(check_folder(path), ground_truth, exclude_images).paths()


def diligent_ground_truth_inputs(path: str | Path) -> list[Path]:
    """The folder and, when present, the ``Normal_gt.mat`` and ``depth_gt.npz`` that
    `load_diligent_ground_truth` reads."""
    folder = check_folder(path)
    return [folder, *(folder / name for name in (NORMALS_FILE, DEPTH_FILE) if optional_file(folder / name))]


def load_diligent_ground_truth(path: str | Path, size: tuple[int, int]) -> GroundTruth | None:
    """Read only the true normals (``Normal_gt.mat``) and depth (``depth_gt.npz``) of a
    DiLiGenT folder, no images.

    Parameters
    ----------
    path : str or pathlib.Path
    size : tuple of int
        The expected (H, W).

    Returns
    -------
    GroundTruth or None
        None when the folder has neither file.
    """
    folder = check_folder(path)
    normals, depth = (folder / name if optional_file(folder / name) else None for name in (NORMALS_FILE, DEPTH_FILE))
    return _ground_truth(normals, depth, size)


def _ground_truth(normals: Path | None, depth: Path | None, size: tuple[int, int]) -> GroundTruth | None:
    """The true normals and depth of the files present, None if neither is."""
    if normals is None and depth is None:
        return None
    return GroundTruth(
        normal=None if normals is None else _read_normals(normals, size),
        depth=None if depth is None else _read_depth(depth, size),
    )


def diligent_image_names(folder: str | Path) -> tuple[str, ...]:
    """The image file names that a DiLiGenT folder's ``filenames.txt`` lists, in its order
    (the images are not read)."""
    return tuple(_read_filenames(Path(folder) / FILENAMES_FILE)[0])


def _read_lines(path: Path) -> list[tuple[int, str]]:
    """Non-blank lines of a text file, stripped, with their 1-based line numbers."""
    check_file(path, _NEEDED)
    text = read_text(path)
    return [(number, line.strip()) for number, line in enumerate(text.splitlines(), start=1) if line.strip()]


def _read_filenames(path: Path) -> tuple[list[str], list[int]]:
    """The image names listed, each once (one image under two lights is a slip, not data),
    and their line numbers."""
    lines = _read_lines(path)
    first: dict[str, int] = {}
    for number, name in lines:
        seen = first.setdefault(os.path.normpath(name), number)
        if seen != number:
            raise DatasetError(
                f"{path}: line {number} lists {name!r} again (line {seen} lists it): each image goes with one light"
            )
    return [name for _, name in lines], [number for number, _ in lines]


def _read_table(path: Path) -> tuple[np.ndarray, list[int]]:
    """Three finite numbers per line: a float64 (N, 3) array and the line numbers."""
    check_file(path, _NEEDED)
    return three_number_lines(path)


def _unit_directions(path: Path, directions: np.ndarray, lines: list[int]) -> np.ndarray:
    norms = np.linalg.norm(directions, axis=1)
    for direction, norm, line in zip(directions, norms, lines, strict=True):
        if abs(norm - 1.0) > UNIT_TOLERANCE:
            raise DatasetError(f"{path}: line {line}: light direction is not a unit vector (norm {norm:.6g})")
        upward = upward_problem(direction[2])
        if upward is not None:
            raise DatasetError(f"{path}: line {line}: light direction {upward}")
    return directions / norms[:, None]


def _read_normals(path: Path, size: tuple[int, int]) -> np.ndarray:
    """The (H, W, 3) real, finite normals of ``Normal_gt.mat`` at `path`, of the images' `size`.

    A `MemoryError` while reading goes through as it is (the command says there is not
    enough memory): it says nothing of the file.
    """
    try:
        variables = scipy.io.loadmat(path)
    except MemoryError:
        raise
    except Exception as error:  # scipy raises many types on a malformed file (MatReadError, ValueError, zlib.error...)
        raise DatasetError(f"{path}: not a readable MATLAB file ({error})") from None
    if NORMALS_VARIABLE not in variables:
        found = sorted(name for name in variables if not name.startswith("__"))
        raise DatasetError(f"{path}: no variable {NORMALS_VARIABLE!r} (found {found})")
    normals = np.asarray(variables[NORMALS_VARIABLE])
    if normals.ndim != 3 or normals.shape[2] != 3:
        raise DatasetError(f"{path}: {NORMALS_VARIABLE} has shape {normals.shape}, expected (H, W, 3)")
    if normals.shape[:2] != tuple(size):
        raise DatasetError(f"{path}: size {format_size(normals.shape)} does not match the images ({format_size(size)})")
    if np.iscomplexobj(normals) or not (np.issubdtype(normals.dtype, np.number) or normals.dtype == bool):
        raise DatasetError(f"{path}: {NORMALS_VARIABLE} holds {normals.dtype} values, expected real numbers")
    normals = normals.astype(np.float32)
    check_finite(path, normals, error=DatasetError)
    return normals


def _read_depth(path: Path, size: tuple[int, int]) -> np.ndarray:
    """The (H, W) float32 depth of ``depth_gt.npz`` at `path`: positive, NaN where unknown."""
    try:
        with np.load(path, allow_pickle=False) as variables:
            found = sorted(variables.files)
            depth = np.asarray(variables[DEPTH_VARIABLE]) if DEPTH_VARIABLE in found else None
    except MemoryError:
        raise
    except Exception as error:  # numpy raises many types on a malformed file (BadZipFile, ValueError, OSError...)
        raise DatasetError(f"{path}: not a readable NumPy .npz file ({error})") from None
    if depth is None:
        raise DatasetError(f"{path}: no variable {DEPTH_VARIABLE!r} (found {found})")
    if depth.ndim != 2 or depth.shape != tuple(size):
        raise DatasetError(f"{path}: {DEPTH_VARIABLE} has shape {depth.shape}, expected the images' {tuple(size)}")
    if not np.issubdtype(depth.dtype, np.floating):
        raise DatasetError(f"{path}: {DEPTH_VARIABLE} holds {depth.dtype} values, expected floating-point numbers")
    depth = depth.astype(np.float32)
    known = ~np.isnan(depth)
    if not (np.isfinite(depth[known]).all() and (depth[known] > 0.0).all()):
        row, column = np.argwhere(known & ~(np.isfinite(depth) & (depth > 0.0)))[0]
        raise DatasetError(
            f"{path}: {DEPTH_VARIABLE} is {depth[row, column]:g} at row {row}, column {column}: a depth is positive, or NaN where unknown"
        )
    return depth
