"""The reconstruction pipeline: photometric stereo, normal integration, height placement."""

from __future__ import annotations

import json
import os
import platform
import re
import time
import warnings
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path, PurePosixPath

import numpy as np

from irtps._shared.checks import check_instance, check_path
from irtps._shared.atomic import atomic_output_dir
from irtps.model.data import pixel_observations
from irtps.io.dataset import Dataset, load_dataset, read_albedo_map, read_height_map, read_normal_map
from irtps.errors import ArgumentError, DatasetError, IrtpsError, IrtpsWarning
from irtps._shared.guarded import read_json
from irtps.ps.image_agreement import ImageAgreement, image_agreement
from irtps.io.imageio import read_mask, write_exr, write_png
from irtps.irt.interreflection import Iteration, check_traceable, remove_interreflections
from irtps.io.mesh import height_field_mesh, write_obj, write_ply
from irtps.model.options import ReconstructOptions
from irtps._shared.paths import check_file, check_folder
from irtps.irt.pipeline import (
    choose_dataset_robust,
    fit_photometric_stereo,
    reconstruction_pass,
    resolve_options,
    timed,
)
from irtps.geometry.placement import Placement
from irtps.ps.fit import FITTED, FLAGS, LOBE_ADVISED, LOBE_FITTED, PsResult, check_lights, format_lobe_share
from irtps.render.radiometry import AlbedoScale
from irtps._shared.records import RUN, stamp

#: Indirect images written at once, one per core up to 4 (on 2 cores, 2 writers take 0.7 of
#: one writer's time).
_EXR_WRITERS = max(1, min(4, os.cpu_count() or 1))
#: What a reconstruction folder holds (`save_reconstruction`); ``indirect`` for IRT-PS only.
RECONSTRUCTION_FILES = (
    "normal.exr",
    "albedo.exr",
    "height.exr",
    "mask.png",
    "mesh.ply",
    "mesh.obj",
    "run.json",
    "indirect",
)
#: An image name's stem that can name its file in ``indirect/``: plain, not hidden.
_PLAIN_STEM = re.compile(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]*")


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
        World size of a pixel.
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
    options = resolve_options(dataset, ReconstructOptions.build(options, **settings))
    _check_input(dataset, options.saturation, options.robust)
    if options.method == "irtps":
        check_traceable(dataset)
    parameters = options.to_dict()
    timings: dict[str, float] = {}
    share = None
    first = None
    if options.robust == "auto" and options.method == "ps" and not options.correct_brightness:
        # The fit that the result is: its photometric stereo makes auto's choice (`lobe_share`'s
        # first pixels beside the Tukey fit).
        first = reconstruction_pass(dataset, dataset.images, options, progress=progress)
        chosen = first.fit.robust_used
        assert chosen is not None, "photometric_stereo's auto mode tells the mode it chose"
        options, share = replace(options, robust=chosen), first.fit.lobe_share
    elif options.robust != "lobe":
        with timed(timings, "lobe_share"):
            options, share = choose_dataset_robust(dataset, options)
        _advise_lobe(dataset, options.robust, share)
    factors = None
    if options.correct_brightness:
        with timed(timings, "brightness_correction"):
            dataset, factors = _brightness_corrected(dataset, options)
    if options.method == "irtps":
        with timed(timings, "irtps"):
            loop = remove_interreflections(dataset, options, progress=progress)
        with timed(timings, "image_agreement"):
            agreement = _image_agreement(dataset, loop.first_fit, options.saturation)
        return Reconstruction(
            normals=loop.fit.normals,
            albedo=loop.albedo,
            height=loop.height,
            mask=dataset.mask,
            flags=loop.fit.flags,
            pixel_size=dataset.scene.camera.pixel_size,
            timings=timings,
            parameters=parameters,
            object_indirect=loop.indirect,
            history=loop.history,
            placement=loop.placement,
            chosen=loop.chosen,
            albedo_scale=loop.albedo_scale,
            lobe_share=share,
            robust_used=options.robust,
            image_names=dataset.names,
            excluded_images=dataset.excluded_images,
            image_agreement=agreement,
            irradiance_factors=factors,
        )
    # Classic photometric stereo: IRT-PS's first pass, with no correction after it.
    if first is None:
        first = reconstruction_pass(dataset, dataset.images, options, progress=progress)
    timings.update(first.timings)
    with timed(timings, "image_agreement"):
        agreement = _image_agreement(dataset, first.fit, options.saturation)
    return Reconstruction(
        normals=first.fit.normals,
        albedo=first.fit.albedo,
        height=first.height,
        mask=dataset.mask,
        flags=first.fit.flags,
        pixel_size=dataset.scene.camera.pixel_size,
        timings=timings,
        parameters=parameters,
        placement=first.placement,
        albedo_scale=first.albedo_scale,
        lobe_share=share,
        robust_used=options.robust,
        image_names=dataset.names,
        excluded_images=dataset.excluded_images,
        image_agreement=agreement,
        irradiance_factors=factors,
    )


