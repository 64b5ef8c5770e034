#!/usr/bin/env python
"""Closest-hit throughput of irtps's tracer versus Embree (through embreex) on the same triangles.

The scene is an all-masked SIZE×SIZE height field (pixel size 1; a smooth relief of a few
sinusoids and a spherical cap, the same as ``benches/bvh.rs``) on a floor inside an
open-topped Cornell box. irtps builds the mesh; ``Renderer.mesh_arrays()`` hands Embree the
very same vertices and triangles. Both trace the same cosine-distributed rays leaving the
height field's pixel vertices (offset 1e-3 along the vertex normal), and the script checks
that they agree before timing them. Rays are timed as drawn (random pixels: incoherent, the
hard case) and sorted by origin pixel (as a render traces them).

embreex traces on one thread (a plain loop over ``rtcIntersect1``); irtps runs on
``--threads`` threads (default 1), so the default comparison is per thread. Times include each
library's own Python-boundary overhead (array conversion in and out), which is small next
to the tracing.

    python benches/embree_compare.py [--size 512] [--rays 1000000] [--repeats 5] [--threads 1]
                                     [--order both|random|pixel] [--embree-fast] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

try:
    from embreex import mesh_construction, rtcore_scene
except ImportError:  # pragma: no cover - depends on the environment
    sys.exit("embree_compare.py needs Embree's Python bindings: pip install embreex")

from irtps import _core
from irtps.model.scene import CornellBox, Floor

OFFSET = 1e-3


def relief(n: int) -> np.ndarray:
    """Heights (n, n) float32: base level, sinusoids and a spherical cap (as in bvh.rs)."""
    scale = n / 512.0
    i, j = np.meshgrid(np.arange(n, dtype=np.float64), np.arange(n, dtype=np.float64), indexing="ij")
    u, v = j / n, i / n
    tau = 2.0 * np.pi
    waves = (
        6.0 * np.sin(tau * 3.0 * u) * np.cos(tau * 2.0 * v)
        + 4.0 * np.sin(tau * (5.0 * u + 4.0 * v))
        + 3.0 * np.cos(tau * 7.0 * v)
    )
    dx, dy = j + 0.5 - n / 2.0, i + 0.5 - n / 2.0
    r2 = dx * dx + dy * dy
    sphere, cap = 200.0 * scale, 150.0 * scale
    bump = np.where(
        r2 < cap * cap, np.sqrt(np.maximum(sphere * sphere - r2, 0.0)) - np.sqrt(sphere * sphere - cap * cap), 0.0
    )
    return ((40.0 + waves) * scale + bump).astype(np.float32)


def build_renderer(n: int) -> tuple[_core.Renderer, np.ndarray]:
    height = relief(n)
    mask = np.ones((n, n), dtype=bool)
    col = np.arange(n, dtype=np.float32) / n
    albedo = np.empty((n, n, 3), dtype=np.float32)
    albedo[..., 0] = 0.5 + 0.3 * col[None, :]
    albedo[..., 1] = 0.6
    albedo[..., 2] = 0.7 - 0.3 * col[:, None]
    half = 0.625 * n
    grey = (0.7, 0.7, 0.7)
    box = CornellBox((-half, half), (-half, half), 0.5 * n, (0.8, 0.1, 0.1), (0.1, 0.8, 0.1), grey, grey)
    renderer = _core.Renderer(
        height,
        mask,
        albedo,
        1.0,
        np.array([[0.0, 0.0, 1.0]], dtype=np.float32),
        np.ones((1, 3), dtype=np.float32),
        floor=Floor(0.0, (0.8, 0.8, 0.8)),
        cornell_box=box,
    )
    return renderer, height


def vertex_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Mean of the adjacent unit facing normals at each vertex (as irtps offsets rays)."""
    p = positions.astype(np.float64)
    a, b, c = (p[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    acc = np.zeros_like(p)
    for k in range(3):
        np.add.at(acc, triangles[:, k], face)
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    return np.where(length > 0, acc / np.where(length > 0, length, 1.0), [0.0, 0.0, 1.0])


def cosine_rays(
    positions: np.ndarray, normals: np.ndarray, pixels: int, count: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cosine-distributed directions around the normals of random height-field vertices:
    origins (N, 3), directions (N, 3) float32 and the index of each origin's vertex."""
    rng = np.random.default_rng(seed)
    vertex = rng.integers(0, pixels, size=count)
    n = normals[vertex]
    u1, u2 = rng.random(count), rng.random(count)
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    # Duff et al. (2017) orthonormal basis, as irtps.sampler.
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    bb = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * bb, -sign * n[:, 0]], axis=1)
    b = np.stack([bb, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    d = (
        t * (r * np.cos(phi))[:, None]
        + b * (r * np.sin(phi))[:, None]
        + n * np.sqrt(np.maximum(1.0 - u1, 0.0))[:, None]
    )
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    origins = positions[vertex].astype(np.float64) + OFFSET * n
    return np.ascontiguousarray(origins, dtype=np.float32), np.ascontiguousarray(d, dtype=np.float32), vertex


def timed(fns, repeats: int) -> list[tuple[list[float], list[float]]]:
    """Wall and CPU seconds of `repeats` calls of each function, taking turns so that load
    from other processes affects all alike."""
    times = [([], []) for _ in fns]
    for _ in range(repeats):
        for fn, (walls, cpus) in zip(fns, times):
            c0, w0 = time.process_time(), time.perf_counter()
            fn()
            walls.append(time.perf_counter() - w0)
            cpus.append(time.process_time() - c0)
    return times


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=512, help="height-field side in pixels (default 512)")
    ap.add_argument("--rays", type=int, default=1_000_000, help="rays per timed run (default 1e6)")
    ap.add_argument(
        "--repeats", type=int, default=5, help="timed runs of each tracer; medians are reported (default 5)"
    )
    ap.add_argument(
        "--threads",
        type=int,
        default=1,
        help="irtps threads (default 1: per-thread comparison; embreex is single-threaded)",
    )
    ap.add_argument(
        "--order",
        choices=["random", "pixel", "both"],
        default="both",
        help="ray order: as drawn, sorted by origin pixel, or both (default)",
    )
    ap.add_argument(
        "--embree-fast",
        action="store_true",
        help="build the Embree scene without RTC_SCENE_FLAG_ROBUST (embreex's default is robust)",
    )
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = ap.parse_args(argv)

    n = args.size
    t0 = time.perf_counter()
    renderer, height = build_renderer(n)
    irtps_setup = time.perf_counter() - t0
    positions, triangles, _, _ = renderer.mesh_arrays()
    # All pixels are masked, so the first n*n vertices are the pixel vertices in row-major order.
    assert np.array_equal(positions[: n * n, 2], height.ravel()), "unexpected vertex order"
    normals = vertex_normals(positions, triangles)
    origins, directions, vertex = cosine_rays(positions, normals, n * n, args.rays, args.seed)
    orders = ["random", "pixel"] if args.order == "both" else [args.order]

    robust = not args.embree_fast
    mode = "robust (RTC_SCENE_FLAG_ROBUST, embreex's default)" if robust else "fast (no RTC_SCENE_FLAG_ROBUST)"
    t0 = time.perf_counter()
    scene = rtcore_scene.EmbreeScene(robust=robust)
    mesh_construction.TriangleMesh(scene, positions, triangles.astype(np.int64))
    embree_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    scene.run(origins[:1], directions[:1], output=1)  # commits the scene: builds Embree's BVH
    embree_build = time.perf_counter() - t0

    print(
        f"scene: {n}x{n} height field in a Cornell box with a floor, {len(triangles):,} triangles, {len(positions):,} vertices"
    )
    print(f"rays: {args.rays:,} cosine-distributed from random height-field pixels; medians of {args.repeats} runs")
    print(
        "  order 'random': as drawn (incoherent); 'pixel': sorted by origin pixel, row-major (as a render traces them)"
    )
    print(f"Embree: {mode}, embreex's single-threaded loop over rtcIntersect1")
    print(
        f"setup: irtps Renderer {irtps_setup:.2f} s (mesh, BVH, light cache); Embree mesh upload {embree_load:.2f} s, BVH commit {embree_build:.2f} s"
    )

    ok = True
    results = {}
    rows = []
    for order in orders:
        perm = np.arange(args.rays) if order == "random" else np.argsort(vertex, kind="stable")
        o, d = np.ascontiguousarray(origins[perm]), np.ascontiguousarray(directions[perm])

        def run_irtps(o=o, d=d):
            return renderer.intersect(o, d, threads=args.threads)

        def run_embree(o=o, d=d):
            return scene.run(o, d, output=1)

        # Agreement (and warm-up).
        t_i, tri_i = run_irtps()
        res = run_embree()
        t_e, tri_e = res["tfar"], res["primID"].astype(np.int64)
        hit_i, hit_e = tri_i >= 0, tri_e >= 0
        both = hit_i & hit_e
        agree = float(np.mean(hit_i == hit_e))
        rel = np.abs(t_i[both] - t_e[both]) / np.maximum(t_e[both], 1e-6)
        within = float(np.mean(rel <= 1e-3)) if both.any() else 1.0
        same_triangle = float(np.mean(tri_i[both] == tri_e[both])) if both.any() else 1.0
        ok = ok and agree > 0.999 and within > 0.999

        (w_i, c_i), (w_e, c_e) = timed([run_irtps, run_embree], args.repeats)
        med_i, med_e = statistics.median(w_i), statistics.median(w_e)
        rate_i, rate_e = args.rays / med_i, args.rays / med_e
        per_thread_i = rate_i / args.threads
        ratio = per_thread_i / rate_e
        print(
            f"order {order}: {hit_i.mean():.1%} hit; agreement: hit/miss {agree:.4%}, "
            f"distance within 1e-3 rel. {within:.4%} of common hits, same triangle {same_triangle:.4%}"
        )
        rows.append(
            (
                order,
                "irtps (pyramid walk)",
                args.threads,
                med_i,
                rate_i,
                per_thread_i,
                statistics.median(c_i) / med_i,
                ratio,
            )
        )
        rows.append((order, "Embree (embreex)", 1, med_e, rate_e, rate_e, statistics.median(c_e) / med_e, None))
        results[order] = {
            "hit_fraction": float(hit_i.mean()),
            "irtps": {
                "threads": args.threads,
                "median_s": med_i,
                "rays_per_s": rate_i,
                "rays_per_s_per_thread": per_thread_i,
                "times_s": w_i,
            },
            "embree": {
                "threads": 1,
                "median_s": med_e,
                "rays_per_s": rate_e,
                "rays_per_s_per_thread": rate_e,
                "times_s": w_e,
            },
            "ratio_irtps_over_embree_per_thread": ratio,
            "agreement": {"hit_miss": agree, "distance_within_1e-3": within, "same_triangle": same_triangle},
        }

    print()
    print(
        f"{'order':<8}{'tracer':<22}{'threads':>8}{'median s':>10}{'rays/s':>13}{'rays/s/thread':>15}{'cpu/wall':>9}{'irtps/Embree':>14}"
    )
    for order, name, threads, med, rate, per_thread, cpu, ratio in rows:
        r = f"{ratio:.2f}" if ratio is not None else ""
        print(f"{order:<8}{name:<22}{threads:>8}{med:>10.3f}{rate:>13,.0f}{per_thread:>15,.0f}{cpu:>9.2f}{r:>14}")

    if not ok:
        print(
            "WARNING: irtps and Embree disagree beyond the tolerance (hit/miss > 99.9%, distances within 1e-3 relative)",
            file=sys.stderr,
        )

    if args.json:
        figures = {
            "size": n,
            "triangles": len(triangles),
            "rays": args.rays,
            "repeats": args.repeats,
            "embree_mode": "robust" if robust else "fast",
            "orders": results,
            "setup_s": {
                "irtps_renderer": irtps_setup,
                "embree_mesh_upload": embree_load,
                "embree_commit": embree_build,
            },
            "machine": {
                "platform": platform.platform(),
                "processor": platform.processor(),
                "cpus": os.cpu_count(),
                "python": platform.python_version(),
            },
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=2) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
