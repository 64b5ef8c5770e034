"""Forward rendering of a scene: the direct image and each inter-reflection bounce, per light."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from irtps import _core
from irtps._shared.checks import check_array, check_finite, check_instance, check_integer, check_mask
from irtps.errors import ArgumentError
from irtps.model.options import RenderOptions
from irtps._shared.resources import check_memory
from irtps.model.camera import Camera
from irtps.model.environment import MeshEnvironment, core_environment
from irtps.model.scene import CornellBox, Light, Scene, stand_in_scene

#: Footprint samples per pixel for the direct image (stratified; shadows are traced exactly).
DEFAULT_DIRECT_SAMPLES = 64

#: Bytes of one float32 RGB pixel.
_PIXEL_BYTES = 3 * np.dtype(np.float32).itemsize

#: Rough bytes per light and pixel of the renderer's light visibility cache (one byte per
#: light at each cache point: the object's mesh vertices and a grid about a pixel apart on
#: the floor and walls).
_CACHE_BYTES_PER_PIXEL = 4


@dataclass
class Rendering:
    """Images of a scene under each of its lights.

    Attributes
    ----------
    direct : numpy.ndarray
        float32 (K, H, W, 3): direct light only, with cast shadows.
    bounces : numpy.ndarray
        float32 (B, K, H, W, 3): ``bounces[b - 1]`` is the light that reached the camera
        after exactly b inter-reflections.
    """

    direct: np.ndarray
    bounces: np.ndarray

    @property
    def indirect(self) -> np.ndarray:
        """float32 (K, H, W, 3): all inter-reflected light (the bounces summed)."""
        return self.bounces.sum(axis=0, dtype=np.float32)

    @property
    def images(self) -> np.ndarray:
        """float32 (K, H, W, 3): what a camera sees, direct plus every bounce rendered."""
        return self.direct + self.indirect


def make_renderer(scene: Scene, height: np.ndarray, albedo: np.ndarray, mask: np.ndarray) -> _core.Renderer:
    """Build the ray-tracing structures of a scene (geometry, BVH, light visibility cache).

    Parameters
    ----------
    scene : Scene
        Camera, lights, floor and environment. A perspective camera, or an orthographic
        stand-in for one (`irtps.model.scene.orthographic_scene`), is traced through its
        pinhole (contract §1b: each pixel's surface point on its rays, at its height).
    height : numpy.ndarray
        (H, W) heights of the object above the floor, world units.
    albedo : numpy.ndarray
        (H, W, 3) RGB albedo in [0, 1].
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.

    Returns
    -------
    irtps._core.Renderer

    Raises
    ------
    ArgumentError
        If `scene` is not a `Scene`, the arrays do not match the camera, or the height or
        the albedo is not finite on the mask.
    IrtpsError
        If the light visibility cache (about ``4 * K * H * W`` bytes) would need more
        memory than is available.
    """
    scene = stand_in_scene(check_instance("scene", scene, Scene), "the scene rendered")
    camera = scene.camera
    pinhole = camera.pinhole
    check_memory(
        _CACHE_BYTES_PER_PIXEL * len(scene.lights) * camera.height * camera.width,
        f"lights: {len(scene.lights)} lights of {camera.width}x{camera.height} images (light visibility cache)",
    )
    expected = (camera.height, camera.width)
    height = np.ascontiguousarray(check_array("height", height, expected, match="the camera", dtype=np.float32))
    mask = np.ascontiguousarray(check_mask(mask, expected, match="the camera"))
    albedo = np.ascontiguousarray(check_array("albedo", albedo, (*expected, 3), match="the camera", dtype=np.float32))
    check_finite("height", height, mask)
    check_finite("albedo", albedo, mask)
    environment = scene.environment
    mesh = environment if isinstance(environment, MeshEnvironment) else None
    box = environment if isinstance(environment, CornellBox) else None
    return _core.Renderer(
        height,
        mask,
        albedo,
        camera.orthographic_pixel_size,
        _light_direction_rows(scene),
        scene.light_emission.astype(np.float32),
        scene.floor,
        box,
        None if pinhole is None else _pinhole_arguments(pinhole),
        scene.light_positions.astype(np.float32) if scene.has_point_lights else None,
        None if mesh is None else core_environment(mesh),
    )


def _light_direction_rows(scene: Scene) -> np.ndarray:
    """float32 (K, 3): each distant light's direction; +z for a point light (unused)."""
    return np.stack(
        [light.direction if isinstance(light, Light) else np.array([0.0, 0.0, 1.0]) for light in scene.lights]
    ).astype(np.float32)


def _pinhole_arguments(pinhole: Camera) -> tuple[float, float, float, float, float]:
    """``(fx, fy, cx, cy, zc)`` of a perspective camera, as the core's renderer takes them."""
    k = pinhole.intrinsics()
    return float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]), pinhole.center_z


