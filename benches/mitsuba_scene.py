"""Mitsuba 3 for the benchmarks that compare with it (mitsuba_compare.py, ps_materials.py,
irtps_synthetic.py): finding LLVM for its vectorised variant, importing it with the
variants that work on this machine, and a contract scene (height field, floor, walls,
lights) built and rendered in Mitsuba, light by light.
"""

from __future__ import annotations

import glob
import os
import re
import subprocess
import sys
import time

import numpy as np

from irtps.model.scene import PointLight


def find_libllvm() -> str | None:
    """DRJIT_LIBLLVM_PATH, else the newest libLLVM-N.so in the usual library folders."""
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return os.environ["DRJIT_LIBLLVM_PATH"]
    found = []
    for pattern in ("/usr/lib/*/libLLVM-*.so*", "/usr/lib/libLLVM-*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*"):
        for path in glob.glob(pattern):
            m = re.search(r"LLVM-?(\d+)", path)
            if m:
                found.append((int(m.group(1)), path))
    return max(found)[1] if found else None


#: A small Mitsuba render, run in a child process to try a variant.
RENDER_PROBE = """
import sys
import mitsuba as mi
mi.set_variant(sys.argv[1])
scene = mi.cornell_box()
scene["sensor"]["film"].update(width=16, height=16)
image = mi.render(mi.load_dict(scene), spp=4)
assert float(image.numpy().mean()) > 0, "a black image"
"""


def probe_failure(variant: str) -> str | None:
    """None when a small render runs in `variant`, else what went wrong. It runs in a child
    process: a libLLVM that Dr.Jit loads but cannot compile every kernel with aborts its
    process (LLVM 15 with Dr.Jit 1.5: "LLVM ERROR: Cannot select: ..." in its first real kernel)."""
    try:
        child = subprocess.run(
            [sys.executable, "-c", RENDER_PROBE, variant], capture_output=True, text=True, timeout=600
        )
    except subprocess.TimeoutExpired:
        return "a 16x16 test render took over 10 minutes"
    if child.returncode == 0:
        return None
    lines = [line.strip() for line in child.stderr.splitlines() if line.strip()]
    errors = [line for line in lines if "ERROR" in line or "Error" in line]
    return (errors or lines or [f"exit status {child.returncode}"])[-1]


def import_mitsuba(variants: list[str], threads: int):
    """Import Mitsuba and Dr.Jit; return (mi, dr, usable variant names). LLVM variants are
    first tried by a small render in a child process, so that a missing or unsupported
    libLLVM shows up here rather than as an abort in the middle of the run."""
    llvm = find_libllvm()
    if llvm and "DRJIT_LIBLLVM_PATH" not in os.environ:
        os.environ["DRJIT_LIBLLVM_PATH"] = llvm
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError:
        sys.exit("mitsuba_compare.py needs Mitsuba 3: pip install mitsuba (or pip install irtps[bench])")
    usable = []
    for variant in variants:
        try:
            failure = probe_failure(variant) if variant.startswith("llvm") else None
            if failure:
                raise RuntimeError(
                    f"a test render failed with libLLVM {os.environ.get('DRJIT_LIBLLVM_PATH', '(none found)')}: {failure}"
                )
            mi.set_variant(variant)
            usable.append(variant)
        except Exception as err:  # noqa: BLE001 - any failure means "not usable here"
            print(
                f"Mitsuba variant {variant} is not usable here ({type(err).__name__}: {err}); "
                "for llvm_ad_rgb install libLLVM (Debian: apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH",
                file=sys.stderr,
            )
    dr.set_thread_count(threads)
    return mi, dr, usable


class Stopwatch:
    """Wall-clock and CPU seconds (all threads of this process) of a `with` block. CPU time
    is the steadier figure when other jobs share the cores."""

    def __enter__(self):
        self.start = (time.perf_counter(), time.process_time())
        return self

    def __exit__(self, *exc) -> None:
        self.seconds = (time.perf_counter() - self.start[0], time.process_time() - self.start[1])


def camera_sensor(mi, cam, top: float, extent: float) -> dict:
    """The Mitsuba sensor (without film and sampler) of an irtps camera over a scene whose
    highest point is `top` and whose size is `extent`.

    Orthographic: its [-1, 1] film width maps to the image's W·s. Perspective (contract §1b):
    the pinhole at the optical centre, the horizontal field of view from fx; Mitsuba's
    perspective sensor has one focal length and a principal point in the image's middle here,
    so other intrinsics are refused. Both look down −z with +y up; Mitsuba's camera x axis
    points left, which puts +x on the image's right."""
    if cam.projection == "perspective":
        if not (
            np.isclose(cam.fx, cam.fy) and np.isclose(cam.cx, cam.width / 2) and np.isclose(cam.cy, cam.height / 2)
        ):
            raise ValueError(
                f"a perspective camera with fx = fy and the principal point in the middle, got {cam.intrinsics().tolist()}"
            )
        eye = float(cam.center_z)
        if eye <= top:
            raise ValueError(f"the optical centre (height {eye}) is not above the scene's top ({top})")
        return {
            "type": "perspective",
            "fov_axis": "x",
            "fov": float(np.degrees(2 * np.arctan(cam.width / (2 * cam.fx)))),
            # Within the gap to the top: an unbounded floor's extent would clip everything.
            "near_clip": 1e-3 * (eye - top),
            "far_clip": 10 * extent + eye,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, eye], target=[0, 0, eye - 1], up=[0, 1, 0]),
        }
    eye = top + extent
    half = cam.width * cam.pixel_size / 2
    to_world = mi.ScalarTransform4f().look_at(origin=[0, 0, eye], target=[0, 0, eye - 1], up=[0, 1, 0])
    return {
        "type": "orthographic",
        "near_clip": 1e-3 * extent,
        "far_clip": 10 * extent + eye,
        "to_world": to_world @ mi.ScalarTransform4f().scale([half, half, 1]),
    }


