"""One pass of the reconstruction pipeline: photometric stereo, normal integration,
placement, the height raised to it inside the mask (`reconstruction_pass`).

Classic photometric stereo is one pass on the data set's images: IRT-PS with zero
corrections. IRT-PS (`irtps.irt.interreflection`) runs one pass per corrected image set, each
given the one before.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from irtps.errors import ArgumentError
from irtps.model.data import Dataset
from irtps.geometry.integrate import integrate_normals
from irtps.geometry.boundary import place_height
from irtps.model.options import OptionError, ReconstructOptions
from irtps.geometry.placement import Placement, fallback_placement, raised
from irtps.ps.fit import MASKED_OUT, PsResult, lobe_share, photometric_stereo
from irtps.render.radiometry import AlbedoScale, absolute_scale, estimate_albedo_scale, scaled_albedo, scaled_scene
from irtps.render.placement import PRECISION_PIXELS, estimate_placement
from irtps.render.residual import compared_observations
from irtps.model.scene import Scene, lights_at
from irtps.geometry.falloff_placement import falloff_placement
from irtps.geometry.surface import surface_albedo

#: Heights are float32 (24 significant bits): a surface placed further than this many pixel
#: sizes from the origin keeps no precision for its relief.
MAX_BASE_HEIGHT_PIXELS = 1e6
#: IRT-PS refines an estimated placement within this many times the mean change of the
#: relief from the pass before.
PLACEMENT_SEARCH_CHANGES = 3.0


@dataclasses.dataclass
class Pass:
    """What one pass of the pipeline reconstructed (`reconstruction_pass`).

    Attributes
    ----------
    fit : PsResult
        Photometric stereo on the pass's images.
    relief : numpy.ndarray
        float32 (H, W) height map of the fit's normals, its mask's boundary median at 0.
    albedo : numpy.ndarray
        The albedo of the triangulated relief that explains the fit (`rendered_albedo`).
    placement : Placement
        Where the relief stands.
    height : numpy.ndarray
        float32 (H, W) relief raised to the placement inside the mask, 0 outside.
    albedo_scale : AlbedoScale or None
        The factor from fitted albedo to rendered reflectance, where it was resolved.
    timings : dict
        Seconds per stage: ``photometric_stereo``, ``integration``, ``placement``.
    """

    fit: PsResult
    relief: np.ndarray
    albedo: np.ndarray
    placement: Placement
    height: np.ndarray
    albedo_scale: AlbedoScale | None
    timings: dict[str, float]


def reconstruction_pass(
    dataset: Dataset,
    images: np.ndarray,
    options: ReconstructOptions,
    *,
    previous: Pass | None = None,
    usable: np.ndarray | None = None,
    rendered: bool = False,
    coverage: np.ndarray | None = None,
    progress: bool = False,
) -> Pass:
    """Photometric stereo on `images`, integration, placement and the placed height.

    Parameters
    ----------
    dataset : Dataset
        Lights, mask, scene and the input images (which place the object).
    images : numpy.ndarray
        (K, H, W, 3): the data set's images, or images corrected for inter-reflections.
    options : ReconstructOptions
        Resolved settings (`resolve_options`).
    previous : Pass, optional
        The pass before (IRT-PS): its placement is refined as the relief changed from its
        relief (`place_surface`), and its albedo scale is kept.
    usable : numpy.ndarray, optional
        The observations compared (`fitted_observations`), computed where needed if not
        given.
    rendered : bool
        The reconstruction will be rendered (IRT-PS): a first pass resolves the albedo
        scale (`resolve_albedo_scale`) even where the placement does not need it.
    coverage : numpy.ndarray, optional
        (H, W): the fraction of each pixel's footprint whose light `images` hold (IRT-PS's
        edge pixels, their surroundings' light subtracted: `irtps.render.surroundings`); the
        albedo is the fitted one over it. Default 1.
    progress : bool
        Show a progress bar for a lobe-mode fit (`fit_photometric_stereo`).

    Returns
    -------
    Pass
        Its ``albedo_scale`` is None where neither the rendering nor the placement needed
        it (classic photometric stereo on absolute irradiance, or with a given placement).
    """
    mask = dataset.mask
    timings: dict[str, float] = {}
    if dataset.scene.has_point_lights:
        return _near_light_pass(dataset, images, options, previous, usable, rendered, coverage, progress)
    with timed(timings, "photometric_stereo"):
        fit = fit_photometric_stereo(dataset, images, options, progress=progress)
    with timed(timings, "integration"):
        relief = surface_relief(dataset, fit.normals, options)
    with timed(timings, "placement"):
        albedo = rendered_albedo(dataset, fit, relief, coverage)
        scene = dataset.scene
        if previous is not None:
            albedo_scale = previous.albedo_scale
            shape_change = float(np.abs(relief - previous.relief)[mask].mean())
            placement = place_surface(
                dataset,
                relief,
                albedo,
                options,
                seed=options.seed,
                previous=previous.placement,
                shape_change=shape_change,
                albedo_scale=albedo_scale,
            )
        elif rendered or (scene.relative_irradiance and scene.floor is not None and options.base_height == "auto"):
            # The floor is rendered to place the object: with the reflectance, so the scale first.
            usable = fitted_observations(dataset, options) if usable is None else usable
            albedo_scale, placement = scale_and_place(dataset, relief, albedo, options, usable, seed=options.seed)
        else:
            albedo_scale, placement = None, place_surface(dataset, relief, albedo, options, seed=options.seed)
    return Pass(
        fit=fit,
        relief=relief,
        albedo=albedo,
        placement=placement,
        height=placed(relief, mask, placement, dataset.scene),
        albedo_scale=albedo_scale,
        timings=timings,
    )


#: Rounds of fitting, integrating and placing under point lights, at most, before the shape
#: settles (`settled_near_fit`).
NEAR_ROUNDS = 20


def _near_light_pass(
    dataset: Dataset,
    images: np.ndarray,
    options: ReconstructOptions,
    previous: Pass | None,
    usable: np.ndarray | None,
    rendered: bool,
    coverage: np.ndarray | None,
    progress: bool,
) -> Pass:
    """`reconstruction_pass` under point lights near the object: the fit, the relief and the
    placement settled together (`settled_near_fit`), from the previous pass's surface; its
    ``photometric_stereo`` timing holds the rounds' integrations and placements too."""
    timings: dict[str, float] = {}
    with timed(timings, "photometric_stereo"):
        fit, relief, placement = settled_near_fit(
            dataset,
            images,
            options,
            start=None if previous is None else previous.height,
            placement=None if previous is None else previous.placement,
            progress=progress,
        )
    with timed(timings, "placement"):
        albedo = rendered_albedo(dataset, fit, relief, coverage)
        height = placed(relief, dataset.mask, placement, dataset.scene)
        if previous is not None:
            albedo_scale = previous.albedo_scale
        elif rendered or dataset.scene.relative_irradiance:
            usable = fitted_observations(dataset, options) if usable is None else usable
            albedo_scale = resolve_albedo_scale(dataset, height, albedo, usable, options, seed=options.seed)
        else:
            albedo_scale = None
    return Pass(fit, relief, albedo, placement, height, albedo_scale, timings)


