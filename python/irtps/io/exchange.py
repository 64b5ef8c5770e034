"""Maps as other tools read them: normal maps as 16-bit PNG images in the OpenGL or the
DirectX convention (RTI viewers, Blender, game engines), depth and height maps as 32-bit
float TIFF and as 16-bit PNG with the scale that turns their levels back into values. (The
mesh as glTF binary is `irtps.io.mesh.write_glb`.)

irtps's own files (EXR) stay what it reads back; these are written beside them by
`irtps.save_reconstruction`.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import tifffile

from irtps._shared.atomic import atomic_write_bytes
from irtps.errors import ArgumentError
from irtps.io.imageio import write_png
from irtps._shared.checks import check_array, check_mask

__all__ = [
    "NORMAL_MAP_CONVENTIONS",
    "normal_map_image",
    "quantised_map",
    "write_float_tiff",
    "write_normal_png",
    "write_quantised_png",
]

#: How a normal map's green channel points: up the image (OpenGL: Blender, RTI viewers,
#: Unity) or down it (DirectX: Unreal, 3ds Max).
NORMAL_MAP_CONVENTIONS = ("opengl", "directx")
#: The levels of a 16-bit PNG.
_LEVELS = 65535


def normal_map_image(normals: np.ndarray, mask: np.ndarray, convention: str = "opengl") -> np.ndarray:
    """The colours of a tangent-space normal map of `normals`.

    Parameters
    ----------
    normals : numpy.ndarray
        (H, W, 3) unit normals, x right, y up the image, z toward the camera.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    convention : {"opengl", "directx"}
        OpenGL: R, G, B = (n + 1) / 2; DirectX flips the green channel (y down the image).

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3) in [0, 1]: (n + 1) / 2, and outside the mask the flat normal's
        (0.5, 0.5, 1), which viewers read as no relief.

    Raises
    ------
    ArgumentError
        Naming `normals`, `mask` or `convention`.

    Examples
    --------
    >>> import numpy as np
    >>> normals = np.zeros((1, 2, 3)); normals[0, 0] = (0.6, 0.8, 0.0)
    >>> normal_map_image(normals, np.array([[True, False]]))[0].tolist()
    [[0.800000011920929, 0.8999999761581421, 0.5], [0.5, 0.5, 1.0]]
    >>> normal_map_image(normals, np.array([[True, False]]), "directx")[0, 0, 1].round(3)
    np.float32(0.1)
    """
    if convention not in NORMAL_MAP_CONVENTIONS:
        raise ArgumentError("convention", f"{convention!r} is not one of {', '.join(NORMAL_MAP_CONVENTIONS)}")
    normals = check_array("normals", normals, (None, None, 3))
    mask = check_mask(mask, normals.shape[:2], match="normals")
    flat = np.array([0.0, 0.0, 1.0])
    shown = np.where(mask[..., None], np.nan_to_num(normals), flat)
    if convention == "directx":
        shown = shown * np.array([1.0, -1.0, 1.0])
    return np.clip((shown + 1.0) / 2.0, 0.0, 1.0).astype(np.float32)


def write_normal_png(path: str | Path, normals: np.ndarray, mask: np.ndarray, convention: str = "opengl") -> None:
    """Write `normal_map_image` (`normals`, `mask`, `convention`) as a 16-bit RGB PNG.

    Parameters
    ----------
    path : str or pathlib.Path
    normals, mask, convention
        As for `normal_map_image`.
    """
    write_png(path, normal_map_image(normals, mask, convention), bit_depth=16)


def quantised_map(values: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, dict]:
    """The 16-bit levels of a map and the scale that turns them back into values.

    Parameters
    ----------
    values : numpy.ndarray
        (H, W) a depth or height map (finite in the mask).
    mask : numpy.ndarray
        (H, W) bool, where `values` are known.

    Returns
    -------
    levels : numpy.ndarray
        uint16 (H, W): 0 outside the mask; inside, 1 at the smallest value, 65535 at the
        largest, evenly between.
    scale : dict
        ``offset`` and ``step``: a level L > 0 stands for ``offset + (L - 1) * step``
        (``step`` 0 when every value is the same); ``no_data``: 0.

    Raises
    ------
    ArgumentError
        Naming `values` (not finite in the mask) or `mask`.

    Examples
    --------
    >>> import numpy as np
    >>> levels, scale = quantised_map(np.array([[2.0, 4.0, 9.0]]), np.array([[True, True, False]]))
    >>> levels.tolist(), scale["offset"], scale["offset"] + 65534 * scale["step"]
    ([[1, 65535, 0]], 2.0, 4.0)
    """
    values = check_array("values", values, (None, None))
    mask = check_mask(mask, values.shape, match="values")
    inside = values[mask]
    if not np.isfinite(inside).all():
        raise ArgumentError("values", "not finite at some pixel of the mask")
    low, high = (float(inside.min()), float(inside.max())) if inside.size else (0.0, 0.0)
    step = (high - low) / (_LEVELS - 1)
    levels = np.zeros(values.shape, dtype=np.uint16)
    if step > 0:
        levels[mask] = np.rint((inside - low) / step).astype(np.uint16) + 1
    else:
        levels[mask] = 1
    return levels, {"offset": low, "step": step, "no_data": 0}


def write_quantised_png(path: str | Path, values: np.ndarray, mask: np.ndarray) -> dict:
    """Write `quantised_map` (`values`, `mask`) as a 16-bit gray PNG.

    Parameters
    ----------
    path : str or pathlib.Path
    values, mask
        As for `quantised_map`.

    Returns
    -------
    dict
        The scale (`quantised_map`), to record beside the file.
    """
    levels, scale = quantised_map(values, mask)
    write_png(path, levels.astype(np.float32) / _LEVELS, bit_depth=16)
    return scale


def write_float_tiff(path: str | Path, values: np.ndarray) -> None:
    """Write a map as a one-channel 32-bit float TIFF (zlib-compressed, by tifffile),
    atomically.

    Parameters
    ----------
    path : str or pathlib.Path
    values : numpy.ndarray
        (H, W).

    Raises
    ------
    ArgumentError
        Naming `values`.
    DatasetError
        If the file cannot be written.
    """
    values = check_array("values", values, (None, None))
    data = io.BytesIO()
    tifffile.imwrite(data, values.astype(np.float32), compression="zlib")
    atomic_write_bytes(path, data.getvalue())