class MitsubaScene:
    """The irtps scene as a Mitsuba scene with one light, re-aimed (a distant light) or moved
    (a point light, a rig's LED) per light; the scene's lights are all of one kind.

    Every triangle is Lambertian with the scene's per-vertex albedo, unless `bsdf` gives
    another Mitsuba BSDF (a dictionary for ``mi.load_dict``) for all of them."""

    def __init__(self, mi, variant: str, renderer, scene, bounces: int, sampler: str, bsdf: dict | None = None):
        mi.set_variant(variant)
        self.mi, self.variant, self.scene, self.bounces = mi, variant, scene, bounces
        positions, triangles, albedo, _ = renderer.mesh_arrays()
        props = mi.Properties()
        props["bsdf"] = mi.load_dict(
            bsdf or {"type": "diffuse", "reflectance": {"type": "mesh_attribute", "name": "vertex_color"}}
        )
        mesh = mi.Mesh(
            "irtps_scene", len(positions), len(triangles), props, has_vertex_normals=False, has_vertex_texcoords=False
        )
        params = mi.traverse(mesh)
        floats, ints = type(params["vertex_positions"]), type(params["faces"])
        params["vertex_positions"] = floats(np.ascontiguousarray(positions, dtype=np.float32).ravel())
        params["faces"] = ints(np.ascontiguousarray(triangles, dtype=np.uint32).ravel())
        params.update()
        mesh.add_attribute("vertex_color", 3, floats(np.ascontiguousarray(albedo, dtype=np.float32).ravel()))
        top = float(positions[:, 2].max())
        extent = float(np.ptp(positions, axis=0).max())
        film = {
            "type": "hdrfilm",
            "width": scene.camera.width,
            "height": scene.camera.height,
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
            "component_format": "float32",
        }
        sensor = dict(camera_sensor(mi, scene.camera, top, extent), film=film)
        sensor["sampler"] = {"type": sampler, "sample_count": 1}
        points = [isinstance(light, PointLight) for light in scene.lights]
        if any(points) and not all(points):
            raise ValueError("MitsubaScene takes lights of one kind, got point and distant lights")
        self.point_lights = all(points)
        if self.point_lights:
            emitter = {"type": "point", "position": [0.0, 0.0, 1.0], "intensity": {"type": "rgb", "value": [1.0] * 3}}
        else:
            emitter = {
                "type": "directional",
                "direction": [0.0, 0.0, -1.0],
                "irradiance": {"type": "rgb", "value": [1.0] * 3},
            }
        self.scene_mi = mi.load_dict(
            {
                "type": "scene",
                "sensor": sensor,
                "object": mesh,
                "light": emitter,
            }
        )
        self.params = mi.traverse(self.scene_mi)
        # max_depth counts path segments: 2 is direct light only, 2 + r adds bounces 1..r.
        # Russian roulette starts only past every rendered depth: it would add noise.
        self.full = mi.load_dict(
            {"type": "path", "max_depth": bounces + 2, "rr_depth": bounces + 10, "hide_emitters": True}
        )
        self.direct = mi.load_dict({"type": "path", "max_depth": 2, "rr_depth": bounces + 10, "hide_emitters": True})
        self.light = None
        self.triangles = len(triangles)

    def set_light(self, k: int) -> None:
        if self.light == k:
            return
        mi = self.mi
        light = self.scene.lights[k]
        if self.point_lights:
            self.params["light.position"] = mi.Point3f(*[float(e) for e in light.position])
            self.params["light.intensity.value"] = mi.Color3f(*[float(e) for e in light.intensity])
            self.params.update()
            self.light = k
            return
        travel = -np.asarray(light.direction, dtype=np.float64)
        up = [0.0, 1.0, 0.0] if abs(travel[1]) < 0.9 else [1.0, 0.0, 0.0]
        # The directional emitter sends light along its local +z.
        self.params["light.to_world"] = mi.Transform4f().look_at(origin=[0, 0, 0], target=travel.tolist(), up=up)
        self.params["light.irradiance.value"] = mi.Color3f(*[float(e) for e in light.irradiance])
        self.params.update()
        self.light = k

    def render(self, k: int, spp: int, seed: int, direct_only: bool = False) -> tuple[np.ndarray, tuple[float, float]]:
        """Image (H, W, 3) under light k, and the (wall, CPU) seconds of mi.render up to the
        NumPy array."""
        self.mi.set_variant(self.variant)
        self.set_light(k)
        with Stopwatch() as watch:
            image = np.array(
                self.mi.render(self.scene_mi, integrator=self.direct if direct_only else self.full, spp=spp, seed=seed),
                dtype=np.float32,
            )
        return image, watch.seconds

    def indirect(self, k: int, spp: int, seed: int) -> tuple[np.ndarray, tuple[float, float]]:
        """Bounces 1..r under light k (full − direct, same samples) and the full render's
        (wall, CPU) seconds."""
        full, seconds = self.render(k, spp, seed)
        direct, _ = self.render(k, spp, seed, direct_only=True)
        return full - direct, seconds