def settled_near_fit(
    dataset: Dataset,
    images: np.ndarray,
    options: ReconstructOptions,
    *,
    start: np.ndarray | None = None,
    placement: Placement | None = None,
    progress: bool = False,
) -> tuple[PsResult, np.ndarray, Placement]:
    """Photometric stereo under point lights near the object, whose direction and
    irradiance at each pixel depend on where its surface point stands: fit with the lights at
    the current surface, integrate, place (`near_placement`), and again, until the placed
    surface moves by less than `PRECISION_PIXELS` of a pixel on average (at most
    `NEAR_ROUNDS` rounds). From `start` (placed heights) and its `placement`, else from the
    level surface at the scene's base height.

    Returns
    -------
    fit, relief, placement
        The last fit (with the lights at the surface before it), its relief (boundary median
        at 0) and where that relief stands.
    """
    scene, mask = dataset.scene, dataset.mask
    height = np.where(mask, scene.base_height, 0).astype(np.float32) if start is None else start
    tolerance = PRECISION_PIXELS * scene.camera.orthographic_pixel_size
    framed = images if images.ndim == 4 else _framed(images, mask)
    change, chosen_by = None, None
    for _ in range(NEAR_ROUNDS):
        fit = fit_photometric_stereo(dataset, images, options, progress=progress, surface=height)
        if options.robust == "auto":
            # The first round chooses the robust mode; the later ones fit with its choice.
            chosen_by, options = fit, with_chosen_robust(options, fit)
        elif chosen_by is not None:
            fit = dataclasses.replace(fit, robust_used=chosen_by.robust_used, lobe_share=chosen_by.lobe_share)
        relief = surface_relief(dataset, fit.normals, options)
        placed_at = near_placement(dataset, relief, framed, options, placement, change)
        settled = placed(relief, mask, placed_at, scene)
        change = float(np.abs(settled - height)[mask].mean())
        height, placement = settled, placed_at
        if change <= tolerance:
            break
    return fit, relief, placed_at