def load_and_reconstruct(
    path: str | Path, method: str | None = None, *, exclude_images: str | None = None, **options
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
        For a malformed `exclude_images`, before the data set is read.

    Examples
    --------
    >>> import tempfile
    >>> from irtps.io.dataset import save_dataset
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
    dataset = load_dataset(path, exclude_images=exclude_images)
    loaded = time.perf_counter() - start
    result = reconstruct(dataset, **options)
    result.timings = {"load": loaded, **result.timings}
    return dataset, result


def _brightness_corrected(dataset: Dataset, options: ReconstructOptions) -> tuple[Dataset, np.ndarray]:
    """The data set with each light's irradiance scaled by its image's brightness against a
    first fit of `options`' robust mode, and the factors (1 where not known)."""
    first = fit_photometric_stereo(dataset, dataset.images, options)
    brightness = _image_agreement(dataset, first, options.saturation).brightness
    factors = np.where(np.isnan(brightness), 1.0, brightness)
    lights = tuple(
        replace(light, irradiance=light.irradiance * factor)
        for light, factor in zip(dataset.scene.lights, factors, strict=True)
    )
    return replace(dataset, scene=replace(dataset.scene, lights=lights)), factors


def _image_agreement(dataset: Dataset, fit: PsResult, saturation: float | None) -> ImageAgreement:
    """How each image agrees with `fit` (`irtps.ps.image_agreement`), over the pixels it fitted
    as asked or with a lobe."""
    fitted = dataset.mask & ((fit.flags == FITTED) | (fit.flags == LOBE_FITTED))
    if not fitted.any():
        unknown = np.full(len(dataset.scene.lights), np.nan)
        return ImageAgreement(unknown, unknown.copy())
    scene = dataset.scene
    return image_agreement(
        dataset.images,
        scene.light_directions,
        scene.light_irradiance,
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


def save_reconstruction(result: Reconstruction, path: str | Path, *, source: str | None = None) -> None:
    """Write a reconstruction folder atomically.

    Files: ``normal.exr`` (R, G, B = nx, ny, nz), ``albedo.exr``, ``height.exr`` (Y),
    ``mask.png``, ``mesh.ply`` (binary; the height field with per-vertex albedo colour and
    normals), ``mesh.obj`` (the same vertices, triangles and normals as Wavefront OBJ text,
    see `irtps.io.mesh`), ``run.json`` (parameters, pixel size, timings, versions, source,
    placement, IRT-PS history with each pass's residual, the pass chosen, the images fitted,
    how each agrees with the fit, those left out, and the factors of ``correct_brightness``)
    and, for IRT-PS, ``indirect/`` (for each image fitted, the estimate of
    its inter-reflected light that the chosen pass removed, with the surroundings' light in the
    edge pixels, `irtps.render.surroundings`, named as `indirect_file_names` says; none when that
    is pass 0).

    Parameters
    ----------
    result : Reconstruction
    path : str or pathlib.Path
        The output folder; replaced only once everything is written.
    source : str, optional
        The input data set, recorded in ``run.json``.

    Raises
    ------
    ArgumentError
        If `result` is not a `Reconstruction`.
    DatasetError
        If the folder cannot be written.
    """
    if not isinstance(result, Reconstruction):
        raise ArgumentError("result", f"expected a Reconstruction, got {type(result).__name__}")
    with atomic_output_dir(check_path("path", path)) as folder:
        write_exr(folder / "normal.exr", result.normals)
        write_exr(folder / "albedo.exr", result.albedo)
        write_exr(folder / "height.exr", result.height)
        write_png(folder / "mask.png", result.mask.astype(np.float32), bit_depth=8)
        vertices, faces, colors, normals = height_field_mesh(
            result.height, result.mask, result.pixel_size, albedo=result.albedo, normals=result.normals
        )
        write_ply(folder / "mesh.ply", vertices, faces, colors=colors, normals=normals)
        write_obj(folder / "mesh.obj", vertices, faces, normals=normals)
        run = {
            **stamp(RUN),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "source": source,
            "parameters": result.parameters,
            "pixel_size": result.pixel_size,
            "timings_s": result.timings,
            "flags": {name: int((result.flags[result.mask] == value).sum()) for value, name in FLAGS.items()},
            "placement": None if result.placement is None else result.placement.to_dict(),
            "history": [asdict(step) for step in result.history],
            "chosen_pass": result.chosen,
            "albedo_scale": None if result.albedo_scale is None else result.albedo_scale.to_dict(),
            "lobe_share": result.lobe_share,
            "robust_used": result.robust_used,
            "images": list(result.image_names),
            "excluded_images": list(result.excluded_images),
            "image_agreement": None if result.image_agreement is None else result.image_agreement.to_dict(),
            "irradiance_factors": None
            if result.irradiance_factors is None
            else [round(float(factor), 4) for factor in result.irradiance_factors],
        }
        if result.object_indirect is not None:
            (folder / "indirect").mkdir()
            # A few at a time (the core compresses with the GIL released), each image made as
            # it is written: never more than the writers' images in memory.
            names = indirect_file_names(result.image_names, len(result.object_indirect))
            with ThreadPoolExecutor(max_workers=_EXR_WRITERS) as writers:
                list(
                    writers.map(
                        lambda k: write_exr(folder / "indirect" / names[k], result.indirect_image(k)), range(len(names))
                    )
                )
        (folder / "run.json").write_text(json.dumps(run, indent=2))


def indirect_file_names(image_names: Sequence[str], count: int) -> list[str]:
    """The files of a reconstruction's ``indirect/``, one for each of the `count` images fitted.

    Each image's own name with ``.exr`` for its extension (``001.exr`` for DiLiGenT's
    ``001.png``, ``000.exr`` for the contract layout's ``000.exr``), so that a file names
    the image whatever was left out; ``000.exr``, ``001.exr`` … by position where the names
    are not `count` distinct plain file names (letters, digits, ``_``, ``-``, ``.``).

    Examples
    --------
    >>> indirect_file_names(["021.png", "041.png"], 2)
    ['021.exr', '041.exr']
    >>> indirect_file_names(["a/x.png", "b/x.png"], 2)
    ['000.exr', '001.exr']
    """
    stems = [PurePosixPath(name).stem for name in image_names]
    if (
        len(stems) == count
        and len({stem.lower() for stem in stems}) == count
        and all(map(_PLAIN_STEM.fullmatch, stems))
    ):
        return [f"{stem}.exr" for stem in stems]
    return [f"{k:03d}.exr" for k in range(count)]


def load_reconstruction(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read the normals, albedo, height and mask of a reconstruction folder.

    Returns
    -------
    (normals (H, W, 3), albedo (H, W, 3), height (H, W), mask (H, W) bool)

    Raises
    ------
    DatasetError
        Naming the file: missing, unreadable, non-finite, or of another size than
        ``normal.exr``; a normal on the mask that is not a unit vector (irtps writes unit
        normals there, even where a pixel had no light: `_check_unit_normals`).
    """
    folder = check_folder(path, missing="no such reconstruction folder")
    normal_path = check_file(folder / "normal.exr", "not a reconstruction folder?")
    normals = read_normal_map(normal_path)
    size = normals.shape[:2]
    albedo = read_albedo_map(folder / "albedo.exr", size)
    height = read_height_map(folder / "height.exr", size)
    mask = read_mask(folder / "mask.png", size)
    _check_unit_normals(normal_path, normals, mask)
    return normals, albedo, height, mask


#: How far from 1 the length of a reconstruction's normal on its mask may be: float32 files
#: hold unit normals to 1e-7, half-float ones (written by other tools) to 1e-3.
NORMAL_LENGTH_TOLERANCE = 1e-2


def _check_unit_normals(path: Path, normals: np.ndarray, mask: np.ndarray) -> None:
    """Refuse a normal on the mask whose length is not 1 (within `NORMAL_LENGTH_TOLERANCE`):
    a zero normal would be scored as 90° off, an error of the file's, not of the shape's."""
    length = np.linalg.norm(normals, axis=-1)
    wrong = mask & (np.abs(length - 1.0) > NORMAL_LENGTH_TOLERANCE)
    if wrong.any():
        row, col = np.argwhere(wrong)[0]
        raise DatasetError(
            f"{path}: the normal at row {row}, column {col} has length {length[row, col]:.3g}, not 1 "
            f"({int(wrong.sum())} of the mask's {int(mask.sum())} normals are not unit vectors)"
        )


#: Fields of ``run.json`` that readers rely on, and the JSON types each may take.
_RUN_FIELDS = {
    "source": (str, type(None)),
    "parameters": (dict,),
    "timings_s": (dict,),
    "flags": (dict,),
    "history": (list,),
}
#: Fields that folders written by older versions of irtps lack.
_OPTIONAL_RUN_FIELDS = {
    "format": (str,),
    "pixel_size": (int, float),
    "placement": (dict, type(None)),
    "chosen_pass": (int, type(None)),
    "albedo_scale": (dict, type(None)),
    "lobe_share": (int, float, type(None)),
    "robust_used": (str, type(None)),
    "images": (list,),
    "excluded_images": (list,),
    "image_agreement": (dict, type(None)),
    "irradiance_factors": (list, type(None)),
}
_HISTORY_FIELDS = {
    "index": (int,),
    "height_change": (int, float, type(None)),
    "timings": (dict,),
    "metrics": (dict, type(None)),
}
_JSON_TYPE_NAMES = {
    dict: "an object",
    list: "a list",
    str: "a string",
    int: "a number",
    float: "a number",
    type(None): "null",
}


def load_run_record(path: str | Path) -> dict:
    """Read and check the ``run.json`` of a reconstruction folder.

    Parameters
    ----------
    path : str or pathlib.Path
        The reconstruction folder (from `save_reconstruction` or ``irtps reconstruct``).

    Returns
    -------
    dict
        The record as written by `save_reconstruction`. ``pixel_size``, ``placement``,
        ``chosen_pass`` and ``albedo_scale`` are absent from folders written before irtps
        recorded them.

    Raises
    ------
    IrtpsError
        Naming the folder or the file and field: a missing folder or ``run.json``, text
        that is not JSON or is past the bounds of `irtps._shared.guarded`, a ``format`` other than
        ``irtps.run/1`` (folders written before irtps recorded it have none), or a field missing or of the wrong type (``source`` a string or
        null; ``parameters``, ``timings_s`` and ``flags`` objects; ``pixel_size`` a
        number; ``history`` a list of objects with an integer ``index``, a numeric or
        null ``height_change`` and an object or null ``metrics``).

    Examples
    --------
    >>> import tempfile
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_reconstruction(reconstruct(data), folder + "/out", source="cap")
    ...     record = load_run_record(folder + "/out")
    >>> record["source"], record["parameters"]["method"], record["history"]
    ('cap', 'ps', [])
    """
    folder = check_folder(path, missing="no such reconstruction folder")
    run_path = check_file(folder / "run.json", "not a reconstruction folder written by irtps reconstruct?")
    record = read_json(run_path, error=IrtpsError)
    _check_fields(run_path, "", record, _RUN_FIELDS, _OPTIONAL_RUN_FIELDS)
    if record.get("format", RUN) != RUN:
        raise IrtpsError(f"{run_path}: format {record['format']!r} is not a reconstruction's ({RUN!r})")
    for k, step in enumerate(record["history"]):
        _check_fields(run_path, f"history[{k}]", step, _HISTORY_FIELDS, {})
    return record


def _check_fields(run_path: Path, name: str, value, required: dict, optional: dict) -> None:
    """Raise `IrtpsError` unless ``value`` is an object whose fields have the listed types."""
    if not isinstance(value, dict):
        raise IrtpsError(f"{run_path}: {name or 'the file'} must be an object, found {json.dumps(value)[:40]}")
    prefix = f"{name}." if name else ""
    for field_name, types in {**required, **optional}.items():
        if field_name not in value:
            if field_name in required:
                raise IrtpsError(f"{run_path}: {prefix}{field_name} is missing")
            continue
        item = value[field_name]
        if isinstance(item, bool) or not isinstance(item, types):
            expected = " or ".join(dict.fromkeys(_JSON_TYPE_NAMES[t] for t in types))
            raise IrtpsError(f"{run_path}: {prefix}{field_name} must be {expected}, found {json.dumps(item)[:40]}")
