"""Benchmark of normal integration (irtps.integrate) on masked fields.

A smooth surface (a spherical cap plus ripples) seen through a disc mask, its exact
normals integrated with ``method="ls"`` and ``method="mestimator"`` (also on normals with
5 % gross outliers), at 512x512 and 1024x1024 pixels; the median of 3 runs of each is
printed as a table, with the accuracy (RMSE after removing the best constant, relative to
the height range). Targets (issue 3): 512x512 <= 1 s and 1024x1024 <= 4 s on the 2-core
development machine.

Usage::

    python benches/integration_bench.py [--sizes 512 1024] [--runs 3] [--profile] [--json PATH]

``--profile`` also times the phases of one ``"ls"`` run per size (checks and slopes,
sparse system, AMG set-up, conjugate gradients).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time

import numpy as np

from irtps import integrate as integ
from irtps.integrate import integrate_normals


def field(n: int, outliers: float = 0.0, seed: int = 0):
    """Exact normals of a cap with ripples on a disc mask, optionally with outliers."""
    s = 1.0 / n
    rows, cols = np.mgrid[0:n, 0:n].astype(float)
    x = (cols + 0.5 - n / 2) * s
    y = (n / 2 - rows - 0.5) * s
    radius, amp, k = 0.6, 0.01, 2 * np.pi * 3
    cap = np.sqrt(np.maximum(radius**2 - x**2 - y**2, 1e-6))
    z = cap + amp * np.sin(k * x) * np.sin(k * y)
    zx = -x / cap + amp * k * np.cos(k * x) * np.sin(k * y)
    zy = -y / cap + amp * k * np.sin(k * x) * np.cos(k * y)
    normals = np.stack([-zx, -zy, np.ones_like(z)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    mask = x**2 + y**2 < 0.45**2
    if outliers > 0:
        rng = np.random.default_rng(seed)
        bad = rng.random((n, n)) < outliers
        v = rng.normal(size=(n, n, 3))
        v[..., 2] = np.abs(v[..., 2])
        v /= np.linalg.norm(v, axis=-1, keepdims=True)
        normals[bad] = v[bad]
    return normals.astype(np.float32), mask, z, s


def relative_rmse(height, truth, mask):
    err = height[mask].astype(np.float64) - truth[mask]
    err -= err.mean()
    return float(np.sqrt(np.mean(err**2)) / np.ptp(truth[mask]))


def profile_ls(normals, mask, s):
    """Time the phases of one least-squares integration (the internals of integrate_normals)."""
    phases = {}
    t = time.perf_counter()
    nn, mm = integ._check_normals_mask(normals, mask)
    p, q = integ._gradients(nn, mm, 10.0)
    phases["checks+slopes"] = time.perf_counter() - t
    t = time.perf_counter()
    problem = integ._Problem(mm, p * s, -q * s)
    a = problem.matrix(np.full(problem.n_edges, 2.0))
    b = problem.rhs(problem.t_f + problem.t_b)
    phases["system"] = time.perf_counter() - t
    t = time.perf_counter()
    amg = integ._AmgPreconditioner(a)
    phases["amg_setup"] = time.perf_counter() - t
    count = [0]

    def precondition(r):
        count[0] += 1
        return amg(r)

    t = time.perf_counter()
    integ._pcg(a, b, precondition, np.zeros(problem.n), 1e-5)
    phases["pcg"] = time.perf_counter() - t
    phases["pcg_iterations"] = count[0]
    phases["amg_levels"] = len(amg.levels)
    return phases


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--profile", action="store_true", help="also time the phases of 'ls'")
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = parser.parse_args(argv)

    targets = {512: 1.0, 1024: 4.0}
    cases = [("ls", 0.0), ("mestimator", 0.0), ("mestimator", 0.05)]
    results = []
    # Warm-up: imports (pyamg) and first-call costs are not what is measured.
    normals, mask, _, s = field(64)
    integrate_normals(normals, mask, pixel_size=s, method="mestimator")

    print(f"{'size':>9} {'method':>10} {'outliers':>8} {'pixels':>8} {'median s':>9} {'runs s':>22} {'target s':>8} {'rel. RMSE':>10}")
    for n in args.sizes:
        for method, outliers in cases:
            normals, mask, truth, s = field(n, outliers)
            times = []
            for _ in range(args.runs):
                t = time.perf_counter()
                height = integrate_normals(normals, mask, pixel_size=s, method=method)
                times.append(time.perf_counter() - t)
            median = statistics.median(times)
            rmse = relative_rmse(height, truth, mask)
            target = targets.get(n)
            results.append(
                {
                    "size": n,
                    "method": method,
                    "outliers": outliers,
                    "pixels": int(mask.sum()),
                    "median_s": median,
                    "runs_s": times,
                    "target_s": target,
                    "relative_rmse": rmse,
                }
            )
            runs = " ".join(f"{t:.2f}" for t in times)
            print(
                f"{n:>4}x{n:<4} {method:>10} {outliers:>8.0%} {int(mask.sum()):>8} {median:>9.2f} {runs:>22} "
                f"{'' if target is None else f'{target:.1f}':>8} {rmse:>10.1e}",
                flush=True,
            )
    profiles = {}
    if args.profile:
        for n in args.sizes:
            normals, mask, _, s = field(n)
            profiles[n] = profile_ls(normals, mask, s)
            print(f"ls {n}x{n} phases: " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in profiles[n].items()))
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    print(f"cores: {os.cpu_count()}, load average after the runs: {load}")
    if args.json:
        import pyamg
        import scipy

        report = {
            "benchmark": "normal integration (irtps.integrate.integrate_normals)",
            "machine": {"cores": os.cpu_count(), "platform": platform.platform(), "load_average": load},
            "versions": {"python": sys.version.split()[0], "numpy": np.__version__, "scipy": scipy.__version__, "pyamg": pyamg.__version__},
            "results": results,
            "profiles": {str(k): v for k, v in profiles.items()},
        }
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(report, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
