"""Synthetic scenes with ground truth: shapes, albedo patterns, lights and surroundings."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage

from irtps._shared.checks import check_choice
from irtps.model.data import Dataset, GroundTruth
from irtps.errors import ArgumentError
from irtps.geometry.boundary import place_height
from irtps.model.options import OptionError, RenderOptions, SynthOptions
from irtps.render.renderer import Rendering, check_render_memory, render
from irtps.model.environment import MeshEnvironment
from irtps.model.scene import Camera, CornellBox, Floor, Light, PointLight, Scene
from irtps.geometry.surface import depth_to_normals, height_to_normals

#: Wall colours of the classic Cornell box (red left, green right), as in the shared renders.
CORNELL_ALBEDO = {
    "left": (0.63, 0.065, 0.05),
    "right": (0.14, 0.45, 0.091),
    "back": (0.725, 0.71, 0.68),
    "front": (0.725, 0.71, 0.68),
}


def _cap(size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A spherical cap sitting on the floor (convex)."""
    r = _radius(size)
    sphere_radius, cap_height = 0.42 * size, 0.22 * size
    inside = sphere_radius**2 - r**2
    height = np.sqrt(np.clip(inside, 0, None)) - (sphere_radius - cap_height)
    mask = height > 0
    return np.where(mask, height, 0.0), mask


