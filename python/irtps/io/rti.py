"""Reflectance-transformation-imaging (RTI) folders, as dome users hold them: a light position
file ``*.lp`` (RTIBuilder, Relight) and the images it lists, JPEG, PNG, TIFF or camera RAW
(`irtps.io.capture`).

The ``.lp`` file holds the image count on its first line, then one line per image,
``filename x y z``: a unit vector toward the light (x right, y up, z toward the camera, the
contract's frame). A file name may be a path written on another machine (``C:\\dome\\a.jpg``):
when nothing is at it, the file of that name beside the ``.lp`` file is read. The lights'
strengths come from ``light_intensities.txt`` beside it when there is one (one RGB line per
``.lp`` line, in its order, as DiLiGenT's and as ``irtps calibrate`` writes it); without it,
`irtps.reconstruct` estimates them (`irtps.model.data.Dataset.irradiance_known` False). The
camera is orthographic, one world unit a pixel, with no floor and no environment; ``mask.png``
is optional.

8-bit images (JPEG, 8-bit PNG or TIFF) are read as sRGB, the encoding of cameras' JPEGs, and
linearised; 16-bit and float images are read as linear. `load_rti`'s ``encoding`` overrides
both.
"""

from __future__ import annotations

from pathlib import Path, PureWindowsPath
from typing import NamedTuple

import numpy as np

from irtps._shared.guarded import read_text
from irtps._shared.paths import check_file, check_folder, exists, optional_file
from irtps.errors import ArgumentError, DatasetError
from irtps.io.image_selection import ImageSelection, select_images
from irtps.io.capture import read_capture_images
from irtps.io.imageio import ENCODINGS, read_mask
from irtps.io.number_lines import check_intensities, three_number_lines
from irtps.model.data import Dataset
from irtps.model.scene import MIN_LIGHTS, Camera, Light, Scene, upward_problem

__all__ = ["load_rti", "lp_file", "rti_image_names", "rti_inputs"]

LP_SUFFIX = ".lp"
MASK_FILE = "mask.png"
#: The lights' RGB strengths, one line per ``.lp`` line, as DiLiGenT's (``irtps calibrate``
#: writes it); optional.
INTENSITIES_FILE = "light_intensities.txt"
#: How far the norm of a listed light direction may be from 1; within it, it is renormalised.
UNIT_TOLERANCE = 1e-2
_JPEG = (".jpg", ".jpeg")
_TIFF = (".tif", ".tiff")


def lp_file(folder: str | Path) -> Path | None:
    """The folder's ``*.lp`` file, None when it has none.

    Raises
    ------
    DatasetError
        When it has more than one: which lights go with the images is then not known.
    """
    found = sorted(path for path in Path(folder).iterdir() if path.suffix.lower() == LP_SUFFIX)
    if len(found) > 1:
        raise DatasetError(
            f"{folder}: {len(found)} light position files ({', '.join(p.name for p in found)}): keep one"
        )
    return found[0] if found else None


class _RtiFiles(NamedTuple):
    """What reading an RTI folder reads, found (and its ``.lp`` parsed) without decoding an
    image."""

    folder: Path
    lp: Path
    #: The lights of the images kept.
    lights: tuple[Light, ...]
    images: list[Path]
    selection: ImageSelection
    mask: Path | None
    #: ``light_intensities.txt``, when the folder has one.
    intensities: Path | None = None

    def paths(self) -> list[Path]:
        optional = [path for path in (self.mask, self.intensities) if path is not None]
        return [self.folder, self.lp, *self.images, *optional]


def rti_image_names(folder: str | Path) -> tuple[str, ...]:
    """The names of the images that a folder's ``.lp`` file lists, in its order (not read)."""
    return tuple(entry[0].name for entry in _read_lp(_the_lp(Path(folder))))


def rti_inputs(path: str | Path, *, exclude_images: str | None = None) -> list[Path]:
    """Every file and folder that `load_rti` reads: the folder, its ``.lp`` file, the images
    it lists but those left out, and the mask when present.

    Raises
    ------
    DatasetError, ArgumentError
        As `load_rti`, for what is found wrong without decoding an image.
    """
    return _rti_files(check_folder(path), exclude_images).paths()


