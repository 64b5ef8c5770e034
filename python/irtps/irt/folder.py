"""The reconstruction folder: `save_reconstruction` writes it, `load_reconstruction` and
`load_run_record` read it back.

Its files (`RECONSTRUCTION_FILES`): the maps as EXR and PNG, the maps and the mesh as other
tools read them (`irtps.io.exchange`), the meshes, ``run.json`` and, for IRT-PS,
``indirect/``. Here rather than in `irtps.io`, the layer of files, because it writes
a `irtps.irt.reconstruct.Reconstruction`, whose pass history and albedo scale belong to
higher layers than ``io``.
"""

from __future__ import annotations

import json
import os
import platform
import re
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from pathlib import Path, PurePosixPath

import numpy as np

from irtps._shared.atomic import atomic_output_dir
from irtps._shared.checks import check_path
from irtps._shared.guarded import read_json
from irtps._shared.paths import check_file, check_folder, resolve_path
from irtps._shared.records import RUN, stamp
from irtps.errors import ArgumentError, DatasetError
from irtps.io.dataset import read_albedo_map, read_height_map, read_normal_map
from irtps.io.exchange import NORMAL_MAP_CONVENTIONS, write_float_tiff, write_normal_png, write_quantised_png
from irtps.io.imageio import read_mask, write_exr, write_png
from irtps.io.mesh import height_field_mesh, pinhole_mesh, write_glb, write_obj, write_ply
from irtps.io.rti import light_file_record
from irtps.irt.reconstruct import Reconstruction
from irtps.model.scene import camera_to_dict
from irtps.ps.fit import FLAGS

#: Indirect images written at once, one per core up to 4 (on 2 cores, 2 writers take 0.7 of
#: one writer's time).
_EXR_WRITERS = max(1, min(4, os.cpu_count() or 1))
#: What a reconstruction folder holds (`save_reconstruction`); ``indirect`` for IRT-PS only,
#: the depth maps and ``discontinuities.png`` for a pinhole camera only.
RECONSTRUCTION_FILES = (
    "normal.exr",
    "albedo.exr",
    "height.exr",
    "mask.png",
    "mesh.ply",
    "mesh.obj",
    "run.json",
    "indirect",
    "depth.exr",
    "discontinuities.png",
    "normal.png",
    "height.tif",
    "height.png",
    "depth.tif",
    "depth.png",
    "mesh.glb",
)
#: An image name's stem that can name its file in ``indirect/``: plain, not hidden.
_PLAIN_STEM = re.compile(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]*")


