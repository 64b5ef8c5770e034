"""Reflectance-transformation-imaging (RTI) folders, as dome users hold them: a light position
file ``*.lp`` (RTIBuilder, Relight) and the images it lists, JPEG, PNG, TIFF or camera RAW
(`irtps.io.capture`).

The ``.lp`` file holds the image count on its first line, then one line per image,
``filename x y z``: a unit vector toward the light (x right, y up, z toward the camera, the
contract's frame). A file name may be a path written on another machine (``C:\\dome\\a.jpg``):
when nothing is at it, the file of that name beside the ``.lp`` file is read. The lights'
strengths come from ``light_intensities.txt`` beside it when there is one (one RGB line per
``.lp`` line, in its order, as DiLiGenT's and as ``irtps calibrate`` writes it); without it,
`irtps.reconstruct` estimates them (`irtps.model.data.Dataset.irradiance_known` False). They
are relative (`irtps.model.scene.Scene.relative_irradiance`: a reconstruction finds their
scale), unless ``irtps calibrate``'s record beside them, ``calibration.json``, says they are
absolute (``"irradiance": "absolute"``: the matte sphere's albedo was given). The camera is
orthographic, one world unit a pixel, with no floor and no environment; ``mask.png``
is optional.

A ``.lp`` file kept elsewhere (``lights``: the one ``irtps calibrate`` wrote for a rig, with its
``light_intensities.txt`` beside it) gives a folder of images its lights without copying
anything into it: the images it names are then found in the folder (a path as written from
the folder, else the file of that name in it), and a ``.lp`` or ``light_intensities.txt`` the
folder holds is not read.

8-bit images (JPEG, 8-bit PNG or TIFF) are read as sRGB, the encoding of cameras' JPEGs, and
linearised; 16-bit and float images are read as linear. `load_rti`'s ``encoding`` overrides
both.
"""

from __future__ import annotations

import hashlib
from pathlib import Path, PureWindowsPath
from typing import NamedTuple

import numpy as np

from irtps._shared.guarded import parse_json, read_text
from irtps._shared.records import CALIBRATION
from irtps._shared.paths import check_file, check_folder, exists, optional_file, resolve_path
from irtps.errors import ArgumentError, DatasetError
from irtps.io.image_selection import ImageSelection, select_images
from irtps.io.capture import read_capture_images
from irtps.io.imageio import ENCODINGS, read_mask
from irtps.io.number_lines import check_intensities, three_number_lines
from irtps.model.data import Dataset
from irtps.model.scene import IRRADIANCE_KINDS, MIN_LIGHTS, Camera, Light, Scene, upward_problem

__all__ = ["light_file_record", "load_rti", "lp_file", "rti_image_names", "rti_inputs"]

LP_SUFFIX = ".lp"
MASK_FILE = "mask.png"
#: The lights' RGB strengths, one line per ``.lp`` line, as DiLiGenT's (``irtps calibrate``
#: writes it); optional.
INTENSITIES_FILE = "light_intensities.txt"
#: ``irtps calibrate``'s record, written beside the two; its ``irradiance`` says whether the
#: strengths are absolute.
CALIBRATION_RECORD = "calibration.json"
#: What a light position file given from outside the folder is, in errors.
_LIGHTS_FILE = "lights: a light position file (*.lp)"
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
    #: ``calibration.json`` when it says that the intensities are absolute.
    absolute_record: Path | None = None

    def paths(self) -> list[Path]:
        optional = [path for path in (self.mask, self.intensities, self.absolute_record) if path is not None]
        return [self.folder, self.lp, *self.images, *optional]


def rti_image_names(folder: str | Path, lights: str | Path | None = None) -> tuple[str, ...]:
    """The names of the images that a folder's ``.lp`` file (or `lights`, see `load_rti`)
    lists, in its order (not read)."""
    folder = Path(folder)
    return tuple(entry[0].name for entry in _read_lp(_the_lp(folder, lights), folder))


def rti_inputs(path: str | Path, *, exclude_images: str | None = None, lights: str | Path | None = None) -> list[Path]:
    """Every file and folder that `load_rti` reads: the folder, its ``.lp`` file (or
    `lights`), the images it lists but those left out, and the mask and the light
    intensities when present (with ``calibration.json`` when it makes them absolute).

    Raises
    ------
    DatasetError, ArgumentError
        As `load_rti`, for what is found wrong without decoding an image.
    """
    return _rti_files(check_folder(path), exclude_images, lights).paths()


