"""Whether IRT-PS's corrections change what the images tell: the first correction's turn of
the normals against the normals' own standard error.

Pass 1 fits the images with pass 0's whole estimate of the inter-reflections removed; the
passes after it only refine that estimate as the shape it was rendered from changes. Where
the first correction turns the normals by less than the images fix them (the standard
error of classic photometric stereo's normals from its own residual:
`irtps.ps.uncertainty.normal_standard_error`; by less than half of it, `NOISE_FRACTION`, as
stopping wrongly costs accuracy and going on wrongly only time), the correction and every
refinement of it move the result by less than its own uncertainty: the loop stops before
rendering pass 1 and returns pass 0, classic photometric stereo (`first_correction`,
`CorrectionSize`, `irtps.irt.loop_state.LoopState.correction_stop`). That is the case of a
real object alone, whose inter-reflections carry little of its light while gloss
and shadow edges leave its fit a far larger residual; an object in a box or beside a wall
turns by several times its standard error (measured: docs/method.md, Convergence).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from irtps.errors import ArgumentError
from irtps.model.data import Dataset, spread_pixels
from irtps.model.scene import lights_at
from irtps.ps.fit import PsResult
from irtps.ps.uncertainty import normal_standard_error

__all__ = ["NOISE_FRACTION", "SAMPLE", "CorrectionSize", "first_correction"]

#: The loop stops only where the first correction turned the normals by less than this
#: fraction of their standard error: stopping wrongly gives up the correction's accuracy,
#: going on wrongly costs only time, so the rule leans toward going on.
NOISE_FRACTION = 0.5
#: Object pixels measured, spread evenly over the mask: the medians of a few thousand stand
#: for those of all of them, at a fraction of the time.
SAMPLE = 4096


@dataclass(frozen=True)
class CorrectionSize:
    """How far the first correction turned the normals, against how precisely the images fix
    them.

    Attributes
    ----------
    change_deg : float
        Median over the object's pixels of the angle between pass 0's and pass 1's normals.
    noise_deg : float
        Median of the standard error of pass 0's normals (`normal_standard_error`).
    pixels : int
        The pixels measured (fitted in both passes, their error determined).
    """

    change_deg: float
    noise_deg: float
    pixels: int

    @property
    def below_noise(self) -> bool:
        """The correction turned the normals by less than `NOISE_FRACTION` of their standard
        error."""
        return self.change_deg < NOISE_FRACTION * self.noise_deg

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return asdict(self)


def first_correction(
    dataset: Dataset, usable: np.ndarray, first: PsResult, second: PsResult, surface: np.ndarray | None = None
) -> CorrectionSize | None:
    """How far pass 1's fit (`second`) turned pass 0's normals (`first`), against their
    standard error from pass 0's residual over the observations fitted (`usable`).

    Parameters
    ----------
    dataset : Dataset
        The input images and lights (distant: a perspective camera's orthographic stand-in).
    usable : numpy.ndarray
        bool (K, H, W, 1): the observations photometric stereo fits
        (`irtps.irt.pipeline.fitted_observations`).
    first, second : PsResult
        Pass 0's and pass 1's fits.
    surface : numpy.ndarray, optional
        (H, W) pass 0's placed heights, where point lights shine from (needed under them).

    Returns
    -------
    CorrectionSize or None
        None where no pixel is fitted in both passes with a determined error.
    """
    measured = np.zeros_like(dataset.mask)
    measured.flat[spread_pixels(dataset.mask, SAMPLE)] = True
    before, after = first.normals[measured], second.normals[measured]
    scene = dataset.scene
    if scene.has_point_lights:
        if surface is None:
            raise ArgumentError("surface", "is needed under point lights: their light at a pixel depends on its point")
        directions, irradiance = lights_at(scene, scene.camera.surface_points(surface)[measured])
    else:
        directions, irradiance = scene.light_directions, scene.light_irradiance
    noise = normal_standard_error(dataset.images, directions, irradiance, measured, usable)[measured]
    fitted = (np.abs(before).sum(axis=1) > 0) & (np.abs(after).sum(axis=1) > 0) & np.isfinite(noise)
    if not fitted.any():
        return None
    cosine = np.clip((before[fitted] * after[fitted]).sum(axis=1), -1.0, 1.0)
    return CorrectionSize(
        change_deg=float(np.median(np.degrees(np.arccos(cosine)))),
        noise_deg=float(np.median(noise[fitted])),
        pixels=int(fitted.sum()),
    )