def near_placement(
    dataset: Dataset,
    relief: np.ndarray,
    images: np.ndarray,
    options: ReconstructOptions,
    previous: Placement | None,
    shape_change: float | None,
) -> Placement:
    """Where `relief` stands under point lights: as ``options.base_height`` gives it, the
    fallback for ``"boundary"``, else from the light's fall-off over `images` (K, H, W, 3)
    (`irtps.geometry.falloff_placement`), within `PLACEMENT_SEARCH_CHANGES` times the
    surface's last move (`shape_change`) of a `previous` estimate."""
    if options.base_height == "boundary":
        return fallback_placement(dataset.scene)
    if options.base_height != "auto":
        return Placement(base_height=float(options.base_height), source="given")
    near = previous if previous is not None and previous.source == "falloff" and shape_change is not None else None
    return falloff_placement(
        dataset.scene,
        relief,
        dataset.mask,
        images,
        robust="tukey" if options.robust == "auto" else options.robust,
        shadow_fraction=options.shadow_fraction,
        saturation=options.saturation,
        near=near,
        radius=0.0 if near is None or shape_change is None else PLACEMENT_SEARCH_CHANGES * shape_change,
    )


def _framed(observations: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(K, N, 3) observations of the mask's pixels as (K, H, W, 3) images, 0 elsewhere."""
    images = np.zeros((observations.shape[0], *mask.shape, 3), dtype=np.float32)
    images[:, mask] = observations
    return images


def pixel_lights(scene: Scene, height: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each light's direction and irradiance at the surface point of each of the mask's
    pixels, the surface of heights `height` (H, W): float64 (N, K, 3) each
    (`irtps.model.scene.lights_at`)."""
    return lights_at(scene, scene.camera.surface_points(height)[mask])


@contextmanager
def timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    """Record in ``timings[stage]`` the seconds that the ``with`` block takes."""
    start = time.perf_counter()
    yield
    timings[stage] = time.perf_counter() - start


def resolve_options(dataset: Dataset, options: ReconstructOptions) -> ReconstructOptions:
    """`options` with the defaults that depend on the data set filled in.

    ``saturation``: the data set's (1 for PNG images); ``integration``: the method's
    default. A numeric ``base_height`` is checked against the data set's scale.

    Raises
    ------
    OptionError
        If ``base_height`` lies so far from the scene that float32 heights lose the relief.
    """
    pixel_size = dataset.scene.camera.orthographic_pixel_size
    base_height = options.base_height
    limit = MAX_BASE_HEIGHT_PIXELS * pixel_size
    if not isinstance(base_height, str) and abs(base_height) > limit:
        raise OptionError(
            "base_height",
            f"{base_height:g} is out of range for this data set: expected at most {MAX_BASE_HEIGHT_PIXELS:g} pixel sizes "
            f"({limit:g} world units) from 0 (heights are float32)",
        )
    return dataclasses.replace(
        options,
        saturation=dataset.saturation if options.saturation is None else options.saturation,
        integration=options.integration_method,
    )


def dataset_lobe_share(dataset: Dataset, options: ReconstructOptions) -> float:
    """The data set's `irtps.ps.fit.lobe_share`, under the options' shadow fraction and
    saturation level (`options` resolved by `resolve_options`: the share leaves the data set's
    saturated observations out)."""
    scene = dataset.scene
    return lobe_share(
        dataset.images,
        scene.light_directions,
        scene.light_irradiance,
        dataset.mask,
        shadow_fraction=options.shadow_fraction,
        saturation=options.saturation,
        views=camera_views(scene),
    )


def camera_views(scene: Scene) -> np.ndarray | None:
    """Each pixel's direction toward the camera when it sees through a pinhole (its own, or
    its orthographic stand-in's: `irtps.model.camera.Camera.view_directions`), else None (a
    distant camera along +z)."""
    viewer = scene.camera.pinhole or scene.camera
    return None if viewer.projection == "orthographic" else viewer.view_directions()


def with_chosen_robust(options: ReconstructOptions, fit: PsResult) -> ReconstructOptions:
    """`options` with a robust mode ``"auto"`` replaced by the mode that `fit`, made with it,
    chose; other modes kept.

    ``"auto"`` is chosen in one place: the fit of the input images
    (`irtps.ps.fit.photometric_stereo`, by `irtps.ps.fit.choose_robust`); classic photometric
    stereo, the brightness correction's first fit and IRT-PS's pass 0 are that fit, and what
    follows them fits with its choice.
    """
    if options.robust != "auto":
        return options
    assert fit.robust_used is not None, "photometric_stereo's auto mode tells the mode it chose"
    return dataclasses.replace(options, robust=fit.robust_used)


def fit_photometric_stereo(
    dataset: Dataset,
    images: np.ndarray,
    options: ReconstructOptions,
    *,
    progress: bool = False,
    surface: np.ndarray | None = None,
) -> PsResult:
    """Photometric stereo on `images` (the data set's, or corrected ones) with the data set's
    lights and mask and the options' robust settings. `images` are (K, H, W, 3), or
    (K, N, 3) at the mask's N pixels in row-major order (the corrected images of IRT-PS).
    `progress`: a progress bar for the lobe mode's fit of (K, H, W, 3) images (asked for, or chosen by
    ``"auto"``), the one slow enough to want one (`irtps.ps.fit.photometric_stereo`). Under
    point lights, each pixel's lights are those at its point of the surface of heights
    `surface` (H, W), which they need (`pixel_lights`)."""
    scene, mask = dataset.scene, dataset.mask
    views = camera_views(scene)
    if scene.has_point_lights:
        if surface is None:
            raise ArgumentError("surface", "is needed under point lights: their light at a pixel depends on its point")
        directions, irradiance = pixel_lights(scene, surface, mask)
    else:
        directions, irradiance = scene.light_directions, scene.light_irradiance
    # (K, N, 3) observations are fitted as one row of N pixels, every one in the mask.
    fitted, fitted_mask, fitted_views = (
        (images, mask, views)
        if images.ndim == 4
        else (images[:, None], np.ones((1, images.shape[1]), dtype=bool), None if views is None else views[mask][None])
    )
    fit = photometric_stereo(
        fitted,
        directions,
        irradiance,
        fitted_mask,
        robust=options.robust,
        shadow_fraction=options.shadow_fraction,
        saturation=options.saturation,
        views=fitted_views,
        progress=progress and options.robust in ("lobe", "auto") and images.ndim == 4,
    )
    if images.ndim == 4:
        return fit
    frame = PsResult(
        normals=np.zeros((*mask.shape, 3), np.float32),
        albedo=np.zeros((*mask.shape, 3), np.float32),
        flags=np.full(mask.shape, MASKED_OUT, np.uint8),
        used=np.zeros(mask.shape, np.uint16),
    )
    for name in ("normals", "albedo", "flags", "used"):
        getattr(frame, name)[mask] = getattr(fit, name)[0]
    return frame


def rendered_albedo(
    dataset: Dataset, fit: PsResult, relief: np.ndarray, coverage: np.ndarray | None = None
) -> np.ndarray:
    """The albedo of the triangulated surface `relief` that explains `fit`
    (`irtps.geometry.surface.surface_albedo`), where the fitted images hold the object's light over
    the fraction `coverage` (H, W) of each pixel's footprint (default 1): within [0, 1] for
    absolute irradiance; in the irradiance's units, unbounded, for relative irradiance
    (`irtps.render.radiometry` scales it)."""
    scene = dataset.scene
    fitted = fit.albedo if coverage is None else fit.albedo / coverage[..., None].astype(np.float32)
    return surface_albedo(
        fitted,
        relief,
        dataset.mask,
        scene.camera.orthographic_pixel_size,
        largest=None if scene.relative_irradiance else 1.0,
    )


def fitted_observations(dataset: Dataset, options: ReconstructOptions) -> np.ndarray:
    """The observations a rendering of the reconstruction is compared with
    (`irtps.render.residual.compared_observations` under the options' robust settings).
    Point lights' irradiance at each pixel is taken on the level surface at the scene's
    base height: it only tells the shadows apart."""
    scene, mask = dataset.scene, dataset.mask
    if scene.has_point_lights:
        level = np.where(mask, scene.base_height, 0.0)
        irradiance = np.transpose(pixel_lights(scene, level, mask)[1], (1, 0, 2))
    else:
        irradiance = scene.light_irradiance
    return compared_observations(
        dataset.images,
        irradiance,
        dataset.mask,
        robust=options.robust != "none",
        shadow_fraction=options.shadow_fraction,
        saturation=options.saturation,
    )


def surface_relief(dataset: Dataset, normals: np.ndarray, options: ReconstructOptions) -> np.ndarray:
    """The height map of `normals`, integrated (``options.integration``), with the median of
    its mask's boundary at 0: float32, 0 outside the mask. Through the pinhole of a
    perspective camera's stand-in, the same integration of the depth's logarithm
    (`pinhole_relief`), whose relief stands along the camera's rays
    (`irtps.geometry.placement.raised`)."""
    mask = dataset.mask
    if dataset.scene.camera.pinhole is not None:
        return pinhole_relief(dataset.scene, normals, mask, options.integration_method)
    height = integrate_normals(
        normals, mask, pixel_size=dataset.scene.camera.orthographic_pixel_size, method=options.integration_method
    )
    return np.where(mask, place_height(height, mask, base_height=0.0), 0).astype(np.float32)


def pinhole_relief(scene: Scene, normals: np.ndarray, mask: np.ndarray, method: str | None) -> np.ndarray:
    """The relief of the depth map that `normals` give through the pinhole of `scene`'s
    orthographic stand-in.

    Along pixel (i, j)'s centre ray ``r = ((j + ½ - cx)/fx, -(i + ½ - cy)/fy, -1)`` the depth
    d of a surface of normal n has ``∂ log d/∂j = -nx / (fx n·r)`` and ``∂ log d/∂i =
    ny / (fy n·r)``: the logarithm of the depth is a height field of those slopes over the
    pixel grid, integrated by `method` (`irtps.geometry.integrate.integrate_normals`; n·r
    kept below -1e-3, a surface seen edge-on, and the slopes within 10 pixel footprints per
    footprint). The relief is the depth map at the stand-in's depth ``D = zc -
    scene.base_height``: ``D * (1 - d / d_b)``, with ``d_b`` the geometric median of the depths
    of the part's boundary, so that it stands at 0 as `place_height` puts it. Float32, 0
    outside `mask`."""
    pinhole = scene.camera.pinhole
    if pinhole is None:
        raise ArgumentError("scene", "its camera is not the orthographic stand-in of a perspective camera")
    fx, fy, _, _ = pinhole.intrinsics()[[0, 1, 0, 1], [0, 1, 2, 2]]
    unit = normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    facing = np.minimum((unit * pinhole.ray_directions()).sum(axis=-1), -1e-3)
    slope_j, slope_i = -unit[..., 0] / (fx * facing), unit[..., 1] / (fy * facing)
    # A height field z over pixels of size 1 has the normal (-dz/dj, dz/di, 1) (y is up).
    log_normals = np.stack([-slope_j, slope_i, np.ones_like(slope_j)], axis=-1)
    log_depth = integrate_normals(log_normals, mask, method=method, max_slope=10.0 / pinhole.focal_length)
    log_ratio = place_height(np.where(mask, log_depth, 0.0), mask, base_height=0.0)
    reference = pinhole.center_z - scene.base_height
    return np.where(mask, reference * -np.expm1(log_ratio), 0).astype(np.float32)


def place_surface(
    dataset: Dataset,
    relief: np.ndarray,
    albedo: np.ndarray,
    options: ReconstructOptions,
    *,
    seed: int = 0,
    previous: Placement | None = None,
    shape_change: float = 0.0,
    albedo_scale: AlbedoScale | None = None,
) -> Placement:
    """Where the surface `relief` (boundary median at 0) stands (contract §6).

    ``options.base_height``: a number is taken as given; ``"boundary"`` is the fallback
    (the floor's height); ``"auto"`` estimates it from the floor in the data set's images
    (`irtps.render.placement.estimate_placement`), with the fallback where nothing fixes it.
    Given the `previous` estimate, for a relief that changed by `shape_change` on average
    (world units), the estimate is refined within three times that change of it; the
    fallback and given placements are kept. With an `albedo_scale` (relative irradiance),
    the floor is rendered with the reflectance and the irradiance it implies.
    """
    scene = dataset.scene
    if albedo_scale is not None:
        scene, albedo = rendered_as(scene, albedo, albedo_scale)
    if previous is not None:
        radius = PLACEMENT_SEARCH_CHANGES * shape_change
        if (
            previous.source not in ("images", "object")
            or radius < PRECISION_PIXELS * scene.camera.orthographic_pixel_size
        ):
            return previous
        return estimate_placement(
            scene,
            relief,
            albedo,
            dataset.mask,
            dataset.images,
            bounces=options.bounces,
            saturation=options.saturation,
            seed=seed,
            near=previous,
            radius=radius,
        )
    if options.base_height == "boundary":
        return fallback_placement(scene)
    if options.base_height != "auto":
        return Placement(base_height=float(options.base_height), source="given")
    return estimate_placement(
        scene,
        relief,
        albedo,
        dataset.mask,
        dataset.images,
        bounces=options.bounces,
        saturation=options.saturation,
        seed=seed,
    )


def scale_and_place(
    dataset: Dataset,
    relief: np.ndarray,
    albedo: np.ndarray,
    options: ReconstructOptions,
    usable: np.ndarray,
    *,
    seed: int = 0,
) -> tuple[AlbedoScale, Placement]:
    """The albedo scale and the placement of a first reconstruction. Each needs the other
    where the irradiance is relative and a floor is seen: the scale is estimated with the
    surface placed provisionally (the given height, else contract §6's fallback), then the
    floor is rendered with that scale to place it."""
    provisional = place_surface(
        dataset,
        relief,
        albedo,
        dataclasses.replace(options, base_height="boundary") if options.base_height == "auto" else options,
    )
    scale = resolve_albedo_scale(
        dataset, placed(relief, dataset.mask, provisional, dataset.scene), albedo, usable, options, seed=seed
    )
    if options.base_height != "auto":
        return scale, provisional
    return scale, place_surface(dataset, relief, albedo, options, seed=seed, albedo_scale=scale)


def resolve_albedo_scale(
    dataset: Dataset,
    height: np.ndarray,
    albedo: np.ndarray,
    usable: np.ndarray,
    options: ReconstructOptions,
    *,
    seed: int = 0,
) -> AlbedoScale:
    """The factor from fitted albedo to reflectance (`irtps.render.radiometry`): the options'
    number, else estimated from the images when the data set's irradiance is relative, else
    1. `height` is the placed reconstruction, `usable` the observations compared."""
    if options.albedo_scale != "auto":
        return AlbedoScale(factor=float(options.albedo_scale), source="given")
    if not dataset.scene.relative_irradiance:
        return absolute_scale()
    return estimate_albedo_scale(
        dataset.scene, height, albedo, dataset.mask, dataset.images, usable, bounces=options.bounces, seed=seed
    )


def rendered_as(scene: Scene, albedo: np.ndarray, albedo_scale: AlbedoScale | None) -> tuple[Scene, np.ndarray]:
    """The scene and albedo to render a reconstruction with: as they are for absolute
    irradiance (or no scale), else the reflectance and the irradiance that `albedo_scale`
    implies."""
    if albedo_scale is None or albedo_scale.source == "absolute":
        return scene, albedo
    return scaled_scene(scene, albedo_scale.factor), scaled_albedo(albedo, albedo_scale.factor)


def placed(relief: np.ndarray, mask: np.ndarray, placement: Placement, scene: Scene) -> np.ndarray:
    """`relief` raised to `placement` inside the mask (`irtps.geometry.placement.raised`):
    float32, 0 outside."""
    return raised(relief, mask, placement.base_height, scene)