def save_reconstruction(
    result: Reconstruction,
    path: str | Path,
    *,
    source: str | None = None,
    intrinsics: str | Path | None = None,
    normal_map: str = "opengl",
    encoding: str | None = None,
    lights: str | Path | None = None,
) -> None:
    """Write a reconstruction folder atomically.

    Files: ``normal.exr`` (R, G, B = nx, ny, nz), ``albedo.exr``, ``height.exr`` (Y),
    ``mask.png``, ``mesh.ply`` (binary; the height field with per-vertex albedo colour and
    normals; with a pinhole camera, the depth map's points in world coordinates, without the
    blocks that a discontinuity crosses: `irtps.io.mesh.pinhole_mesh`), ``mesh.obj`` (the same vertices, triangles and normals as Wavefront OBJ text,
    see `irtps.io.mesh`), ``run.json`` (parameters, pixel size, timings, versions, source,
    placement, IRT-PS history with each pass's residual, the pass chosen, the images fitted,
    how each agrees with the fit, those left out, and the factors of ``correct_brightness``)
    and, for IRT-PS, ``indirect/`` (for each image fitted, the estimate of
    its inter-reflected light that the chosen pass removed, with the surroundings' light in the
    edge pixels, `irtps.render.surroundings`, named as `indirect_file_names` says; none when that
    is pass 0). With a pinhole camera also ``depth.exr`` (Y: the depth along the optical axis,
    0 outside the mask; `Reconstruction.depth`) and ``discontinuities.png`` (8-bit: 1 at both
    pixels of each edge that is a depth discontinuity, 0 elsewhere).

    For other tools (`irtps.io.exchange`): ``normal.png`` (16-bit RGB normal map, (n + 1) / 2,
    in the `normal_map` convention, flat outside the mask), ``height.tif`` (32-bit float) and
    ``height.png`` (16-bit: 0 outside the mask, level L > 0 the height offset + (L - 1) step,
    both recorded in ``run.json`` under ``exports``), with a pinhole camera ``depth.tif`` and
    ``depth.png`` likewise, and ``mesh.glb`` (glTF 2.0 binary: the mesh of ``mesh.ply`` with its
    normals and linear albedo as vertex colours).

    Parameters
    ----------
    result : Reconstruction
    path : str or pathlib.Path
        The output folder; replaced only once everything is written.
    source : str, optional
        The input data set, recorded in ``run.json``.
    intrinsics : str or pathlib.Path, optional
        The ``K.txt`` that gave the data set its camera (``--intrinsics``), recorded in
        ``run.json`` (as an absolute path, beside the camera as ``scene.json`` holds it).
    normal_map : {"opengl", "directx"}
        The convention of ``normal.png``: green up the image (OpenGL), or down it (DirectX).
    encoding : {"srgb", "linear"}, optional
        How the images were decoded when they were read (`irtps.load_dataset`), recorded in
        ``run.json`` (None: by the layout).
    lights : str or pathlib.Path, optional
        The light position file that gave a folder of images its lights (``--lights``),
        recorded in ``run.json`` with a digest of it and of its intensities
        (`irtps.io.rti.light_file_record`).

    Raises
    ------
    ArgumentError
        If `result` is not a `Reconstruction`, or naming `normal_map`.
    DatasetError
        If the folder cannot be written.
    """
    if not isinstance(result, Reconstruction):
        raise ArgumentError("result", f"expected a Reconstruction, got {type(result).__name__}")
    if normal_map not in NORMAL_MAP_CONVENTIONS:
        raise ArgumentError("normal_map", f"{normal_map!r} is not one of {', '.join(NORMAL_MAP_CONVENTIONS)}")
    lights_record = None if lights is None else light_file_record(check_path("lights", lights))
    with atomic_output_dir(check_path("path", path)) as folder:
        write_exr(folder / "normal.exr", result.normals)
        write_exr(folder / "albedo.exr", result.albedo)
        write_exr(folder / "height.exr", result.height)
        write_png(folder / "mask.png", result.mask.astype(np.float32), bit_depth=8)
        if result.depth is not None:
            write_exr(folder / "depth.exr", result.depth)
        if result.discontinuities is not None:
            write_png(folder / "discontinuities.png", _edge_pixels(result.discontinuities), bit_depth=8)
        if result.depth is not None and result.camera is not None:
            vertices, faces, colors, normals = pinhole_mesh(
                result.depth,
                result.mask,
                result.camera,
                result.discontinuities,
                albedo=result.albedo,
                normals=result.normals,
            )
        else:
            vertices, faces, colors, normals = height_field_mesh(
                result.height, result.mask, result.pixel_size, albedo=result.albedo, normals=result.normals
            )
        write_ply(folder / "mesh.ply", vertices, faces, colors=colors, normals=normals)
        write_obj(folder / "mesh.obj", vertices, faces, normals=normals)
        write_glb(folder / "mesh.glb", vertices, faces, colors=colors, normals=normals)
        exports = _write_exports(folder, result, normal_map)
        run = {
            **stamp(RUN),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "source": source,
            "parameters": result.parameters,
            "pixel_size": result.pixel_size,
            "camera": None if result.camera is None else camera_to_dict(result.camera),
            "intrinsics": None if intrinsics is None else str(resolve_path(intrinsics)),
            "lights": lights_record,
            "encoding": encoding,
            "timings_s": result.timings,
            "flags": {name: int((result.flags[result.mask] == value).sum()) for value, name in FLAGS.items()},
            "placement": None if result.placement is None else result.placement.to_dict(),
            "history": [asdict(step) for step in result.history],
            "chosen_pass": result.chosen,
            "stop": None if result.stop is None else result.stop.to_dict(),
            "albedo_scale": None if result.albedo_scale is None else result.albedo_scale.to_dict(),
            "lobe_share": result.lobe_share,
            "robust_used": result.robust_used,
            "images": list(result.image_names),
            "excluded_images": list(result.excluded_images),
            "image_agreement": None if result.image_agreement is None else result.image_agreement.to_dict(),
            "irradiance_factors": None
            if result.irradiance_factors is None
            else [round(float(factor), 4) for factor in result.irradiance_factors],
            "estimated_irradiance": None
            if result.estimated_irradiance is None
            else np.round(result.estimated_irradiance, 5).tolist(),
            "exports": exports,
        }
        if result.object_indirect is not None:
            (folder / "indirect").mkdir()
            # A few at a time (the core compresses with the GIL released), each image made as
            # it is written: never more than the writers' images in memory. Run-length
            # compressed: each is 0 around the object, and K of them are written.
            names = indirect_file_names(result.image_names, len(result.object_indirect))
            with ThreadPoolExecutor(max_workers=_EXR_WRITERS) as writers:
                list(
                    writers.map(
                        lambda k: write_exr(folder / "indirect" / names[k], result.indirect_image(k), "rle"),
                        range(len(names)),
                    )
                )
        (folder / "run.json").write_text(json.dumps(run, indent=2))


