"""Where the object stands: its base height, estimated from the floor around it (contract §6).

Normals fix a height field only up to a constant, but the floor does not: the object's cast
shadows on it, and the light the object sends to it, move with the object's height. The
images are whole frames, so the floor around the object is seen under every light.
`estimate_placement` renders that floor (direct light with the object's cast shadows, plus
inter-reflected light, under at most `MAX_LIGHTS` well-spread lights) for the reconstructed
shape raised by an offset, and takes the offset whose rendering matches the observed floor
best: a coarse scan over every height the
object can stand at, then Brent's method around the best. Where nothing in the data fixes
the offset (no floor, no visible floor, or a floor that does not change with the offset), it
falls back to contract §6: the median height of the mask boundary on the floor
(`irtps.geometry.placement.fallback_placement`, with the `Placement` it returns).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.optimize import minimize_scalar

from irtps.geometry.placement import Placement, fallback_placement, floor_height, raised, spread_lights
from irtps.model.scene import Scene
from irtps.render.renderer import make_renderer

__all__ = ["estimate_placement"]

#: Offsets tried by the coarse scan (evenly spaced over the range, ends included).
SCAN_POINTS = 9
#: Pixels rendered per offset at most (on a regular grid over the visible floor, or the object).
MAX_COMPARED_PIXELS = 16384
#: Camera paths per floor pixel for the inter-reflected light, and footprint samples for
#: the direct light; the same random numbers at every offset, so the scan is smooth.
PATH_SAMPLES = 16
DIRECT_SAMPLES = 4
#: Lights rendered at most: the renderer's set-up (its light visibility cache) grows with
#: the number of lights and is rebuilt at every height tried, while a few well-spread
#: lights' shadows fix the height as well as many.
MAX_LIGHTS = 8
#: The floor is compared at most this many pixels across (`_coarse`).
MAX_SIDE = 128
#: Precision of the estimate, in pixel sizes.
PRECISION_PIXELS = 0.05
#: The floor must change with the offset by this many times its Monte-Carlo noise.
SIGNIFICANCE = 3.0


def estimate_placement(
    scene: Scene,
    height: np.ndarray,
    albedo: np.ndarray,
    mask: np.ndarray,
    images: np.ndarray,
    *,
    bounces: int = 3,
    saturation: float | None = None,
    seed: int = 0,
    near: Placement | None = None,
    radius: float = 0.0,
) -> Placement:
    """Estimate how high the object stands from the floor around it in the images.

    Parameters
    ----------
    scene : Scene
        Camera, lights, floor and environment.
    height : numpy.ndarray
        (H, W) the reconstructed shape, placed with its boundary median at 0 (any constant
        offset; only the relief matters).
    albedo : numpy.ndarray
        (H, W, 3) the reconstructed albedo.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    images : numpy.ndarray
        (K, H, W, 3) the observed images (the floor is read outside `mask`).
    bounces : int
        Inter-reflection bounces rendered onto the floor.
    saturation : float, optional
        Observations at or above it are left out of the comparison.
    seed : int
        Seed of the random numbers (the same at every offset).
    near : Placement, optional
        An earlier estimate (``source="images"``) for a shape that has since changed: the
        search is then only within `radius` of it (for IRT-PS's later passes). By default
        every height from the floor up to the image's larger side is scanned.
    radius : float
        World units, with `near`.

    Returns
    -------
    Placement
        ``source="images"``, or the fallback with its reason.

    Examples
    --------
    A 6-high block on the floor, lit from four sides at 45°: its shadows fix its height.

    >>> import numpy as np
    >>> from irtps import Camera, Floor, Light, Scene, render
    >>> c, s = np.cos(np.radians(45)), np.sin(np.radians(45))
    >>> lights = [Light(direction=(s * np.cos(a), s * np.sin(a), c), irradiance=(np.pi,) * 3)
    ...           for a in np.radians([0, 90, 180, 270])]
    >>> scene = Scene(Camera(40, 40, 1.0), lights, floor=Floor(0.0, (0.8, 0.8, 0.8)))
    >>> mask = np.zeros((40, 40), bool)
    >>> mask[14:26, 14:26] = True
    >>> albedo = np.where(mask[..., None], 0.5, 0.0) * np.ones(3)
    >>> images = render(scene, np.where(mask, 6.0, 0.0), albedo, mask, bounces=1, samples=16).images
    >>> placement = estimate_placement(scene, np.zeros((40, 40)), albedo, mask, images, bounces=1)
    >>> placement.source, round(placement.base_height)
    ('images', 6)
    """
    if scene.floor is None and scene.environment is None:
        return fallback_placement(scene, "the scene has no floor: nothing in the images fixes the object's height")
    chosen = spread_lights(scene.nominal_light_directions, MAX_LIGHTS)
    scene = dataclasses.replace(scene, lights=tuple(scene.lights[k] for k in chosen))
    images = np.asarray(images, dtype=np.float32)[chosen]
    unsaturated = (
        np.ones((*images.shape[:3], 1), dtype=bool)
        if saturation is None
        else ~np.any(images >= saturation, axis=-1, keepdims=True)
    )
    mask = np.asarray(mask, dtype=bool)
    relief = np.where(mask, np.asarray(height, dtype=np.float64), 0.0)
    coarse = _Compared(*_coarse(scene, relief, np.asarray(albedo, dtype=np.float64), mask, images, unsaturated))
    why_not_floor = coarse.why_not_floor()
    if why_not_floor is None:
        placement = coarse.search("floor", bounces, seed, near, radius)
        if placement.source == "images" or scene.environment is None:
            return placement
        why_not_floor = placement.reason
    if near is not None and near.source != "object":
        return fallback_placement(scene, why_not_floor)
    placement = coarse.search("object", bounces, seed, near, radius)
    if placement.source == "object":
        return dataclasses.replace(placement, reason=why_not_floor)
    return fallback_placement(scene, f"{why_not_floor}, and {placement.reason}")


class _Compared:
    """The (coarse) scene, reconstruction and observations that a placement is searched with."""

    def __init__(self, scene, relief, albedo, mask, images, unsaturated) -> None:
        self.scene, self.relief, self.albedo, self.mask = scene, relief, albedo, mask
        self.images, self.unsaturated = images, unsaturated

    def why_not_floor(self) -> str | None:
        """Why the floor cannot place the object, or None."""
        if self.scene.floor is None:
            return "the scene has no floor"
        if self.mask.all():
            return "the mask covers the whole image: no floor is visible"
        return None

    def search(self, evidence: str, bounces: int, seed: int, near: Placement | None, radius: float) -> Placement:
        """The offset whose rendering of the `evidence` (``"floor"``: the pixels around the
        object; ``"object"``: its own, lit by the surroundings too) matches the observations
        best: a scan of every height, or Brent's method within `radius` of `near`; the
        fallback, with its reason, where they do not change with the offset."""
        scene, mask = self.scene, self.mask
        pixels = _grid_pixels(~mask if evidence == "floor" else mask)
        what = "the floor" if evidence == "floor" else "the object"
        observed = self.images.reshape(len(self.images), -1, 3)[:, pixels]
        usable = np.broadcast_to(self.unsaturated.reshape(len(self.images), -1, 1)[:, pixels], observed.shape)
        scale = float(np.abs(observed[usable]).sum())
        if scale <= 0:
            return fallback_placement(scene, f"{what} is black in every image: nothing fixes the object's height")
        pixel_list = pixels.tolist()

        def residual(offset: float, path_seed: int = seed) -> float:
            renderer = make_renderer(scene, raised(self.relief, mask, offset, scene), self.albedo, mask)
            planes = renderer.render_pixels(pixel_list, bounces, PATH_SAMPLES, DIRECT_SAMPLES, path_seed, False)
            rendered = planes.sum(axis=0)
            if evidence == "object":
                rendered = rendered * _albedo_refit(rendered, observed, usable)
            return float(np.abs(rendered - observed)[usable].sum()) / scale

        def found(offset: float, value: float) -> Placement:
            if evidence == "floor":
                return Placement(offset, "images", floor_residual=value, floor_pixels=int(pixels.size))
            return Placement(offset, "object", object_residual=value, object_pixels=int(pixels.size))

        low = floor_height(scene)
        high = low + _height_range(scene)
        precision = PRECISION_PIXELS * scene.camera.orthographic_pixel_size
        if near is not None:
            bracket = (max(low, near.base_height - radius), min(high, near.base_height + radius))
            result = minimize_scalar(residual, bounds=bracket, method="bounded", options={"xatol": precision})
            return found(float(result.x), float(result.fun))
        scan = np.linspace(low, high, SCAN_POINTS)
        values = [residual(offset) for offset in scan]
        best = int(np.argmin(values))
        step = scan[1] - scan[0]
        bracket = (max(low, scan[best] - step), min(high, scan[best] + step))
        result = minimize_scalar(residual, bounds=bracket, method="bounded", options={"xatol": precision})
        offset, value = (
            (float(result.x), float(result.fun)) if result.fun <= values[best] else (float(scan[best]), values[best])
        )
        noise = abs(residual(offset, seed + 1) - value)
        if max(values) - value <= SIGNIFICANCE * noise:
            return fallback_placement(
                scene,
                f"{what} looks the same whatever the object's height"
                + (" (no shadow or light of the object falls on it)" if evidence == "floor" else ""),
            )
        return found(offset, value)


def _coarse(
    scene: Scene, relief: np.ndarray, albedo: np.ndarray, mask: np.ndarray, images: np.ndarray, unsaturated: np.ndarray
):
    """The scene and its arrays averaged over f×f blocks of pixels, so that the image's larger
    side is at most `MAX_SIDE` pixels (unchanged if it already is).

    The renderer is set up again at every height tried, at a cost that grows with the pixel
    count, while the floor's shadows fix the height as well at a coarser scale. The image is
    cropped by the same number of pixels on opposite sides (f is raised until both
    remainders are even), so the coarse camera is centred as the contract's (§1). A block
    is on the object where any of its pixels is: the coarse skirt then stands, on average
    over where the object's edge falls in its blocks, where the full-resolution one does
    (with most of its pixels instead, the object shrinks by about a quarter block a side,
    and is placed too high). Its relief
    and albedo are those of its object pixels; it is usable where none of its
    observations is saturated.
    """
    rows, cols = mask.shape
    factor = -(-max(rows, cols) // MAX_SIDE)
    while factor > 1 and (rows % factor % 2 or cols % factor % 2):
        factor += 1
    if factor <= 1:
        return scene, relief, albedo, mask, images, unsaturated
    top, left = rows % factor // 2, cols % factor // 2
    size = (rows // factor, cols // factor)

    def blocks(array: np.ndarray, axis: int) -> np.ndarray:
        """`array` cropped, with axes (axis, axis + 1) split into blocks (block, within)."""
        index = [slice(None)] * array.ndim
        index[axis], index[axis + 1] = slice(top, top + size[0] * factor), slice(left, left + size[1] * factor)
        cropped = array[tuple(index)]
        shape = (*cropped.shape[:axis], size[0], factor, size[1], factor, *cropped.shape[axis + 2 :])
        return cropped.reshape(shape)

    count = blocks(mask.astype(np.float64), 0).sum(axis=(1, 3))
    inside = count > 0
    weight = np.maximum(count, 1.0)
    coarse_relief = blocks(relief * mask, 0).sum(axis=(1, 3)) / weight
    coarse_albedo = blocks(albedo * mask[..., None], 0).sum(axis=(1, 3)) / weight[..., None]
    coarse_images = blocks(images, 1).mean(axis=(2, 4), dtype=np.float32)
    coarse_unsaturated = blocks(unsaturated, 1).all(axis=(2, 4))
    pinhole = scene.camera.pinhole
    if pinhole is not None:  # coarse pixel (I, J) spans u in [left + J f, left + (J + 1) f)
        pinhole = dataclasses.replace(
            pinhole,
            width=size[1],
            height=size[0],
            fx=pinhole.fx / factor,
            fy=pinhole.fy / factor,
            cx=(pinhole.cx - left) / factor,
            cy=(pinhole.cy - top) / factor,
        )
    camera = dataclasses.replace(
        scene.camera,
        width=size[1],
        height=size[0],
        pixel_size=scene.camera.orthographic_pixel_size * factor,
        pinhole=pinhole,
    )
    coarse_scene = dataclasses.replace(scene, camera=camera)
    return (
        coarse_scene,
        np.where(inside, coarse_relief, 0.0),
        np.where(inside[..., None], coarse_albedo, 0.0),
        inside,
        coarse_images,
        coarse_unsaturated,
    )


def _height_range(scene: Scene) -> float:
    """How far above the floor the boundary may stand: the image's larger side."""
    camera = scene.camera
    return max(camera.width, camera.height) * camera.orthographic_pixel_size


def _albedo_refit(rendered: np.ndarray, observed: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Per pixel and channel, the least-squares scale of `rendered` (K, N, 3) to `observed`
    over the `usable` lights (1 where nothing is rendered): what the object's albedo would
    be for the rendering to match. Photometric stereo's albedo takes in the inter-reflected
    light it does not model; refitted, the object's pixels compare the way the light changes
    from image to image, which the surroundings' light on the object shapes, not its level."""
    weights = np.where(usable, rendered, 0.0)
    energy = (weights * rendered).sum(axis=0)
    return np.where(energy > 0, (weights * observed).sum(axis=0) / np.where(energy > 0, energy, 1.0), 1.0)


def _grid_pixels(selected: np.ndarray) -> np.ndarray:
    """Row-major indices of the `selected` pixels, on a regular grid of at most
    `MAX_COMPARED_PIXELS`."""
    pixels = np.flatnonzero(np.asarray(selected, dtype=bool))
    step = max(1, -(-pixels.size // MAX_COMPARED_PIXELS))
    return pixels[::step]
