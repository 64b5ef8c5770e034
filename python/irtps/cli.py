"""The ``irtps`` command line."""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from irtps.atomic import atomic_output_dir
from irtps.batch import SUMMARY_JSON, SUMMARY_MARKDOWN, connect, local_cluster, reconstruct_many, summary_table, write_summary
from irtps.dataset import Dataset, GroundTruth, load_dataset, load_ground_truth, load_scene_object, save_dataset
from irtps.errors import IrtpsError, IrtpsWarning
from irtps.evaluate import evaluate, format_metrics
from irtps.integrate import METHODS as INTEGRATION_METHODS
from irtps.interreflection import ESTIMATORS, UPDATES
from irtps.reconstruct import METHODS, load_and_reconstruct, load_reconstruction, save_reconstruction
from irtps.render import Rendering, render
from irtps.surface import height_to_normals
from irtps.synth import SHAPES, synthesize
from irtps.table import comparison_table, format_table, method_names


def _bounce_files(rendering: Rendering) -> dict[str, np.ndarray]:
    """The per-bounce images as extra data-set files ``gt/bounceN/KKK.exr``."""
    files = {}
    for b, per_light in enumerate(rendering.bounces, start=1):
        for k, image in enumerate(per_light):
            files[f"gt/bounce{b}/{k:03d}.exr"] = image
    return files


def _add_render_options(parser: argparse.ArgumentParser, samples: int) -> None:
    parser.add_argument("--bounces", type=int, default=4, help="inter-reflection bounces to render (default 4)")
    parser.add_argument("--samples", type=int, default=samples, help=f"camera paths per pixel (default {samples})")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def _check_output(out: Path, *inputs: Path) -> None:
    """Refuse an output folder that is an input or holds one: replacing it would delete the input."""
    target = out.resolve()
    for source in inputs:
        resolved = source.resolve()
        if resolved == target or target in resolved.parents:
            raise IrtpsError(f"--out {out}: replacing it would delete the input {source}; choose another output folder")


def _cmd_render(args: argparse.Namespace) -> None:
    _check_output(args.out, args.dataset)
    scene, height, albedo, mask = load_scene_object(args.dataset)
    start = time.perf_counter()
    rendering = render(scene, height, albedo, mask, bounces=args.bounces, samples=args.samples, seed=args.seed, progress=not args.quiet)
    seconds = time.perf_counter() - start
    truth = GroundTruth(height=np.where(mask, height, 0), normal=height_to_normals(height, mask, scene.camera.pixel_size), albedo=albedo, direct=rendering.direct)
    dataset = Dataset(scene=scene, images=rendering.images, mask=mask, gt=truth)
    save_dataset(dataset, args.out, extra=_bounce_files(rendering))
    if not args.quiet:
        print(f"rendered {len(scene.lights)} lights x {args.bounces} bounces at {args.samples} samples/pixel in {seconds:.1f} s -> {args.out}")


def _cmd_synth(args: argparse.Namespace) -> None:
    start = time.perf_counter()
    dataset, rendering = synthesize(
        args.shape,
        size=args.size,
        lights=args.lights,
        albedo=args.albedo,
        environment=args.environment,
        floor=args.floor,
        bounces=args.bounces,
        samples=args.samples,
        seed=args.seed,
        progress=not args.quiet,
    )
    save_dataset(dataset, args.out, extra=_bounce_files(rendering))
    if not args.quiet:
        seconds = time.perf_counter() - start
        indirect = rendering.indirect[:, dataset.mask].mean() / max(float(dataset.images[:, dataset.mask].mean()), 1e-12)
        print(
            f"synthesized {args.shape} ({args.size}x{args.size}, {args.lights} lights, {args.environment}) in {seconds:.1f} s; "
            f"inter-reflections are {100 * indirect:.1f}% of the object's light -> {args.out}"
        )


def _reconstruct_options(args: argparse.Namespace) -> dict:
    """The keyword arguments of `irtps.reconstruct` given by `_add_reconstruct_options`."""
    names = ("method", "robust", "shadow_fraction", "saturation", "integration", "base_height", "bounces", "iterations", "samples", "seed", "relaxation", "update", "stride", "estimator")
    return {name: getattr(args, name) for name in names}