def load_rti(
    path: str | Path,
    *,
    exclude_images: str | None = None,
    encoding: str | None = None,
    lights: str | Path | None = None,
) -> Dataset:
    """Read an RTI folder: a ``*.lp`` light position file and its images.

    Parameters
    ----------
    path : str or pathlib.Path
        The folder of the images (and of ``mask.png``, when there is one).
    exclude_images : str, optional
        Images to leave out, not read (`irtps.io.image_selection`): by file name, with or
        without its extension (a number names an image whose file name is that number).
    encoding : {"srgb", "linear"}, optional
        How the images' values map to light; default by bit depth: 8-bit images sRGB,
        16-bit and float ones linear.
    lights : str or pathlib.Path, optional
        A ``.lp`` file kept outside the folder, read instead of the folder's own: its images
        are found in the folder, and the strengths are read from the
        ``light_intensities.txt`` beside it (an ``irtps calibrate`` output folder holds both).

    Returns
    -------
    Dataset
        Linear images in the ``.lp`` file's order, the lights' directions from it and their
        strengths from ``light_intensities.txt`` (relative, or absolute when ``calibration.json``
        says so), or unknown without it (``irradiance_known`` False); ``saturation`` 1.0 when
        every image holds integer codes (the largest clips).

    Raises
    ------
    DatasetError
        Naming the file (and line): no ``.lp`` file or several (without `lights`), a count
        that disagrees with its lines, a line that is not ``filename x y z``, an image that is missing, listed
        twice or not a JPEG, PNG, TIFF or RAW file that can be read, a direction that is not a
        unit vector (beyond 1e-2) or points away from the camera, fewer than 3 images,
        images of different sizes; a ``light_intensities.txt`` whose line count is not the
        ``.lp`` file's or whose line is not three non-negative numbers; a ``calibration.json``
        beside it that is not JSON, or is ``irtps calibrate``'s and whose ``irradiance`` is not
        ``"absolute"``, ``"relative"`` or null.
    ArgumentError
        Naming ``encoding`` or ``exclude_images``.
    """
    if encoding is not None and encoding not in ENCODINGS:
        raise ArgumentError("encoding", f"{encoding!r} is not one of {', '.join(ENCODINGS)}")
    files = _rti_files(check_folder(path), exclude_images, lights)
    images, integer_codes = read_capture_images(files.images, encoding, where=files.lp)
    size = images.shape[1:3]
    mask = read_mask(files.mask, size) if files.mask is not None else np.ones(size, dtype=bool)
    return Dataset(
        scene=Scene(
            camera=Camera(width=size[1], height=size[0], pixel_size=1.0),
            lights=files.lights,
            relative_irradiance=files.intensities is not None and files.absolute_record is None,
        ),
        images=images,
        mask=mask,
        source=str(files.folder),
        saturation=1.0 if integer_codes else None,
        image_names=files.selection.names,
        excluded_images=files.selection.excluded,
        irradiance_known=files.intensities is not None,
    )


def light_file_record(path: str | Path) -> dict:
    """What a reconstruction records of a light position file kept outside its folder (the
    ``lights`` of `load_rti`): its absolute path, and one SHA-256 digest of its text and of
    the ``light_intensities.txt`` beside it, so that a resumed batch sees a calibration
    written again over the same file.

    Raises
    ------
    DatasetError
        Naming the file, when either cannot be read.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     _ = (Path(folder) / "rig.lp").write_text("3\\na.png 0 0 1\\nb.png 0.6 0 0.8\\nc.png 0 0.6 0.8\\n")
    ...     sorted(light_file_record(Path(folder) / "rig.lp"))
    ['file', 'sha256']
    """
    lp = check_file(path, _LIGHTS_FILE)
    digest = hashlib.sha256(read_text(lp).encode())
    intensities = lp.parent / INTENSITIES_FILE
    if optional_file(intensities):
        digest.update(b"\0" + read_text(intensities).encode())
        if _strengths_absolute(lp.parent):
            digest.update(b"\0absolute")
    return {"file": str(resolve_path(lp)), "sha256": digest.hexdigest()}


