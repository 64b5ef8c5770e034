"""The lights' relative strengths from the images, when only their directions are known
(semi-calibrated photometric stereo).

A Lambertian pixel p lit by light k shows ``I_kp = e_k b_p . l_k``, with ``b_p`` its albedo
times its normal and ``e_k`` the light's unknown strength. Written with ``u_k = 1 / e_k``,
``u_k I_kp = l_k . b_p`` is linear in both: whatever ``b_p``, the vector ``u * i_p`` lies in
the span of the light directions, so its part outside that span, ``P u * i_p`` (P the
projector off the span of L's columns), vanishes. Over the pixels, ``u`` is then the
eigenvector of the smallest eigenvalue of ``P * (I^T I)`` (elementwise product; Mo, Shi, Lu
and Matsushita, "Semi-calibrated photometric stereo", TPAMI 2018), solved here on the sum of
the channels.

Only pixels that every light reaches count (no observation in shadow or saturated), and of
those, the half whose observations that solution explains best, chosen again until the half
settles (least trimmed squares: a highlight or a cast shadow at up to half the pixels does
not move it). Each channel's strengths then come from the same solution on those pixels,
channel by channel (the channels' sum is exactly Lambertian only under lights of one
colour).
"""

from __future__ import annotations

import numpy as np

from irtps._shared.checks import check_array, check_finite, check_mask
from irtps.errors import ArgumentError

__all__ = ["estimate_light_intensities"]

#: Most re-choices of the better half of the pixels; it settles in a few.
_ROUNDS = 50


def estimate_light_intensities(
    images: np.ndarray,
    light_directions: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    shadow_fraction: float = 0.05,
    saturation: float | None = None,
) -> np.ndarray:
    """Estimate each light's relative RGB strength from images under lights of known
    direction.

    Parameters
    ----------
    images : numpy.ndarray
        (K, H, W, 3) linear images, one per light.
    light_directions : numpy.ndarray
        (K, 3) unit vectors toward the lights (K >= 4, not coplanar).
    mask : numpy.ndarray, optional
        (H, W) bool, the object's pixels; default every pixel.
    shadow_fraction : float
        An observation whose channel sum is at most this fraction of the pixel's brightest is
        in shadow (as `irtps.photometric_stereo` tells shadows).
    saturation : float, optional
        Observations with a channel at or above it are left out.

    Returns
    -------
    numpy.ndarray
        float64 (K, 3): each light's strength per channel, the median light's 1 in each
        channel (a colour common to every light cannot be told from the albedo's, nor an
        overall scale).

    Raises
    ------
    ArgumentError
        Naming the argument: shapes that disagree, non-finite values, fewer than 4 lights,
        lights in one plane, a `shadow_fraction` outside [0, 1); naming ``images`` when fewer
        pixels than lights are lit by every light, or when they do not fix the strengths.

    Examples
    --------
    A sphere under 8 lights of unequal strength: their strengths come back.

    >>> import numpy as np
    >>> y, x = np.mgrid[-1:1:64j, -1:1:64j]
    >>> mask = x**2 + y**2 < 0.8
    >>> normals = np.dstack([x, y, np.sqrt(np.clip(1 - x**2 - y**2, 0, None))])
    >>> angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    >>> lights = np.c_[0.4 * np.cos(angles), 0.4 * np.sin(angles), np.full(8, np.sqrt(0.84))]
    >>> strength = np.linspace(0.7, 1.3, 8)[:, None] * np.ones(3)
    >>> images = strength[:, None, None] * np.clip(normals @ lights.T, 0, None).transpose(2, 0, 1)[..., None]
    >>> found = estimate_light_intensities(images, lights, mask)
    >>> bool(np.allclose(found, strength / np.median(strength, axis=0)))
    True
    """
    images = check_array("images", images, (None, None, None, 3), dtype=np.float32, copy=False)
    directions = check_array("light_directions", light_directions, (len(images), 3), match="images")
    check_finite("light_directions", directions, unit="light")
    mask = check_mask(mask, images.shape[1:3], match="images")
    if not 0 <= shadow_fraction < 1:
        raise ArgumentError("shadow_fraction", f"{shadow_fraction} is outside [0, 1)")
    if len(directions) < 4:
        raise ArgumentError("light_directions", f"{len(directions)} lights: at least 4 are needed")
    if np.linalg.matrix_rank(directions, tol=1e-6) < 3:
        raise ArgumentError("light_directions", "the lights lie in one plane: they do not fix a normal")
    observations = images[:, mask].astype(np.float64)  # (K, P, 3)
    check_finite("images", observations, unit="light")
    lit = _lit_by_every_light(observations, shadow_fraction, saturation)
    if lit.sum() < len(directions):
        raise ArgumentError(
            "images",
            f"{int(lit.sum())} pixels are lit by every light (not in shadow, not saturated): fewer than the "
            f"{len(directions)} lights, too few to tell their strengths apart; give the intensities",
        )
    off_span = np.eye(len(directions)) - directions @ np.linalg.pinv(directions)
    gray = observations[:, lit].sum(axis=-1)  # (K, N)
    inverse, kept = _trimmed_inverse_strengths(gray, off_span)
    chosen = observations[:, lit][:, kept]  # (K, M, 3)
    # Each channel alone is exactly Lambertian (their sum is so only under lights of one
    # colour): the same solution on the chosen pixels, channel by channel, where it is
    # positive (a channel dark on the object tells nothing).
    strengths = np.repeat((1.0 / inverse)[:, None], 3, axis=1)
    for channel in range(3):
        per_channel = _inverse_strengths(chosen[..., channel], off_span)
        if (per_channel > 0).all():
            strengths[:, channel] = 1.0 / per_channel
    return strengths / np.median(strengths, axis=0)


def _lit_by_every_light(observations: np.ndarray, shadow_fraction: float, saturation: float | None) -> np.ndarray:
    """bool (P,): the pixels with no observation in shadow or saturated."""
    brightness = observations.sum(axis=-1)  # (K, P)
    lit = (brightness > shadow_fraction * brightness.max(axis=0)).all(axis=0)
    if saturation is not None:
        lit &= ~(observations >= saturation).any(axis=(0, 2))
    return lit


def _inverse_strengths(values: np.ndarray, off_span: np.ndarray) -> np.ndarray:
    """``u = 1 / e`` (K,) from `values` (K, N) of pixels lit by every light: the eigenvector
    of the smallest eigenvalue of ``P * (I^T I)`` (P = `off_span`, the projector off the
    span of the light directions), signed to sum positive (all positive when the values fix
    the strengths)."""
    _, vectors = np.linalg.eigh(off_span * (values @ values.T))
    return vectors[:, 0] * np.sign(vectors[:, 0].sum())


def _trimmed_inverse_strengths(gray: np.ndarray, off_span: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``u = 1 / e`` (K,) from the channel sums `gray` (K, N) of pixels lit by every light, on
    the half of them it explains best, and that half (bool (N,))."""
    kept = np.ones(gray.shape[1], dtype=bool)
    for _ in range(_ROUNDS):
        inverse = _inverse_strengths(gray[:, kept], off_span)
        scaled = gray.T * inverse
        misfit = np.linalg.norm(scaled @ off_span, axis=1) / np.linalg.norm(scaled, axis=1)
        better = misfit <= np.median(misfit)
        if (better == kept).all():
            break
        kept = better
    if not (inverse > 0).all():
        raise ArgumentError(
            "images", "they do not fix the lights' strengths (some come out negative): give the intensities"
        )
    return inverse, kept