def render_memory_bytes(lights: int, size: tuple[int, int], bounces: int) -> int:
    """The memory the images of `render` take: float32 RGB (H, W) per light for the direct
    image, each bounce, and the indirect sum and camera images derived from them."""
    return (1 + bounces + 2) * lights * size[0] * size[1] * _PIXEL_BYTES


def check_render_memory(lights: int, size: tuple[int, int], bounces: int) -> None:
    """Refuse a rendering whose images would not fit in memory, before allocating anything.

    Cheap: call it before building a scene of many lights (as ``irtps.render.synth.synthesize``
    should, before making its lights).

    Parameters
    ----------
    lights : int
        Number of lights K.
    size : tuple of int
        Image (H, W).
    bounces : int
        Number of bounces B.

    Raises
    ------
    IrtpsError
        ``"lights: K lights of WxH images (direct light, B bounces and their sums, float32
        RGB) need X, more than the Y available"``.
    """
    height, width = size
    check_memory(
        render_memory_bytes(lights, size, bounces),
        f"lights: {lights} lights of {width}x{height} images (direct light, {bounces} bounces and their sums, float32 RGB)",
    )


def render(
    scene: Scene,
    height: np.ndarray,
    albedo: np.ndarray,
    mask: np.ndarray,
    *,
    bounces: int = 4,
    samples: int = 256,
    direct_samples: int | None = None,
    seed: int = 0,
    progress: bool = False,
) -> Rendering:
    """Render the direct image and the images of bounces 1..B for every light of a scene.

    Each camera path is traced once and serves all K lights, so K lights cost little more
    than one. The result depends only on the inputs and `seed`, not on the thread count.

    Parameters
    ----------
    scene : Scene
        Camera, lights, floor and environment. A perspective camera, or an orthographic
        stand-in for one (`irtps.model.scene.orthographic_scene`), is traced through its
        pinhole (contract §1b).
    height, albedo, mask : numpy.ndarray
        The object: (H, W) heights, (H, W, 3) albedo, (H, W) bool mask.
    bounces : int
        Number of inter-reflection bounces B to render (0 for the direct image only).
    samples : int
        Camera paths per pixel for the bounces.
    direct_samples : int, optional
        Footprint samples per pixel for the direct image; by default
        ``min(samples, 64)`` (stratified, with exact shadow rays); 0 skips the direct image
        (left at 0) when only the bounces are wanted.
    seed : int
        Seed of every random choice.
    progress : bool
        Show a progress bar on standard error.

    Returns
    -------
    Rendering

    Raises
    ------
    ArgumentError
        On a bad count or arrays that do not match the camera.
    IrtpsError
        Checked before anything is allocated (see `check_render_memory`): images that
        would not fit in memory.

    Examples
    --------
    >>> import numpy as np
    >>> from irtps import Camera, Light, Scene, render
    >>> lights = [Light(direction=d, irradiance=(np.pi,) * 3) for d in
    ...           ([0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8])]
    >>> scene = Scene(Camera(8, 8, 1.0), lights)
    >>> flat = render(scene, np.zeros((8, 8)), np.full((8, 8, 3), 0.5), np.ones((8, 8), bool),
    ...               bounces=1, samples=4)
    >>> round(float(flat.direct[1, 4, 4, 0]), 4)  # albedo · cos θ = 0.5 · 0.8
    0.4
    """
    check_instance("scene", scene, Scene)
    check_counts(bounces, samples, seed)
    direct_samples = min(samples, DEFAULT_DIRECT_SAMPLES) if direct_samples is None else direct_samples
    if direct_samples < 0 or (direct_samples == 0 and bounces == 0):
        raise ArgumentError("direct_samples", f"{direct_samples} must be at least 1 (or 0 with bounces)")
    check_render_memory(len(scene.lights), (scene.camera.height, scene.camera.width), bounces)
    renderer = make_renderer(scene, height, albedo, mask)
    planes = _render_planes(renderer, scene, bounces, samples, direct_samples, seed, True, progress)
    if direct_samples == 0:
        direct = np.zeros(planes.shape[1:], dtype=np.float32)
        return Rendering(direct=direct, bounces=planes)
    return Rendering(direct=planes[0], bounces=planes[1:])


