"""What each ``irtps`` command does with its parsed arguments: one ``run_COMMAND`` function
per command, which `irtps.cli.parser` sets as the command's ``run``."""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from irtps._shared.atomic import atomic_output_dir
from irtps._shared.by_name import files_by_name
from irtps._shared.output_rule import check_output
from irtps._shared.paths import check_folder, resolve_path
from irtps._shared.records import TABLE, stamp, written_by_irtps
from irtps.batch.cluster import connect, local_cluster
from irtps.batch.plan import output_names
from irtps.batch.run import reconstruct_many
from irtps.calibrate.circles import parse_circle
from irtps.calibrate.folder import LP_FILE, save_calibration
from irtps.calibrate.lights import calibrate_lights
from irtps.calibrate.summary import format_calibration
from irtps.batch.summary import SUMMARY_JSON, SUMMARY_MARKDOWN, summary_table, write_summary
from irtps.errors import DatasetError, IrtpsError
from irtps.evaluate.table import comparison_table, format_table, method_names
from irtps.geometry.placement import format_placement
from irtps.geometry.surface import depth_to_normals, height_to_normals
from irtps.io.capture import capture_image_paths, read_capture
from irtps.io.dataset import Dataset, GroundTruth, load_dataset, load_ground_truth, load_scene_object
from irtps.io.dataset_files import dataset_inputs, scene_object_inputs
from irtps.io.dataset_writer import save_dataset
from irtps.io.image_selection import exclusions_by_name, format_images_fitted
from irtps.irt.folder import load_reconstruction, save_reconstruction
from irtps.irt.reconstruct import load_and_reconstruct
from irtps.model.metrics import evaluate, format_metrics
from irtps.model.scene import MIN_LIGHTS
from irtps.model.options import (
    ClusterOptions,
    ReconstructOptions,
    RenderOptions,
    SynthOptions,
    TableOptions,
    from_arguments,
)
from irtps.ps.fit import format_lobe_share
from irtps.ps.image_agreement import format_image_agreement
from irtps.render.radiometry import format_albedo_scale
from irtps.render.renderer import Rendering, render
from irtps.render.synth import synthesize


def _bounce_files(rendering: Rendering) -> dict[str, np.ndarray]:
    """The per-bounce images as extra data-set files ``gt/bounceN/KKK.exr``."""
    files = {}
    for b, per_light in enumerate(rendering.bounces, start=1):
        for k, image in enumerate(per_light):
            files[f"gt/bounce{b}/{k:03d}.exr"] = image
    return files


def run_render(args: argparse.Namespace) -> None:
    """``irtps render``: render a data set's true object into a new data set."""
    options = from_arguments(RenderOptions, args)
    check_output(args.out, scene_object_inputs(args.dataset), force=args.force)
    scene, height, albedo, mask = load_scene_object(args.dataset)
    start = time.perf_counter()
    rendering = render(
        scene,
        height,
        albedo,
        mask,
        bounces=options.bounces,
        samples=options.samples,
        seed=options.seed,
        progress=not args.quiet,
    )
    seconds = time.perf_counter() - start
    camera = scene.camera
    if camera.optical_center is None:
        depth, normal = None, height_to_normals(height, mask, camera.orthographic_pixel_size)
    else:
        depth = np.where(mask, camera.optical_center[2] - height, 0)  # contract §1b: z = zc - d
        normal = depth_to_normals(depth, mask, camera)
    truth = GroundTruth(
        height=np.where(mask, height, 0), normal=normal, albedo=albedo, direct=rendering.direct, depth=depth
    )
    dataset = Dataset(scene=scene, images=rendering.images, mask=mask, gt=truth)
    record = {"command": "render", "source": str(resolve_path(args.dataset)), **options.to_dict()}
    save_dataset(dataset, args.out, extra=_bounce_files(rendering), rendering=record)
    if not args.quiet:
        print(
            f"rendered {len(scene.lights)} lights x {options.bounces} bounces at {options.samples} samples/pixel in {seconds:.1f} s -> {args.out}"
        )


def run_synth(args: argparse.Namespace) -> None:
    """``irtps synth``: synthesize a scene with ground truth and render it."""
    scene_options, options = from_arguments(SynthOptions, args), from_arguments(RenderOptions, args)
    check_output(args.out, [], force=args.force)
    start = time.perf_counter()
    settings = {"shape": args.shape, **scene_options.to_dict(), **options.to_dict()}
    dataset, rendering = synthesize(**settings, progress=not args.quiet)
    save_dataset(dataset, args.out, extra=_bounce_files(rendering), rendering={"command": "synth", **settings})
    if not args.quiet:
        seconds = time.perf_counter() - start
        indirect = rendering.indirect[:, dataset.mask].mean() / max(
            float(dataset.images[:, dataset.mask].mean()), 1e-12
        )
        print(
            f"synthesized {args.shape} ({scene_options.size}x{scene_options.size}, {scene_options.lights} lights, {scene_options.environment}) "
            f"in {seconds:.1f} s; inter-reflections are {100 * indirect:.1f}% of the object's light -> {args.out}"
        )


