"""The robust scale that irtps's fits and checks share: the median absolute deviation, made
a standard deviation."""

from __future__ import annotations

import numpy as np

__all__ = ["MAD_TO_SIGMA", "median_and_sigma"]

#: Median absolute deviation to the standard deviation of a normal distribution.
MAD_TO_SIGMA = 1.4826


def median_and_sigma(values: np.ndarray) -> tuple[float, float]:
    """The median of `values` and their robust standard deviation, `MAD_TO_SIGMA` × the median
    absolute deviation from it: a few wild values move neither.

    Examples
    --------
    >>> median_and_sigma(np.array([1.0, 2.0, 3.0, 4.0, 100.0]))
    (3.0, 1.4826)
    """
    center = float(np.median(values))
    return center, MAD_TO_SIGMA * float(np.median(np.abs(values - center)))
