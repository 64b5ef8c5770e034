"""Error against sample count, for the renderers that mitsuba_compare.py sets side by side:
each renderer's curve (`Curve`) and the error of images against a reference rendered in two
independent halves, its own noise removed (`ErrorMeter`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Curve:
    """Error, wall time and CPU time of one renderer at each sample count."""

    name: str
    samples: list[int] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    cpu_seconds: list[float] = field(default_factory=list)
    error: list[float] = field(default_factory=list)
    raw_error: list[float] = field(default_factory=list)
    extra: list[dict] = field(default_factory=list)

    def add(self, spp: int, seconds: tuple[float, float], error: tuple[float, float], **extra) -> None:
        self.samples.append(spp)
        self.seconds.append(seconds[0])
        self.cpu_seconds.append(seconds[1])
        self.error.append(error[0])
        self.raw_error.append(error[1])
        self.extra.append(extra)

    def at(self, target: float, values: list[float]) -> tuple[float | None, str]:
        """`values` (per sample count) where the error reaches `target`, interpolated in
        log-log between neighbouring counts: (value, "") inside the measured range, (value
        at the fewest samples, "upper bound") when even that is better, (None, "not reached")
        when the best is worse."""
        order = sorted(range(len(self.samples)), key=self.samples.__getitem__)
        errors = [max(self.error[i], 1e-12) for i in order]
        values = [values[i] for i in order]
        if errors[0] <= target:
            return values[0], "upper bound"
        for i in range(len(order) - 1):
            e0, e1 = errors[i], errors[i + 1]
            if e0 >= target >= e1 and e0 > e1:
                f = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
                return math.exp(math.log(values[i]) + f * (math.log(values[i + 1]) - math.log(values[i]))), ""
        return None, "not reached"

    def to_dict(self) -> dict:
        return {
            "samples": self.samples,
            "wall_seconds": self.seconds,
            "cpu_seconds": self.cpu_seconds,
            "relative_rmse": self.error,
            "relative_rmse_uncorrected": self.raw_error,
            "details": self.extra,
        }


class ErrorMeter:
    """Relative RMSE over the object's pixels, against a two-half reference, noise removed."""

    def __init__(self, half_a: np.ndarray, half_b: np.ndarray, mask: np.ndarray):
        self.mask = mask
        a, b = half_a[:, mask].astype(np.float64), half_b[:, mask].astype(np.float64)
        self.reference = 0.5 * (a + b)
        self.reference_noise = float(np.mean((a - b) ** 2) / 4)  # variance of the mean of the halves
        self.scale = float(self.reference.mean())

    def __call__(self, images: np.ndarray) -> tuple[float, float]:
        """(noise-corrected, raw) relative RMSE of (K, H, W, 3) images."""
        squared = float(np.mean((images[:, self.mask].astype(np.float64) - self.reference) ** 2))
        return math.sqrt(max(squared - self.reference_noise, 0.0)) / self.scale, math.sqrt(squared) / self.scale
