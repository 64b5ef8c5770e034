"""Resumed batches: whether an output folder of an earlier run is complete and can be kept."""

from __future__ import annotations

import json
from pathlib import Path

from irtps._shared.paths import resolve_path
from irtps.errors import IrtpsError
from irtps.io.dataset_files import dataset_image_names
from irtps.io.image_selection import select_images
from irtps.io.intrinsics import Intrinsics, read_intrinsics
from irtps.io.rti import light_file_record
from irtps.irt.folder import indirect_file_names, load_reconstruction, load_run_record
from irtps.model.options import ReconstructOptions

__all__ = ["complete_output"]


def complete_output(
    destination: str,
    source: str,
    options: ReconstructOptions,
    exclude_images: str | None,
    intrinsics: str | None = None,
    normal_map: str = "opengl",
    encoding: str | None = None,
    *,
    lights: str | None = None,
) -> tuple | None:
    """The normals, albedo, height and mask of a complete output folder of `source` made
    with `options`, leaving out the images of `exclude_images`, with the intrinsics file
    `intrinsics` (or none) and its camera as it reads now, its normal map in the convention
    `normal_map`, its images decoded by `encoding`, its lights from the light position file
    `lights` (or the folder's own) as it and its intensities read now (see
    `irtps.batch.task.reconstruct_to_folder`), and its recorded robust mode, or None."""
    folder = Path(destination)
    try:
        record = load_run_record(folder)
        maps = load_reconstruction(folder)
        exports = record.get("exports") or {}
        scaled = [name for name in exports if name != "normal.png"]  # height.png, depth.png
        files = ["mesh.ply", "mesh.obj", "mesh.glb", "normal.png", *scaled, *(Path(n).stem + ".tif" for n in scaled)]
        written = all(_nonempty_file(folder / name) for name in files)
        same_normal_map = (exports.get("normal.png") or {}).get("convention") == normal_map
        indirect = not record.get("chosen_pass") or _complete_indirect(folder / "indirect", record.get("images", []))
        excluded = select_images(dataset_image_names(source, lights=lights), exclude_images, where=source).excluded
        camera = None if intrinsics is None else read_intrinsics(intrinsics)
        light_file = None if lights is None else light_file_record(lights)
    except (IrtpsError, OSError):
        return None
    same_run = (
        record["source"] == str(resolve_path(source))
        and _same_options(record["parameters"], options)
        and tuple(record.get("excluded_images", ())) == excluded
        and _same_intrinsics(record, intrinsics, camera)
        and same_normal_map
        and record.get("encoding") == encoding
        and record.get("lights") == light_file
    )
    return (maps, record.get("robust_used")) if same_run and written and indirect else None


def _complete_indirect(folder: Path, images: list[str]) -> bool:
    """Whether a folder holds one file for each image fitted (`indirect_file_names`; images
    numbered from ``000.exr`` where ``run.json`` does not list them) and nothing else, none
    empty."""
    files = {file.name: file for file in folder.iterdir()}
    expected = indirect_file_names(images, len(images) if images else len(files))
    return bool(files) and files.keys() == set(expected) and all(map(_nonempty_file, files.values()))


def _same_intrinsics(record: dict, intrinsics: str | None, camera: Intrinsics | None) -> bool:
    """Whether a ``run.json`` was made with the intrinsics file `intrinsics` (or none), whose
    focal lengths and principal point (`camera`, as read now) its camera has."""
    if record.get("intrinsics") != (None if intrinsics is None else str(resolve_path(intrinsics))):
        return False
    if camera is None:
        return True
    recorded = record.get("camera") or {}
    return all(recorded.get(name) == getattr(camera, name) for name in ("fx", "fy", "cx", "cy"))


def _nonempty_file(path: Path) -> bool:
    return path.is_file() and path.stat().st_size > 0


def _same_options(recorded: dict, options: ReconstructOptions) -> bool:
    """Whether a ``run.json``'s parameters are `options`; an option left unset (None),
    which the reconstruction resolves for each data set, matches any recorded value."""
    wanted = json.loads(json.dumps(options.to_dict()))
    return recorded.keys() == wanted.keys() and all(
        value is None or recorded[key] == value for key, value in wanted.items()
    )
