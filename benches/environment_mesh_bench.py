"""Cost of a large environment mesh: the rig's light box as given, against the same box cut
into about two million triangles, side by side in one process.

On ``../shared/data/mitsuba/cap_rig`` (its object from ground truth, its 12 point lights), the
light box's 2 210 triangles are split by midpoint subdivision (each triangle into four, five
times: 2 262 040 triangles, the same surfaces and vertex albedo). For each mesh it times
reading and checking its PLY file and building its BVH (once a run), then what every pass
pays: building the renderer (the object's mesh, BVH and light cache; the environment's BVH
is shared) and rendering what one IRT-PS pass renders (3 bounces, 64 paths a pixel, every
light); medians over the repeats, after a warm-up. Target (issue 48): the
two-million-triangle mesh costs at most 20 % more time per pass than the light box.

    python benches/environment_mesh_bench.py [--repeats 5] [--levels 5]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import irtps
from irtps.model.environment import MeshEnvironment, read_environment_mesh, write_environment_mesh
from irtps import _core
from irtps.render.renderer import make_renderer

RIG = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mitsuba" / "cap_rig"
#: What one IRT-PS pass renders (the defaults of `irtps.model.options.ReconstructOptions`).
BOUNCES, SAMPLES = 3, 64
#: Target: the large mesh's time per pass over the light box's.
TIME_TARGET = 1.2


def subdivided(mesh: MeshEnvironment, levels: int) -> MeshEnvironment:
    """`mesh` with each triangle split into four at its edges' midpoints, `levels` times."""
    corners = mesh.vertices[mesh.triangles]  # (F, 3, 3)
    albedo = mesh.albedo[mesh.triangles]
    for _ in range(levels):
        corners, albedo = (_split(values) for values in (corners, albedo))
    # Corners shared by neighbouring triangles become one vertex, as in a scan's mesh.
    vertices, index = np.unique(np.c_[corners.reshape(-1, 3), albedo.reshape(-1, 3)], axis=0, return_inverse=True)
    return MeshEnvironment(vertices[:, :3], index.reshape(-1, 3), vertices[:, 3:], file=mesh.file)


def _split(values: np.ndarray) -> np.ndarray:
    """Per-corner values (F, 3, C) of each triangle's four children (4F, 3, C)."""
    a, b, c = values[:, 0], values[:, 1], values[:, 2]
    ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
    return np.stack(
        [np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))], axis=1
    ).reshape(-1, 3, values.shape[-1])


def timed(function, repeats: int) -> tuple[float, object]:
    """Median seconds of `repeats` calls of `function` after one warm-up, and its result."""
    result = function()
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--levels", type=int, default=5)
    args = parser.parse_args()
    scene, height, albedo, mask = irtps.load_scene_object(RIG)
    box = scene.environment
    assert isinstance(box, MeshEnvironment)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for name, mesh in (("light box", box), ("subdivided", subdivided(box, args.levels))):
            path = Path(folder) / f"{name.replace(' ', '_')}.ply"
            write_environment_mesh(mesh, path)
            load, mesh = timed(lambda path=path: read_environment_mesh(path), args.repeats)
            check, with_mesh = timed(lambda m=mesh: dataclasses.replace(scene, environment=m), args.repeats)
            arrays = (
                np.ascontiguousarray(mesh.vertices, dtype=np.float32),
                np.ascontiguousarray(mesh.triangles, dtype=np.uint32),
                np.ascontiguousarray(mesh.albedo, dtype=np.float32),
            )
            accel, _ = timed(lambda arrays=arrays: _core.Environment(*arrays), args.repeats)
            build, _ = timed(lambda s=with_mesh: make_renderer(s, height, albedo, mask), args.repeats)
            render, _ = timed(
                lambda s=with_mesh: irtps.render(s, height, albedo, mask, bounces=BOUNCES, samples=SAMPLES),
                args.repeats,
            )
            rows.append((name, len(mesh.triangles), load + check, accel, build, render))
    base = rows[0][4] + rows[0][5]
    print(
        f"cap_rig, {len(scene.lights)} point lights, {BOUNCES} bounces x {SAMPLES} paths a pixel; median of {args.repeats}"
    )
    print(
        "| environment | triangles | read and check s | its BVH s (once a run) | build s | render s "
        "| pass s (build + render) | vs light box |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, triangles, load, accel, build, render in rows:
        per_pass = build + render
        print(
            f"| {name} | {triangles} | {load:.3f} | {accel:.3f} | {build:.3f} | {render:.3f} | {per_pass:.3f} "
            f"| {per_pass / base:.2f}x |"
        )
    ratio = (rows[1][4] + rows[1][5]) / base
    print(f"target: at most {TIME_TARGET:.1f}x per pass: {'met' if ratio <= TIME_TARGET else 'NOT met'} ({ratio:.2f}x)")


if __name__ == "__main__":
    main()