def _cmd_reconstruct(args: argparse.Namespace) -> None:
    _check_output(args.out, args.data)
    dataset, result = load_and_reconstruct(args.data, **_reconstruct_options(args), progress=not args.quiet)
    save_reconstruction(result, args.out, source=str(args.data.resolve()))
    if not args.quiet:
        stages = ", ".join(f"{name} {seconds:.2f} s" for name, seconds in result.timings.items())
        print(f"reconstructed {args.data} ({args.method}; {stages}) -> {args.out}")
        for step in result.history:
            change = "" if step.height_change is None else f"  height change {step.height_change:.4f}"
            error = "" if step.metrics is None or step.metrics["normal_mean_angular_deg"] is None else f"  normal error {step.metrics['normal_mean_angular_deg']:.2f} deg"
            print(f"  pass {step.index}:{error}{change}")
        if dataset.gt is not None:
            metrics = evaluate(mask=result.mask, normals=result.normals, albedo=result.albedo, height=result.height, gt=dataset.gt)
            print(format_metrics(metrics))


def _cmd_batch(args: argparse.Namespace) -> None:
    if args.scheduler is not None and (args.workers is not None or args.threads_per_worker is not None):
        raise IrtpsError("--workers and --threads-per-worker set up the local cluster; with --scheduler, give them to 'dask worker' (--nworkers, --nthreads)")
    options = _reconstruct_options(args)
    if args.scheduler is None:
        cluster = local_cluster(args.workers, 1 if args.threads_per_worker is None else args.threads_per_worker)
    else:
        cluster = connect(args.scheduler)
    with cluster as client:
        results = reconstruct_many(args.data, args.out, client=client, progress=not args.quiet, **options)
    write_summary(results, args.out, settings=options)
    print(summary_table(results), end="")
    failed = sum(result.failed for result in results)
    if failed:
        raise IrtpsError(f"{failed} of {len(results)} data sets failed (see {args.out / SUMMARY_MARKDOWN})")
    if not args.quiet:
        print(f"{len(results)} data sets reconstructed into {args.out}/; summary in {args.out / SUMMARY_MARKDOWN} and {args.out / SUMMARY_JSON}")


def _cmd_evaluate(args: argparse.Namespace) -> None:
    normals, albedo, height, mask = load_reconstruction(args.out)
    truth = load_ground_truth(args.gt, mask.shape)
    if truth is None:
        raise IrtpsError(f"{args.gt}: has no ground truth (gt/ or Normal_gt.mat)")
    metrics = evaluate(mask=mask, normals=normals, albedo=albedo, height=height, gt=truth)
    print(json.dumps(metrics.to_dict(), indent=2) if args.json else format_metrics(metrics))


def _cmd_report(args: argparse.Namespace) -> None:
    # Imported here: matplotlib, which the report draws with, would slow down every other command's start.
    from irtps.report import write_report

    page = write_report(args.out, args.report_out, truth=args.truth)
    if not args.quiet:
        figures = sorted(path.name for path in page.parent.glob("*.png"))
        print(f"report of {args.out}: {len(figures)} figures ({', '.join(figures)}) and the page {page}")


def _run_table(datasets, args, out: Path | None, sources: dict[str, str] | None = None) -> str:
    """Compute the comparison table and write it under `out`; with `sources` (data set name ->
    the path recorded as its source), the reconstructions too."""
    from tqdm import tqdm

    total = len(datasets) * len(method_names(args.bounces, not args.no_paper))
    with tqdm(total=total, desc="table", unit="run", disable=args.quiet, leave=False) as bar:

        def finished(name, method, result):
            if sources is not None and out is not None:
                save_reconstruction(result, out / name / method, source=sources[name])
            bar.update(1)

        table = comparison_table(
            datasets, bounces=args.bounces, iterations=args.iterations, samples=args.samples, seed=args.seed, paper=not args.no_paper, on_result=finished
        )
    text = format_table(table)
    if out is not None:
        (out / "table.md").write_text(text)
        (out / "table.json").write_text(json.dumps(table, indent=2))
    return text


def _cmd_table(args: argparse.Namespace) -> None:
    datasets = [(folder.name, load_dataset(folder)) for folder in args.data]
    if args.out is None:
        print(_run_table(datasets, args, None), end="")
        return
    _check_output(args.out, *args.data)
    with atomic_output_dir(args.out) as folder:
        text = _run_table(datasets, args, folder)
    print(text, end="")
    if not args.quiet:
        print(f"table written to {args.out / 'table.md'} and {args.out / 'table.json'}")