def load_rti(path: str | Path, *, exclude_images: str | None = None, encoding: str | None = None) -> Dataset:
    """Read an RTI folder: a ``*.lp`` light position file and its images.

    Parameters
    ----------
    path : str or pathlib.Path
    exclude_images : str, optional
        Images to leave out, not read (`irtps.io.image_selection`): by file name, with or
        without its extension (a number names an image whose file name is that number).
    encoding : {"srgb", "linear"}, optional
        How the images' values map to light; default by bit depth: 8-bit images sRGB,
        16-bit and float ones linear.

    Returns
    -------
    Dataset
        Linear images in the ``.lp`` file's order, the lights' directions from it and their
        strengths from ``light_intensities.txt`` (relative), or unknown without it
        (``irradiance_known`` False); ``saturation`` 1.0 when every image holds integer codes
        (the largest clips).

    Raises
    ------
    DatasetError
        Naming the file (and line): no ``.lp`` file or several, a count that disagrees with
        its lines, a line that is not ``filename x y z``, an image that is missing, listed
        twice or not a JPEG, PNG, TIFF or RAW file that can be read, a direction that is not a
        unit vector (beyond 1e-2) or points away from the camera, fewer than 3 images,
        images of different sizes; a ``light_intensities.txt`` whose line count is not the
        ``.lp`` file's or whose line is not three non-negative numbers.
    ArgumentError
        Naming ``encoding`` or ``exclude_images``.
    """
    if encoding is not None and encoding not in ENCODINGS:
        raise ArgumentError("encoding", f"{encoding!r} is not one of {', '.join(ENCODINGS)}")
    files = _rti_files(check_folder(path), exclude_images)
    images, integer_codes = read_capture_images(files.images, encoding, where=files.lp)
    size = images.shape[1:3]
    mask = read_mask(files.mask, size) if files.mask is not None else np.ones(size, dtype=bool)
    return Dataset(
        scene=Scene(
            camera=Camera(width=size[1], height=size[0], pixel_size=1.0),
            lights=files.lights,
            relative_irradiance=files.intensities is not None,
        ),
        images=images,
        mask=mask,
        source=str(files.folder),
        saturation=1.0 if integer_codes else None,
        image_names=files.selection.names,
        excluded_images=files.selection.excluded,
        irradiance_known=files.intensities is not None,
    )


def _the_lp(folder: Path) -> Path:
    lp = lp_file(folder)
    if lp is None:
        raise DatasetError(f"{folder}: no light position file (*.lp)")
    check_file(lp)
    return lp


def _rti_files(folder: Path, exclude_images: str | None) -> _RtiFiles:
    lp = _the_lp(folder)
    entries = _read_lp(lp)
    if len(entries) < MIN_LIGHTS:
        raise DatasetError(f"{lp}: {len(entries)} images: photometric stereo needs at least {MIN_LIGHTS}")
    selection = select_images([entry[0].name for entry in entries], exclude_images, where=str(folder))
    kept = [entries[k] for k in selection.kept]
    for image, _, line in kept:
        check_file(image, f"listed on line {line} of {lp.name}")
    intensities = _intensities(folder / INTENSITIES_FILE, lp, len(entries))
    strengths = [np.ones(3)] * len(kept) if intensities is None else [intensities[k] for k in selection.kept]
    lights = tuple(
        Light(direction=direction, irradiance=strength) for (_, direction, _), strength in zip(kept, strengths)
    )
    mask = folder / MASK_FILE if optional_file(folder / MASK_FILE) else None
    intensities_file = None if intensities is None else folder / INTENSITIES_FILE
    return _RtiFiles(folder, lp, lights, [image for image, _, _ in kept], selection, mask, intensities_file)


def _intensities(path: Path, lp: Path, count: int) -> np.ndarray | None:
    """The (N, 3) RGB intensities of ``light_intensities.txt`` in the ``.lp`` file's order, or
    None when the folder has no such file."""
    if not optional_file(path):
        return None
    intensities, lines = three_number_lines(path)
    if len(intensities) != count:
        raise DatasetError(f"{path}: {len(intensities)} lines, but {lp.name} lists {count} images")
    check_intensities(path, intensities, lines)
    return intensities


def _read_lp(path: Path) -> list[tuple[Path, np.ndarray, int]]:
    """Each image of a ``.lp`` file with its unit light direction and line number."""
    lines = [(number, line.strip()) for number, line in enumerate(read_text(path).splitlines(), 1) if line.strip()]
    if not lines:
        raise DatasetError(f"{path}: empty: expected the image count, then 'filename x y z' lines")
    number, first = lines[0]
    if not first.isdigit():
        raise DatasetError(f"{path}: line {number}: expected the image count, got {first[:60]!r}")
    count, rows = int(first), lines[1:]
    if count != len(rows):
        raise DatasetError(f"{path}: line {number} counts {count} images, but {len(rows)} lines follow")
    entries: list[tuple[Path, np.ndarray, int]] = []
    seen: dict[str, int] = {}
    for number, line in rows:
        parts = line.rsplit(maxsplit=3)
        try:
            direction = np.array([float(value) for value in parts[1:]])
        except ValueError:
            direction = np.array([])
        if len(parts) != 4 or direction.shape != (3,) or not np.isfinite(direction).all():
            raise DatasetError(f"{path}: line {number}: expected 'filename x y z', got {line[:80]!r}")
        norm = float(np.linalg.norm(direction))
        if abs(norm - 1.0) > UNIT_TOLERANCE:
            raise DatasetError(f"{path}: line {number}: light direction is not a unit vector (norm {norm:.6g})")
        upward = upward_problem(direction[2] / norm)
        if upward is not None:
            raise DatasetError(f"{path}: line {number}: light direction {upward}")
        image = _image_path(path.parent, parts[0])
        if image.name in seen:
            raise DatasetError(f"{path}: line {number}: {image.name} is listed again (line {seen[image.name]})")
        seen[image.name] = number
        entries.append((image, direction / norm, number))
    return entries


def _image_path(folder: Path, name: str) -> Path:
    """The image a ``.lp`` line names: the path as written when something is there, else the
    file of that name (a Windows or POSIX path's last part) beside the ``.lp`` file."""
    written = folder / name
    if exists(written):
        return written
    return folder / PureWindowsPath(name).name
