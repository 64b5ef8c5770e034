"""Image files (OpenEXR and PNG) through the Rust core ``irtps._core``.

Arrays are row-major, top row first: (H, W) for one channel, (H, W, 3) for RGB.
PNG values are linear, divided by ``2^bits - 1``. Errors raised by the core
(``ValueError``, ``OSError``) become `DatasetError` with the same message. A path that
is there but is not a readable regular file (a directory, a FIFO, a symlink loop ...) is
refused before it is opened, so that reading never blocks (see `irtps._shared.paths`).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from irtps import _core
from irtps._shared.checks import check_finite
from irtps.errors import DatasetError, IrtpsWarning
from irtps._shared.paths import MISSING, check_file, file_problem
from irtps._shared.resources import check_memory

# The largest image irtps reads or makes, declared by the model (the scene and options check it),
# importable here too.
from irtps.model.constants import MAX_IMAGE_PIXELS as MAX_IMAGE_PIXELS

PNG_BIT_DEPTHS = (8, 16)
"""Bit depths of PNG files that can be written."""


#: How the values of an image file map to light: "srgb" (the sRGB curve of cameras' JPEG
#: and 8-bit files), "linear".
ENCODINGS = ("srgb", "linear")


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """The linear light of sRGB-encoded values in [0, 1] (IEC 61966-2-1).

    Examples
    --------
    >>> srgb_to_linear(np.array([0.0, 0.04045, 0.5, 1.0])).round(5).tolist()
    [0.0, 0.00313, 0.21404, 1.0]
    """
    values = np.asarray(values, dtype=np.float64)
    return np.where(values <= 0.04045, values / 12.92, ((values + 0.055) / 1.055) ** 2.4)


def read_exr(path: str | Path) -> np.ndarray:
    """Read an OpenEXR file with channels R, G, B or a single Y: the image of its display
    window, in which the pixels of its data window are placed where that window lies; the
    display window's pixels outside the data window are 0, and data outside the display
    window are not read.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    numpy.ndarray
        float32, (H, W, 3) for R, G, B or (H, W) for Y.

    Raises
    ------
    DatasetError
        If the file is missing, unreadable, corrupt or has other channels.
    """
    _check_readable(path)
    return _core.read_exr(str(path))


def write_exr(path: str | Path, array: np.ndarray, compression: str = "zip") -> None:
    """Write a 32-bit float OpenEXR file (Y for (H, W), R, G, B for (H, W, 3)).

    Parameters
    ----------
    path : str or pathlib.Path
    array : numpy.ndarray
        (H, W) or (H, W, 3); converted to float32.
    compression : str
        Lossless either way: ``"zip"`` (deflate, the smaller file) or ``"rle"`` (runs of
        equal bytes: several times faster to write, and nearly as small for an image that
        is mostly one value, such as an object's light with 0 around it).

    Raises
    ------
    ArgumentError
        Naming ``compression`` when it is neither.
    """
    _core.write_exr(str(path), _image_array(path, array), compression)


def read_png(path: str | Path) -> tuple[np.ndarray, int]:
    """Read an 8- or 16-bit PNG file, alpha dropped.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    values : numpy.ndarray
        float32 in [0, 1] (stored value / (2^bits - 1)); (H, W) for gray,
        (H, W, 3) for colour.
    bit_depth : int
        8 or 16.
    """
    _check_readable(path)
    return _core.read_png(str(path))


def write_png(path: str | Path, array: np.ndarray, bit_depth: int = 8) -> None:
    """Write a gray ((H, W)) or RGB ((H, W, 3)) PNG of values in [0, 1] (clipped).

    Parameters
    ----------
    path : str or pathlib.Path
    array : numpy.ndarray
    bit_depth : {8, 16}
    """
    if bit_depth not in PNG_BIT_DEPTHS:
        raise DatasetError(f"{path}: PNG bit depth must be 8 or 16, got {bit_depth}")
    _core.write_png(str(path), _image_array(path, array), bit_depth)


def read_image(path: str | Path) -> np.ndarray:
    """Read an .exr or .png image as linear RGB.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3); a Y-only EXR or a gray PNG is replicated to 3 channels.

    Raises
    ------
    DatasetError
        If the file cannot be read, has an unknown extension or holds non-finite values.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".exr":
        image = read_exr(path)
    elif suffix == ".png":
        image, _ = read_png(path)
    else:
        raise DatasetError(f"{path}: unknown image type {suffix!r}: expected .exr or .png")
    if image.ndim == 2:
        image = np.repeat(image[:, :, None], 3, axis=2)
    check_finite(path, image, error=DatasetError)
    return image


