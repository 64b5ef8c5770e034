"""What the IRT-PS loop carries from one pass to the next (`LoopState`), and what each pass
recorded (`Iteration`).

The loop (`irtps.irt.interreflection.remove_interreflections`) runs one pass per image set;
the state holds the images the next pass fits, the running estimate of the light subtracted
from them and how it moves (`irtps.irt.update`), and the best pass so far, judged by its
residual against the input images.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from irtps.irt.early_exit import CorrectionSize
from irtps.irt.pipeline import Pass
from irtps.irt.relaxation import AdaptiveStep
from irtps.ps.fit import PsResult
from irtps.render.residual import Residual

__all__ = ["SIGNIFICANCE", "STOP_REASONS", "TREND", "BestPass", "Iteration", "LoopState", "Stop", "within_noise"]

#: Two residuals differ when they are this many standard deviations of their Monte-Carlo
#: noise (combined) apart.
SIGNIFICANCE = 2.0
#: The loop stops when the residual has not fallen, beyond its noise, over this many passes
#: (from the pass this many before the last to the last): one pass is not enough, as an
#: over-relaxed step can raise the residual once on the way down.
TREND = 2


#: Why the loop stopped (`Stop.reason`).
STOP_REASONS = ("iterations", "below_noise", "stalled")


def within_noise(residual: Residual, other: Residual) -> bool:
    """Whether `residual` is no higher than `other` beyond `SIGNIFICANCE` times their combined
    Monte-Carlo noise."""
    return residual.object <= other.object + SIGNIFICANCE * float(np.hypot(residual.noise, other.noise))


@dataclass
class Iteration:
    """What one pass of the loop measured.

    Attributes
    ----------
    index : int
        0 is classic photometric stereo on the input images.
    height_change : float or None
        Mean absolute change of the height map from the previous pass (world units).
    residual : dict
        `irtps.render.residual.Residual` of the pass's reconstruction, as a dict.
    base_height : float or None
        Where the pass's reconstruction stands (`irtps.geometry.placement.Placement.base_height`).
    step : float or None
        The step taken toward the estimate rendered from this pass (None on the last).
    timings : dict
        Seconds per stage.
    metrics : dict or None
        Errors against ground truth (`irtps.model.metrics.Metrics.to_dict`), when present.
    """

    index: int
    height_change: float | None
    residual: dict = field(default_factory=dict)
    base_height: float | None = None
    step: float | None = None
    timings: dict[str, float] = field(default_factory=dict)
    metrics: dict | None = None


@dataclass(frozen=True)
class Stop:
    """Why the loop stopped where it did.

    Attributes
    ----------
    reason : str
        One of `STOP_REASONS`: ``"iterations"``, the largest number of corrections was made;
        ``"below_noise"``, pass 1's fit of the corrected images turned the normals by less
        than half their standard error (`irtps.irt.early_exit`), so the loop stopped before
        rendering it and kept pass 0 (`LoopState.correction_stop`);
        ``"stalled"``, the residual did not fall beyond its noise over the last `TREND`
        passes (`LoopState.stalled_out`).
    after_pass : int
        The last pass rendered and judged.
    message : str
        The reason in words, with its figures.
    correction : CorrectionSize or None
        Pass 1's turn of the normals against their standard error, where it was measured.
    """

    reason: str
    after_pass: int
    message: str
    correction: CorrectionSize | None = None

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return {
            "reason": self.reason,
            "after_pass": self.after_pass,
            "message": self.message,
            "correction": None if self.correction is None else self.correction.to_dict(),
        }


@dataclass
class BestPass:
    """The pass with the lowest residual so far, and the light subtracted from its images
    (None for pass 0)."""

    residual: Residual
    index: int
    reconstruction: Pass
    subtracted: np.ndarray | None


@dataclass
class LoopState:
    """The IRT-PS loop between two passes.

    Attributes
    ----------
    observed : numpy.ndarray
        (K, N, 3) input observations A₀ at the mask's N pixels, row-major.
    saturated : numpy.ndarray or None
        (K, N, 1) bool, the observations at or above the saturation level, kept as observed
        in every corrected image set; None without a level.
    images : numpy.ndarray
        The images the next pass fits: the input (K, H, W, 3) before pass 1, then corrected
        (K, N, 3) observations.
    step : float
        The step toward the next estimate (the fixed relaxation, or the adaptive one's last).
    steps : AdaptiveStep
        The adaptive step's record of steps taken and their noise.
    previous : Pass or None
        The last pass.
    estimate : numpy.ndarray or None
        The running estimate Eₜ of the inter-reflections in the object's pixels (K, N, 3).
    previous_change : numpy.ndarray or None
        The last change of the estimate, before the step.
    subtracted : numpy.ndarray or None
        What the next pass's images have subtracted from A₀: Eₜ, plus the surroundings' light
        Sₜ in edge pixels.
    coverage : numpy.ndarray or None
        How much of each edge pixel the surroundings' correction covers
        (`irtps.render.surroundings`), for the next pass's placement.
    best : BestPass or None
        The pass of the lowest residual so far.
    residuals : list of Residual
        Every pass's residual.
    history : list of Iteration
        Every pass's record.
    first_fit : PsResult or None
        Pass 0's fit: classic photometric stereo of the input images.
    correction : CorrectionSize or None
        How far pass 1 turned pass 0's normals against their standard error, once measured.
    """

    observed: np.ndarray
    saturated: np.ndarray | None
    images: np.ndarray
    step: float
    steps: AdaptiveStep = field(default_factory=AdaptiveStep)
    previous: Pass | None = None
    estimate: np.ndarray | None = None
    previous_change: np.ndarray | None = None
    subtracted: np.ndarray | None = None
    coverage: np.ndarray | None = None
    best: BestPass | None = None
    residuals: list[Residual] = field(default_factory=list)
    history: list[Iteration] = field(default_factory=list)
    first_fit: PsResult | None = None
    correction: CorrectionSize | None = None

    def judge(self, index: int, current: Pass, residual: Residual) -> None:
        """Record pass `index`'s `residual`; the pass chosen so far is the one of the lowest
        residual."""
        self.residuals.append(residual)
        if self.best is None or residual.object < self.best.residual.object:
            self.best = BestPass(residual, index, current, self.subtracted)

    def stop(self, index: int, iterations: int, early_stop: bool) -> Stop | None:
        """Why the loop stops after pass `index`, or None to go on: `iterations` corrections
        made, or with `early_stop` the residual stalled."""
        if index >= iterations:
            asked = (
                "no correction was asked for"
                if iterations == 0
                else f"the {iterations} corrections asked for were made"
            )
            return Stop("iterations", index, asked, self.correction)
        if not early_stop:
            return None
        if self.stalled_out:
            return Stop(
                "stalled",
                index,
                f"the residual did not fall by more than {SIGNIFICANCE:g} times its Monte-Carlo noise over the last {TREND} passes",
                self.correction,
            )
        return None

    def correction_stop(self) -> Stop | None:
        """After pass 1's fit: stop before rendering it, keeping pass 0, where its correction
        turned the normals by less than half their standard error (`correction`,
        `irtps.irt.early_exit.NOISE_FRACTION`); else None."""
        size = self.correction
        if size is None or not size.below_noise:
            return None
        return Stop(
            "below_noise",
            0,
            f"the first correction turned the normals by {size.change_deg:.3g} deg (median), less than half the "
            f"{size.noise_deg:.3g} deg that their fit's residual leaves them uncertain: the inter-reflections are "
            "below what the images tell apart, and the result is classic photometric stereo's",
            size,
        )

    @property
    def stalled_out(self) -> bool:
        """The residual has not fallen beyond its noise over the last `TREND` passes."""
        if len(self.residuals) <= TREND:
            return False
        return within_noise(self.residuals[-1 - TREND], self.residuals[-1])