def _write_exports(folder: Path, result: Reconstruction, normal_map: str) -> dict:
    """Write the maps other tools read (`irtps.io.exchange`) into `folder`; what ``run.json``
    records of them: the normal map's convention and each 16-bit map's scale."""
    write_normal_png(folder / "normal.png", result.normals, result.mask, normal_map)
    exports: dict = {"normal.png": {"convention": normal_map}}
    maps = {"height": result.height} if result.depth is None else {"height": result.height, "depth": result.depth}
    for name, values in maps.items():
        write_float_tiff(folder / f"{name}.tif", values)
        exports[f"{name}.png"] = write_quantised_png(folder / f"{name}.png", values, result.mask)
    return exports


def _edge_pixels(discontinuities: np.ndarray) -> np.ndarray:
    """float32 (H, W): 1 at both pixels of each edge marked in the bool (H, W, 2) map of
    edges to the right neighbour and to the pixel below, 0 elsewhere."""
    right, down = discontinuities[..., 0], discontinuities[..., 1]
    marked = right | down
    marked[:, 1:] |= right[:, :-1]
    marked[1:] |= down[:-1]
    return marked.astype(np.float32)


def indirect_file_names(image_names: Sequence[str], count: int) -> list[str]:
    """The files of a reconstruction's ``indirect/``, one for each of the `count` images fitted.

    Each image's own name with ``.exr`` for its extension (``001.exr`` for DiLiGenT's
    ``001.png``, ``000.exr`` for the contract layout's ``000.exr``), so that a file names
    the image whatever was left out; ``000.exr``, ``001.exr`` … by position where the names
    are not `count` distinct plain file names (letters, digits, ``_``, ``-``, ``.``).

    Examples
    --------
    >>> indirect_file_names(["021.png", "041.png"], 2)
    ['021.exr', '041.exr']
    >>> indirect_file_names(["a/x.png", "b/x.png"], 2)
    ['000.exr', '001.exr']
    """
    stems = [PurePosixPath(name).stem for name in image_names]
    if (
        len(stems) == count
        and len({stem.lower() for stem in stems}) == count
        and all(map(_PLAIN_STEM.fullmatch, stems))
    ):
        return [f"{stem}.exr" for stem in stems]
    return [f"{k:03d}.exr" for k in range(count)]