def _cmd_demo(args: argparse.Namespace) -> None:
    start = time.perf_counter()
    with atomic_output_dir(args.out) as folder:
        dataset, rendering = synthesize(
            "cap", size=args.size, lights=12, environment="cornell", bounces=4, samples=256, seed=args.seed, progress=not args.quiet
        )
        save_dataset(dataset, folder / "data", extra=_bounce_files(rendering))
        # Recorded as the final place of the data set, which `irtps report` reads ground truth from.
        text = _run_table([("cap_cornell", dataset)], args, folder, {"cap_cornell": str(args.out.resolve() / "data")})
    share = rendering.indirect[:, dataset.mask].mean() / dataset.images[:, dataset.mask].mean()
    print(
        f"A {args.size}x{args.size} spherical cap on the floor of a Cornell box (red and green walls), 12 lights; "
        f"inter-reflections are "
        f"{100 * share:.0f}% of the light on the object. Errors of classic photometric stereo (PS) and of IRT-PS "
        f"estimating r = {', '.join(map(str, args.bounces))} bounces (best in bold; lower is better):\n"
    )
    print(text)
    print(
        f"Done in {time.perf_counter() - start:.0f} s. Outputs in {args.out}/: data/ (the synthetic data set with ground "
        f"truth), cap_cornell/PS/, cap_cornell/IRTPSr*/ and cap_cornell/Paper-r*/ (normals, albedo, height, mesh.ply, mesh.obj, "
        f"run.json), "
        f"table.md, table.json. See one as pictures with: irtps report {args.out / 'cap_cornell' / method_names(args.bounces, False)[-1]}"
    )


