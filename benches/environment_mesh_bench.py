"""Cost of a large environment mesh: the rig's light box as given, against the same box cut
into about two million triangles, side by side in one process.

On ``../shared/data/mitsuba/cap_rig`` (its object from ground truth, its 12 point lights, its
images), the light box's 2 210 triangles are split by midpoint subdivision (each triangle into
four, five times: 2 262 040 triangles, the same surfaces and vertex albedo). For each mesh it
times, once a run: reading and checking its PLY file, building its BVH, and tracing the shadow
the mesh casts on itself at its vertices (the first renderer of a fresh mesh, less a later
one); and per pass: what one IRT-PS pass renders (`irtps.render.residual.render_with_residual`
with the defaults: 3 bounces, 64 paths a pixel, every light; its renderer built inside), and
the whole image with its direct light (`irtps.render`, what ``irtps render`` does). The two
meshes alternate within each repeat, so that both see the same machine; each figure is the
median over the repeats, after a warm-up, and each ratio the median of the repeats' ratios.
Target (issue 48): the two-million-triangle mesh costs at most 20 % more time per pass than
the light box.

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
from irtps.model.environment import MeshEnvironment, core_environment, read_environment_mesh, write_environment_mesh
from irtps.render.renderer import make_renderer
from irtps.render.residual import render_with_residual

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


def timed(function) -> tuple[float, object]:
    """Seconds that one call of `function` takes, and its result."""
    start = time.perf_counter()
    result = function()
    return time.perf_counter() - start, result


def once_a_run(path: Path, scene, height, albedo, mask) -> tuple[float, float, float]:
    """Seconds to read and check the mesh at `path`, to build its BVH, and to trace its own
    shadows (a fresh mesh's first renderer less its second)."""
    load, mesh = timed(lambda: read_environment_mesh(path))
    accel, _ = timed(lambda: core_environment(mesh))
    check, with_mesh = timed(lambda: dataclasses.replace(scene, environment=mesh))  # its view, through the BVH
    first, _ = timed(lambda: make_renderer(with_mesh, height, albedo, mask))
    second, _ = timed(lambda: make_renderer(with_mesh, height, albedo, mask))
    return load + check, accel, max(first - second, 0.0)


def per_pass(scene, height, albedo, mask, images) -> tuple[float, float]:
    """Seconds of what one IRT-PS pass renders, and of the whole image with its direct light."""
    one_pass, _ = timed(
        lambda: render_with_residual(scene, height, albedo, mask, images, bounces=BOUNCES, samples=SAMPLES)
    )
    image, _ = timed(lambda: irtps.render(scene, height, albedo, mask, bounces=BOUNCES, samples=SAMPLES))
    return one_pass, image


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--levels", type=int, default=5)
    args = parser.parse_args()
    dataset = irtps.load_dataset(RIG)
    scene, height, albedo, mask = irtps.load_scene_object(RIG)
    box = scene.environment
    assert isinstance(box, MeshEnvironment)
    meshes = {"light box": box, "subdivided": subdivided(box, args.levels)}
    with tempfile.TemporaryDirectory() as folder:
        setup = {}
        for name, mesh in meshes.items():
            path = Path(folder) / f"{name.replace(' ', '_')}.ply"
            write_environment_mesh(mesh, path)
            setup[name] = [once_a_run(path, scene, height, albedo, mask) for _ in range(args.repeats)]
            meshes[name] = read_environment_mesh(path)
    scenes = {name: dataclasses.replace(scene, environment=mesh) for name, mesh in meshes.items()}
    for name, with_mesh in scenes.items():  # warm-up: each mesh's BVH and own shadows, once a run
        per_pass(with_mesh, height, albedo, mask, dataset.images)
    seconds: dict[str, list[tuple[float, float]]] = {name: [] for name in scenes}
    for _ in range(args.repeats):
        for name, with_mesh in scenes.items():
            seconds[name].append(per_pass(with_mesh, height, albedo, mask, dataset.images))
    print(
        f"cap_rig, {len(scene.lights)} point lights, {BOUNCES} bounces x {SAMPLES} paths a pixel; "
        f"median of {args.repeats}, the meshes alternating"
    )
    print(
        "| environment | triangles | read and check s | its BVH s | its own shadows s "
        "| IRT-PS pass s | vs light box | whole image s | vs light box |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    base = seconds["light box"]
    ratios = {}
    for name, mesh in meshes.items():
        load, accel, shadows = (statistics.median(column) for column in zip(*setup[name]))
        one_pass, image = (statistics.median(column) for column in zip(*seconds[name]))
        pass_ratio, image_ratio = (
            statistics.median(ours[i] / theirs[i] for ours, theirs in zip(seconds[name], base)) for i in (0, 1)
        )
        ratios[name] = pass_ratio
        print(
            f"| {name} | {len(mesh.triangles)} | {load:.3f} | {accel:.3f} | {shadows:.3f} | {one_pass:.3f} "
            f"| {pass_ratio:.2f}x | {image:.3f} | {image_ratio:.2f}x |"
        )
    ratio = ratios["subdivided"]
    print(f"target: at most {TIME_TARGET:.1f}x per pass: {'met' if ratio <= TIME_TARGET else 'NOT met'} ({ratio:.2f}x)")


if __name__ == "__main__":
    main()