def load_reconstruction(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read the normals, albedo, height and mask of a reconstruction folder.

    Returns
    -------
    (normals (H, W, 3), albedo (H, W, 3), height (H, W), mask (H, W) bool)

    Raises
    ------
    DatasetError
        Naming the file: missing, unreadable, non-finite, or of another size than
        ``normal.exr``; a normal on the mask that is not a unit vector (irtps writes unit
        normals there, even where a pixel had no light: `_check_unit_normals`).
    """
    folder = check_folder(path, missing="no such reconstruction folder")
    normal_path = check_file(folder / "normal.exr", "not a reconstruction folder?")
    normals = read_normal_map(normal_path)
    size = normals.shape[:2]
    albedo = read_albedo_map(folder / "albedo.exr", size)
    height = read_height_map(folder / "height.exr", size)
    mask = read_mask(folder / "mask.png", size)
    _check_unit_normals(normal_path, normals, mask)
    return normals, albedo, height, mask


#: How far from 1 the length of a reconstruction's normal on its mask may be: float32 files
#: hold unit normals to 1e-7, half-float ones (written by other tools) to 1e-3.
NORMAL_LENGTH_TOLERANCE = 1e-2


def _check_unit_normals(path: Path, normals: np.ndarray, mask: np.ndarray) -> None:
    """Refuse a normal on the mask whose length is not 1 (within `NORMAL_LENGTH_TOLERANCE`):
    a zero normal would be scored as 90° off, an error of the file's, not of the shape's."""
    length = np.linalg.norm(normals, axis=-1)
    wrong = mask & (np.abs(length - 1.0) > NORMAL_LENGTH_TOLERANCE)
    if wrong.any():
        row, col = np.argwhere(wrong)[0]
        raise DatasetError(
            f"{path}: the normal at row {row}, column {col} has length {length[row, col]:.3g}, not 1 "
            f"({int(wrong.sum())} of the mask's {int(mask.sum())} normals are not unit vectors)"
        )


#: Fields of ``run.json`` that readers rely on, and the JSON types each may take.
_RUN_FIELDS = {
    "source": (str, type(None)),
    "parameters": (dict,),
    "timings_s": (dict,),
    "flags": (dict,),
    "history": (list,),
}
#: Fields that folders written by older versions of irtps lack.
_OPTIONAL_RUN_FIELDS = {
    "format": (str,),
    "pixel_size": (int, float),
    "placement": (dict, type(None)),
    "chosen_pass": (int, type(None)),
    "albedo_scale": (dict, type(None)),
    "lobe_share": (int, float, type(None)),
    "robust_used": (str, type(None)),
    "images": (list,),
    "excluded_images": (list,),
    "image_agreement": (dict, type(None)),
    "irradiance_factors": (list, type(None)),
    "camera": (dict, type(None)),
    "intrinsics": (str, type(None)),
    "lights": (dict, type(None)),
    "stop": (dict, type(None)),
}
_HISTORY_FIELDS = {
    "index": (int,),
    "height_change": (int, float, type(None)),
    "timings": (dict,),
    "metrics": (dict, type(None)),
}
_JSON_TYPE_NAMES = {
    dict: "an object",
    list: "a list",
    str: "a string",
    int: "a number",
    float: "a number",
    type(None): "null",
}


def load_run_record(path: str | Path) -> dict:
    """Read and check the ``run.json`` of a reconstruction folder.

    Parameters
    ----------
    path : str or pathlib.Path
        The reconstruction folder (from `save_reconstruction` or ``irtps reconstruct``).

    Returns
    -------
    dict
        The record as written by `save_reconstruction`. ``pixel_size``, ``placement``,
        ``chosen_pass`` and ``albedo_scale`` are absent from folders written before irtps
        recorded them.

    Raises
    ------
    DatasetError
        Naming the folder or the file and field: a missing folder or ``run.json``, text
        that is not JSON or is past the bounds of `irtps._shared.guarded`, a ``format`` other than
        ``irtps.run/1`` (folders written before irtps recorded it have none), or a field missing
        or of the wrong type (``source`` a string or null; ``parameters``, ``timings_s`` and
        ``flags`` objects; ``pixel_size`` a number; ``history`` a list of objects with an
        integer ``index``, a numeric or null ``height_change`` and an object or null
        ``metrics``). A `DatasetError` is an `IrtpsError` and a ``ValueError``.

    Examples
    --------
    >>> import tempfile
    >>> from irtps.irt.reconstruct import reconstruct
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_reconstruction(reconstruct(data), folder + "/out", source="cap")
    ...     record = load_run_record(folder + "/out")
    >>> record["source"], record["parameters"]["method"], record["history"]
    ('cap', 'ps', [])
    """
    folder = check_folder(path, missing="no such reconstruction folder")
    run_path = check_file(folder / "run.json", "not a reconstruction folder written by irtps reconstruct?")
    record = read_json(run_path)
    _check_fields(run_path, "", record, _RUN_FIELDS, _OPTIONAL_RUN_FIELDS)
    if record.get("format", RUN) != RUN:
        raise DatasetError(f"{run_path}: format {record['format']!r} is not a reconstruction's ({RUN!r})")
    for k, step in enumerate(record["history"]):
        _check_fields(run_path, f"history[{k}]", step, _HISTORY_FIELDS, {})
    return record


def _check_fields(run_path: Path, name: str, value, required: dict, optional: dict) -> None:
    """Raise `DatasetError` unless ``value`` is an object whose fields have the listed types."""
    if not isinstance(value, dict):
        raise DatasetError(f"{run_path}: {name or 'the file'} must be an object, found {json.dumps(value)[:40]}")
    prefix = f"{name}." if name else ""
    for field_name, types in {**required, **optional}.items():
        if field_name not in value:
            if field_name in required:
                raise DatasetError(f"{run_path}: {prefix}{field_name} is missing")
            continue
        item = value[field_name]
        if isinstance(item, bool) or not isinstance(item, types):
            expected = " or ".join(dict.fromkeys(_JSON_TYPE_NAMES[t] for t in types))
            raise DatasetError(f"{run_path}: {prefix}{field_name} must be {expected}, found {json.dumps(item)[:40]}")
