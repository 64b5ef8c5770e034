"""The ``irtps`` command line."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from irtps._shared.atomic import atomic_output_dir
from irtps.batch.cluster import connect, local_cluster
from irtps.batch.plan import output_names
from irtps.batch.run import reconstruct_many
from irtps.batch.summary import SUMMARY_JSON, SUMMARY_MARKDOWN, summary_table, write_summary
from irtps.io.dataset import (
    Dataset,
    GroundTruth,
    dataset_inputs,
    load_dataset,
    load_scene_object,
    load_ground_truth,
    save_dataset,
    scene_object_inputs,
)
from irtps.errors import ArgumentError, IrtpsError, IrtpsWarning
from irtps.model.metrics import evaluate, format_metrics
from irtps.ps.image_agreement import format_image_agreement
from irtps.io.image_selection import exclusions_by_name, format_images_fitted
from irtps.model.options import (
    ClusterOptions,
    ReconstructOptions,
    int_argument,
    RenderOptions,
    SynthOptions,
    TableOptions,
    add_arguments,
    from_arguments,
)
from irtps._shared.output_rule import check_output, escaped
from irtps._shared.paths import check_folder, resolve_path
from irtps.geometry.placement import format_placement
from irtps.ps.fit import format_lobe_share
from irtps.render.radiometry import format_albedo_scale
from irtps._shared.records import TABLE, stamp, written_by_irtps
from irtps.irt.folder import load_reconstruction, save_reconstruction
from irtps.irt.reconstruct import load_and_reconstruct
from irtps.render.renderer import Rendering, render
from irtps._shared.resources import return_freed_memory
from irtps.geometry.surface import height_to_normals
from irtps.render.synth import SHAPES, synthesize
from irtps.evaluate.table import comparison_table, format_table, method_names

#: Argument groups of the reconstruction options.
RECONSTRUCT_GROUPS = {"IRT-PS": "IRT-PS (--method irtps)"}


def _bounce_files(rendering: Rendering) -> dict[str, np.ndarray]:
    """The per-bounce images as extra data-set files ``gt/bounceN/KKK.exr``."""
    files = {}
    for b, per_light in enumerate(rendering.bounces, start=1):
        for k, image in enumerate(per_light):
            files[f"gt/bounce{b}/{k:03d}.exr"] = image
    return files


def _cmd_render(args: argparse.Namespace) -> None:
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
    truth = GroundTruth(
        height=np.where(mask, height, 0),
        normal=height_to_normals(height, mask, scene.camera.pixel_size),
        albedo=albedo,
        direct=rendering.direct,
    )
    dataset = Dataset(scene=scene, images=rendering.images, mask=mask, gt=truth)
    record = {"command": "render", "source": str(resolve_path(args.dataset)), **options.to_dict()}
    save_dataset(dataset, args.out, extra=_bounce_files(rendering), rendering=record)
    if not args.quiet:
        print(
            f"rendered {len(scene.lights)} lights x {options.bounces} bounces at {options.samples} samples/pixel in {seconds:.1f} s -> {args.out}"
        )


def _cmd_synth(args: argparse.Namespace) -> None:
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


def _cmd_reconstruct(args: argparse.Namespace) -> None:
    options = from_arguments(ReconstructOptions, args)
    check_output(args.out, dataset_inputs(args.data, exclude_images=args.exclude_images), force=args.force)
    dataset, result = load_and_reconstruct(
        args.data, options=options, progress=not args.quiet, exclude_images=args.exclude_images
    )
    save_reconstruction(result, args.out, source=str(resolve_path(args.data)))
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
        if dataset.gt is not None:
            metrics = evaluate(
                mask=result.mask, normals=result.normals, albedo=result.albedo, height=result.height, gt=dataset.gt
            )
            print(format_metrics(metrics))


def _cmd_batch(args: argparse.Namespace) -> None:
    options, cluster_options = from_arguments(ReconstructOptions, args), from_arguments(ClusterOptions, args)
    exclusions = exclusions_by_name(args.exclude_images, output_names(args.data))
    check_output(args.out, _batch_inputs(args.data, exclusions), force=args.force or _holds_batch_outputs(args.out))
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


def _batch_inputs(folders: list[Path], exclusions: dict[str, str | None]) -> list[Path]:
    """Every file and folder that a batch reads (`irtps.io.dataset.dataset_inputs`); of a data
    set that cannot be read, its folder (its task fails as it reads, writing nothing)."""
    inputs: list[Path] = []
    for folder, images in zip(folders, exclusions.values(), strict=True):
        try:
            inputs += dataset_inputs(folder, exclude_images=images)
        except IrtpsError:
            inputs.append(folder)
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


def _cmd_evaluate(args: argparse.Namespace) -> None:
    normals, albedo, height, mask = load_reconstruction(args.out)
    truth = load_ground_truth(args.gt, mask.shape)
    if truth is None:
        raise IrtpsError(f"{args.gt}: has no ground truth (gt/ or Normal_gt.mat)")
    metrics = evaluate(mask=mask, normals=normals, albedo=albedo, height=height, gt=truth)
    print(json.dumps(metrics.to_dict(), indent=2) if args.json else format_metrics(metrics))


def _cmd_report(args: argparse.Namespace) -> None:
    # Imported here: matplotlib, which the report draws with, would slow down every other command's start.
    from irtps.report.build import REPORT_FOLDER, report_inputs, write_report

    check_folder(args.out, missing="no such reconstruction folder")
    out = args.out / REPORT_FOLDER if args.report_out is None else args.report_out
    check_output(out, report_inputs(args.out, args.truth), force=args.force)
    page = write_report(args.out, out, truth=args.truth)
    if not args.quiet:
        figures = sorted(path.name for path in page.parent.glob("*.png"))
        print(f"report of {args.out}: {len(figures)} figures ({', '.join(figures)}) and the page {page}")


def _run_table(
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


def _cmd_table(args: argparse.Namespace) -> None:
    options = from_arguments(TableOptions, args)
    names = output_names(args.data)
    exclusions = exclusions_by_name(args.exclude_images, names)
    if args.out is not None:
        inputs = [
            path
            for folder, name in zip(args.data, names, strict=True)
            for path in dataset_inputs(folder, exclude_images=exclusions[name])
        ]
        check_output(args.out, inputs, force=args.force)
    datasets = [
        (name, load_dataset(folder, exclude_images=exclusions[name]))
        for name, folder in zip(names, args.data, strict=True)
    ]
    if args.out is None:
        print(_run_table(datasets, options, args.quiet, None), end="")
        return
    with atomic_output_dir(args.out) as folder:
        text = _run_table(datasets, options, args.quiet, folder)
    print(text, end="")
    if not args.quiet:
        print(f"table written to {args.out / 'table.md'} and {args.out / 'table.json'}")


def _cmd_demo(args: argparse.Namespace) -> None:
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
        text = _run_table(
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


def _add_exclude_images(parser: argparse.ArgumentParser) -> None:
    """``--exclude-images`` of the commands that take many data sets."""
    parser.add_argument(
        "--exclude-images",
        metavar="[NAME=]LIST",
        action="append",
        default=[],
        help="images to leave out (not read), as for 'irtps reconstruct': LIST for every DATA, NAME=LIST for the DATA named NAME "
        "(its folder's name, as in the summary: bearPNG=1-20); repeat it for more, a data set's lists are joined",
    )


def _add_force(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace OUT even if it is an existing file, or a folder with content that irtps did not write (never an input)",
    )


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line, like every other error of irtps."""

    def error(self, message: str):
        self.exit(2, f"irtps: error: {escaped(message)} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``irtps`` command."""
    parser = _Parser(
        prog="irtps",
        description="Iterative Ray Tracing Photometric Stereo: shape and colour from photometric-stereo images, "
        "with inter-reflections removed by ray tracing.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps demo\n  irtps synth cavity --out cavity\n  irtps reconstruct cavity --out cavity_ps\n"
        "  irtps evaluate cavity_ps --gt cavity\n  irtps batch cavity cap --out runs\n  irtps report cavity_ps\n  irtps render cavity --out cavity_rerendered --samples 512\n\n"
        "Run 'irtps COMMAND --help' for a command's options.",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = commands.add_parser(
        "render",
        help="render a data set's true object: direct light and each inter-reflection bounce",
        description="Render the object of DATASET (scene.json, gt/height.exr, gt/albedo.exr, mask.png) under each of "
        "its lights and write a complete data set to OUT: images/ (direct plus all bounces), gt/direct/, gt/bounceN/, "
        "gt/height.exr, gt/normal.exr, gt/albedo.exr, scene.json, mask.png. OUT is replaced atomically.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps render shared/data/mitsuba/cap_cornell --out cap_irtps\n"
        "  irtps render my_scene --out my_render --bounces 2 --samples 64 --quiet",
    )
    p.add_argument("dataset", type=Path, help="data set folder (contract layout)")
    p.add_argument("--out", type=Path, required=True, help="output data set folder")
    add_arguments(p, RenderOptions)
    _add_force(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.set_defaults(run=_cmd_render)

    p = commands.add_parser(
        "synth",
        help="synthesize a scene with ground truth and render it",
        description="Make a synthetic data set: a height-field SHAPE with uniform or textured albedo, lit by LIGHTS "
        "distant lights, optionally inside a Cornell box, rendered with inter-reflections; written to OUT in the "
        "contract layout with ground truth and each bounce separately.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps synth cap --out cap\n  irtps synth grooves --out grooves --environment none --size 128 --lights 20\n"
        "  irtps synth relief --out relief --albedo textured --seed 3",
    )
    p.add_argument("shape", choices=sorted(SHAPES), help="the object's shape")
    p.add_argument("--out", type=Path, required=True, help="output data set folder")
    add_arguments(p, SynthOptions)
    add_arguments(p, RenderOptions)
    _add_force(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.set_defaults(run=_cmd_synth)

    p = commands.add_parser(
        "reconstruct",
        help="recover normals, albedo, a height map and a mesh from a data set",
        description="Reconstruct the object of DATA (contract layout, or DiLiGenT layout, detected) and write OUT: "
        "normal.exr (R, G, B = nx, ny, nz), albedo.exr, height.exr, mask.png, mesh.ply (the height field with "
        "per-vertex albedo colour and normals), mesh.obj (the same mesh for any viewer) and run.json (parameters, "
        "timings, versions, the data set's path, the placement, the robust mode used and the lobe share that auto "
        "chose it by, the images fitted and those left out, and how each image agrees with the fit: one whose brightness "
        "is far from the others' had another light or exposure than recorded, one whose spread is wider was taken as "
        "the object or the camera moved); with --method irtps also "
        "indirect/NAME.exr (for each image NAME.png or NAME.exr fitted, the estimated inter-reflected light, with the "
        "floor's light in the edge pixels, that was subtracted) and each pass's residual in run.json: the reconstruction rendered again and compared with the "
        "images, the number to judge a run by without ground truth. The result is the pass with the lowest residual "
        "(pass 0 is classic PS). "
        "When DATA has ground truth, the errors are printed too. OUT is replaced atomically.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps reconstruct shared/data/diligent/ballPNG --out ball\n"
        "  irtps reconstruct shared/data/mitsuba/cap_cornell --out cap_irtps --method irtps --bounces 3\n"
        "  irtps reconstruct cavity --out cavity_ps --integration mestimator\n"
        "  irtps reconstruct capture --out capture_ps --saturation 0.99 --base-height boundary\n"
        "  irtps reconstruct shared/data/diligent/readingPNG --out reading --robust trim\n"
        "  irtps reconstruct metal_capture --out metal --robust lobe\n"
        "  irtps reconstruct rig_capture --out rig --method irtps --albedo-scale 0.8\n"
        "  irtps reconstruct bearPNG --out bear --exclude-images 1-20",
    )
    p.add_argument("data", type=Path, help="data set folder")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument(
        "--exclude-images",
        metavar="LIST",
        help="images to leave out (not read): numbers and ranges of numbers that match the images' numbered file names "
        "(1-20,37: DiLiGenT's 001.png ... 020.png and 037.png; the irtps layout's images count from 000.exr), or file "
        "names; for images a light misfired in, that the object moved in, or that cannot be read",
    )
    add_arguments(p, ReconstructOptions, groups=RECONSTRUCT_GROUPS)
    _add_force(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.set_defaults(run=_cmd_reconstruct)

    p = commands.add_parser(
        "batch",
        help="reconstruct many data sets on a Dask cluster, with a summary",
        description="Reconstruct each DATA into OUT/NAME/ (NAME: the folder's name, made unique with -2, -3 ...), "
        "the files of 'irtps reconstruct', each written atomically by the worker that reconstructed it. Runs on a "
        "local Dask cluster (one worker process per core, one data set at a time each) or, with --scheduler, on a "
        "running Dask cluster whose workers see the same file system under the same paths. A data set that fails is "
        "reported and the others go on. Prints a summary (status, seconds, mean angular error when there is ground "
        "truth, the error of a failed data set) and writes it to OUT/batch.md and OUT/batch.json; exits with status "
        "2 if any data set failed. Needs Dask: pip install 'irtps[batch]'.\n\n"
        "A worker process that dies (killed, out of memory) loses nothing: its data set runs again on another worker "
        "or the restarted one, up to 3 times (Dask's distributed.scheduler.allowed-failures), and the summary counts the "
        "lost workers; a data set that kills every worker that runs it fails with a KilledWorker error. With --resume, "
        "a batch run again (e.g. after it was stopped) keeps each output folder that is complete and reports it as "
        "'reused'.\n\n"
        "On a cluster with a shared file system: run 'dask scheduler' on one node, "
        "'RAYON_NUM_THREADS=1 dask worker tcp://HOST:8786 --nworkers $(nproc) --nthreads 1' on each compute node, "
        "then 'irtps batch ... --scheduler tcp://HOST:8786'.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps batch shared/data/diligent/*PNG --out diligent_ps\n"
        "  irtps batch shared/data/diligent/*PNG --out diligent_ps --exclude-images bearPNG=1-20\n"
        "  irtps batch scenes/* --out runs --method irtps --bounces 2 --workers 2 --threads-per-worker 4\n"
        "  irtps batch /shared/scenes/* --out /shared/runs --method irtps --scheduler tcp://head-node:8786\n"
        "  irtps batch scenes/* --out runs --method irtps --bounces 2 --resume   # after an interrupted run",
    )
    p.add_argument("data", type=Path, nargs="+", help="data set folders")
    p.add_argument(
        "--out", type=Path, required=True, help="folder for one reconstruction folder per data set and the summary"
    )
    _add_exclude_images(p)
    add_arguments(p, ReconstructOptions, groups=RECONSTRUCT_GROUPS)
    add_arguments(p.add_argument_group("cluster"), ClusterOptions)
    _add_force(p)
    p.add_argument(
        "--resume",
        action="store_true",
        help="keep each output folder that is complete (run.json, written last, records the same data set, options and images left out, and "
        "every file it goes with is there) instead of reconstructing it again; others are redone",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=_cmd_batch)

    p = commands.add_parser(
        "evaluate",
        help="compare a reconstruction with ground truth",
        description="Print the errors of the reconstruction in OUT against the ground truth of the data set GT "
        "(gt/ folder, or DiLiGenT's Normal_gt.mat): mean and median angular error, the IRT-PS paper's normal, "
        "albedo and height errors, and the height error after removing the best constant offset.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps evaluate ball --gt shared/data/diligent/ballPNG\n  irtps evaluate cavity_ps --gt cavity --json",
    )
    p.add_argument("out", type=Path, help="reconstruction folder (from irtps reconstruct)")
    p.add_argument("--gt", type=Path, required=True, help="data set folder with ground truth")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=_cmd_evaluate)

    p = commands.add_parser(
        "report",
        help="figures and a web page of a reconstruction",
        description="Draw the reconstruction in OUT as PNG figures: the normal map, the albedo, a shaded relief of the "
        "height field; with ground truth the angular, height and albedo error maps; for IRT-PS runs the estimated "
        "inter-reflected light and the convergence of the iterations. Write them with index.html, one self-contained "
        "page (figures embedded) that shows them beside the run's parameters and metrics, to OUT/report/ (replaced "
        "atomically). Ground truth comes from the data set recorded in OUT/run.json, or --truth.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps report cap_irtps\n  irtps report ball --truth shared/data/diligent/ballPNG\n"
        "  irtps report cap_irtps --out cap_irtps_report --quiet",
    )
    p.add_argument("out", metavar="OUT", type=Path, help="reconstruction folder (from irtps reconstruct)")
    p.add_argument(
        "--truth",
        metavar="DATASET",
        type=Path,
        default=None,
        help="data set with ground truth (default: the run's own data set, if it has any)",
    )
    p.add_argument(
        "--out", metavar="DIR", dest="report_out", type=Path, default=None, help="report folder (default OUT/report)"
    )
    _add_force(p)
    p.add_argument("--quiet", action="store_true", help="print nothing")
    p.set_defaults(run=_cmd_report)

    p = commands.add_parser(
        "table",
        help="the IRT-PS paper's comparison table: PS against IRT-PS r1, r2, r3",
        description="Reconstruct each DATA (with ground truth) by classic photometric stereo and by IRT-PS estimating "
        "1, 2 and 3 bounces, and print the errors in the layout of the paper's Table 1: rows Height (as reconstructed "
        "and offset-aligned), Albedo, Normal (the paper's metrics) and mean angular error, per data set and overall, "
        "best value in bold. --out writes table.md and table.json.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps table shared/data/mitsuba/cap_cornell shared/data/mitsuba/grooves_dark --out table\n"
        "  irtps table cavity --bounces 3 --iterations 4 --samples 128\n"
        "  irtps table rig_a rig_b --exclude-images rig_b=7,12",
    )
    p.add_argument("data", type=Path, nargs="+", help="data set folders with ground truth")
    p.add_argument("--out", type=Path, help="folder for table.md and table.json")
    _add_exclude_images(p)
    add_arguments(p, TableOptions)
    _add_force(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=_cmd_table)

    p = commands.add_parser(
        "demo",
        help="synthesize a scene with strong inter-reflection, reconstruct it both ways, print the table",
        description="The main job on an embedded default: synthesize a spherical cap on the floor of a Cornell box "
        "(light bounced from the floor and colour bled from the red and green walls), reconstruct it by classic "
        "photometric stereo and by IRT-PS, print the comparison table and write everything to OUT.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps demo\n  irtps demo --out demo --size 96 --samples 256",
    )
    p.add_argument("--out", type=Path, default=Path("irtps-demo"), help="output folder (default irtps-demo)")
    p.add_argument("--size", type=int_argument, default=64, help="image size in pixels (default 64)")
    add_arguments(p, TableOptions, defaults={"iterations": 5, "samples": 128})
    _add_force(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=_cmd_demo)
    return parser


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every partial output is removed on the way out."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise _Terminated()


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    if issubclass(category, IrtpsWarning):
        print(f"irtps: warning: {escaped(str(message))}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def _argument_name(parser: argparse.ArgumentParser, command: str, argument: str) -> str:
    """An argument's name as `command` takes it on the command line: ``exclude_images`` is
    ``--exclude-images`` (an argument that is no option of the command keeps its name)."""
    flag = "--" + argument.replace("_", "-")
    subcommands = next(action for action in parser._actions if isinstance(action, argparse._SubParsersAction))
    return flag if flag in subcommands.choices[command]._option_string_actions else argument


def main(argv: list[str] | None = None) -> int:
    """Run the ``irtps`` command; returns the exit status.

    0 on success; 2 on bad input, printed as ``irtps: error: ...`` naming the file or
    field; 130 on Ctrl-C and 143 on SIGTERM, after removing any partial output.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    return_freed_memory()
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default", IrtpsWarning)  # each message once
            warnings.showwarning = _show_warning
            args.run(args)
    except ArgumentError as err:
        print(
            f"irtps: error: {_argument_name(parser, args.command, err.argument)}: {escaped(err.problem)}",
            file=sys.stderr,
        )
        return 2
    except (IrtpsError, OSError) as err:
        print(f"irtps: error: {escaped(str(err))}", file=sys.stderr)
        return 2
    except MemoryError as err:
        print(f"irtps: error: not enough memory ({escaped(str(err)) or 'allocation failed'})", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:
        print("irtps: interrupted; no partial output was left", file=sys.stderr)
        return 128 + signal.SIGTERM if isinstance(interrupt, _Terminated) else 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0


if __name__ == "__main__":
    sys.exit(main())
