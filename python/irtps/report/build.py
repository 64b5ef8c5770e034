"""A reconstruction folder as pictures: PNG figures and one self-contained HTML page.

`build_report` reads a folder written by ``irtps reconstruct`` (`irtps.save_reconstruction`)
and draws its figures; `write_report` writes them, with the page ``index.html`` that shows
them beside the run's parameters and metrics, to ``report/`` in that folder. The figures:

- ``normal.png``: the normal map in the standard encoding ``(n + 1) / 2``;
- ``albedo.png``: the albedo (`irtps.report.display.albedo_to_rgb` says how it is scaled);
- ``shading.png``: a shaded relief of the height field (`irtps.report.display.hillshade`);
- with ground truth: ``angular_error.png``, ``height_error.png``, ``albedo_error.png``;
- IRT-PS runs: ``indirect.png``, the estimated inter-reflected light, and
  ``convergence.png``, the error and height change per pass;
- ``agreement.png``: each image's brightness and spread against the fit
  (`irtps.ps.image_agreement`), the images farthest out named.

Ground truth comes from the data set named by ``run.json``'s ``source`` (or the one given
as ``truth``); without it the page says why there are no error maps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from irtps._shared.atomic import atomic_output_dir
from irtps.io.dataset import GroundTruth, load_ground_truth
from irtps.io.dataset_files import ground_truth_inputs, is_data_set
from irtps.report.display import albedo_to_rgb, hillshade, normal_to_rgb, object_window, radiance_to_rgb
from irtps.errors import DatasetError, IrtpsError
from irtps.model.metrics import ErrorMaps, Metrics, error_maps, evaluate
from irtps.report.figures import ERROR_SCALE_PERCENTILE, agreement_png, convergence_png, error_map_png, image_png
from irtps.report.shape_view import shape_mesh, shape_view_html, surface_colours
from irtps.model.camera import Camera
from irtps.ps.image_agreement import ImageAgreement
from irtps.io.imageio import read_exr, read_png
from irtps._shared.guarded import shown
from irtps._shared.output_rule import check_output
from irtps._shared.paths import folder_problem
from irtps.irt.folder import RECONSTRUCTION_FILES, load_reconstruction, load_run_record
from irtps.report.page import recorded_agreement, report_html
from irtps.report.rig_figure import rig_png, shows_a_rig
from irtps.io.dataset_files import SCENE_FILE
from irtps.model.scene import load_scene

__all__ = ["PAGE_FILE", "REPORT_FOLDER", "Report", "ReportFigure", "build_report", "report_inputs", "write_report"]

#: The report's folder inside a reconstruction folder, and its page.
REPORT_FOLDER = "report"
PAGE_FILE = "index.html"

#: How to give a report its ground truth, for the page.
NO_TRUTH_HINT = "give one with --truth DATASET"

#: World units per pixel assumed for runs whose run.json predates the recorded pixel size.
ASSUMED_PIXEL_SIZE = 1.0


@dataclass(frozen=True)
class ReportFigure:
    """One figure of a report.

    Attributes
    ----------
    name : str
        File name without ``.png``, e.g. ``"normal"``.
    title : str
        Short title (also drawn in the image).
    caption : str
        What the figure shows and how its colours are scaled.
    png : bytes
        The PNG file.
    wide : bool
        Shown across the page's full width (a plot with several panels).
    """

    name: str
    title: str
    caption: str
    png: bytes
    wide: bool = False


@dataclass
class Report:
    """What a report shows about one reconstruction folder.

    Attributes
    ----------
    run_dir : pathlib.Path
        The reconstruction folder.
    record : dict
        Its ``run.json`` (`irtps.irt.folder.load_run_record`).
    size : tuple of int
        (H, W) of the maps.
    object_pixels : int
        Pixels in the mask.
    window : tuple of slice
        The rows and columns the figures show (`irtps.report.display.object_window`).
    figures : list of ReportFigure
        In the order the page shows them.
    metrics : Metrics or None
        Errors against ground truth, None without it.
    ground_truth : str
        Where the ground truth came from, or why there is none.
    notes : list of str
        Anything else the reader should know (e.g. an assumed pixel size).
    shape_view : str or None
        The 3-D view's HTML (`irtps.report.shape_view`), None when the run's camera is not
        known.
    """

    run_dir: Path
    record: dict
    size: tuple[int, int]
    object_pixels: int
    window: tuple[slice, slice]
    figures: list[ReportFigure] = field(default_factory=list)
    metrics: Metrics | None = None
    ground_truth: str = ""
    notes: list[str] = field(default_factory=list)
    shape_view: str | None = None


def build_report(run_dir: str | Path, *, truth: str | Path | None = None) -> Report:
    """Read a reconstruction folder and draw its figures.

    Parameters
    ----------
    run_dir : str or pathlib.Path
        A folder written by ``irtps reconstruct`` (or `irtps.save_reconstruction`).
    truth : str or pathlib.Path, optional
        A data set with ground truth (irtps or DiLiGenT layout) to compare with; by
        default the run's source data set (``run.json`` ``source``) when it is still
        there and has ground truth.

    Returns
    -------
    Report

    Raises
    ------
    DatasetError
        Naming the folder or file: not a reconstruction folder, a malformed
        ``run.json`` or image.
    IrtpsError
        Naming it: a ``truth`` folder without ground truth.

    Examples
    --------
    >>> import tempfile
    >>> from irtps import reconstruct, save_reconstruction
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_reconstruction(reconstruct(data), folder + "/out")
    ...     report = build_report(folder + "/out")
    >>> [figure.name for figure in report.figures]
    ['normal', 'albedo', 'shading', 'agreement']
    >>> report.metrics is None, report.ground_truth
    (True, 'none, so no error maps: run.json names no source data set (give one with --truth DATASET).')
    """
    folder = Path(run_dir)
    record = load_run_record(folder)
    normals, albedo, height, mask = load_reconstruction(folder)
    window = object_window(mask)
    report = Report(run_dir=folder, record=record, size=mask.shape, object_pixels=int(mask.sum()), window=window)
    shown = mask[window]
    report.figures += [
        _normal_figure(normals[window], shown),
        _albedo_figure(albedo[window], shown),
        _shading_figure(height[window], shown, record, report.notes),
    ]
    rig = _rig_figure(record, height, mask, report.notes)
    if rig is not None:
        report.figures.append(rig)
    if (folder / "discontinuities.png").exists():
        report.figures.append(_discontinuity_figure(folder / "discontinuities.png", normals, mask, window))
    indirect = _indirect_figure(folder / "indirect", mask, window)
    if indirect is not None:
        report.figures.append(indirect)
    gt, report.ground_truth = _ground_truth(record, truth, mask.shape)
    if gt is not None:
        report.metrics = evaluate(mask=mask, normals=normals, albedo=albedo, height=height, gt=gt)
        maps = error_maps(mask=mask, normals=normals, albedo=albedo, height=height, gt=gt)
        report.figures += _error_figures(maps, report.metrics, window)
    if (len(record["history"]) > 1 or record.get("stop")) and any("residual" in step for step in record["history"]):
        report.figures.append(_convergence_figure(record["history"], record.get("chosen_pass"), record.get("stop")))
    agreement = recorded_agreement(record)
    if agreement is not None and not np.isnan(agreement.brightness).all():
        report.figures.append(_agreement_figure(record["images"], agreement))
    report.shape_view = _shape_view(
        folder, record, height, albedo, mask, gt, maps if gt is not None else None, report.notes
    )
    return report


def write_report(run_dir: str | Path, out: str | Path | None = None, *, truth: str | Path | None = None) -> Path:
    """Write the figures and the HTML page of a reconstruction folder, atomically.

    Parameters
    ----------
    run_dir : str or pathlib.Path
        A folder written by ``irtps reconstruct``.
    out : str or pathlib.Path, optional
        The report folder, replaced as a whole once complete; default ``run_dir/report``.
    truth : str or pathlib.Path, optional
        As for `build_report`.

    Returns
    -------
    pathlib.Path
        The page, ``out/index.html``; the figures are ``out/NAME.png``.

    Raises
    ------
    IrtpsError
        As for `build_report`; `irtps._shared.output_rule.OutputError` if ``out`` is, holds or
        lies inside one of `report_inputs`.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from irtps import reconstruct, save_reconstruction
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_reconstruction(reconstruct(data), folder + "/out")
    ...     page = write_report(folder + "/out")
    ...     files = sorted(path.name for path in page.parent.iterdir())
    >>> page.relative_to(folder).as_posix(), files
    ('out/report/index.html', ['agreement.png', 'albedo.png', 'index.html', 'normal.png', 'shading.png'])
    """
    folder = Path(run_dir)
    target = folder / REPORT_FOLDER if out is None else Path(out)
    check_output(target, report_inputs(folder, truth), force=True, option="out")
    report = build_report(folder, truth=truth)
    page = report_html(report)
    with atomic_output_dir(target) as temp:
        for figure in report.figures:
            (temp / f"{figure.name}.png").write_bytes(figure.png)
        (temp / PAGE_FILE).write_text(page, encoding="utf-8")
    return target / PAGE_FILE


def _normal_figure(normals: np.ndarray, mask: np.ndarray) -> ReportFigure:
    caption = (
        "Reconstructed normals in the standard encoding RGB = (n + 1) / 2: red grows with x (right), green with y "
        "(up), blue with z (toward the camera); a surface facing the camera is light blue. Grey: outside the mask."
    )
    return ReportFigure("normal", "Normals", caption, image_png(normal_to_rgb(normals, mask), "Normals"))


def _albedo_figure(albedo: np.ndarray, mask: np.ndarray) -> ReportFigure:
    rgb, scale = albedo_to_rgb(albedo, mask)
    if scale == 1.0:
        how = "unscaled: a reflectance in [0, 1]"
    else:
        how = f"× {scale:.3g}, which makes the 99th percentile of the object's values white (the albedo exceeds 1: its scale is relative)"
    caption = f"Reconstructed RGB albedo, {how}; sRGB-encoded for the screen. Grey: outside the mask."
    return ReportFigure("albedo", "Albedo", caption, image_png(rgb, "Albedo"))


def _shading_figure(height: np.ndarray, mask: np.ndarray, record: dict, notes: list[str]) -> ReportFigure:
    pixel_size = record.get("pixel_size")
    if pixel_size is None:
        pixel_size = ASSUMED_PIXEL_SIZE
        notes.append(
            f"run.json does not record the pixel size (an older irtps wrote it): the shaded relief assumes {ASSUMED_PIXEL_SIZE:g} world unit per pixel."
        )
    caption = (
        "The reconstructed height field (height.exr) as a matte grey surface lit from the upper left, 45° above the "
        "image plane: it shows the integrated shape itself, bumps and dents included. Grey: outside the mask."
    )
    return ReportFigure(
        "shading", "Shaded height field", caption, image_png(hillshade(height, mask, pixel_size), "Shaded height field")
    )


def _discontinuity_figure(
    path: Path, normals: np.ndarray, mask: np.ndarray, window: tuple[slice, slice]
) -> ReportFigure:
    """The normals, dimmed, with the pixels of the depth discontinuities in red."""
    values, _ = read_png(path)
    if values.shape[:2] != mask.shape:
        raise DatasetError(
            f"{path}: {values.shape[1]}x{values.shape[0]} pixels, the reconstruction has {mask.shape[1]}x{mask.shape[0]}"
        )
    edges = (values.reshape(*mask.shape, -1) > 0).any(axis=-1) & mask
    rgb = 0.35 + 0.4 * normal_to_rgb(normals, mask)
    rgb[edges] = (0.9, 0.1, 0.1)
    caption = (
        "The depth discontinuities (discontinuities.png) that the integration through the pinhole kept, in red, over "
        f"the normals dimmed: {int(edges.sum())} pixels on an edge across which the depth jumps (occluding contours). "
        "The mesh leaves the 2x2 blocks that they cross out, rather than joining the two sides with a wall."
    )
    return ReportFigure(
        "discontinuities", "Depth discontinuities", caption, image_png(rgb[window], "Depth discontinuities")
    )


def _indirect_figure(folder: Path, mask: np.ndarray, window: tuple[slice, slice]) -> ReportFigure | None:
    paths = sorted(folder.glob("*.exr"))
    if not paths:
        return None
    total = np.zeros((*mask.shape, 3))
    for path in paths:
        image = read_exr(path)
        if image.shape != total.shape:
            raise DatasetError(f"{path}: shape {image.shape} differs from the reconstruction's {total.shape}")
        total += image
    rgb, scale = radiance_to_rgb(total[window] / len(paths), mask[window])
    caption = (
        f"The inter-reflected light that IRT-PS estimated and removed in its last pass, averaged over the "
        f"{len(paths)} images (indirect/*.exr); × {scale:.3g} so that the 99th percentile is white, sRGB-encoded. "
        "Colour bled from coloured surroundings shows here; so does, at the object's edge, the light of the floor or box "
        "that the edge pixels see past the object (subtracted with it)."
    )
    return ReportFigure(
        "indirect", "Estimated inter-reflections", caption, image_png(rgb, "Estimated inter-reflections")
    )


def report_inputs(run_dir: str | Path, truth: str | Path | None = None) -> list[Path]:
    """What a report of `run_dir` reads: the reconstruction's files and what is read of the
    data set of its ground truth (`truth`, else the source recorded in ``run.json`` when it
    is there; `irtps.io.dataset_files.ground_truth_inputs`).

    Parameters
    ----------
    run_dir : str or pathlib.Path
        A folder written by ``irtps reconstruct``.
    truth : str or pathlib.Path, optional

    Returns
    -------
    list of pathlib.Path

    Raises
    ------
    DatasetError
        As `irtps.load_ground_truth`, for what is found wrong with the ground truth's data
        set without decoding a map.
    """
    folder = Path(run_dir)
    inputs = [folder / name for name in RECONSTRUCTION_FILES]
    if truth is None:
        try:
            truth = _recorded_source(load_run_record(folder))[0]
        except IrtpsError:
            return inputs  # the report itself says what is wrong with run.json
        if truth is None:
            return inputs  # no ground truth is read
    return [*inputs, *ground_truth_inputs(truth)]


def _recorded_source(record: dict) -> tuple[str | None, str]:
    """The source data set that ``run.json`` records, when it is a data set to compare with;
    else None, and why not (a recorded path may be anything: gone, the run itself, ``/``)."""
    source = record["source"]
    if source is None:
        return None, "run.json names no source data set"
    if folder_problem(source) is not None:
        return None, f"the source data set {shown(source, 200)} is not there"
    lights = record.get("lights") or {}
    if lights:
        return (
            None,
            f"the source {shown(source, 200)} is a folder of images given its lights by {shown(lights.get('file'), 200)}",
        )
    if not is_data_set(source):
        return None, f"the recorded source {shown(source, 200)} is not a data set"
    return source, ""


def _ground_truth(record: dict, truth: str | Path | None, size: tuple[int, int]) -> tuple[GroundTruth | None, str]:
    """The ground truth to compare with, and a sentence saying where it came from or why there is none."""
    if truth is not None:
        gt = load_ground_truth(truth, size)
        if gt is None:
            raise IrtpsError(f"{truth}: has no ground truth (gt/ or Normal_gt.mat)")
        return gt, f"from {truth}."
    source, why_not = _recorded_source(record)
    if source is None:
        return None, f"none, so no error maps: {why_not} ({NO_TRUTH_HINT})."
    gt = load_ground_truth(source, size)
    if gt is None:
        return None, f"none, so no error maps: the source data set {source} has none ({NO_TRUTH_HINT})."
    return gt, f"from the source data set {source}."


def _rig_figure(record: dict, height: np.ndarray, mask: np.ndarray, notes: list[str]) -> ReportFigure | None:
    """The rig around the object (`irtps.report.rig_figure`), when the recorded source data
    set has point lights or a mesh around the object."""
    source, _ = _recorded_source(record)
    if source is None or not (Path(source) / SCENE_FILE).is_file():
        return None
    try:
        scene = load_scene(Path(source) / SCENE_FILE)
    except IrtpsError as error:
        notes.append(f"The rig is not drawn: {error}")
        return None
    if not shows_a_rig(scene) or (scene.camera.height, scene.camera.width) != mask.shape:
        return None
    caption = (
        "The reconstructed surface (grey points, each pixel's on its camera ray) inside the source data set's "
        "surroundings given as a mesh (in their albedo), with its point lights (numbered stars, as its images) "
        "and the camera's optical centre (blue); world units."
    )
    return ReportFigure("rig", "The rig", caption, rig_png(scene, height, mask, "The rig"))


def _shape_view(
    folder: Path,
    record: dict,
    height: np.ndarray,
    albedo: np.ndarray,
    mask: np.ndarray,
    gt: GroundTruth | None,
    maps: ErrorMaps | None,
    notes: list[str],
) -> str | None:
    """The 3-D view of the reconstructed surface, beside the true one when the ground truth
    has a height or a depth map (`irtps.report.shape_view`)."""
    try:
        camera = _recorded_camera(record, mask.shape)
    except (IrtpsError, KeyError, TypeError, ValueError) as error:
        notes.append(f"The 3-D view is not shown: run.json's camera cannot be read ({error}).")
        return None
    errors = None if maps is None else maps.angular_deg
    scale = (
        None if errors is None or np.isnan(errors).all() else float(np.nanpercentile(errors, ERROR_SCALE_PERCENTILE))
    )
    breaks_file = folder / "discontinuities.png"
    breaks = None
    if breaks_file.exists():
        flags = read_png(breaks_file)[0] > 0
        breaks = np.asarray(flags.any(axis=-1) if flags.ndim == 3 else flags)
    meshes = [
        shape_mesh("reconstruction", camera, height, mask, surface_colours(albedo, mask, errors, scale), breaks=breaks)
    ]
    true_height = None if gt is None else _true_height(gt, camera, mask.shape)
    if true_height is not None:
        true_mask = np.isfinite(true_height) & mask
        if true_mask.any():
            assert gt is not None
            colours = surface_colours(gt.albedo, true_mask, None, None)
            meshes.append(shape_mesh("truth", camera, np.nan_to_num(true_height), true_mask, colours))
    shown_meshes = [mesh for mesh in meshes if mesh is not None]
    if not shown_meshes:
        return None
    caption = (
        "The surface in 3-D"
        + (", the true one on its right" if len(shown_meshes) > 1 else "")
        + f" ({'through the pinhole' if camera.projection == 'perspective' else 'orthographic heights'}, world units). "
        "Drag to turn, scroll to zoom; coloured by albedo or by the normals' angular error "
        + ("(the report's error colours)." if scale is not None else "(without ground truth: grey).")
    )
    return shape_view_html(shown_meshes, caption)


def _recorded_camera(record: dict, shape: tuple[int, int]) -> Camera:
    """The camera of a run (``run.json``'s ``camera``, or its pixel size, 1 when it has none)."""
    recorded = record.get("camera")
    if recorded and recorded.get("projection") == "perspective":
        x, y, z = (float(value) for value in recorded["optical_center"])
        return Camera(
            width=int(recorded["width"]),
            height=int(recorded["height"]),
            projection="perspective",
            fx=float(recorded["fx"]),
            fy=float(recorded["fy"]),
            cx=float(recorded["cx"]),
            cy=float(recorded["cy"]),
            optical_center=(x, y, z),
        )
    # an older run without its pixel size: 1 world unit a pixel, as the shaded relief says
    return Camera(width=shape[1], height=shape[0], pixel_size=float(record.get("pixel_size") or 1.0))


def _true_height(gt: GroundTruth, camera: Camera, shape: tuple[int, int]) -> np.ndarray | None:
    """The true heights (NaN where unknown): the ground truth's height map, or its depth turned
    into heights through the pinhole."""
    if gt.height is not None and gt.height.shape == shape:
        return gt.height.astype(np.float64)
    if gt.depth is not None and gt.depth.shape == shape and camera.projection == "perspective":
        assert camera.optical_center is not None
        return camera.optical_center[2] - gt.depth.astype(np.float64)
    return None


def _error_figures(maps: ErrorMaps, metrics: Metrics, window: tuple[slice, slice]) -> list[ReportFigure]:
    scale = "Colour scale from 0 to the 99th percentile; grey: not evaluated."
    figures = []
    if maps.angular_deg is not None:
        title = f"Angular error (mean {metrics.normal_mean_angular_deg:.2f}°)"
        caption = f"Angle between the reconstructed and the true normal, per pixel (median {metrics.normal_median_angular_deg:.2f}°). {scale}"
        figures.append(
            ReportFigure("angular_error", title, caption, error_map_png(maps.angular_deg[window], title, "degrees"))
        )
    if maps.height_aligned is not None:
        title = f"Height error (mean {metrics.height_error_aligned:.3g})"
        caption = (
            f"|H_true − H − c| per pixel, in world units, after removing the median offset c = {metrics.height_offset:.3g} "
            f"(normals fix the height only up to a constant). {scale}"
        )
        figures.append(
            ReportFigure(
                "height_error", title, caption, error_map_png(maps.height_aligned[window], title, "world units")
            )
        )
    if maps.albedo is not None:
        title = f"Albedo error (mean {metrics.albedo_error:.3g})"
        caption = f"|ρ_true − ρ| per pixel, averaged over R, G and B, without rescaling. {scale}"
        figures.append(
            ReportFigure("albedo_error", title, caption, error_map_png(maps.albedo[window], title, "|Δ albedo|"))
        )
    return figures


def _agreement_figure(names: list[str], agreement: ImageAgreement) -> ReportFigure:
    caption = (
        "Each image's observed brightness over the brightness the fit predicts (classic photometric stereo's fit of "
        "the images as they are), at the object pixels it lights within 60° of their fitted normal. Left: the median, "
        "over the median image's: an image far from 1 had another light or exposure than recorded. Right: the spread "
        "of the ratio (robust standard deviation of its logarithm): an image well above the others was taken as the "
        "object or the camera moved. The three images farthest out in each are named; leave one out with "
        "--exclude-images if it is faulty."
    )
    png = agreement_png(names, agreement.brightness, agreement.spread)
    return ReportFigure("agreement", "How each image agrees with the fit", caption, png, wide=True)


def _stop_title(stop: dict | None) -> str | None:
    """The convergence plot's title: where the loop stopped and why, in short."""
    if not isinstance(stop, dict):
        return None
    reasons = {
        "iterations": "the corrections asked for were made",
        "below_noise": "the first correction was below the normals' noise",
        "stalled": "the residual stopped falling",
    }
    reason = reasons.get(str(stop.get("reason")))
    return None if reason is None else f"Stopped after pass {stop.get('after_pass')}: {reason}"


def _convergence_figure(history: list[dict], chosen: int | None, stop: dict | None) -> ReportFigure:
    passes = [step["index"] for step in history]
    errors = [(step["metrics"] or {}).get("normal_mean_angular_deg") for step in history]
    residuals = [(step.get("residual") or {}).get("object") for step in history]
    caption = (
        "Pass 0 is classic photometric stereo; each later pass subtracts the estimated inter-reflections and fits "
        "again. Left (when the data set has ground truth): mean angular error. Right: each pass's reconstruction "
        "rendered again (direct light with cast shadows plus the bounces estimated) against the input images, "
        "Σ|rendered − observed| / Σ|observed| on the object: the measure of a run without ground truth. The ringed "
        "pass, the one with the lowest residual, is the result."
    )
    if isinstance(stop, dict) and isinstance(stop.get("message"), str):
        caption += f" The loop stopped after pass {stop.get('after_pass')}: {stop['message']}."
    return ReportFigure(
        "convergence",
        "Convergence of the iterations",
        caption,
        convergence_png(passes, errors, residuals, chosen, _stop_title(stop)),
        wide=True,
    )
