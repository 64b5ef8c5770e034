"""How well a reconstruction explains its images, without ground truth.

A reconstruction (height, albedo, placement) is rendered again in its known surroundings:
direct light with cast shadows plus inter-reflected light after 1..r bounces, under every
light. Its relative residual is the mean absolute difference from the input images over the
mean absolute input, on the object's pixels and, where the scene has a floor, on the
visible surroundings. On the object it compares the observations that photometric stereo
fits (`compared_observations`): a real object's shadows hold light that the Lambertian
rendering of a slightly wrong shape can match by chance, so that a worse shape could seem
to explain them better; measured on DiLiGenT reading, the residual over every observation
fell from classic photometric stereo to IRT-PS's first pass while the error rose by 1.3°,
and the residual over the fitted observations rose with it. The same rendering gives IRT-PS its next estimate of the
inter-reflected light, so the residual costs only the direct image.

The inter-reflected light is rendered as two independent halves of the camera paths; the
residuals of the two halves tell the residual's Monte-Carlo noise, by which IRT-PS decides
that a pass no longer improves on the last.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from irtps._checks import check_array, check_mask
from irtps.errors import ArgumentError
from irtps.render import check_counts, check_frame_memory, make_renderer, render_sparse
from irtps.scene import Scene

__all__ = ["Rerendering", "Residual", "compared_observations", "render_with_residual"]

#: Footprint samples per pixel of the direct image the residual compares (stratified, with
#: exact shadow rays).
DIRECT_SAMPLES = 16
#: The second half of the camera paths uses the seed moved by this much (the seeds of the
#: passes, seed + t, never reach it).
_SECOND_HALF_SEED = 2**63


@dataclass(frozen=True)
class Residual:
    """Relative residuals of a re-rendered reconstruction against its images.

    Attributes
    ----------
    object : float
        Σ|rendered − observed| / Σ|observed| over the object's pixels, all lights and
        channels, for the observations photometric stereo fits (`compared_observations`).
    surroundings : float or None
        The same over the pixels outside the mask (every observation that is not
        saturated); None without a floor.
    noise : float
        Monte-Carlo standard deviation of `object` (from two independent halves of the
        camera paths; 0 with a single path per pixel).
    """

    object: float
    surroundings: float | None
    noise: float

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return asdict(self)


@dataclass
class Rerendering:
    """A reconstruction rendered again: its inter-reflected light and its residual.

    Attributes
    ----------
    indirect : numpy.ndarray
        float32 (K, H, W, 3), bounces 1..r summed.
    residual : Residual
    noise_energy : numpy.ndarray
        float64 (H, W): Σ over lights and channels of the Monte-Carlo variance of
        `indirect` at each pixel (from its two independent halves; 0 with one path).
    """

    indirect: np.ndarray
    residual: Residual
    noise_energy: np.ndarray


def render_with_residual(
    scene: Scene,
    height: np.ndarray,
    albedo: np.ndarray,
    mask: np.ndarray,
    images: np.ndarray,
    *,
    bounces: int,
    samples: int,
    seed: int = 0,
    stride: int = 1,
    usable: np.ndarray | None = None,
) -> Rerendering:
    """Render a reconstruction's inter-reflected light and its residual against `images`.

    Parameters
    ----------
    scene, height, albedo, mask
        The reconstruction in its surroundings, as for `irtps.render.render`.
    images : numpy.ndarray
        (K, H, W, 3) the observed images.
    bounces : int
        Inter-reflection bounces r rendered (1..r).
    samples : int
        Camera paths per pixel for the inter-reflected light.
    seed : int
        Seed of the random numbers.
    stride : int
        As for `irtps.render.render_indirect`: 1 traces paths at every pixel, s > 1 at one
        in s×s and interpolates (the object and its surroundings apart).
    usable : numpy.ndarray, optional
        (K, H, W, 1) bool, the observations to compare (`compared_observations`); default
        all.

    Returns
    -------
    Rerendering

    Raises
    ------
    ArgumentError
        Naming a count out of range (`bounces`, `samples`, `seed`, `stride`) or an array
        that does not match the camera.

    Examples
    --------
    A flat square of the right albedo explains its images far better than one 20 % too
    dark (what remains is the sampling of the border pixels' footprints).

    >>> import numpy as np
    >>> from irtps import Camera, Light, Scene, render
    >>> lights = [Light(direction=d, irradiance=(np.pi,) * 3) for d in
    ...           ([0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8])]
    >>> scene = Scene(Camera(8, 8, 1.0), lights)
    >>> height, mask = np.zeros((8, 8)), np.ones((8, 8), bool)
    >>> albedo = np.full((8, 8, 3), 0.5)
    >>> images = render(scene, height, albedo, mask, bounces=1, samples=4).images
    >>> right = render_with_residual(scene, height, albedo, mask, images, bounces=1, samples=4).residual
    >>> dark = render_with_residual(scene, height, 0.8 * albedo, mask, images, bounces=1, samples=4).residual
    >>> round(right.object, 2), round(dark.object, 2), right.surroundings
    (0.06, 0.23, None)
    """
    check_counts(bounces, samples, seed)
    if stride < 1:
        raise ArgumentError("stride", f"{stride} must be at least 1")
    mask = np.asarray(mask, dtype=bool)
    check_frame_memory(scene, planes=4 if stride > 1 else 1)
    renderer = make_renderer(scene, height, albedo, mask)
    first = max(1, samples // 2)
    second = samples - first
    seeds = (seed, seed + _SECOND_HALF_SEED)
    rows = scene.camera.height
    indirect = np.empty(images.shape, dtype=np.float32)
    noise_energy = np.zeros(mask.shape)
    sums = _Sums(scene.floor is not None)
    if stride > 1:
        halves = [_sparse_frame(renderer, mask, bounces, count, half_seed, stride) for count, half_seed in zip((first, second), seeds) if count]
    chunk = max(1, rows // 32)
    for start in range(0, rows, chunk):
        stop = min(rows, start + chunk)
        if stride == 1:
            planes = renderer.render_rows(start, stop, bounces, first, DIRECT_SAMPLES, seeds[0], False)
            direct, parts = planes[0], [planes[1]]
            if second:
                parts.append(renderer.render_rows(start, stop, bounces, second, 0, seeds[1], False)[0])
        else:
            direct = renderer.render_rows(start, stop, 0, 1, DIRECT_SAMPLES, seed, False)[0]
            parts = [half[:, start:stop] for half in halves]
        counts = (first, second)[: len(parts)]
        indirect[:, start:stop] = sum(count * part for count, part in zip(counts, parts)) / samples
        if len(parts) == 2:
            # Var(mean of halves of n1, n2 paths) = (n1 n2 / n²)·E|A − B|² for per-path variance shared.
            spread = np.square(parts[0] - parts[1], dtype=np.float64).sum(axis=(0, 3))
            noise_energy[start:stop] = spread * first * second / samples**2
        sums.add(direct, parts, indirect[:, start:stop], images[:, start:stop], mask[start:stop], None if usable is None else usable[:, start:stop])
    return Rerendering(indirect=indirect, residual=sums.residual(), noise_energy=noise_energy)


def compared_observations(
    images: np.ndarray, irradiance: np.ndarray, mask: np.ndarray, *, robust: bool, shadow_fraction: float, saturation: float | None
) -> np.ndarray:
    """The observations the residual compares: bool (K, H, W, 1).

    On the object, those photometric stereo fits (`irtps.ps.photometric_stereo`'s rule: in
    robust mode, not in shadow, i.e. a channel sum over the irradiance above
    `shadow_fraction` of the pixel's brightest, and not saturated); around it, every
    observation that is not saturated.

    Examples
    --------
    >>> import numpy as np
    >>> images = np.array([1.0, 0.5, 0.01]).reshape(3, 1, 1, 1) * np.ones((3, 1, 2, 3))
    >>> kept = compared_observations(images, np.ones((3, 3)), np.array([[True, False]]),
    ...                              robust=True, shadow_fraction=0.05, saturation=None)
    >>> kept[:, 0, :, 0].tolist()  # the dark observation is left out on the object only
    [[True, True], [True, True], [False, True]]
    """
    images = check_array("images", images, (None, None, None, 3), dtype=None)
    mask = check_mask(mask, images.shape[1:3], match="images")
    usable = np.ones((*images.shape[:3], 1), dtype=bool)
    if saturation is not None:
        usable &= ~(images >= saturation).any(axis=-1, keepdims=True)
    if robust:
        usable &= _lit(images, irradiance, shadow_fraction) | ~mask[None, :, :, None]
    return usable


def _lit(images: np.ndarray, irradiance: np.ndarray, shadow_fraction: float) -> np.ndarray:
    """Photometric stereo's rule for a lit observation (`irtps.ps.photometric_stereo`): its
    channels over their irradiance, summed, above `shadow_fraction` of the pixel's
    brightest. bool (K, H, W, 1) for (K, H, W, 3) images."""
    brightness = (images / np.asarray(irradiance, dtype=np.float32)[:, None, None, :]).sum(axis=-1, keepdims=True, dtype=np.float32)
    return brightness > shadow_fraction * brightness.max(axis=0, keepdims=True)


def _sparse_frame(renderer, mask: np.ndarray, bounces: int, samples: int, seed: int, stride: int) -> np.ndarray:
    """The inter-reflected light of the object and of its surroundings, each rendered
    sparsely and interpolated on its own (no blending across the mask's edge)."""
    frame = render_sparse(renderer, mask, bounces, samples, seed, stride)
    if (~mask).any():
        frame += render_sparse(renderer, ~mask, bounces, samples, seed, stride)
    return frame


class _Sums:
    """Running sums of |rendered − observed| and |observed| on the object and around it,
    for the full estimate and for each half of the paths."""

    def __init__(self, surroundings: bool) -> None:
        self.surroundings = surroundings
        self.object = np.zeros(2)
        self.around = np.zeros(2)
        self.halves = np.zeros(2)

    def add(self, direct, parts, indirect, observed, mask, usable) -> None:
        keep = np.broadcast_to(mask[None, :, :, None], observed.shape)
        if usable is not None:
            keep = keep & usable
        self.object += _difference(direct + indirect, observed, keep)
        if len(parts) == 2:
            self.halves += [_difference(direct + part, observed, keep)[0] for part in parts]
        if self.surroundings:
            around = np.broadcast_to(~mask[None, :, :, None], observed.shape)
            self.around += _difference(direct + indirect, observed, around if usable is None else around & usable)

    def residual(self) -> Residual:
        scale = max(self.object[1], np.finfo(float).tiny)
        around = self.around[0] / self.around[1] if self.surroundings and self.around[1] > 0 else None
        noise = abs(self.halves[0] - self.halves[1]) / scale / 2
        return Residual(object=float(self.object[0] / scale), surroundings=None if around is None else float(around), noise=float(noise))


def _difference(rendered: np.ndarray, observed: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """[Σ|rendered − observed|, Σ|observed|] over `keep`."""
    return np.array([float(np.abs(rendered - observed)[keep].sum()), float(np.abs(observed)[keep].sum())])