def read_images(paths: Sequence[str | Path]) -> np.ndarray:
    """Read a stack of same-sized .exr / .png images in parallel, as linear RGB.

    Parameters
    ----------
    paths : sequence of str or pathlib.Path

    Returns
    -------
    numpy.ndarray
        float32 (K, H, W, 3).

    Raises
    ------
    DatasetError
        Naming the first file that cannot be read, differs in size from the
        first image, or holds non-finite values.
    """
    if not paths:
        raise DatasetError("no image files given")
    for path in paths:
        _check_readable(path)
    return _core.read_images([str(path) for path in paths])


def clip_negative(paths: Sequence[str | Path], images: np.ndarray) -> None:
    """Set the negative values of a stack of images to 0, in place, warning if there are any.

    Radiance cannot be negative, but dark-frame subtraction and denoising leave small
    negative values in real captures; photometric stereo reads them as no light.

    Parameters
    ----------
    paths : sequence of str or pathlib.Path
        The file of each image, for the warning.
    images : numpy.ndarray
        (K, ...) float array.

    Warns
    -----
    IrtpsWarning
        Naming the first image with negative values, their count and the lowest one.
    """
    negative = (images < 0).reshape(len(images), -1).sum(axis=1)
    if not negative.any():
        return
    first = int(np.flatnonzero(negative)[0])
    others = int(np.count_nonzero(negative)) - 1
    more = f" (and {others} more images have some)" if others else ""
    warnings.warn(
        f"{paths[first]}: {negative[first]} negative values (down to {images[first].min():g}) clipped to 0{more}",
        IrtpsWarning,
        stacklevel=2,
    )
    np.maximum(images, 0, out=images)


def read_mask(path: str | Path, shape: tuple[int, int]) -> np.ndarray:
    """Read a mask image: a pixel is in the mask if any channel is non-zero.

    Parameters
    ----------
    path : str or pathlib.Path
    shape : tuple of int
        The expected (H, W).

    Returns
    -------
    numpy.ndarray
        bool (H, W).

    Raises
    ------
    DatasetError
        If the file cannot be read, its size is not ``shape`` or no pixel is set.
    """
    mask = np.any(read_image(path) != 0.0, axis=2)
    if mask.shape != tuple(shape):
        raise DatasetError(f"{path}: size {format_size(mask.shape)} does not match the images ({format_size(shape)})")
    if not mask.any():
        raise DatasetError(f"{path}: the mask is empty (every pixel is zero)")
    return mask


def image_size(path: str | Path) -> tuple[int, int] | None:
    """The (H, W) an .exr or .png file claims in its header, read without decoding the pixels.

    For sizing what decoding a stack of images will need before doing it. The file must be a
    readable regular file (checked first, so that a FIFO does not block).

    Returns
    -------
    tuple of int or None
        None when the header cannot be parsed (an unknown type, a corrupt file): the
        decoder then reports the problem.

    Raises
    ------
    DatasetError
        If ``path`` is not a readable regular file.
    """
    check_file(path)
    try:
        with open(path, "rb") as file:
            head = file.read(_HEADER_BYTES)
    except OSError as error:
        raise DatasetError(f"{path}: cannot read ({error.strerror or error})") from None
    suffix = Path(path).suffix.lower()
    if suffix == ".png":
        return _png_size(head)
    if suffix == ".exr":
        return _exr_size(head)
    return None


_HEADER_BYTES = 1 << 16
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_EXR_MAGIC = b"\x76\x2f\x31\x01"