def render_indirect(
    scene: Scene,
    height: np.ndarray,
    albedo: np.ndarray,
    mask: np.ndarray,
    *,
    bounces: int = 3,
    samples: int = 256,
    seed: int = 0,
    stride: int = 1,
    progress: bool = False,
) -> np.ndarray:
    """Render only the inter-reflected light: bounces 1..B summed, for every light.

    The same paths as `render`, without the direct image and without keeping the bounces
    apart: this is the estimate IRT-PS subtracts, at a fraction of the memory.

    Parameters
    ----------
    scene, height, albedo, mask, bounces, samples, seed, progress
        As for `render`.
    stride : int
        1 renders every pixel. s > 1 renders only the masked pixels of a randomly shifted
        grid one pixel in s×s (plus the mask's edge pixels) and fills the other masked
        pixels by linear interpolation over their Delaunay triangulation (the paper's
        sparse estimate with non-uniform interpolation): about s² times faster, slightly
        blurred. Pixels outside the mask are then 0.

    Returns
    -------
    numpy.ndarray
        float32 (K, H, W, 3).
    """
    check_instance("scene", scene, Scene)
    check_counts(bounces, samples, seed)
    if bounces < 1:
        raise ArgumentError("bounces", f"{bounces} must be at least 1")
    stride = check_integer("stride", stride, 1)
    check_frame_memory(scene)
    renderer = make_renderer(scene, height, albedo, mask)
    if stride == 1:
        return _render_planes(renderer, scene, bounces, samples, 0, seed, False, progress)[0]
    return render_sparse(renderer, np.asarray(mask, dtype=bool), bounces, samples, seed, stride)


def check_frame_memory(scene: Scene, planes: int = 1) -> None:
    """Refuse to allocate `planes` float32 RGB images per light of the scene's camera when
    they would not fit in memory (`irtps._shared.resources.check_memory`)."""
    camera = scene.camera
    check_memory(
        planes * len(scene.lights) * camera.height * camera.width * _PIXEL_BYTES,
        f"lights: {len(scene.lights)} lights of {camera.width}x{camera.height} images (inter-reflected light, float32 RGB)",
    )


def render_sparse(
    renderer: _core.Renderer, mask: np.ndarray, bounces: int, samples: int, seed: int, stride: int
) -> np.ndarray:
    """Inter-reflected light (bounces 1..B summed) at a sparse subset of the pixels of
    `mask`, interpolated to the rest of them: float32 (K, H, W, 3), 0 outside `mask`.

    The subset is a randomly shifted grid of one pixel in `stride`×`stride` plus the edge
    of `mask`; the rest is filled by linear interpolation over the subset's Delaunay
    triangulation (nearest value outside its hull)."""
    from scipy import ndimage
    from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator

    rows, cols = np.indices(mask.shape)
    shift_row, shift_col = np.random.default_rng(seed).integers(0, stride, size=2)
    on_grid = ((rows - shift_row) % stride == 0) & ((cols - shift_col) % stride == 0)
    edge = mask & ~ndimage.binary_erosion(mask)
    chosen = mask & (on_grid | edge)
    pixels = np.flatnonzero(chosen)
    values = renderer.render_pixels(pixels.tolist(), bounces, samples, 0, seed, False)[0]  # (K, N, 3)
    k = values.shape[0]
    flat = np.moveaxis(values, 1, 0).reshape(len(pixels), k * 3)
    known = np.column_stack([rows.ravel()[pixels], cols.ravel()[pixels]])
    wanted = np.argwhere(mask & ~chosen)
    out = np.zeros((k, *mask.shape, 3), dtype=np.float32)
    out[:, chosen] = values
    if len(wanted):
        if len(pixels) >= 3:
            filled = LinearNDInterpolator(known, flat)(wanted)
            missing = np.isnan(filled).any(axis=1)
        else:
            filled = np.empty((len(wanted), k * 3))
            missing = np.ones(len(wanted), dtype=bool)
        if missing.any():
            filled[missing] = NearestNDInterpolator(known, flat)(wanted[missing])
        out[:, wanted[:, 0], wanted[:, 1]] = np.moveaxis(filled.reshape(len(wanted), k, 3), 1, 0)
    return out


def check_counts(bounces: int, samples: int, seed: int) -> None:
    """Raise `OptionError` naming the first of bounces, samples and seed out of range."""
    RenderOptions(bounces=bounces, samples=samples, seed=seed)


def _render_planes(
    renderer, scene: Scene, bounces: int, samples: int, direct_samples: int, seed: int, split: bool, progress: bool
) -> np.ndarray:
    """Render all rows in chunks (for the progress bar): float32 (P, K, H, W, 3)."""
    rows, cols = scene.camera.height, scene.camera.width
    planes = int(direct_samples > 0) + (bounces if split else min(bounces, 1))
    out = np.empty((planes, len(scene.lights), rows, cols, 3), dtype=np.float32)
    chunk = max(1, rows // 32)
    with tqdm(total=rows, unit="row", desc="render", disable=not progress, leave=False) as bar:
        for start in range(0, rows, chunk):
            stop = min(rows, start + chunk)
            out[:, :, start:stop] = renderer.render_rows(start, stop, bounces, samples, direct_samples, seed, split)
            bar.update(stop - start)
    return out