def _robust_line(asked: str, used: str | None, share: float | None) -> str:
    """What ``irtps reconstruct`` says of the robust mode of its fit."""
    if share is None:
        return f"robust mode {used}"
    if asked == "auto":
        return f"robust mode {used}, chosen by auto: {format_lobe_share(share, auto=True)}"
    return f"robust mode {used}; {format_lobe_share(share, used)}"


def run_reconstruct(args: argparse.Namespace) -> None:
    """``irtps reconstruct``: reconstruct one data set and report the run."""
    options = from_arguments(ReconstructOptions, args)
    inputs = dataset_inputs(
        args.data, exclude_images=args.exclude_images, intrinsics=args.intrinsics, lights=args.lights
    )
    check_output(args.out, inputs, force=args.force)
    dataset, result = load_and_reconstruct(
        args.data,
        options=options,
        progress=not args.quiet,
        exclude_images=args.exclude_images,
        intrinsics=args.intrinsics,
        encoding=args.encoding,
        lights=args.lights,
    )
    save_reconstruction(
        result,
        args.out,
        source=str(resolve_path(args.data)),
        intrinsics=args.intrinsics,
        normal_map=args.normal_map,
        encoding=args.encoding,
        lights=args.lights,
    )
    if not args.quiet:
        stages = ", ".join(f"{name} {seconds:.2f} s" for name, seconds in result.timings.items())
        print(f"reconstructed {args.data} ({options.method}; {stages}) -> {args.out}")
        if result.excluded_images:
            print(f"  {format_images_fitted(len(result.image_names), result.excluded_images)}")
        print(f"  {_robust_line(options.robust, result.robust_used, result.lobe_share)}")
        if result.irradiance_factors is not None:
            factors = result.irradiance_factors
            print(
                f"  irradiance scaled by each image's brightness against a first fit: {factors.min():.2f} to {factors.max():.2f} (--correct-brightness)"
            )
        if result.image_agreement is not None:
            for line in format_image_agreement(result.image_names, result.image_agreement):
                print(f"  {line}")
        if result.placement is not None:
            print(f"  placement: {format_placement(result.placement)}")
        if result.albedo_scale is not None:
            print(f"  {format_albedo_scale(result.albedo_scale)}")
        for step in result.history:
            residual = f"  residual {step.residual['object']:.4f}"
            if step.residual.get("surroundings") is not None:
                residual += f" (surroundings {step.residual['surroundings']:.4f})"
            change = "" if step.height_change is None else f"  height change {step.height_change:.4f}"
            error = (
                ""
                if step.metrics is None or step.metrics["normal_mean_angular_deg"] is None
                else f"  normal error {step.metrics['normal_mean_angular_deg']:.2f} deg"
            )
            chosen = "  <- result" if step.index == result.chosen else ""
            print(f"  pass {step.index}:{residual}{error}{change}{chosen}")
        if result.stop is not None:
            print(f"  stopped after pass {result.stop.after_pass}: {result.stop.message}")
        if dataset.gt is not None:
            metrics = evaluate(
                mask=result.mask, normals=result.normals, albedo=result.albedo, height=result.height, gt=dataset.gt
            )
            print(format_metrics(metrics))


def run_batch(args: argparse.Namespace) -> None:
    """``irtps batch``: reconstruct many data sets on a Dask cluster, with a summary."""
    options, cluster_options = from_arguments(ReconstructOptions, args), from_arguments(ClusterOptions, args)
    names = output_names(args.data)
    exclusions = exclusions_by_name(args.exclude_images, names)
    intrinsics = files_by_name("intrinsics", args.intrinsics, names)
    lights = files_by_name("lights", args.lights, names)
    check_output(
        args.out,
        _batch_inputs(args.data, exclusions, intrinsics, lights),
        force=args.force or _holds_batch_outputs(args.out),
    )
    if args.force and os.path.lexists(args.out) and not args.out.is_dir():
        args.out.unlink()  # OUT is a folder that the data sets' folders go into, not replaced as a whole
    if cluster_options.scheduler is None:
        threads = cluster_options.threads_per_worker
        cluster = local_cluster(cluster_options.workers, 1 if threads is None else threads)
    else:
        cluster = connect(cluster_options.scheduler)
    with cluster as client:
        results = reconstruct_many(
            args.data,
            args.out,
            options,
            client=client,
            progress=not args.quiet,
            resume=args.resume,
            exclude_images=exclusions,
            intrinsics=intrinsics,
            normal_map=args.normal_map,
            encoding=args.encoding,
            lights=lights,
        )
    write_summary(results, args.out, settings=options.to_dict())
    print(summary_table(results), end="")
    failed = sum(result.failed for result in results)
    if failed:
        raise IrtpsError(f"{failed} of {len(results)} data sets failed (see {args.out / SUMMARY_MARKDOWN})")
    if not args.quiet:
        reused = sum(result.status == "reused" for result in results)
        kept = f" ({reused} complete from an earlier run, kept)" if reused else ""
        print(
            f"{len(results) - reused} data sets reconstructed into {args.out}/{kept}; summary in {args.out / SUMMARY_MARKDOWN} and {args.out / SUMMARY_JSON}"
        )


