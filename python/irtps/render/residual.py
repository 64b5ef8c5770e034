"""How well a reconstruction explains its images, without ground truth.

A reconstruction (height, albedo, placement) is rendered again in its known surroundings:
direct light with cast shadows plus inter-reflected light after 1..r bounces, under every
light. Its relative residual is the mean absolute difference from the input images over the
mean absolute input, on the object's pixels and, where the scene has a floor, on the
visible surroundings. On the object it compares the observations that photometric stereo
fits (`compared_observations`): a real object's shadows hold light that the Lambertian
rendering of a slightly wrong shape can match by chance, so that a worse shape could seem
to explain them better: on DiLiGenT reading, the residual over every observation fell
from classic photometric stereo to IRT-PS's first pass while the error rose, and the
residual over the fitted observations rose with it (docs/method.md, The residual). The same rendering gives IRT-PS its next estimate of the
inter-reflected light, so the residual costs only the direct image.

The inter-reflected light is rendered as two independent halves of the camera paths; the
residuals of the two halves tell the residual's Monte-Carlo noise, by which IRT-PS decides
that a pass no longer improves on the last.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from irtps import _core
from irtps._shared.checks import check_array, check_mask
from irtps.model.data import observation_brightness, pixel_observations
from irtps.errors import ArgumentError
from irtps.render.renderer import check_counts, check_frame_memory, make_renderer, render_sparse
from irtps.model.environment import MeshEnvironment
from irtps.model.scene import Scene

__all__ = ["Rerendering", "Residual", "compared_observations", "render_with_residual"]

#: Footprint samples per pixel of the direct image the residual compares (stratified; each
#: light's visibility from the renderer's light cache, with a shadow ray only where a
#: shadow's edge crosses the triangle: one ray a light and sample would be 1536 a pixel
#: under 96 lights, more than the camera paths).
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
        saturated); None without a floor or an environment mesh (a rig's: contract §3b).
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
        float32 (K, N, 3), bounces 1..r summed, at the N pixels of the mask (row-major
        order): all that photometric stereo fits.
    residual : Residual
    noise_energy : numpy.ndarray
        float64 (N,): Σ over lights and channels of the Monte-Carlo variance of
        `indirect` at each of those pixels (from its two independent halves; 0 with one
        path).
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
        The reconstruction in its surroundings, as for `irtps.render.renderer.render`.
    images : numpy.ndarray
        (K, H, W, 3) the observed images.
    bounces : int
        Inter-reflection bounces r rendered (1..r).
    samples : int
        Camera paths per pixel for the inter-reflected light.
    seed : int
        Seed of the random numbers.
    stride : int
        As for `irtps.render.renderer.render_indirect`: 1 traces paths at every pixel, s > 1 at one
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
    counts: tuple[int, ...] = (first, samples - first) if samples > first else (first,)
    seeds = (seed, seed + _SECOND_HALF_SEED)
    rendering = _Halves(renderer, bounces, counts, seeds, seed, stride)
    object_pixels = np.flatnonzero(mask)
    observed = pixel_observations(images, mask).astype(np.float32, copy=False)
    compared = None if usable is None else np.ascontiguousarray(pixel_observations(usable, mask)[..., 0])
    indirect = np.empty(observed.shape, dtype=np.float32)
    noise_energy = np.zeros(len(object_pixels))
    sparse = rendering.sparse(mask)
    on_object, halves = np.zeros(2), np.zeros(2)
    for chunk in _chunks(len(object_pixels)):
        direct, parts = rendering.pixels(
            object_pixels[chunk], None if sparse is None else [half[:, chunk] for half in sparse]
        )
        indirect[:, chunk], noise_energy[chunk], sums = _core.compare_rendering(
            direct, parts, counts, observed, compared, chunk.start
        )
        on_object += sums[:2]
        if len(parts) == 2:
            halves += sums[2:]
    del sparse
    scale = max(on_object[1], np.finfo(float).tiny)
    surroundings = None
    if scene.floor is not None or isinstance(scene.environment, MeshEnvironment):
        surroundings = _surroundings_residual(rendering, ~mask, images, usable, counts)
    residual = Residual(
        object=float(on_object[0] / scale),
        surroundings=surroundings,
        noise=float(abs(halves[0] - halves[1]) / scale / 2),
    )
    return Rerendering(indirect=indirect, residual=residual, noise_energy=noise_energy)


def compared_observations(
    images: np.ndarray,
    irradiance: np.ndarray,
    mask: np.ndarray,
    *,
    robust: bool,
    shadow_fraction: float,
    saturation: float | None,
) -> np.ndarray:
    """The observations the residual compares: bool (K, H, W, 1), for images under lights of
    `irradiance` (K, 3), or (K, N, 3) at each of the mask's N pixels (point lights near the
    object).

    On the object, those photometric stereo fits (`irtps.ps.fit.photometric_stereo`'s rule: in
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
    # One image at a time: no temporary the size of the images.
    if saturation is not None:
        for kept, image in zip(usable, images):
            kept[..., 0] = ~(
                (image[..., 0] >= saturation) | (image[..., 1] >= saturation) | (image[..., 2] >= saturation)
            )
    if robust:
        # Shadows are told apart on the object only: around it every observation is kept.
        irradiance = np.asarray(irradiance, dtype=np.float32)
        pixels = np.flatnonzero(mask)
        per_pixel = irradiance if irradiance.ndim == 3 else irradiance[:, None, :]
        brightness = observation_brightness(pixel_observations(images, mask), per_pixel)
        level = shadow_fraction * brightness.max(axis=0, initial=0.0)
        flat = usable.reshape(len(images), -1)
        flat[:, pixels] &= brightness > level
    return usable


class _Halves:
    """Renders pixels as the residual needs them: the direct image, and the inter-reflected
    light of each half of the camera paths (traced, or taken from sparse frames)."""

    def __init__(
        self, renderer, bounces: int, counts: tuple[int, ...], seeds: tuple[int, int], seed: int, stride: int
    ) -> None:
        self.renderer, self.bounces, self.counts, self.seeds, self.seed, self.stride = (
            renderer,
            bounces,
            counts,
            seeds,
            seed,
            stride,
        )

    def sparse(self, pixels: np.ndarray) -> list[np.ndarray] | None:
        """With a stride above 1, each half's inter-reflected light at the listed pixels of
        the bool image `pixels`, rendered sparsely and interpolated: (K, N, 3) each."""
        if self.stride == 1:
            return None
        return [
            render_sparse(self.renderer, pixels, self.bounces, count, half_seed, self.stride)[:, pixels]
            for count, half_seed in zip(self.counts, self.seeds)
        ]

    def pixels(self, pixels: np.ndarray, sparse: list[np.ndarray] | None) -> tuple[np.ndarray, list[np.ndarray]]:
        """(direct (K, n, 3), [each half's inter-reflected light (K, n, 3)]) at the listed
        pixels (flat indices); `sparse` gives the halves when the stride is above 1."""
        listed = pixels.tolist()
        if sparse is not None:
            return self.renderer.render_pixels(listed, 0, 1, DIRECT_SAMPLES, self.seed, False, True)[0], sparse
        planes = self.renderer.render_pixels(
            listed, self.bounces, self.counts[0], DIRECT_SAMPLES, self.seeds[0], False, True
        )
        parts = [planes[1]]
        if len(self.counts) == 2:
            parts.append(self.renderer.render_pixels(listed, self.bounces, self.counts[1], 0, self.seeds[1], False)[0])
        return planes[0], parts


def _surroundings_residual(
    rendering: _Halves, around: np.ndarray, images: np.ndarray, usable: np.ndarray | None, counts: tuple[int, ...]
) -> float | None:
    """The residual over the pixels of the bool image `around`: every observation that is
    not saturated (`usable`); None when there is none."""
    pixels = np.flatnonzero(around)
    sparse = rendering.sparse(around)
    sums = np.zeros(2)
    for chunk in _chunks(len(pixels)):
        direct, parts = rendering.pixels(pixels[chunk], None if sparse is None else [half[:, chunk] for half in sparse])
        rows, cols = np.unravel_index(pixels[chunk], around.shape)
        keep = None if usable is None else usable[:, rows, cols, 0]
        sums += _core.compare_rendering(
            direct, parts, counts, np.asarray(images[:, rows, cols], dtype=np.float32), keep
        )[2][:2]
    return float(sums[0] / sums[1]) if sums[1] > 0 else None


def _chunks(count: int) -> list[slice]:
    """Slices of about a 32nd of `count` items (at least 1024): rendered together, they bound
    the renderer's output buffers."""
    size = max(1024, -(-count // 32))
    return [slice(start, min(count, start + size)) for start in range(0, count, size)]
