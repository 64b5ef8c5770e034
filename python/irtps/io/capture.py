"""Images as cameras and capture software save them: JPEG, PNG, TIFF, EXR or camera RAW, 8-bit
ones sRGB encoded (a camera's JPEG pipeline), 16-bit and float ones linear.

Camera RAW files (``.dng``, ``.cr2``, ``.cr3``, ``.nef``, ``.arw``, ``.raf``, ``.orf``,
``.rw2``, ``.pef``, ``.srw``) are read through LibRaw (rawpy, an optional dependency:
``pip install "irtps[raw]"``): demosaiced, white-balanced as shot, in linear sRGB primaries,
16-bit, without brightening, gamma, LibRaw's stretch of the white level to the brightest
pixel, or the camera's rotation (as JPEG files are read), so values stay proportional to light
and the sensor's clip is the largest code.

The readers of the RTI layout (`irtps.io.rti`) and of light-calibration captures
(`irtps calibrate`) share them.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import tifffile
from PIL import Image, UnidentifiedImageError

from irtps._shared.paths import check_folder
from irtps.errors import ArgumentError, DatasetError
from irtps.io.imageio import ENCODINGS, check_stack_memory, format_size, image_size, read_exr, read_png, srgb_to_linear

__all__ = [
    "CAPTURE_SUFFIXES",
    "Capture",
    "capture_image_paths",
    "read_capture",
    "read_capture_image",
    "read_capture_images",
]

_JPEG = (".jpg", ".jpeg")
_TIFF = (".tif", ".tiff")
#: Camera RAW files, read through rawpy.
RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".nef", ".arw", ".raf", ".orf", ".rw2", ".pef", ".srw")
#: The image files a capture may hold, by extension.
CAPTURE_SUFFIXES = (*_JPEG, ".png", *_TIFF, ".exr", *RAW_SUFFIXES)
#: Integer codes at or above this fraction of the largest are clipped: the largest, and LibRaw's
#: clip of a RAW file after white balance (one 16-bit code below it).
SATURATED_LEVEL = 1.0 - 1e-4
#: Files of a capture folder that are not one of its images.
_NOT_IMAGES = ("mask.png",)


class Capture(NamedTuple):
    """A capture's images, read."""

    #: float32 (K, H, W, 3) linear RGB.
    images: np.ndarray
    #: (K, H, W) bool: pixels at the largest code in a channel (clipped); all False for float images.
    saturated: np.ndarray
    #: The image files, in the order of `images`.
    paths: tuple[Path, ...]