def _batch_inputs(
    folders: list[Path],
    exclusions: dict[str, str | None],
    intrinsics: dict[str, Path | None],
    lights: dict[str, Path | None],
) -> list[Path]:
    """Every file and folder that a batch reads (`irtps.io.dataset_files.dataset_inputs`); of a data
    set that cannot be read, its folder and its intrinsics and light position files (its task
    fails as it reads, writing nothing)."""
    inputs: list[Path] = []
    for folder, images, camera, light_file in zip(
        folders, exclusions.values(), intrinsics.values(), lights.values(), strict=True
    ):
        try:
            inputs += dataset_inputs(folder, exclude_images=images, intrinsics=camera, lights=light_file)
        except IrtpsError:
            inputs += [path for path in (folder, camera, light_file) if path is not None]
    return inputs


def _holds_batch_outputs(out: Path) -> bool:
    """Whether ``out`` is a folder of an earlier batch, even one stopped before its summary:
    nothing in it but reconstruction folders, leftovers of atomic writes (hidden) and a summary."""
    try:
        entries = [entry for entry in out.iterdir() if not entry.name.startswith(".")]
    except OSError:  # missing, not a folder: check_output says what is wrong
        return False
    return all(
        entry.name in (SUMMARY_JSON, SUMMARY_MARKDOWN) or (entry.is_dir() and written_by_irtps(entry))
        for entry in entries
    )


def run_calibrate(args: argparse.Namespace) -> None:
    """``irtps calibrate``: each light's direction and strength from a capture of calibration spheres."""
    chrome = None if args.chrome is None else parse_circle(args.chrome, "chrome")
    matte = None if args.matte is None else parse_circle(args.matte, "matte")
    paths = capture_image_paths(args.capture)
    if len(paths) < MIN_LIGHTS:
        raise DatasetError(
            f"{args.capture}: {len(paths)} images: a calibration needs at least {MIN_LIGHTS}, one light each"
        )
    names = [path.name for path in paths]
    inputs: list[Path] = [args.capture, *paths]
    if args.names_from is not None:
        named = capture_image_paths(args.names_from)
        if len(named) != len(paths):
            raise DatasetError(
                f"{args.names_from}: {len(named)} images, but the capture {args.capture} has {len(paths)}: "
                "--names-from needs the images taken under the same lights, one each"
            )
        names, inputs = [path.name for path in named], [*inputs, args.names_from]
    check_output(args.out, inputs, force=args.force)
    capture = read_capture(paths, args.encoding, where=args.capture)
    calibration = calibrate_lights(
        capture.images,
        saturated=capture.saturated,
        chrome=chrome,
        matte=matte,
        matte_albedo=args.matte_albedo,
        names=[path.name for path in paths],
        where=str(args.capture),
    )
    written = save_calibration(
        calibration,
        args.out,
        names=names,
        mean_image=capture.images.mean(axis=0),
        source=str(resolve_path(args.capture)),
        encoding=args.encoding,
    )
    if not args.quiet:
        print(f"calibrated {len(paths)} lights from {args.capture} -> {args.out} ({', '.join(written)})")
        for line in format_calibration(calibration, names):
            print(f"  {line}")
        lights = args.out / LP_FILE
        if args.names_from is None:
            print(
                f"  for a capture taken under these lights: irtps calibrate {args.capture} --out {args.out} "
                f"--names-from CAPTURE (to name its images), then irtps reconstruct CAPTURE --lights {lights} --out RESULT"
            )
        else:
            print(f"  next: irtps reconstruct {args.names_from} --lights {lights} --out RESULT")


def run_evaluate(args: argparse.Namespace) -> None:
    """``irtps evaluate``: print a reconstruction's errors against ground truth."""
    normals, albedo, height, mask = load_reconstruction(args.out)
    truth = load_ground_truth(args.gt, mask.shape)
    if truth is None:
        raise DatasetError(f"{args.gt}: has no ground truth (gt/ or Normal_gt.mat)")
    metrics = evaluate(mask=mask, normals=normals, albedo=albedo, height=height, gt=truth)
    print(json.dumps(metrics.to_dict(), indent=2) if args.json else format_metrics(metrics))