def _add_table_options(parser: argparse.ArgumentParser, iterations: int, samples: int) -> None:
    parser.add_argument("--bounces", type=int, nargs="+", default=[1, 2, 3], help="IRT-PS variants: bounces estimated (default 1 2 3)")
    parser.add_argument("--iterations", type=int, default=iterations, help=f"IRT-PS corrections at most (default {iterations})")
    parser.add_argument("--samples", type=int, default=samples, help=f"camera paths per pixel per estimate (default {samples})")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--no-paper", action="store_true", help="leave out the paper's own estimator (columns 'Paper-rN')")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_reconstruct_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--method", choices=METHODS, default="ps", help="reconstruction method (default ps)")
    parser.add_argument("--robust", action=argparse.BooleanOptionalAction, default=True, help="drop shadowed and saturated observations (default on)")
    parser.add_argument("--shadow-fraction", type=float, default=0.05, help="shadow threshold relative to a pixel's brightest (default 0.05)")
    parser.add_argument("--saturation", type=float, default=None, help="raw value at or above which an observation is saturated")
    parser.add_argument("--integration", choices=INTEGRATION_METHODS, default=None, help="normal integration (default ls for ps, footprint for irtps)")
    parser.add_argument("--base-height", type=float, default=None, help="height of the object's boundary (default: the floor's)")
    irt = parser.add_argument_group("IRT-PS (--method irtps)")
    irt.add_argument("--bounces", type=int, default=3, help="inter-reflection bounces estimated (default 3)")
    irt.add_argument("--iterations", type=int, default=8, help="largest number of corrections (default 8)")
    irt.add_argument("--samples", type=int, default=256, help="camera paths per pixel per estimate (default 256)")
    irt.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    irt.add_argument("--relaxation", type=float, default=1.0, help="fraction of each new estimate taken (default 1)")
    irt.add_argument("--update", choices=UPDATES, default="original", help="A0 - E (original, default) or the paper's A_t - E_t (previous)")
    irt.add_argument("--stride", type=int, default=1, help="estimate at one pixel in SxS and interpolate (faster; default 1: every pixel)")
    irt.add_argument("--estimator", choices=ESTIMATORS, default="physical", help="indirect estimate: physical (default) or the paper's heuristic")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``irtps`` command."""
    parser = argparse.ArgumentParser(
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
    _add_render_options(p, samples=256)
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
    p.add_argument("--size", type=int, default=96, help="image width and height in pixels (default 96)")
    p.add_argument("--lights", type=int, default=12, help="number of lights (default 12)")
    p.add_argument("--albedo", choices=["uniform", "textured"], default="uniform", help="albedo pattern (default uniform)")
    p.add_argument("--environment", choices=["cornell", "none"], default="cornell", help="surroundings (default cornell)")
    p.add_argument("--floor", action=argparse.BooleanOptionalAction, default=None, help="a floor (default: only with the box)")
    _add_render_options(p, samples=256)
    p.set_defaults(run=_cmd_synth)

    p = commands.add_parser(
        "reconstruct",
        help="recover normals, albedo, a height map and a mesh from a data set",
        description="Reconstruct the object of DATA (contract layout, or DiLiGenT layout, detected) and write OUT: "
        "normal.exr (R, G, B = nx, ny, nz), albedo.exr, height.exr, mask.png, mesh.ply (the height field with "
        "per-vertex albedo colour and normals), mesh.obj (the same mesh for any viewer) and run.json (parameters, "
        "timings, versions, the data set's path); with --method irtps also "
        "indirect/NNN.exr (the estimated inter-reflected light) and the per-iteration history in run.json. "
        "When DATA has ground truth, the errors are printed too. OUT is replaced atomically.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps reconstruct shared/data/diligent/ballPNG --out ball\n"
        "  irtps reconstruct shared/data/mitsuba/cap_cornell --out cap_irtps --method irtps --bounces 3\n"
        "  irtps reconstruct cavity --out cavity_ps --integration mestimator\n"
        "  irtps reconstruct capture --out capture_ps --saturation 0.99 --base-height 0",
    )
    p.add_argument("data", type=Path, help="data set folder")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    _add_reconstruct_options(p)
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
        "On a cluster with a shared file system: run 'dask scheduler' on one node, "
        "'RAYON_NUM_THREADS=1 dask worker tcp://HOST:8786 --nworkers $(nproc) --nthreads 1' on each compute node, "
        "then 'irtps batch ... --scheduler tcp://HOST:8786'.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  irtps batch shared/data/diligent/*PNG --out diligent_ps\n"
        "  irtps batch scenes/* --out runs --method irtps --bounces 2 --workers 2 --threads-per-worker 4\n"
        "  irtps batch /shared/scenes/* --out /shared/runs --method irtps --scheduler tcp://head-node:8786",
    )
    p.add_argument("data", type=Path, nargs="+", help="data set folders")
    p.add_argument("--out", type=Path, required=True, help="folder for one reconstruction folder per data set and the summary")
    _add_reconstruct_options(p)
    dask = p.add_argument_group("cluster")
    dask.add_argument("--scheduler", metavar="ADDRESS", help="run on the Dask cluster of this scheduler (e.g. tcp://head-node:8786) instead of a local one")
    dask.add_argument("--workers", type=int, default=None, metavar="N", help="local cluster: worker processes (default: cores / threads per worker)")
    dask.add_argument("--threads-per-worker", type=int, default=None, metavar="T", help="local cluster: data sets per worker at once, and its Rust threads (default 1)")
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
    p.add_argument("--truth", metavar="DATASET", type=Path, default=None, help="data set with ground truth (default: the run's own data set, if it has any)")
    p.add_argument("--out", metavar="DIR", dest="report_out", type=Path, default=None, help="report folder (default OUT/report)")
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
        "  irtps table cavity --bounces 3 --iterations 4 --samples 128",
    )
    p.add_argument("data", type=Path, nargs="+", help="data set folders with ground truth")
    p.add_argument("--out", type=Path, help="folder for table.md and table.json")
    _add_table_options(p, iterations=8, samples=256)
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
    p.add_argument("--size", type=int, default=64, help="image size in pixels (default 64)")
    _add_table_options(p, iterations=5, samples=128)
    p.set_defaults(run=_cmd_demo)
    return parser


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every partial output is removed on the way out."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise _Terminated()


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    if issubclass(category, IrtpsWarning):
        print(f"irtps: warning: {message}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def main(argv: list[str] | None = None) -> int:
    """Run the ``irtps`` command; returns the exit status.

    0 on success; 2 on bad input, printed as ``irtps: error: ...`` naming the file or
    field; 130 on Ctrl-C and 143 on SIGTERM, after removing any partial output.
    """
    args = build_parser().parse_args(argv)
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default", IrtpsWarning)  # each message once
            warnings.showwarning = _show_warning
            args.run(args)
    except (IrtpsError, OSError) as err:
        print(f"irtps: error: {err}", file=sys.stderr)
        return 2
    except MemoryError as err:
        print(f"irtps: error: not enough memory ({err or 'allocation failed'})", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:
        print("irtps: interrupted; no partial output was left", file=sys.stderr)
        return 128 + signal.SIGTERM if isinstance(interrupt, _Terminated) else 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0


if __name__ == "__main__":
    sys.exit(main())
