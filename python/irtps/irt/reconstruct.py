"""The reconstruction pipeline: photometric stereo, normal integration, height placement.

The folder a `Reconstruction` is saved to and read back from is `irtps.irt.folder`'s.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from irtps._shared.checks import check_instance
from irtps.model.data import pixel_observations
from irtps.io.dataset import Dataset, load_dataset
from irtps.errors import ArgumentError, DatasetError, IrtpsError, IrtpsWarning
from irtps.ps.image_agreement import ImageAgreement, image_agreement
from irtps.ps.semi_calibrated import estimate_light_intensities
from irtps.irt.interreflection import check_traceable, remove_interreflections
from irtps.irt.loop_state import Iteration, Stop
from irtps.model.options import ReconstructOptions
from irtps.model.camera import Camera
from irtps.model.scene import emission_of, orthographic_scene, with_emission
from irtps.geometry.bilateral_integration import integrate_bilateral
from irtps.irt.pipeline import (
    dataset_lobe_share,
    fit_photometric_stereo,
    pixel_lights,
    placed,
    reconstruction_pass,
    resolve_options,
    settled_near_fit,
    timed,
    with_chosen_robust,
)
from irtps.geometry.placement import Placement
from irtps.ps.fit import OK, LOBE_ADVISED, LOBE, PsResult, check_lights, format_lobe_share
from irtps.render.radiometry import AlbedoScale


@dataclass
class Reconstruction:
    """Shape and colour recovered from a data set.

    Attributes
    ----------
    normals : numpy.ndarray
        float32 (H, W, 3) unit normals, 0 outside the mask.
    albedo : numpy.ndarray
        float32 (H, W, 3) RGB albedo.
    height : numpy.ndarray
        float32 (H, W) heights (world units), 0 outside the mask, placed per contract §6.
    mask : numpy.ndarray
        bool (H, W).
    flags : numpy.ndarray
        uint8 (H, W) per-pixel photometric-stereo flags (see `irtps.ps.fit.FLAGS`).
    pixel_size : float
        World size of a pixel (of a perspective camera's orthographic stand-in at the
        object's base: `irtps.model.scene.orthographic_scene`).
    timings : dict
        Seconds spent in each stage.
    parameters : dict
        The settings used.
    object_indirect : numpy.ndarray or None
        IRT-PS: float32 (K, N, 3), the estimate of the inter-reflected light (and of the
        surroundings' light in the edge pixels) subtracted from the images at the mask's N
        pixels (row-major order) to get the pass returned.
    history : list of Iteration
        IRT-PS: one entry per pass (residual, height change, step, timings, errors when
        ground truth is present); empty for classic photometric stereo.
    placement : Placement or None
        Where the object stands and how that was decided (contract §6).
    chosen : int or None
        IRT-PS: the pass returned, the one with the lowest residual (0: classic
        photometric stereo's).
    albedo_scale : AlbedoScale or None
        The factor from the fitted albedo (``albedo``, in the units of the data set's
        irradiance) to the reflectance rendered (`irtps.render.radiometry`): IRT-PS's, and classic
        PS's where the irradiance is relative and the floor was rendered to place the object.
    lobe_share : float or None
        Unless ``robust="lobe"`` was asked for: the share of the object's pixels that the
        lobe mode fits with a specular lobe (`irtps.ps.fit.lobe_share`); from half of them on,
        the object looks glossy or metallic: ``robust="auto"`` fits it with the lobe mode,
        and another mode warns, advising it.
    robust_used : str or None
        The robust mode of the fit (`irtps.ps.fit.ROBUST_MODES`): the one asked for, or the one
        ``"auto"`` chose (`irtps.ps.fit.choose_robust`); None where not recorded.
    image_names : tuple of str
        The images fitted (`Dataset.names`), in order: IRT-PS's ``object_indirect[k]`` is
        image ``image_names[k]``'s.
    excluded_images : tuple of str
        The data set's images left out (`Dataset.excluded_images`).
    image_agreement : ImageAgreement or None
        How each image fitted agrees with classic photometric stereo's fit of the images as
        they are (IRT-PS's pass 0; `irtps.ps.image_agreement`): an image whose brightness is far
        from the others' had another light or exposure than recorded; one whose spread is
        wider was taken as the object or the camera moved.
    irradiance_factors : numpy.ndarray or None
        With ``correct_brightness``: float64 (K,), the factor each light's irradiance was
        scaled by before the fit (its image's brightness against a first fit; 1 where not
        known).
    estimated_irradiance : numpy.ndarray or None
        For a data set that gave no light strengths (`Dataset.irradiance_known` False):
        float64 (K, 3), each light's RGB strength as estimated from the images and used
        throughout, the median light's 1 in each channel
        (`irtps.ps.semi_calibrated.estimate_light_intensities`).
    depth : numpy.ndarray or None
        With a pinhole camera: float32 (H, W) depth along the optical axis, 0 outside the
        mask, integrated from ``normals`` through the pinhole so that it keeps its
        discontinuities (`irtps.geometry.bilateral_integration`), scaled to the median depth
        of the placed heights below the optical centre (normals fix it only up to scale).
    discontinuities : numpy.ndarray or None
        With ``depth``: bool (H, W, 2), the edges to the right neighbour (``[..., 0]``) and
        to the pixel below (``[..., 1]``) that are depth discontinuities.
    camera : Camera or None
        The data set's camera (a pinhole's own, not its orthographic stand-in's).
    stop : Stop or None
        IRT-PS: why the loop stopped where it did (`irtps.irt.loop_state.Stop`).
    """

    normals: np.ndarray
    albedo: np.ndarray
    height: np.ndarray
    mask: np.ndarray
    flags: np.ndarray
    pixel_size: float
    timings: dict[str, float] = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    object_indirect: np.ndarray | None = None
    history: list[Iteration] = field(default_factory=list)
    placement: Placement | None = None
    chosen: int | None = None
    albedo_scale: AlbedoScale | None = None
    lobe_share: float | None = None
    robust_used: str | None = None
    image_names: tuple[str, ...] = ()
    excluded_images: tuple[str, ...] = ()
    image_agreement: ImageAgreement | None = None
    irradiance_factors: np.ndarray | None = None
    estimated_irradiance: np.ndarray | None = None
    depth: np.ndarray | None = None
    discontinuities: np.ndarray | None = None
    camera: Camera | None = None
    stop: Stop | None = None

    @property
    def indirect(self) -> np.ndarray | None:
        """IRT-PS: float32 (K, H, W, 3), `object_indirect` as images (0 around the object);
        made on each access."""
        if self.object_indirect is None:
            return None
        return np.stack([self.indirect_image(k) for k in range(len(self.object_indirect))])

    def indirect_image(self, k: int) -> np.ndarray:
        """float32 (H, W, 3): the estimate of image `k`'s inter-reflected light (IRT-PS)."""
        if self.object_indirect is None:
            raise ArgumentError("k", "a classic photometric stereo reconstruction has no inter-reflection estimate")
        image = np.zeros((*self.mask.shape, 3), dtype=np.float32)
        image[self.mask] = self.object_indirect[k]
        return image


def reconstruct(
    dataset: Dataset,
    method: str | None = None,
    *,
    options: ReconstructOptions | None = None,
    progress: bool = False,
    **settings,
) -> Reconstruction:
    """Recover normals, albedo and a height map from a data set.

    Parameters
    ----------
    dataset : Dataset
        Images, lights and mask (`irtps.load_dataset`).
    method : str, optional
        ``"ps"``: classic calibrated Lambertian photometric stereo; ``"irtps"``: the same,
        iterated with the inter-reflections estimated by ray tracing and removed
        (`irtps.irt.interreflection.remove_interreflections`). Overrides ``options.method``.
    options : ReconstructOptions, optional
        Every setting (`irtps.model.options.ReconstructOptions`: photometric stereo, integration,
        placement, IRT-PS); default all defaults.
    progress : bool
        Show a progress bar: IRT-PS's passes, or the lobe mode's fit.
    **settings
        Fields of `ReconstructOptions` that replace those of `options`, e.g.
        ``bounces=2``. ``saturation`` defaults to ``dataset.saturation`` (1.0 for PNG
        images, else none); ``base_height`` to ``"auto"``: estimated from the floor around
        the object (`irtps.render.placement`), the floor's height where nothing fixes it.

    Returns
    -------
    Reconstruction
        Its ``parameters`` are the options used, with the defaults resolved.

    Raises
    ------
    ArgumentError
        If `dataset` is not a `Dataset`.
    DatasetError
        Naming ``dataset.source``: lights that are (nearly) coplanar or have a zero
        irradiance, or images black on the whole object; for IRT-PS, naming its mask file, a
        mask with no 2×2 block of object pixels, which makes no surface to trace
        (`irtps.irt.interreflection.check_traceable`; ``ArgumentError`` naming
        ``dataset.mask`` for a data set made in memory). Classic photometric stereo fits
        any mask, pixel by pixel.
    OptionError
        Naming the option: a value out of range or not among the choices (also a
        `ValueError`).

    Warns
    -----
    IrtpsWarning
        For a perspective camera, that the steps that take a pixel size use its
        orthographic stand-in (`irtps.model.scene.orthographic_scene`; ``pixel_size`` is
        then the stand-in's), while renderings trace through the pinhole and IRT-PS
        integrates along its rays.
        When observations are saturated, with their count; when most of the object's pixels
        reflect a broad specular lobe and the robust mode asked for is neither ``"auto"`` nor
        ``"lobe"``, advising the lobe mode (`Reconstruction.lobe_share`).

    Examples
    --------
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=24, lights=6, bounces=0, environment="none")
    >>> result = reconstruct(data)
    >>> result.normals.shape, sorted(result.timings)
    ((24, 24, 3), ['image_agreement', 'integration', 'photometric_stereo', 'placement'])
    >>> reconstruct(data, samples=0)
    Traceback (most recent call last):
    ...
    irtps.model.options.OptionError: samples: 0 is out of range: expected an integer from 1 to 1048576
    """
    check_instance("dataset", dataset, Dataset)
    if method is not None:
        settings["method"] = method
    options = ReconstructOptions.build(options, **settings)
    camera = dataset.scene.camera
    dataset = _orthographic(dataset)
    options = resolve_options(dataset, options)
    _check_input(dataset, options.saturation, options.robust)
    if options.method == "irtps":
        check_traceable(dataset)
    parameters = options.to_dict()
    timings: dict[str, float] = {}
    estimated = None
    if not dataset.irradiance_known:
        with timed(timings, "light_intensities"):
            dataset, estimated = _with_estimated_irradiance(dataset, options)
    share = None
    first = None
    if options.robust not in ("auto", "lobe") and not dataset.scene.has_point_lights:
        # A mode asked for: the share only advises the lobe mode where it would fit better.
        with timed(timings, "lobe_share"):
            share = dataset_lobe_share(dataset, options)
        _advise_lobe(dataset, options.robust, share)
    factors = None
    if options.correct_brightness:
        with timed(timings, "brightness_correction"):
            dataset, factors, brightness_fit = _brightness_corrected(dataset, options)
        options, share = _chosen(options, brightness_fit, share)
    elif options.robust == "auto" and options.method == "ps":
        # The fit that the result is chooses the mode.
        first = reconstruction_pass(dataset, dataset.images, options, progress=progress)
        options, share = _chosen(options, first.fit, share)
    if options.method == "irtps":
        with timed(timings, "irtps"):
            loop = remove_interreflections(dataset, options, progress=progress)
        options, share = _chosen(options, loop.first_fit, share)
        fit, first_fit, albedo, height = loop.fit, loop.first_fit, loop.albedo, loop.height
        placement, albedo_scale = loop.placement, loop.albedo_scale
        indirect, history, chosen, stop = loop.indirect, loop.history, loop.chosen, loop.stop
    else:
        # Classic photometric stereo: IRT-PS's first pass, with no correction after it.
        if first is None:
            first = reconstruction_pass(dataset, dataset.images, options, progress=progress)
        timings.update(first.timings)
        fit = first_fit = first.fit
        albedo, height, placement, albedo_scale = first.fit.albedo, first.height, first.placement, first.albedo_scale
        indirect, history, chosen, stop = None, [], None, None
    with timed(timings, "image_agreement"):
        agreement = _image_agreement(dataset, first_fit, options.saturation, height)
    depth, discontinuities = _pinhole_depth(camera, fit.normals, dataset.mask, height, timings)
    return Reconstruction(
        normals=fit.normals,
        albedo=albedo,
        height=height,
        mask=dataset.mask,
        flags=fit.flags,
        pixel_size=dataset.scene.camera.orthographic_pixel_size,
        timings=timings,
        parameters=parameters,
        placement=placement,
        albedo_scale=albedo_scale,
        lobe_share=share,
        robust_used=options.robust,
        image_names=dataset.names,
        excluded_images=dataset.excluded_images,
        image_agreement=agreement,
        irradiance_factors=factors,
        estimated_irradiance=estimated,
        depth=depth,
        discontinuities=discontinuities,
        camera=camera,
        object_indirect=indirect,
        history=history,
        chosen=chosen,
        stop=stop,
    )


def load_and_reconstruct(
    path: str | Path,
    method: str | None = None,
    *,
    exclude_images: str | None = None,
    intrinsics: str | Path | None = None,
    encoding: str | None = None,
    lights: str | Path | None = None,
    **options,
) -> tuple[Dataset, Reconstruction]:
    """Read a data set folder and reconstruct it, timing the reading too.

    Parameters
    ----------
    path : str or pathlib.Path
        A data set folder, as for `irtps.load_dataset`.
    method : str, optional
        As for `reconstruct`.
    exclude_images : str, optional
        Images not to read (`irtps.load_dataset`), e.g. ``"1-20"``.
    intrinsics : str or pathlib.Path, optional
        A ``K.txt`` that gives the data set a perspective camera (`irtps.load_dataset`).
    encoding : {"srgb", "linear"}, optional
        How the images' values map to light (`irtps.load_dataset`).
    lights : str or pathlib.Path, optional
        A light position file (``*.lp``) kept outside the folder, which gives a folder of
        images its lights (`irtps.load_dataset`).
    **options
        The other keyword arguments of `reconstruct` (``options``, ``progress``, fields
        of `ReconstructOptions`).

    Returns
    -------
    (Dataset, Reconstruction)
        The data set (for its ground truth) and the reconstruction, whose ``timings``
        start with ``"load"``, the seconds spent reading.

    Raises
    ------
    DatasetError
        If the folder is not a readable data set (see `irtps.load_dataset`).
    OptionError
        For an option out of range, before the data set is read.
    ArgumentError
        For a malformed `exclude_images`, before the data set is read; naming `lights`
        given to a data set whose lights are its own (`irtps.load_dataset`).

    Examples
    --------
    >>> import tempfile
    >>> from irtps.io.dataset_writer import save_dataset
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=24, lights=6, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_dataset(data, folder + "/cap")
    ...     dataset, result = load_and_reconstruct(folder + "/cap")
    >>> list(result.timings)
    ['load', 'photometric_stereo', 'integration', 'placement', 'image_agreement']
    """
    if method is not None:
        options["method"] = method
    settings = {key: value for key, value in options.items() if key not in ("options", "progress")}
    ReconstructOptions.build(options.get("options"), **settings)  # a bad option fails before the data set is read
    start = time.perf_counter()
    dataset = load_dataset(path, exclude_images=exclude_images, intrinsics=intrinsics, encoding=encoding, lights=lights)
    loaded = time.perf_counter() - start
    result = reconstruct(dataset, **options)
    result.timings = {"load": loaded, **result.timings}
    return dataset, result


def _pinhole_depth(
    camera: Camera, normals: np.ndarray, mask: np.ndarray, height: np.ndarray, timings: dict[str, float]
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """With a pinhole `camera`: the depth along its axis that `normals` give through it
    (`irtps.geometry.bilateral_integration`), 0 outside `mask`, scaled to the median depth of
    the placed `height` below the optical centre (median 1 where the camera has none), and
    its discontinuities, timed in `timings` as ``"depth"``; else (None, None)."""
    if camera.projection != "perspective":
        return None, None
    with timed(timings, "depth"):
        integrated = integrate_bilateral(normals, mask, intrinsics=camera.intrinsics())
    depth = integrated.surface
    scale = 1.0
    if camera.optical_center is not None:
        scale = float(np.median(camera.optical_center[2] - height[mask])) / float(np.median(depth[mask]))
    return np.where(mask, depth * np.float32(scale), 0).astype(np.float32), integrated.discontinuities


def _orthographic(dataset: Dataset) -> Dataset:
    """`dataset`, seen by the orthographic stand-in of a perspective camera
    (`irtps.model.scene.orthographic_scene`, which warns)."""
    scene = orthographic_scene(dataset.scene, dataset.source or "the data set")
    return dataset if scene is dataset.scene else replace(dataset, scene=scene)


def _brightness_corrected(dataset: Dataset, options: ReconstructOptions) -> tuple[Dataset, np.ndarray, PsResult]:
    """The data set with each light's irradiance scaled by its image's brightness against a
    first fit of `options`' robust mode, the factors (1 where not known), and that fit."""
    if dataset.scene.has_point_lights:
        first, relief, placement = settled_near_fit(dataset, dataset.images, options)
        height = placed(relief, dataset.mask, placement, dataset.scene)
    else:
        first, height = fit_photometric_stereo(dataset, dataset.images, options), None
    brightness = _image_agreement(dataset, first, options.saturation, height).brightness
    factors = np.where(np.isnan(brightness), 1.0, brightness)
    lights = tuple(
        with_emission(light, emission_of(light) * factor)
        for light, factor in zip(dataset.scene.lights, factors, strict=True)
    )
    return replace(dataset, scene=replace(dataset.scene, lights=lights)), factors, first


def _with_estimated_irradiance(dataset: Dataset, options: ReconstructOptions) -> tuple[Dataset, np.ndarray]:
    """The data set with its lights' strengths estimated from its images, which it did not
    give, and those strengths (K, 3); says so in a warning."""
    try:
        strengths = estimate_light_intensities(
            dataset.images,
            dataset.scene.light_directions,
            dataset.mask,
            shadow_fraction=options.shadow_fraction,
            saturation=options.saturation,
        )
    except ArgumentError as error:
        raise DatasetError(
            f"{dataset.source or 'the data set'}: no light intensities given, and {error.problem}"
        ) from None
    lights = tuple(with_emission(light, row) for light, row in zip(dataset.scene.lights, strengths, strict=True))
    spread = strengths.mean(axis=1)
    warnings.warn(
        f"{dataset.source or 'the data set'}: no light intensities given: estimated from the images "
        f"(semi-calibrated photometric stereo), from {spread.min():.2f} to {spread.max():.2f} of the median light's",
        IrtpsWarning,
        stacklevel=3,
    )
    # Relative by construction (the median light's is 1): IRT-PS estimates their scale from the
    # images, as for DiLiGenT's relative intensities, and renders with it.
    scene = replace(dataset.scene, lights=lights, relative_irradiance=True)
    return replace(dataset, scene=scene, irradiance_known=True), strengths


def _chosen(options: ReconstructOptions, fit: PsResult, share: float | None) -> tuple[ReconstructOptions, float | None]:
    """`options` with the robust mode that `fit` chose for ``"auto"`` (`with_chosen_robust`),
    and the lobe share: the one `fit` measured to choose, else `share`."""
    if options.robust != "auto":
        return options, share
    return with_chosen_robust(options, fit), fit.lobe_share


def _image_agreement(
    dataset: Dataset, fit: PsResult, saturation: float | None, height: np.ndarray | None
) -> ImageAgreement:
    """How each image agrees with `fit` (`irtps.ps.image_agreement`), over the pixels it fitted
    as asked or with a lobe; under point lights, with their light at the surface of heights
    `height` (not measured without one)."""
    fitted = dataset.mask & ((fit.flags == OK) | (fit.flags == LOBE))
    scene = dataset.scene
    if not fitted.any() or (scene.has_point_lights and height is None):
        unknown = np.full(len(dataset.scene.lights), np.nan)
        return ImageAgreement(unknown, unknown.copy())
    if height is not None and scene.has_point_lights:
        directions, irradiance = pixel_lights(scene, height, fitted)
    else:
        directions, irradiance = scene.light_directions, scene.light_irradiance
    return image_agreement(
        dataset.images,
        directions,
        irradiance,
        fit.normals,
        fit.albedo,
        fitted,
        saturation=saturation,
    )


def _advise_lobe(dataset: Dataset, robust_used: str, share: float) -> None:
    """Warn when the data set's `irtps.ps.fit.lobe_share` advises the lobe mode and the fit is
    another mode's."""
    if share >= LOBE_ADVISED and robust_used != "lobe":
        warnings.warn(
            f"{dataset.source or 'the data set'}: {format_lobe_share(share)} (a broad highlight, as glossy and metallic surfaces reflect, "
            f"which robust mode '{robust_used}' sets aside)",
            IrtpsWarning,
            stacklevel=3,
        )


def _check_input(dataset: Dataset, saturation: float | None, robust: str) -> None:
    """Refuse lights that cannot determine a normal and images black on the whole object;
    warn about saturated observations."""
    source = dataset.source or "the data set"
    try:
        # Point lights' directions differ pixel by pixel: the fit checks each pixel's.
        if not dataset.scene.has_point_lights:
            check_lights(dataset.scene.light_directions, dataset.scene.light_irradiance)
    except IrtpsError as err:
        raise DatasetError(f"{source}: {err}") from None
    observed = pixel_observations(dataset.images, dataset.mask)
    if not (observed > 0).any():
        raise DatasetError(f"{source}: every image is black on the object (no value above 0 in the mask)")
    if saturation is None:
        return
    saturated = np.any(observed >= saturation, axis=2)
    count = int(saturated.sum())
    if count:
        fate = "used as they are (robust mode none)" if robust == "none" else "left out of the fit"
        images = int(saturated.any(axis=1).sum())
        warnings.warn(
            f"{source}: {count} observations in {images} images are saturated (a channel at or above {saturation:g}); {fate}",
            IrtpsWarning,
            stacklevel=3,
        )