def _cavity(size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A square block with a spherical bowl hollowed out of its top (concave)."""
    rows, cols = _grid(size)
    half = 0.4 * size
    mask = (np.abs(rows) < half) & (np.abs(cols) < half)
    top, bowl_radius, depth = 0.3 * size, 0.3 * size, 0.2 * size
    sphere_radius = (bowl_radius**2 + depth**2) / (2 * depth)
    r2 = rows**2 + cols**2
    dent = np.where(
        r2 < bowl_radius**2, np.sqrt(np.clip(sphere_radius**2 - r2, 0, None)) - (sphere_radius - depth), 0.0
    )
    return np.where(mask, top - dent, 0.0), mask


def _grooves(size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A block with parallel V-grooves (90° opening), strong self inter-reflection."""
    rows, cols = _grid(size)
    half = 0.42 * size
    mask = (np.abs(rows) < half) & (np.abs(cols) < half)
    period = max(4.0, size / 6)
    phase = np.abs(((cols + half) / period) % 1.0 - 0.5) * 2  # 1 at ridges, 0 in valleys
    height = 0.1 * size + 0.5 * period * phase
    return np.where(mask, height, 0.0), mask


def _relief(size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A smooth random relief on a disc (convex and concave parts)."""
    mask = _radius(size) < 0.45 * size
    noise = ndimage.gaussian_filter(rng.standard_normal((size, size)), sigma=size / 12, mode="wrap")
    noise /= np.abs(noise).max()
    height = 0.12 * size + 0.08 * size * noise
    return np.where(mask, height, 0.0), mask


def _pedestal(size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A round pedestal with vertical sides, a flat top well above the floor, a smooth bump
    in its middle and a steep-walled ring trench around it (convex, concave, and a mask
    boundary far from the floor)."""
    r = _radius(size)
    mask = r < 0.43 * size
    top, bump_radius, bump_height = 0.18 * size, 0.2 * size, 0.16 * size
    bump = np.where(r < bump_radius, bump_height * np.cos(0.5 * np.pi * r / bump_radius) ** 2, 0.0)
    trench_radius, trench_width, trench_depth = 0.3 * size, 0.03 * size, 0.065 * size
    trench = trench_depth * np.clip(1 - np.abs(r - trench_radius) / trench_width, 0, 1) ** 0.5
    return np.where(mask, top + bump - trench, 0.0), mask


#: Shape generators by name: each returns (height, mask) in pixel units.
SHAPES: dict[str, Callable[[int, np.random.Generator], tuple[np.ndarray, np.ndarray]]] = {
    "cap": _cap,
    "cavity": _cavity,
    "grooves": _grooves,
    "relief": _relief,
    "pedestal": _pedestal,
}


def _grid(size: int) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    return rows - (size - 1) / 2, cols - (size - 1) / 2


def _radius(size: int) -> np.ndarray:
    rows, cols = _grid(size)
    return np.hypot(rows, cols)


def ring_lights(count: int, *, max_zenith_deg: float = 50.0, irradiance: float = np.pi) -> list[Light]:
    """Lights spread evenly over a cone around the camera axis (a Fibonacci spiral).

    Parameters
    ----------
    count : int
        Number of lights (at least 3).
    max_zenith_deg : float
        Largest angle between a light and the +z axis, degrees.
    irradiance : float
        Irradiance of every light in every channel (π gives the textbook ``ρ n·l``).

    Returns
    -------
    list of Light
    """
    if count < 3:
        raise ArgumentError("count", f"{count} lights given, photometric stereo needs at least 3")
    golden = np.pi * (3 - np.sqrt(5))
    cos_max = np.cos(np.radians(max_zenith_deg))
    index = np.arange(count) + 0.5
    z = 1 - (1 - cos_max) * index / count
    radial = np.sqrt(1 - z**2)
    azimuth = golden * np.arange(count)
    directions = np.stack([radial * np.cos(azimuth), radial * np.sin(azimuth), z], axis=1)
    return [Light(direction=d, irradiance=np.full(3, irradiance)) for d in directions]


def make_albedo(mask: np.ndarray, pattern: str, rng: np.random.Generator, colour=(0.8, 0.8, 0.8)) -> np.ndarray:
    """RGB albedo: ``"uniform"`` (`colour` everywhere) or ``"textured"`` (smooth colour patches)."""
    size = mask.shape
    if pattern == "uniform":
        albedo = np.broadcast_to(np.asarray(colour, dtype=np.float64), (*size, 3)).copy()
    elif pattern == "textured":
        noise = np.stack(
            [ndimage.gaussian_filter(rng.standard_normal(size), sigma=max(size) / 16) for _ in range(3)], axis=-1
        )
        noise /= np.abs(noise).max()
        albedo = 0.55 + 0.35 * noise
    else:
        raise ArgumentError("pattern", f"unknown {pattern!r}; expected one of uniform, textured")
    return np.where(mask[..., None], albedo, 0.0).astype(np.float32)


#: A filling shape (`synthesize`'s ``fill``) is made for an image this many times as large.
FILL_SCALE = 2


def filled(shape: str, size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """`shape` made for an image `FILL_SCALE` times as large, its middle `size` × `size`
    pixels: (height, mask), the mask every pixel (each shape's mask reaches beyond the
    middle's corners at that scale)."""
    height, mask = SHAPES[shape](FILL_SCALE * size, rng)
    start = (FILL_SCALE * size - size) // 2
    middle = (slice(start, start + size),) * 2
    height, mask = height[middle], mask[middle]
    if not mask.all():
        raise ArgumentError("fill", f"the {shape} does not fill a {size}x{size} frame")
    return height, mask


#: A synthetic pinhole's focal length, in image sizes: about 45° across the image.
PINHOLE_FOCAL_SIZES = 1.2


def synthetic_camera(size: int, projection: str) -> Camera:
    """The camera of a synthetic scene of `size` pixels a side: orthographic with pixel size
    1, or a pinhole on the image's centre with focal length `PINHOLE_FOCAL_SIZES` image sizes,
    its optical centre as high above the floor (z = 0) as that focal length in pixels, where
    a pixel is then 1 wide."""
    if projection == "orthographic":
        return Camera(size, size, 1.0)
    focal = PINHOLE_FOCAL_SIZES * size
    center = size / 2.0
    return Camera(
        size, size, projection="perspective", fx=focal, fy=focal, cx=center, cy=center, optical_center=(0, 0, focal)
    )


#: Albedo of the light box's floor and walls (`light_box`), and of its coloured side wall.
LIGHT_BOX_GREY, LIGHT_BOX_CARD = (0.78, 0.78, 0.76), (0.85, 0.62, 0.25)


def light_box(size: int) -> MeshEnvironment:
    """A rig's light box around an object of `size` pixels, as a mesh (contract §3b): a grey
    floor at height 0 and grey back and left walls, an orange right wall (a reflector card),
    open at the front and the top, each side ``1.8 * size`` long and the walls ``0.8 * size``
    high, two triangles a face."""
    half, top = 0.9 * size, 0.8 * size
    faces = {
        "floor": [(-half, -half, 0.0), (half, -half, 0.0), (half, half, 0.0), (-half, half, 0.0)],
        "back": [(-half, half, 0.0), (half, half, 0.0), (half, half, top), (-half, half, top)],
        "left": [(-half, -half, 0.0), (-half, half, 0.0), (-half, half, top), (-half, -half, top)],
        "right": [(half, -half, 0.0), (half, half, 0.0), (half, half, top), (half, -half, top)],
    }
    vertices = np.array([corner for corners in faces.values() for corner in corners], dtype=np.float64)
    albedo = np.array([LIGHT_BOX_CARD if name == "right" else LIGHT_BOX_GREY for name in faces for _ in range(4)])
    triangles = np.array(
        [[4 * f, 4 * f + 1, 4 * f + 2] for f in range(len(faces))]
        + [[4 * f, 4 * f + 2, 4 * f + 3] for f in range(len(faces))]
    )
    return MeshEnvironment(vertices, triangles, albedo)


def near_lights(distant: list[Light], distance: float) -> list[PointLight]:
    """Point lights at `distance` from the world origin in the directions of `distant`
    lights, each of intensity ``π distance²`` (the irradiance π at the origin)."""
    return [
        PointLight(position=light.direction * distance, intensity=np.full(3, np.pi * distance**2)) for light in distant
    ]


def synthesize(
    shape: str,
    *,
    size: int = 96,
    lights: int = 12,
    albedo: str = "uniform",
    environment: str = "cornell",
    floor: bool | None = None,
    base: float | None = None,
    fill: bool = False,
    camera: str = "orthographic",
    lights_near: float | None = None,
    bounces: int = 4,
    samples: int = 256,
    seed: int = 0,
    progress: bool = False,
) -> tuple[Dataset, Rendering]:
    """Make a synthetic data set with ground truth, rendered with inter-reflections.

    Parameters
    ----------
    shape : str
        One of `SHAPES`: ``"cap"``, ``"cavity"``, ``"grooves"``, ``"relief"``,
        ``"pedestal"``.
    size : int
        Image width and height in pixels (pixel size 1).
    lights : int
        Number of lights, spread by `ring_lights`.
    albedo : str
        ``"uniform"`` or ``"textured"``.
    environment : str
        ``"cornell"`` (a box with red and green side walls), ``"light-box"`` (a rig's light
        box given as a mesh, `light_box`: it holds the floor) or ``"none"``.
    floor : bool, optional
        Whether there is a floor besides; by default only with the Cornell box.
    base : float, optional
        Height of the object's boundary (the median over its mask's edge) above the floor,
        in pixel sizes; its sides run vertically down to the floor (contract §2). By
        default, the shape's own (about 1 for the cap, 0.1–0.3 of `size` for the others).
    fill : bool
        The object fills the frame: the shape is made for an image `FILL_SCALE` times as
        large and the middle `size` × `size` pixels are seen, every one on the object, its
        edges leaving the image (its skirt stands at the image's border). No floor or wall
        is then in view, and placement falls back to the boundary unless `base` is given.
    camera : str
        ``"orthographic"`` (pixel size 1) or ``"perspective"``: a pinhole on the image's
        centre with focal length ``1.2 * size`` pixels (about 45° across), its optical centre
        ``1.2 * size`` above the floor, where a pixel is then 1 wide (`PINHOLE_FOCAL_SIZES`).
        Each object pixel's surface point lies on its centre ray at its height (contract
        §1b); the ground truth adds the depth, and the normals are the depth map's
        (`irtps.depth_to_normals`).
    lights_near : float, optional
        Point lights near the object instead of distant ones (a rig's LEDs, contract §4b):
        each ``lights_near * size`` from the middle of the floor in the direction of the
        distant light it replaces (`ring_lights`), of intensity ``π (lights_near * size)²``,
        which gives the irradiance π there.
    bounces, samples, seed, progress
        As for `irtps.render`.

    Returns
    -------
    (Dataset, Rendering)
        The data set (images = direct + all bounces; ground truth height, normals, albedo
        and direct images) and the rendering with each bounce separately.

    Examples
    --------
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=3, bounces=1, samples=4)
    >>> data.images.shape
    (3, 16, 16, 3)
    """
    check_choice("shape", shape, SHAPES)
    SynthOptions(
        size=size,
        lights=lights,
        albedo=albedo,
        environment=environment,
        floor=floor,
        base=base,
        fill=fill,
        camera=camera,
        lights_near=lights_near,
    )
    RenderOptions(bounces=bounces, samples=samples, seed=seed)
    check_render_memory(lights, (size, size), bounces)
    rng = np.random.default_rng(seed)
    height, mask = filled(shape, size, rng) if fill else SHAPES[shape](size, rng)
    if base is not None:
        height = place_height(height, mask, base_height=base, per_component=False)
        if height[mask].min() < 0:
            raise OptionError(
                "base",
                f"{base:g} puts part of the {shape} below the floor (its lowest point is {-height[mask].min() + base:.3g} below its boundary)",
            )
    height = np.where(mask, height, 0.0).astype(np.float32)
    has_floor = environment == "cornell" if floor is None else floor
    surroundings: CornellBox | MeshEnvironment | None = None
    if environment == "cornell":
        half = 0.55 * size
        a = CORNELL_ALBEDO
        surroundings = CornellBox(
            (-half, half), (-half, half), 0.5 * size, a["left"], a["right"], a["back"], a["front"]
        )
    elif environment == "light-box":
        surroundings = light_box(size)
    distant = ring_lights(lights)
    scene = Scene(
        camera=synthetic_camera(size, camera),
        lights=tuple(distant if lights_near is None else near_lights(distant, lights_near * size)),
        floor=Floor(0.0, (0.8, 0.8, 0.8)) if has_floor else None,
        environment=surroundings,
    )
    albedo_map = make_albedo(mask, albedo, rng)
    rendering = render(scene, height, albedo_map, mask, bounces=bounces, samples=samples, seed=seed, progress=progress)
    if scene.camera.optical_center is None:
        depth, normal = None, height_to_normals(height, mask)
    else:
        depth = np.where(mask, scene.camera.optical_center[2] - height, 0).astype(np.float32)
        normal = depth_to_normals(depth, mask, scene.camera)
    truth = GroundTruth(height=height, normal=normal, albedo=albedo_map, direct=rendering.direct, depth=depth)
    dataset = Dataset(scene=scene, images=rendering.images, mask=mask, gt=truth, source=f"synth:{shape}")
    return dataset, rendering
