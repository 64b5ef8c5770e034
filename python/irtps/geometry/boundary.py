"""The mask's boundary and the height it stands at (contract §6).

:func:`mask_boundary` finds the boundary pixels of a mask, and :func:`place_height` fixes the
free constant that normal integration leaves (:func:`irtps.geometry.integrate.integrate_normals`)
as the contract asks: the median height of the mask boundary is put at the floor height (or
a given base height). `FOUR_CONNECTED` is the connectivity of both, and of the integration's
connected components.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

from irtps._shared.checks import check_array, check_finite, check_mask, check_number
from irtps.errors import ArgumentError

__all__ = ["mask_boundary", "place_height"]

#: 4-connectivity: the finite differences only ever join 4-neighbours. The mask's components
#: and boundary come from scipy.ndimage (label, binary_erosion), not scikit-image: its
#: measure.label does the same labelling, and segmentation.find_boundaries(mode="inner") does
#: not count the image border as boundary, which place_height needs; scikit-image has no
#: normal integration, so it would be a dependency for nothing scipy does not already do.
FOUR_CONNECTED = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)


def place_height(height, mask=None, *, base_height: float = 0.0, per_component: bool = True) -> np.ndarray:
    """Shift heights so that the object stands at a base height (contract §6).

    The median height over the mask boundary is set to `base_height`. Boundary pixels are
    the masked pixels with at least one unmasked 4-neighbour, or on the image border. By
    default each 4-connected component of the mask is shifted on its own, as normal
    integration leaves each with its own free constant.

    Parameters
    ----------
    height : array_like
        (H, W) heights, e.g. from :func:`irtps.geometry.integrate.integrate_normals`.
    mask : array_like, optional
        (H, W) bool, the object's pixels; default: every pixel.
    base_height : float
        Height to put the boundary median at: the floor height, 0 when there is no floor.
    per_component : bool
        Shift each 4-connected component of the mask separately (default); if False, one
        shift for the whole mask, from the median over all its boundary pixels.

    Returns
    -------
    numpy.ndarray
        float32 (H, W) heights, 0 outside the mask.

    Raises
    ------
    ArgumentError
        If `height` is not 2-D, has non-finite values inside the mask, `mask` has another
        shape or is empty, or `base_height` is not finite.

    Examples
    --------
    >>> import numpy as np
    >>> h = np.full((5, 5), 3.0)
    >>> h[2, 2] = 7.0
    >>> z = place_height(h, base_height=1.0)
    >>> float(z[0, 0]), float(z[2, 2])
    (1.0, 5.0)
    """
    height = check_array("height", height, (None, None), nonempty=True)
    mask = check_mask(mask, height.shape, match="height")
    if not mask.any():
        raise ArgumentError("mask", "empty (no pixel set)")
    check_finite("height", height, mask)
    base_height = check_number("base_height", base_height)

    boundary = mask_boundary(mask)
    out = np.zeros(height.shape, np.float64)
    if per_component:
        labels, count = scipy.ndimage.label(mask, structure=FOUR_CONNECTED)
        medians = scipy.ndimage.median(height, labels=np.where(boundary, labels, 0), index=np.arange(1, count + 1))
        shift = np.concatenate([[0.0], base_height - np.asarray(medians, np.float64)])
        out[mask] = height[mask] + shift[labels[mask]]
    else:
        out[mask] = height[mask] + (base_height - np.median(height[boundary]))
    return out.astype(np.float32)


def mask_boundary(mask) -> np.ndarray:
    """The boundary pixels of a mask: masked, with an unmasked 4-neighbour or on the border.

    Parameters
    ----------
    mask : array_like
        (H, W) bool.

    Returns
    -------
    numpy.ndarray
        (H, W) bool.

    Examples
    --------
    >>> import numpy as np
    >>> m = np.zeros((5, 5), bool)
    >>> m[1:4, 1:4] = True
    >>> mask_boundary(m).astype(int)[1:4, 1:4].tolist()
    [[1, 1, 1], [1, 0, 1], [1, 1, 1]]
    """
    mask = check_mask(mask)
    inner = scipy.ndimage.binary_erosion(mask, structure=FOUR_CONNECTED, border_value=0)
    return mask & ~inner