def _png_size(head: bytes) -> tuple[int, int] | None:
    if len(head) < 24 or not head.startswith(_PNG_SIGNATURE) or head[12:16] != b"IHDR":
        return None
    width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    return (height, width) if width > 0 and height > 0 else None


def _exr_size(head: bytes) -> tuple[int, int] | None:
    """The (H, W) that reading the first header of an EXR file takes memory for: the larger of
    its data window (decoded) and its display window (the image read)."""
    if not head.startswith(_EXR_MAGIC) or len(head) < 8:
        return None
    windows = _exr_windows(head)
    if windows is None or len(windows) < 2:
        return None
    return max(windows, key=lambda size: size[0] * size[1])


def _exr_windows(head: bytes) -> list[tuple[int, int]] | None:
    """The (H, W) of the data and display windows of the first header of an EXR file, in
    the header's order; None if one is empty or the header cannot be parsed."""
    windows = []
    at = 8
    while at < len(head) and head[at] != 0:
        name_end = head.find(b"\0", at)
        type_end = head.find(b"\0", name_end + 1) if name_end >= 0 else -1
        if type_end < 0 or type_end + 5 > len(head):
            return None
        name = head[at:name_end]
        length = int.from_bytes(head[type_end + 1 : type_end + 5], "little", signed=True)
        value = head[type_end + 5 : type_end + 5 + length]
        if length < 0 or len(value) < length:
            return None
        if name in (b"dataWindow", b"displayWindow") and length == 16:
            x0, y0, x1, y1 = (int.from_bytes(value[i : i + 4], "little", signed=True) for i in range(0, 16, 4))
            width, height = x1 - x0 + 1, y1 - y0 + 1
            if width <= 0 or height <= 0:
                return None
            windows.append((height, width))
        at = type_end + 5 + length
    return windows


def check_stack_memory(paths: list[Path], size: tuple[int, int] | None = None, where: str | Path | None = None) -> None:
    """Refuse, before decoding any, a stack of images that would not fit in memory.

    Parameters
    ----------
    paths : list of pathlib.Path
        The images, all of the first one's size.
    size : tuple of int, optional
        The (H, W) expected, used when the first image's header cannot be parsed.
    where : str or pathlib.Path, optional
        The folder or file that lists the images, named in the message (by default the
        first image's folder).

    Raises
    ------
    IrtpsError
        ``"WHERE: K images of WxH decoded as float32 RGB need X GB, more than the Y GB
        available"``.
    DatasetError
        If the first image is not a readable regular file.
    """
    claimed = image_size(paths[0])
    if claimed is not None and size is not None:
        claimed = max(claimed, (size[0], size[1]), key=lambda shape: shape[0] * shape[1])
    shape = claimed or size
    if shape is None:
        return
    check_memory(
        len(paths) * shape[0] * shape[1] * 3 * np.dtype(np.float32).itemsize,
        f"{paths[0].parent if where is None else where}: {len(paths)} images of {format_size(shape)} decoded as float32 RGB",
    )


def png_saturation(paths: list[Path]) -> float | None:
    """1.0 (the largest code value, read as 1) when every image is a PNG file, else None."""
    return 1.0 if all(path.suffix.lower() == ".png" for path in paths) else None


def format_size(shape: Sequence[int]) -> str:
    """An image size as ``"WxH"`` (width x height) from a shape starting with (H, W)."""
    return f"{shape[1]}x{shape[0]}"


def _image_array(path: str | Path, array: np.ndarray) -> np.ndarray:
    array = np.ascontiguousarray(array, dtype=np.float32)
    if not (array.ndim == 2 or (array.ndim == 3 and array.shape[2] == 3)):
        raise DatasetError(f"{path}: cannot write an array of shape {array.shape}: expected (H, W) or (H, W, 3)")
    return array


def _check_readable(path: str | Path) -> None:
    """Refuse, before opening it, a path that is there but is not a readable regular file.

    A missing file is left to the core, whose message says so.
    """
    problem = file_problem(path)
    if problem is not None and problem != MISSING:
        raise DatasetError(f"{path}: {problem}")
