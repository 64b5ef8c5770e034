#!/usr/bin/env python
"""Time irtps and Mitsuba 3 rendering the indirect light of the same images, at equal error.

The scene is a synthetic data set (``irtps synth``: by default V-grooves of albedo 0.8 in a
Cornell box with a floor, 128×128 pixels, 20 lights). Both renderers produce its indirect
component: bounces 1..r (r = ``--bounces``, default 3) for every light, each pixel averaged
over its square footprint, as the scene contract defines it.

- **irtps**: ``irtps.render.renderer.render_indirect``, one call for all lights (each traced path
  serves every light). Its time includes building the BVH and the light-visibility cache.
- **Mitsuba 3**: the very same triangles (``Renderer.mesh_arrays()``: height field, skirt,
  floor and walls, per-vertex albedo as a ``vertex_color`` mesh attribute), one-sided
  ``diffuse`` BSDFs, a ``directional`` emitter of the light's irradiance, an
  ``orthographic`` sensor whose pixels are the contract's, a ``box`` pixel filter and the
  ``path`` integrator with Russian roulette off, and the ``multijitter`` sampler (of
  Mitsuba's samplers, the lowest error per sample here: 0.066 at 256 spp against 0.098 for
  ``independent``, 0.069 ``stratified``, 0.080 ``ldsampler``). One image per light: the indirect part is
  ``render(max_depth = r + 2) − render(max_depth = 2)`` with the same seed, so that the
  direct light (identical in both, sample for sample) cancels exactly. Only the first render
  is timed (the subtraction is free for Mitsuba), and scene loading is not timed.

Before anything is timed, a Mitsuba direct-only render must match irtps's direct image
(mean absolute difference at most 2 % of the mean), else the script stops: the two would not
be rendering the same scene.

Error is the RMSE over the object's pixels, all lights and channels, relative to the mean of
the reference. The reference is Mitsuba (unbiased) at ``--reference-samples`` per pixel,
rendered as two independent halves A and B; the halves' disagreement gives the reference's
own noise, which is removed from every error (E|x − ref|² − E|A − B|²/4 is an unbiased estimate
of x's squared error against the exact image). irtps at its highest sample count then shows
its bias against the exact image (its light-visibility cache interpolates shadows).

Each renderer is timed at several sample counts; the time each needs to reach the target error
(Mitsuba's at ``--key-samples``, 256 by default) is interpolated in log-log, and the ratio of
those times is the speed-up at equal error, both in wall-clock and in CPU seconds (the latter
is steadier when other jobs share the cores). irtps times are medians of ``--repeats`` calls.
Mitsuba times are K × its median time per light (every light is rendered and timed, unless
``--mitsuba-lights`` says otherwise).
Finally one IRT-PS iteration (photometric stereo, integration, indirect estimate) is timed on
the same scene.

    python benches/mitsuba_compare.py [--size 128] [--lights 20] [--bounces 3]
        [--variant auto|llvm|scalar|both] [--threads 2] [--json PATH] ...

Needs ``pip install mitsuba`` (the ``bench`` extra). Its LLVM variant needs a libLLVM recent
enough for Dr.Jit (Debian: ``apt-get install libllvm19``; Debian 12's LLVM 15 cannot compile
Dr.Jit 1.5's kernels); the script finds the newest one, or set ``DRJIT_LIBLLVM_PATH``, and
tries it with a small render before the run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from error_curves import Curve, ErrorMeter
from mitsuba_scene import MitsubaScene, Stopwatch, import_mitsuba

VARIANTS = {"llvm": "llvm_ad_rgb", "scalar": "scalar_rgb"}
#: Largest mean absolute difference between the two direct images, relative to their mean.
DIRECT_TOLERANCE = 0.02
#: Footprint samples per pixel of both direct images in that check.
DIRECT_SAMPLES = 256


def parse_counts(text: str) -> list[int]:
    counts = sorted({int(v) for v in text.split(",") if v.strip()})
    if not counts or counts[0] < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected positive integers separated by commas")
    return counts


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument(
        "--shape",
        default="grooves",
        help="synthetic shape (irtps synth: cap, cavity, grooves, relief; default grooves)",
    )
    ap.add_argument(
        "--albedo", default="uniform", choices=["uniform", "textured"], help="albedo pattern (default uniform, 0.8)"
    )
    ap.add_argument("--size", type=int, default=128, help="image width and height in pixels (default 128)")
    ap.add_argument("--lights", type=int, default=20, help="number of lights (default 20)")
    ap.add_argument(
        "--bounces", type=int, default=3, help="inter-reflection bounces r in the indirect component (default 3)"
    )
    ap.add_argument(
        "--irtps-samples",
        type=parse_counts,
        default=parse_counts("4,8,16,32,64,128,256,1024"),
        help="irtps paths per pixel to time (default 4,8,...,256,1024)",
    )
    ap.add_argument(
        "--mitsuba-samples",
        type=parse_counts,
        default=parse_counts("16,64,256"),
        help="Mitsuba samples per pixel to time (default 16,64,256: squares, which every sampler takes as they are)",
    )
    ap.add_argument(
        "--key-samples",
        type=int,
        default=256,
        help="Mitsuba's sample count whose error is the target (default 256; must be in --mitsuba-samples)",
    )
    ap.add_argument(
        "--reference-samples",
        type=int,
        default=1024,
        help="Mitsuba samples per pixel of the reference, split in two halves (default 1024)",
    )
    ap.add_argument(
        "--reference-file",
        type=Path,
        help="cache the reference here (.npz): loaded when it matches the settings, else rendered and saved",
    )
    ap.add_argument(
        "--variant",
        default="auto",
        choices=["auto", "llvm", "scalar", "both"],
        help="Mitsuba variant(s) to time: llvm_ad_rgb, scalar_rgb, both, or auto (llvm when it works, else scalar)",
    )
    ap.add_argument(
        "--sampler",
        default="multijitter",
        help="Mitsuba sampler plugin (default multijitter, the lowest error here; also independent, stratified, ldsampler, orthogonal)",
    )
    ap.add_argument(
        "--mitsuba-lights",
        type=int,
        help="time Mitsuba on only this many of the lights (spread evenly) at every count except --key-samples, to save time; default all",
    )
    ap.add_argument("--threads", type=int, default=2, help="threads for both renderers (default 2)")
    ap.add_argument(
        "--repeats", type=int, default=3, help="timed irtps calls per sample count; medians are reported (default 3)"
    )
    ap.add_argument(
        "--paired-repeats", type=int, default=5, help="turns of the paired timing at equal error (default 5)"
    )
    ap.add_argument(
        "--iteration-samples",
        type=parse_counts,
        help="irtps paths per pixel for the timed IRT-PS iteration (default: irtps's default, 256 and the equal-error count)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = ap.parse_args(argv)
    if args.key_samples not in args.mitsuba_samples:
        ap.error(f"--key-samples {args.key_samples} is not in --mitsuba-samples")
    if args.reference_samples < 2:
        ap.error("--reference-samples must be at least 2")
    return args


# --------------------------------------------------------------------------- measurements


def timed_irtps(case, spp: int, seed: int, repeats: int):
    from irtps.render.renderer import render_indirect

    times, image = [], None
    for r in range(repeats):
        with Stopwatch() as watch:
            image = render_indirect(
                case.scene, case.height, case.albedo, case.mask, bounces=case.bounces, samples=spp, seed=seed + r
            )
        times.append(watch.seconds)
    return image, times


@dataclass
class Case:
    scene: object
    height: np.ndarray
    albedo: np.ndarray
    mask: np.ndarray
    bounces: int
    dataset: object


def make_case(args) -> Case:
    from irtps.render.synth import synthesize

    # The data set's images (direct + 4 bounces at 64 paths) feed only the IRT-PS iteration.
    dataset, _ = synthesize(
        args.shape,
        size=args.size,
        lights=args.lights,
        albedo=args.albedo,
        environment="cornell",
        bounces=4,
        samples=64,
        seed=args.seed,
    )
    gt = dataset.gt
    return Case(dataset.scene, gt.height, gt.albedo, dataset.mask, args.bounces, dataset)


def check_direct(ms: MitsubaScene, case: Case, lights: list[int], seed: int) -> dict:
    """Mitsuba's direct-only images against irtps's, both with DIRECT_SAMPLES per pixel
    (fewer leave per-pixel errors of several percent where a shadow edge crosses a crease)."""
    from irtps.render.renderer import render

    ours = render(
        case.scene,
        case.height,
        case.albedo,
        case.mask,
        bounces=0,
        samples=DIRECT_SAMPLES,
        direct_samples=DIRECT_SAMPLES,
        seed=seed,
    ).direct
    result = {}
    for k in lights:
        theirs, _ = ms.render(k, DIRECT_SAMPLES, seed + 17, direct_only=True)
        diff = float(np.abs(theirs - ours[k]).mean() / ours[k].mean())
        result[k] = diff
    return result


def reference(args, ms: MitsubaScene, case: Case) -> tuple[np.ndarray, np.ndarray, float]:
    """Two independent halves of Mitsuba's indirect at --reference-samples, (K, H, W, 3) each."""
    key = {
        "shape": args.shape,
        "albedo": args.albedo,
        "size": args.size,
        "lights": args.lights,
        "bounces": args.bounces,
        "samples": args.reference_samples,
        "seed": args.seed,
    }
    if args.reference_file and args.reference_file.exists():
        cached = np.load(args.reference_file)
        if json.loads(str(cached["key"])) == key:
            print(f"reference: loaded from {args.reference_file}")
            return cached["a"], cached["b"], float(cached["seconds"])
        print(f"reference: {args.reference_file} was made with other settings; rendering anew")
    half = args.reference_samples // 2
    halves = np.zeros((2, len(case.scene.lights), args.size, args.size, 3), dtype=np.float32)
    start = time.perf_counter()
    for k in range(len(case.scene.lights)):
        for h in range(2):
            halves[h, k], _ = ms.indirect(k, half, seed=1_000_003 + 2 * k + h)
        if sys.stderr.isatty():
            print(f"\rreference: light {k + 1}/{len(case.scene.lights)}", end="", file=sys.stderr, flush=True)
    seconds = time.perf_counter() - start
    print(
        f"{chr(13) if sys.stderr.isatty() else ''}reference: {ms.variant}, {args.reference_samples} samples per pixel in two halves, rendered in {seconds:.0f} s"
    )
    if args.reference_file:
        np.savez_compressed(args.reference_file, a=halves[0], b=halves[1], seconds=seconds, key=json.dumps(key))
    return halves[0], halves[1], seconds