def read_capture_image(path: str | Path, encoding: str | None = None) -> tuple[np.ndarray, bool]:
    """Read one image of a capture as linear RGB.

    Parameters
    ----------
    path : str or pathlib.Path
        A JPEG, PNG, TIFF, EXR or camera RAW file (by its extension).
    encoding : {"srgb", "linear"}, optional
        How its values map to light; default by bit depth: 8-bit sRGB, 16-bit and float
        linear. EXR and RAW images are linear.

    Returns
    -------
    image : numpy.ndarray
        float32 (H, W, 3); a gray image is replicated to 3 channels, an alpha channel dropped.
    integer_codes : bool
        Whether the file holds integer codes (its largest value clips).

    Raises
    ------
    DatasetError
        Naming the file: an unknown extension, a file that cannot be read, a shape that is not
        an image, non-finite values, ``"srgb"`` for an EXR or RAW image, a RAW file without
        rawpy installed.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    bits: int | None
    if suffix == ".png":
        values, bits = read_png(path)
    elif suffix in _JPEG:
        values, bits = _read_jpeg(path), 8
    elif suffix in _TIFF:
        values, bits = _read_tiff(path)
    elif suffix == ".exr":
        if encoding == "srgb":
            raise DatasetError(f"{path}: an EXR image is stored linear; the 'srgb' encoding does not apply to it")
        values, bits = read_exr(path), None
    elif suffix in RAW_SUFFIXES:
        if encoding == "srgb":
            raise DatasetError(f"{path}: a camera RAW file is linear; the 'srgb' encoding does not apply to it")
        values, bits = _read_raw(path), 16
    else:
        raise DatasetError(f"{path}: not a JPEG, PNG, TIFF, EXR or camera RAW file (by its extension)")
    if values.ndim == 2:
        values = np.repeat(values[..., None], 3, axis=2)
    if values.ndim != 3 or values.shape[2] < 3:
        raise DatasetError(f"{path}: expected a gray or RGB image, got shape {values.shape}")
    values = values[..., :3]
    if not np.isfinite(values).all():
        raise DatasetError(f"{path}: holds non-finite values")
    chosen = encoding or ("srgb" if bits == 8 else "linear")
    linear = srgb_to_linear(np.clip(values, 0.0, 1.0)) if chosen == "srgb" else np.clip(values, 0.0, None)
    return linear.astype(np.float32), bits is not None


def read_capture_images(
    paths: Sequence[Path], encoding: str | None = None, where: str | Path | None = None
) -> tuple[np.ndarray, bool]:
    """Read same-sized capture images into one stack (`read_capture_image` each).

    Parameters
    ----------
    paths : sequence of pathlib.Path
        At least one image.
    encoding : {"srgb", "linear"}, optional
    where : str or pathlib.Path, optional
        What the stack is read for, named when it would not fit in memory.

    Returns
    -------
    images : numpy.ndarray
        float32 (K, H, W, 3).
    integer_codes : bool
        Whether every file holds integer codes.

    Raises
    ------
    DatasetError
        As `read_capture_image`; images of different sizes; a stack too large for memory.
    ArgumentError
        Naming ``encoding``.
    """
    if encoding is not None and encoding not in ENCODINGS:
        raise ArgumentError("encoding", f"{encoding!r} is not one of {', '.join(ENCODINGS)}")
    check_stack_memory(list(paths), _header_size(paths[0]), where=where)
    first, integer_codes = read_capture_image(paths[0], encoding)
    size = first.shape[:2]
    images = np.empty((len(paths), *first.shape), dtype=np.float32)  # filled image by image
    images[0] = first
    for k, image_path in enumerate(paths[1:], start=1):
        image, integer = read_capture_image(image_path, encoding)
        if image.shape[:2] != size:
            raise DatasetError(
                f"{image_path}: size {format_size(image.shape)} differs from {paths[0].name}'s ({format_size(size)})"
            )
        images[k], integer_codes = image, integer_codes and integer
    return images, integer_codes


def capture_image_paths(folder: str | Path) -> list[Path]:
    """The images of a capture folder: its JPEG, PNG, TIFF, EXR or camera RAW files (``mask.png`` aside),
    in name order, numbers in names compared as numbers (``img2`` before ``img10``).

    Raises
    ------
    DatasetError
        Naming the folder: missing, not a folder, holding no image or images of several kinds.
    """
    folder = check_folder(folder)
    found = [
        path
        for path in folder.iterdir()
        if path.suffix.lower() in CAPTURE_SUFFIXES and path.name.lower() not in _NOT_IMAGES and path.is_file()
    ]
    if not found:
        raise DatasetError(f"{folder}: no image (JPEG, PNG, TIFF, EXR or camera RAW file)")
    kinds = sorted({_kind(path) for path in found})
    if len(kinds) > 1:
        raise DatasetError(f"{folder}: holds images of several kinds ({', '.join(kinds)}): keep one kind in the folder")
    return sorted(found, key=_natural_key)


def read_capture(paths: Sequence[Path], encoding: str | None = None, where: str | Path | None = None) -> Capture:
    """Read a capture's images and find their clipped pixels.

    Parameters
    ----------
    paths : sequence of pathlib.Path
    encoding : {"srgb", "linear"}, optional
    where : str or pathlib.Path, optional
        What the images are read for, named when they would not fit in memory.

    Returns
    -------
    Capture

    Raises
    ------
    DatasetError, ArgumentError
        As `read_capture_images`.
    """
    images, integer_codes = read_capture_images(paths, encoding, where)
    saturated = (
        np.asarray((images >= SATURATED_LEVEL).any(axis=-1))
        if integer_codes
        else np.zeros(images.shape[:3], dtype=bool)
    )
    return Capture(images, saturated, tuple(paths))


def _kind(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix in RAW_SUFFIXES:
        return "RAW"
    return "JPEG" if suffix in _JPEG else "TIFF" if suffix in _TIFF else suffix[1:].upper()


def _natural_key(path: Path) -> list[object]:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]


def _header_size(path: Path) -> tuple[int, int] | None:
    """(H, W) of an image from its header (no pixel decoded), None when it cannot tell."""
    if path.suffix.lower() in (".png", ".exr"):
        return image_size(path)
    if path.suffix.lower() in RAW_SUFFIXES:
        return None
    try:
        with Image.open(path) as image:
            return image.height, image.width
    except (OSError, UnidentifiedImageError, Image.DecompressionBombError):
        return None


def _read_jpeg(path: Path) -> np.ndarray:
    try:
        with Image.open(path) as image:
            return np.asarray(image.convert("RGB"), dtype=np.float64) / 255.0
    except (OSError, UnidentifiedImageError, Image.DecompressionBombError) as error:
        raise DatasetError(f"{path}: cannot be read as a JPEG image: {error}") from None


def _read_raw(path: Path) -> np.ndarray:
    """Values in [0, 1] of a camera RAW file, demosaiced and linear (the module docstring)."""
    try:
        import rawpy
    except ImportError:
        raise DatasetError(f"{path}: reading camera RAW files needs rawpy: pip install 'irtps[raw]'") from None
    try:
        with rawpy.imread(str(path)) as raw:
            rgb = raw.postprocess(
                gamma=(1, 1),
                no_auto_bright=True,
                adjust_maximum_thr=0.0,
                output_bps=16,
                use_camera_wb=True,
                user_flip=0,
            )
    except (rawpy.LibRawError, OSError, ValueError) as error:
        raise DatasetError(f"{path}: cannot be read as a camera RAW file: {error}") from None
    return rgb.astype(np.float64) / 65535.0


def _read_tiff(path: Path) -> tuple[np.ndarray, int | None]:
    """Values of a TIFF file in [0, 1] for integer codes (as they are for floats), and its
    bits per channel (None for floats)."""
    try:
        raw = tifffile.imread(path)
    except (OSError, ValueError, tifffile.TiffFileError) as error:
        raise DatasetError(f"{path}: cannot be read as a TIFF image: {error}") from None
    if np.issubdtype(raw.dtype, np.integer):
        return raw.astype(np.float64) / np.iinfo(raw.dtype).max, raw.dtype.itemsize * 8
    if np.issubdtype(raw.dtype, np.floating):
        return raw.astype(np.float64), None
    raise DatasetError(f"{path}: TIFF samples of type {raw.dtype} are not supported")
