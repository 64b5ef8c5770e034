"""One pass of the reconstruction pipeline: photometric stereo, then normal integration and
placement; classic photometric stereo is one pass, IRT-PS one pass per corrected image set.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from irtps.dataset import Dataset
from irtps.integrate import integrate_normals, place_height
from irtps.options import OptionError, ReconstructOptions
from irtps.ps import PsResult, photometric_stereo

#: Heights are float32 (24 significant bits): a surface placed further than this many pixel
#: sizes from the origin keeps no precision for its relief.
MAX_BASE_HEIGHT_PIXELS = 1e6

#: IRT-PS's default tolerance on the mean height change, in pixel sizes.
DEFAULT_TOLERANCE_PIXELS = 0.002


def resolve_options(dataset: Dataset, options: ReconstructOptions) -> ReconstructOptions:
    """`options` with the defaults that depend on the data set filled in.

    ``saturation``: the data set's (1 for PNG images); ``integration``: the method's
    default; ``base_height``: the floor's height (0 without a floor); ``tolerance``:
    0.002 pixel sizes.

    Raises
    ------
    OptionError
        If ``base_height`` lies so far from the scene that float32 heights lose the relief.
    """
    scene = dataset.scene
    pixel_size = scene.camera.pixel_size
    base_height = options.base_height
    if base_height is None:
        base_height = scene.floor.height if scene.floor is not None else 0.0
    limit = MAX_BASE_HEIGHT_PIXELS * pixel_size
    if abs(base_height) > limit:
        raise OptionError(
            "base_height",
            f"{base_height:g} is out of range for this data set: expected at most {MAX_BASE_HEIGHT_PIXELS:g} pixel sizes "
            f"({limit:g} world units) from 0 (heights are float32)",
        )
    return dataclasses.replace(
        options,
        saturation=dataset.saturation if options.saturation is None else options.saturation,
        integration=options.integration_method,
        base_height=base_height,
        tolerance=DEFAULT_TOLERANCE_PIXELS * pixel_size if options.tolerance is None else options.tolerance,
    )


def fit_photometric_stereo(dataset: Dataset, images: np.ndarray, options: ReconstructOptions) -> PsResult:
    """Photometric stereo on `images` (the data set's, or corrected ones) with the data set's
    lights and mask and the options' robust settings."""
    scene = dataset.scene
    return photometric_stereo(
        images,
        scene.light_directions,
        scene.light_irradiance,
        dataset.mask,
        robust=options.robust,
        shadow_fraction=options.shadow_fraction,
        saturation=options.saturation,
    )


def surface_height(dataset: Dataset, normals: np.ndarray, options: ReconstructOptions) -> np.ndarray:
    """The height map of `normals`: integrated (``options.integration``), placed at
    ``options.base_height`` (contract §6), float32, 0 outside the mask."""
    mask = dataset.mask
    height = integrate_normals(normals, mask, pixel_size=dataset.scene.camera.pixel_size, method=options.integration_method)
    height = place_height(height, mask, base_height=0.0 if options.base_height is None else options.base_height)
    return np.where(mask, height, 0).astype(np.float32)