def spread(count: int, total: int) -> list[int]:
    return (
        sorted({round(i * (total - 1) / max(count - 1, 1)) for i in range(count)})
        if count < total
        else list(range(total))
    )


def time_iteration(case: Case, samples: int, repeats: int, seed: int) -> dict:
    """Seconds of one IRT-PS pass (photometric stereo, integration, indirect estimate with the
    residual's direct image); the placement is given, as its search runs once per data set."""
    from irtps.errors import IrtpsWarning
    from irtps.irt.interreflection import remove_interreflections

    totals, stages = [], []
    with warnings.catch_warnings():
        # Only the pass's time counts here: whether one pass (or the 1-path warm-up) explains
        # the images better than classic photometric stereo is the accuracy benchmarks' job.
        warnings.simplefilter("ignore", IrtpsWarning)
        remove_interreflections(
            case.dataset, bounces=case.bounces, iterations=1, samples=1, seed=seed
        )  # warm-up (imports, caches)
        for r in range(repeats):
            result = remove_interreflections(
                case.dataset, bounces=case.bounces, iterations=1, samples=samples, seed=seed + r, base_height="boundary"
            )
            timings = result.history[0].timings
            totals.append(sum(timings.values()))
            stages.append(timings)
    median = statistics.median(totals)
    chosen = stages[totals.index(sorted(totals)[len(totals) // 2])]
    return {"samples": samples, "seconds": median, "runs": totals, "stages": chosen}


# --------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    # Both renderers get the same number of threads; rayon reads this when its pool starts.
    os.environ["RAYON_NUM_THREADS"] = str(args.threads)
    wanted = {
        "auto": ["llvm_ad_rgb", "scalar_rgb"],
        "llvm": ["llvm_ad_rgb"],
        "scalar": ["scalar_rgb"],
        "both": ["llvm_ad_rgb", "scalar_rgb"],
    }[args.variant]
    mi, dr, usable = import_mitsuba(wanted, args.threads)
    if args.variant == "auto":
        usable = usable[:1]
    if not usable:
        sys.exit("no usable Mitsuba variant")

    from irtps import __version__ as irtps_version
    from irtps.render.renderer import make_renderer

    case = make_case(args)
    renderer = make_renderer(case.scene, case.height, case.albedo, case.mask)
    k_count = len(case.scene.lights)
    scenes = {}
    for variant in usable:
        start = time.perf_counter()
        scenes[variant] = MitsubaScene(mi, variant, renderer, case.scene, args.bounces, args.sampler)
        scenes[variant].load_seconds = time.perf_counter() - start
    first = scenes[usable[0]]
    print(
        f"scene: synth {args.shape} ({args.albedo} albedo) in a Cornell box, {args.size}x{args.size}, {k_count} lights, "
        f"r = {args.bounces}, {first.triangles:,} triangles, {int(case.mask.sum()):,} object pixels"
    )
    print(
        f"threads: {args.threads} for both (RAYON_NUM_THREADS, drjit.set_thread_count); Mitsuba {mi.__version__}, "
        f"variants {', '.join(usable)}, sampler {args.sampler}; irtps {irtps_version}"
    )
    if any(v.startswith("llvm") for v in usable):
        print(f"libLLVM: {os.environ.get('DRJIT_LIBLLVM_PATH')}")

    # 1. Same scene? Direct light must agree.
    figures: dict = {"direct_check": {}}
    for variant, ms in scenes.items():
        checked = check_direct(ms, case, spread(3, k_count), args.seed)
        figures["direct_check"][variant] = checked
        worst = max(checked.values())
        print(
            f"direct-light check ({variant}, lights {list(checked)}): mean |Mitsuba - irtps| / mean = "
            + ", ".join(f"{v:.2%}" for v in checked.values())
        )
        if worst > DIRECT_TOLERANCE:
            sys.exit(
                f"Mitsuba's direct image differs from irtps's by {worst:.1%} of the mean (limit {DIRECT_TOLERANCE:.0%}): "
                "the two do not render the same scene; nothing was timed"
            )

    # 2. Reference.
    half_a, half_b, ref_seconds = reference(args, first, case)
    meter = ErrorMeter(half_a, half_b, case.mask)
    ref_noise = math.sqrt(meter.reference_noise) / meter.scale
    print(
        f"reference: mean indirect on the object {meter.scale:.4f}; its own noise (relative RMSE) {ref_noise:.4f}, removed from every error below"
    )

    # 3. Sweeps, taking turns so that load from other processes affects both alike.
    from irtps.render.renderer import render_indirect

    render_indirect(case.scene, case.height, case.albedo, case.mask, bounces=args.bounces, samples=1, seed=0)  # warm-up
    irtps_curve = Curve("irtps")
    mitsuba_curves = {v: Curve(v) for v in usable}
    levels = max(len(args.irtps_samples), len(args.mitsuba_samples))
    for level in range(levels):
        if level < len(args.irtps_samples):
            spp = args.irtps_samples[level]
            image, times = timed_irtps(case, spp, seed=100 * (level + 1), repeats=args.repeats)
            wall, cpu = (statistics.median(t[i] for t in times) for i in (0, 1))
            irtps_curve.add(spp, (wall, cpu), meter(image), runs=times)
            print(
                f"irtps        {spp:5d} paths/px: {wall:8.3f} s wall, {cpu:8.3f} s CPU for all {k_count} lights; "
                f"relative RMSE {irtps_curve.error[-1]:.4f}",
                flush=True,
            )
        if level < len(args.mitsuba_samples):
            spp = args.mitsuba_samples[level]
            for variant, ms in scenes.items():
                subset = (
                    list(range(k_count))
                    if spp == args.key_samples or not args.mitsuba_lights
                    else spread(args.mitsuba_lights, k_count)
                )
                if variant.startswith("llvm"):
                    ms.render(subset[0], spp, seed=7)  # compile this sample count's kernel first
                images = np.zeros((k_count, args.size, args.size, 3), dtype=np.float32)
                per_light = []
                for k in subset:
                    images[k], seconds = ms.indirect(k, spp, seed=10_000 * (level + 1) + k)
                    per_light.append(seconds)
                sub_meter = meter if len(subset) == k_count else ErrorMeter(half_a[subset], half_b[subset], case.mask)
                wall, cpu = (statistics.median(t[i] for t in per_light) for i in (0, 1))
                mitsuba_curves[variant].add(
                    spp,
                    (k_count * wall, k_count * cpu),
                    sub_meter(images[subset]),
                    per_light_median=(wall, cpu),
                    per_light=per_light,
                    lights_timed=subset,
                )
                print(
                    f"{variant:<12} {spp:5d} spp:      {k_count * wall:8.3f} s wall, {k_count * cpu:8.3f} s CPU for {k_count} lights "
                    f"({wall:.3f} s wall per light, median of {len(subset)}); relative RMSE {mitsuba_curves[variant].error[-1]:.4f}",
                    flush=True,
                )

    # 4. Equal error: the count irtps needs to match Mitsuba's error at --key-samples, then
    # paired timings (irtps at that count, Mitsuba at the key count, taking turns) so that both
    # meet the same load from other jobs.
    print()
    print(
        f"irtps at {irtps_curve.samples[-1]} paths/px: relative RMSE {irtps_curve.error[-1]:.4f} "
        "(mostly its bias against the exact image)"
    )
    results = {}
    for variant, curve in mitsuba_curves.items():
        key = curve.samples.index(args.key_samples)
        target = curve.error[key]
        spp_equal, note = irtps_curve.at(target, irtps_curve.samples)
        entry = {
            "target_relative_rmse": target,
            "mitsuba_samples": args.key_samples,
            "irtps_equivalent_samples": spp_equal,
            "irtps_note": note,
        }
        if spp_equal is None:
            print(
                f"{variant}: Mitsuba at {args.key_samples} spp reaches {target:.4f}, which irtps does not reach (best {min(irtps_curve.error):.4f})"
            )
        else:
            entry["irtps_samples_timed"] = max(1, round(spp_equal))
            print(
                f"{variant} at {args.key_samples} spp has relative RMSE {target:.4f}; irtps reaches it at about {spp_equal:.0f} paths/px"
                f"{' (' + note + ')' if note else ''}"
            )
            for label, values, theirs in (
                ("wall", irtps_curve.seconds, curve.seconds[key]),
                ("cpu", irtps_curve.cpu_seconds, curve.cpu_seconds[key]),
            ):
                ours, _ = irtps_curve.at(target, values)
                entry[f"sweep_{label}"] = {"mitsuba_seconds": theirs, "irtps_seconds": ours, "ratio": theirs / ours}
        results[variant] = entry
    counts = sorted({e["irtps_samples_timed"] for e in results.values() if "irtps_samples_timed" in e})
    if counts:
        paired_irtps = {n: [] for n in counts}
        paired_mitsuba = {v: [] for v in results if "irtps_samples_timed" in results[v]}
        for r, k in enumerate(
            spread(args.paired_repeats, k_count) if args.paired_repeats < k_count else list(range(args.paired_repeats))
        ):
            for n in counts:
                _, times = timed_irtps(case, n, seed=500 + r, repeats=1)
                paired_irtps[n].append(times[0])
            for variant, runs in paired_mitsuba.items():
                _, seconds = scenes[variant].indirect(k % k_count, args.key_samples, seed=900_000 + r)
                runs.append(seconds)
        print(f"paired timings ({args.paired_repeats} turns; Mitsuba: one light per turn, times {k_count} lights):")
        for variant, per_light in paired_mitsuba.items():
            entry = results[variant]
            n = entry["irtps_samples_timed"]
            bound = "at least " if entry["irtps_note"] else ""
            for i, label in enumerate(("wall", "cpu")):
                theirs = k_count * statistics.median(t[i] for t in per_light)
                ours = statistics.median(t[i] for t in paired_irtps[n])
                entry[label] = {
                    "mitsuba_seconds": theirs,
                    "mitsuba_seconds_per_light": theirs / k_count,
                    "irtps_seconds": ours,
                    "ratio": theirs / ours,
                    "mitsuba_runs": [t[i] for t in per_light],
                    "irtps_runs": [t[i] for t in paired_irtps[n]],
                }
                print(
                    f"  {variant:<12} {label:<4}: Mitsuba {args.key_samples} spp {theirs / k_count:6.3f} s per light, {theirs:7.2f} s for {k_count}; "
                    f"irtps {n} paths/px {ours:6.3f} s -> Mitsuba / irtps = {bound}{theirs / ours:.1f}x at equal error "
                    f"(sweep: {entry[f'sweep_{label}']['ratio']:.1f}x)"
                )
    figures.update(equal_error=results)

    # 5. One IRT-PS iteration.
    counts = args.iteration_samples
    if counts is None:
        from irtps.model.options import ReconstructOptions

        counts = sorted(
            {ReconstructOptions().samples, 256}
            | {e["irtps_samples_timed"] for e in results.values() if "irtps_samples_timed" in e}
        )
    iterations = []
    for spp in counts:
        it = time_iteration(case, spp, args.repeats, args.seed)
        iterations.append(it)
        verdict = "meets" if it["seconds"] < 2.0 else "misses"
        stages = ", ".join(f"{name} {s:.3f} s" for name, s in it["stages"].items())
        print(
            f"one IRT-PS iteration, {k_count} lights, {args.size}x{args.size}, r = {args.bounces}, {spp} paths/px: "
            f"{it['seconds']:.3f} s (median of {args.repeats}; {stages}): {verdict} the 2 s target"
        )

    if args.json:
        figures.update(
            settings={k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
            triangles=first.triangles,
            object_pixels=int(case.mask.sum()),
            reference={
                "variant": first.variant,
                "samples": args.reference_samples,
                "seconds": ref_seconds,
                "mean_indirect": meter.scale,
                "own_relative_noise": ref_noise,
            },
            irtps=irtps_curve.to_dict(),
            mitsuba={v: c.to_dict() for v, c in mitsuba_curves.items()},
            mitsuba_scene_load_seconds={v: ms.load_seconds for v, ms in scenes.items()},
            iteration=iterations,
            machine={
                "platform": platform.platform(),
                "processor": platform.processor(),
                "cpus": os.cpu_count(),
                "python": platform.python_version(),
                "mitsuba": mi.__version__,
                "drjit": dr.__version__,
                "irtps": irtps_version,
            },
        )
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=1))
        print(f"figures written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
