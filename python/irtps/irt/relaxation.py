"""The adaptive step of the IRT-PS loop toward each new estimate of the inter-reflections.

The estimate Eₜ moves toward each new rendering by a step that adapts to how the loop
converges (a secant estimate of its contraction): above 1 where the estimates converge
slowly in one direction, below 1 where they oscillate (`AdaptiveStep`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["STEP_BOUNDS", "AdaptiveStep"]

#: Bounds of the adaptive step toward each new estimate. Above 2 the Monte-Carlo noise of
#: the estimates would grow without bound; the upper bound keeps it within √3 of one
#: estimate's.
STEP_BOUNDS = (0.5, 1.9)


class AdaptiveStep:
    """The step toward each new estimate, from how much of the last change remains.

    For a fixed-point map that contracts by ρ, a step ω leaves a fraction q = 1 − ω(1 − ρ)
    of each change in the next; q = <change, previous> / ‖previous‖² (on the object's
    pixels) gives 1 − ρ, and the step that would have removed it all is ω / (1 − q),
    within `STEP_BOUNDS`. Where the previous change is not above its noise, the loop has
    settled within that noise, and the step averages the running and the new estimate, each
    weighed by its inverse noise (within `STEP_BOUNDS`): a step of 1 there would take the
    whole noise of one new estimate into the running one. Where the change grew, nothing says
    how the loop contracts, and the step is 1 (a plain fixed-point iteration). Both products
    are corrected for the Monte-Carlo noise of the estimates, which would otherwise pull q
    toward 0 (or below) once the changes are mostly noise: the noise energy of each new
    estimate is measured (its two halves), and that of the running estimate follows from the
    steps taken.
    """

    def __init__(self) -> None:
        self.step = 1.0
        self.new_noise = 0.0
        self.running_noise = 0.0
        self.previous_running = 0.0

    def taken(self, step: float, new_noise: float) -> None:
        """Record the step taken toward a new estimate of noise energy `new_noise`."""
        self.previous_running, self.new_noise, self.step = self.running_noise, new_noise, step
        self.running_noise = (1 - step) ** 2 * self.previous_running + step**2 * new_noise

    def next(self, change: np.ndarray, previous_change: np.ndarray) -> float:
        """The step for `change` (K, N, 3 on the object's pixels), the difference between
        the newest estimate and the running one, given the `previous_change`."""
        now, before = change, previous_change
        # Noise shared by the two changes: the running estimate's before the last step
        # enters both with the same sign, the last new estimate's with opposite signs.
        shared = (1 - self.step) * self.previous_running - self.step * self.new_noise
        noise = self.new_noise + self.previous_running
        energy = float(np.vdot(before, before)) - noise
        if energy <= noise:
            # The changes are mostly noise: the loop has settled within it, and the step that
            # averages the running and the new estimate best weighs each by its inverse noise.
            return float(
                np.clip(
                    self.running_noise / max(self.running_noise + self.new_noise, np.finfo(float).tiny), *STEP_BOUNDS
                )
            )
        kept = (float(np.vdot(now, before)) - shared) / energy
        if kept >= 1:
            # The change grew: no sign of how the loop contracts.
            return 1.0
        return float(np.clip(self.step / (1 - kept), *STEP_BOUNDS))