def run_report(args: argparse.Namespace) -> None:
    """``irtps report``: figures and a web page of a reconstruction."""
    # Imported here: matplotlib, which the report draws with, would slow down every other command's start.
    from irtps.report.build import REPORT_FOLDER, report_inputs, write_report

    check_folder(args.out, missing="no such reconstruction folder")
    out = args.out / REPORT_FOLDER if args.report_out is None else args.report_out
    check_output(out, report_inputs(args.out, args.truth), force=args.force)
    page = write_report(args.out, out, truth=args.truth)
    if not args.quiet:
        figures = sorted(path.name for path in page.parent.glob("*.png"))
        print(f"report of {args.out}: {len(figures)} figures ({', '.join(figures)}) and the page {page}")


def _make_table(
    datasets, options: TableOptions, quiet: bool, out: Path | None, sources: dict[str, str] | None = None
) -> str:
    """Compute the comparison table and write it under `out`; with `sources` (data set name ->
    the path recorded as its source), the reconstructions too."""
    from tqdm import tqdm

    total = len(datasets) * len(method_names(options.bounces, options.paper))
    with tqdm(total=total, desc="table", unit="run", disable=quiet, leave=False) as bar:

        def finished(name, method, result):
            if sources is not None and out is not None:
                save_reconstruction(result, out / name / method, source=sources[name])
            bar.update(1)

        table = comparison_table(datasets, options, on_result=finished)
    text = format_table(table)
    if out is not None:
        (out / "table.md").write_text(text)
        (out / "table.json").write_text(json.dumps({**stamp(TABLE), **table}, indent=2))
    return text


def run_table(args: argparse.Namespace) -> None:
    """``irtps table``: the paper's comparison table of data sets with ground truth."""
    options = from_arguments(TableOptions, args)
    names = output_names(args.data)
    exclusions = exclusions_by_name(args.exclude_images, names)
    intrinsics = files_by_name("intrinsics", args.intrinsics, names)
    if args.out is not None:
        inputs = [
            path
            for folder, name in zip(args.data, names, strict=True)
            for path in dataset_inputs(folder, exclude_images=exclusions[name], intrinsics=intrinsics[name])
        ]
        check_output(args.out, inputs, force=args.force)
    datasets = [
        (name, load_dataset(folder, exclude_images=exclusions[name], intrinsics=intrinsics[name]))
        for name, folder in zip(names, args.data, strict=True)
    ]
    if args.out is None:
        print(_make_table(datasets, options, args.quiet, None), end="")
        return
    with atomic_output_dir(args.out) as folder:
        text = _make_table(datasets, options, args.quiet, folder)
    print(text, end="")
    if not args.quiet:
        print(f"table written to {args.out / 'table.md'} and {args.out / 'table.json'}")


def run_demo(args: argparse.Namespace) -> None:
    """``irtps demo``: synthesize a scene, reconstruct it both ways, print the table."""
    options = from_arguments(TableOptions, args)
    size = from_arguments(SynthOptions, args).size  # the demo's only scene option
    check_output(args.out, [], force=args.force)
    start = time.perf_counter()
    settings: dict[str, Any] = {
        "shape": "cap",
        "size": size,
        "lights": 12,
        "environment": "cornell",
        "bounces": 4,
        "samples": 256,
        "seed": options.seed,
    }
    with atomic_output_dir(args.out) as folder:
        dataset, rendering = synthesize(**settings, progress=not args.quiet)
        save_dataset(
            dataset, folder / "data", extra=_bounce_files(rendering), rendering={"command": "demo", **settings}
        )
        # Recorded as the final place of the data set, which `irtps report` reads ground truth from.
        text = _make_table(
            [("cap_cornell", dataset)], options, args.quiet, folder, {"cap_cornell": str(args.out.resolve() / "data")}
        )
    share = rendering.indirect[:, dataset.mask].mean() / dataset.images[:, dataset.mask].mean()
    print(
        f"A {size}x{size} spherical cap on the floor of a Cornell box (red and green walls), 12 lights; "
        f"inter-reflections are "
        f"{100 * share:.0f}% of the light on the object. Errors of classic photometric stereo (PS) and of IRT-PS "
        f"estimating r = {', '.join(map(str, options.bounces))} bounces (best in bold; lower is better):\n"
    )
    print(text)
    print(
        f"Done in {time.perf_counter() - start:.0f} s. Outputs in {args.out}/: data/ (the synthetic data set with ground "
        f"truth), cap_cornell/PS/, cap_cornell/IRTPSr*/ and cap_cornell/Paper-r*/ (normals, albedo, height, mesh.ply, mesh.obj, "
        f"run.json), "
        f"table.md, table.json. See one as pictures with: irtps report {args.out / 'cap_cornell' / method_names(options.bounces, False)[-1]}"
    )