def _strengths_absolute(folder: str | Path) -> bool:
    """Whether the ``light_intensities.txt`` in `folder` holds absolute irradiances: True when
    ``irtps calibrate``'s record there (``calibration.json``, format ``irtps.calibration/1``)
    says ``"irradiance": "absolute"``. False without it, for another tool's file of that name,
    and for a record written before it said (its strengths were relative).

    Raises
    ------
    DatasetError
        Naming the record: it cannot be read or is not JSON, or it is ours and its
        ``irradiance`` is not ``"absolute"``, ``"relative"`` or null.

    Examples
    --------
    >>> import json, tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     before = _strengths_absolute(folder)
    ...     record = {"format": "irtps.calibration/1", "irradiance": "absolute"}
    ...     _ = (Path(folder) / "calibration.json").write_text(json.dumps(record))
    ...     before, _strengths_absolute(folder)
    (False, True)
    """
    path = Path(folder) / CALIBRATION_RECORD
    if not optional_file(path):
        return False
    record = parse_json(read_text(path), str(path))
    if not isinstance(record, dict) or record.get("format") != CALIBRATION:
        return False
    kind = record.get("irradiance")
    if kind is not None and kind not in IRRADIANCE_KINDS:
        raise DatasetError(
            f"{path}: irradiance is {kind!r}: expected one of {', '.join(map(repr, IRRADIANCE_KINDS))} or null"
        )
    return kind == "absolute"


def _the_lp(folder: Path, lights: str | Path | None) -> Path:
    """`lights`, or else the folder's own ``.lp`` file; checked to be a readable file."""
    if lights is not None:
        return check_file(lights, _LIGHTS_FILE)
    lp = lp_file(folder)
    if lp is None:
        raise DatasetError(f"{folder}: no light position file (*.lp)")
    check_file(lp)
    return lp


def _rti_files(folder: Path, exclude_images: str | None, lights_file: str | Path | None = None) -> _RtiFiles:
    lp = _the_lp(folder, lights_file)
    entries = _read_lp(lp, folder)
    if len(entries) < MIN_LIGHTS:
        raise DatasetError(f"{lp}: {len(entries)} images: photometric stereo needs at least {MIN_LIGHTS}")
    selection = select_images([entry[0].name for entry in entries], exclude_images, where=str(folder))
    kept = [entries[k] for k in selection.kept]
    names_hint = "" if lights_file is None else f" of {folder}: 'irtps calibrate --names-from' names a capture's images"
    for image, _, line in kept:
        check_file(image, f"listed on line {line} of {lp}{names_hint}")
    intensities_file = lp.parent / INTENSITIES_FILE
    intensities = _intensities(intensities_file, lp, len(entries))
    strengths = [np.ones(3)] * len(kept) if intensities is None else [intensities[k] for k in selection.kept]
    lights = tuple(
        Light(direction=direction, irradiance=strength) for (_, direction, _), strength in zip(kept, strengths)
    )
    mask = folder / MASK_FILE if optional_file(folder / MASK_FILE) else None
    absolute = intensities is not None and _strengths_absolute(lp.parent)
    return _RtiFiles(
        folder,
        lp,
        lights,
        [image for image, _, _ in kept],
        selection,
        mask,
        None if intensities is None else intensities_file,
        lp.parent / CALIBRATION_RECORD if absolute else None,
    )


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


def _read_lp(path: Path, folder: Path) -> list[tuple[Path, np.ndarray, int]]:
    """Each image of a ``.lp`` file, found in `folder`, with its unit light direction and line
    number."""
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
        image = _image_path(folder, parts[0])
        if image.name in seen:
            raise DatasetError(f"{path}: line {number}: {image.name} is listed again (line {seen[image.name]})")
        seen[image.name] = number
        entries.append((image, direction / norm, number))
    return entries


def _image_path(folder: Path, name: str) -> Path:
    """The image a ``.lp`` line names: the path as written (from `folder`) when something is
    there, else the file of that name (a Windows or POSIX path's last part) in `folder`."""
    written = folder / name
    if exists(written):
        return written
    return folder / PureWindowsPath(name).name
