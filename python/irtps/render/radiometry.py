"""The radiometric scale: the factor that turns the fitted albedo into reflectance.

When a data set's irradiance is relative (`irtps.Scene.relative_irradiance`; DiLiGenT's
intensities, an uncalibrated rig), image k holds ``ρ E_k (n·l)/π`` for irradiances known
only up to one common factor, and photometric stereo gives ``ρ / c`` for some unknown c. The
direct light does not tell c, but the inter-reflections do: bounce j carries ``c^j`` more
light than a rendering with the fitted albedo predicts. Rendering with albedo ``c × fitted``
and irradiance ``E / c`` gives the direct light unchanged and every bounce right
(`scaled_scene`, `scaled_albedo`).

`estimate_albedo_scale` renders the object (direct light with cast shadows plus bounces
1..r) at a grid of its pixels under a few well-spread lights for each factor tried, and keeps
the factor whose rendering matches the images best, between the one that makes the brightest
albedo 1 (reflectance cannot exceed 1) and 2^-8 of it (nearly no inter-reflection): Brent's
method on the factor's logarithm. When the best factor is at the low end, the images show no
more inter-reflection than the rendering predicts with almost none, and IRT-PS corrects
little. When the rendering does not change with the factor beyond its Monte-Carlo noise (a
convex object without surroundings sends no light to itself), nothing fixes it: the factor
is 1 (the irradiance taken as given) and the reason is recorded.
"""

from __future__ import annotations

import dataclasses
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from irtps.geometry.placement import spread_lights
from irtps.render.renderer import make_renderer
from irtps.model.scene import Scene, emission_of, with_emission

__all__ = [
    "AlbedoScale",
    "absolute_scale",
    "estimate_albedo_scale",
    "format_albedo_scale",
    "scaled_albedo",
    "scaled_scene",
]

#: Lights rendered at most for the estimate (well spread, as for the placement).
MAX_LIGHTS = 8
#: Object pixels rendered at most (a regular grid over the mask).
MAX_PIXELS = 4096
#: Camera paths per pixel for the inter-reflected light, and footprint samples for the
#: direct light; the same random numbers at every factor.
PATH_SAMPLES = 32
DIRECT_SAMPLES = 4
#: The brightest albedo is this percentile of the fitted albedo's largest channel: a few
#: pixels of highlight or noise do not set the range.
BRIGHTEST_PERCENTILE = 99.0
#: The factors searched span this ratio below the largest one.
RANGE = 2.0**8
#: Precision of the estimate, as a ratio.
PRECISION = 1.02
#: The rendering must change over the range by this many times its Monte-Carlo noise.
SIGNIFICANCE = 3.0


@dataclass(frozen=True)
class AlbedoScale:
    """The factor from fitted albedo to reflectance.

    Attributes
    ----------
    factor : float
        Reflectance = ``factor`` × fitted albedo.
    source : str
        ``"absolute"`` (the irradiance is absolute: 1), ``"images"`` (estimated) or
        ``"given"`` (by the user).
    low, high : float or None
        The range searched (``"images"``).
    residual : float or None
        The rendering's relative residual at `factor` on the pixels compared (``"images"``).
    reason : str or None
        Why the images did not fix the factor, when they did not (it is then 1).
    """

    factor: float
    source: str
    low: float | None = None
    high: float | None = None
    residual: float | None = None
    reason: str | None = None

    def to_dict(self) -> dict:
        """The scale as a JSON-ready dict."""
        return asdict(self)


def absolute_scale() -> AlbedoScale:
    """The scale of a data set with absolute irradiance: 1."""
    return AlbedoScale(factor=1.0, source="absolute")


def format_albedo_scale(scale: AlbedoScale | dict) -> str:
    """One line for a person: the factor and where it came from.

    Examples
    --------
    >>> format_albedo_scale(AlbedoScale(0.5, "images", 0.004, 1.1, 0.2))
    'albedo scale 0.5 (estimated from the inter-reflections, searched 0.004 to 1.1)'
    >>> format_albedo_scale({"factor": 1.0, "source": "absolute"})
    'albedo scale 1 (the irradiance is absolute)'
    """
    fields = scale if isinstance(scale, dict) else scale.to_dict()
    text = f"albedo scale {fields['factor']:.3g}"
    if fields.get("reason"):
        return f"{text} ({fields['reason']})"
    if fields["source"] == "images":
        return f"{text} (estimated from the inter-reflections, searched {fields['low']:.3g} to {fields['high']:.3g})"
    return text + (" (the irradiance is absolute)" if fields["source"] == "absolute" else " (given)")


def scaled_scene(scene: Scene, factor: float) -> Scene:
    """`scene` with every light's irradiance divided by `factor` (and marked absolute)."""
    lights = tuple(
        with_emission(light, np.asarray(emission_of(light), dtype=np.float64) / factor) for light in scene.lights
    )
    return dataclasses.replace(scene, lights=lights, relative_irradiance=False)


def scaled_albedo(albedo: np.ndarray, factor: float) -> np.ndarray:
    """The reflectance of a fitted `albedo`: ``factor × albedo`` within [0, 1], float32."""
    return np.clip(np.asarray(albedo, dtype=np.float32) * np.float32(factor), 0.0, 1.0)


def estimate_albedo_scale(
    scene: Scene,
    height: np.ndarray,
    albedo: np.ndarray,
    mask: np.ndarray,
    images: np.ndarray,
    usable: np.ndarray,
    *,
    bounces: int = 3,
    seed: int = 0,
) -> AlbedoScale:
    """Estimate the factor from fitted albedo to reflectance from the inter-reflections.

    Parameters
    ----------
    scene : Scene
        Camera, (relative) lights and surroundings.
    height : numpy.ndarray
        (H, W) the reconstructed heights, placed.
    albedo : numpy.ndarray
        (H, W, 3) the fitted albedo (photometric stereo's, in the units of the irradiance).
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    images : numpy.ndarray
        (K, H, W, 3) the observed images.
    usable : numpy.ndarray
        (K, H, W, 1) bool, the observations to compare
        (`irtps.render.residual.compared_observations`).
    bounces : int
        Inter-reflection bounces rendered.
    seed : int
        Seed of the random numbers (the same at every factor).

    Returns
    -------
    AlbedoScale
        ``source="images"``.

    Examples
    --------
    A V-groove of reflectance 0.8 whose irradiance was recorded at a quarter of its value:
    photometric stereo fits an albedo 4 times too bright, and the inter-reflections tell
    the factor back.

    >>> import numpy as np
    >>> from irtps import Camera, Light, Scene, render
    >>> lights = [Light(direction=(np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)),
    ...                 irradiance=(np.pi,) * 3) for t, a in [(0, 0), (0.6, 0), (0.6, 2), (0.6, 4)]]
    >>> scene = Scene(Camera(24, 24, 1.0), lights)
    >>> mask = np.ones((24, 24), bool)
    >>> height = 2.0 * np.abs(np.arange(24) - 11.5)[None, :] * np.ones((24, 1))
    >>> images = render(scene, height, np.full((24, 24, 3), 0.8), mask, bounces=3, samples=64).images
    >>> relative = Scene(scene.camera, [Light(l.direction, l.irradiance / 4) for l in lights],
    ...                  relative_irradiance=True)
    >>> usable = np.ones((4, 24, 24, 1), bool)
    >>> scale = estimate_albedo_scale(relative, height, np.full((24, 24, 3), 3.2), mask, images, usable)
    >>> round(scale.factor, 2)
    0.25
    """
    mask = np.asarray(mask, dtype=bool)
    albedo = np.asarray(albedo, dtype=np.float32)
    brightest = float(np.percentile(albedo[mask].max(axis=1), BRIGHTEST_PERCENTILE)) if mask.any() else 0.0
    if not brightest > 0:
        return AlbedoScale(
            factor=1.0, source="images", reason="the object is black in every image: nothing fixes the albedo scale"
        )
    high = 1.0 / brightest
    low = high / RANGE
    chosen = spread_lights(scene.nominal_light_directions, MAX_LIGHTS)
    scene = dataclasses.replace(scene, lights=tuple(scene.lights[k] for k in chosen))
    pixels = _grid(mask, MAX_PIXELS)
    observed = np.asarray(images, dtype=np.float32)[chosen].reshape(len(chosen), -1, 3)[:, pixels]
    compared = np.broadcast_to(
        np.asarray(usable, dtype=bool)[chosen].reshape(len(chosen), -1, 1)[:, pixels], observed.shape
    )
    total = float(np.abs(observed[compared]).sum())
    if total <= 0:
        return AlbedoScale(
            factor=1.0,
            source="images",
            reason="no observation of the object to compare: nothing fixes the albedo scale",
        )
    pixel_list = pixels.tolist()
    height = np.asarray(height, dtype=np.float32)

    # One geometry for every factor: only the reflectance and the irradiance change.
    geometry = make_renderer(scene, height, scaled_albedo(albedo, high), mask)

    def rendered(factor: float, path_seed: int) -> np.ndarray:
        renderer = geometry.with_reflectance(
            scaled_albedo(albedo, factor), scaled_scene(scene, factor).light_irradiance.astype(np.float32)
        )
        return renderer.render_pixels(pixel_list, bounces, PATH_SAMPLES, DIRECT_SAMPLES, path_seed, True)

    bounce_powers = _BouncePowers.of(scene, albedo[mask], rendered, seed)

    def residual(log_factor: float, path_seed: int = seed) -> float:
        factor = float(np.exp(log_factor))
        planes = None if path_seed != seed or bounce_powers is None else bounce_powers.at(factor)
        if planes is None:
            planes = rendered(factor, path_seed)
        return float(np.abs(planes.sum(axis=0) - observed)[compared].sum()) / total

    result = minimize_scalar(
        residual, bounds=(np.log(low), np.log(high)), method="bounded", options={"xatol": np.log(PRECISION)}
    )
    # Brent's method never tries the ends of the range: the end is the answer when it is better.
    ends = [(residual(np.log(high)), np.log(high)), (residual(np.log(low)), np.log(low))]
    best_residual, best_log = min([(float(result.fun), float(result.x)), *ends])
    noise = abs(residual(best_log, seed + 1) - best_residual)
    if max(value for value, _ in ends) - best_residual <= SIGNIFICANCE * noise:
        return AlbedoScale(
            factor=1.0,
            source="images",
            low=low,
            high=high,
            reason="the images look the same whatever the albedo scale: no inter-reflection seen",
        )
    return AlbedoScale(factor=float(np.exp(best_log)), source="images", low=low, high=high, residual=best_residual)


@dataclass
class _BouncePowers:
    """A rendering's planes as a polynomial in the albedo factor, where that is exact.

    Scaling the reflectance by f and the irradiance by 1/f leaves the direct light as it is
    and multiplies bounce b by f^b, when every bounce is off the object (no floor or box)
    and no reflectance is clipped at 1 (f at most `unclipped`). The planes rendered once at
    `unclipped`, with the same camera paths as every other factor, then give every such
    factor's without tracing a ray.
    """

    planes: np.ndarray
    unclipped: float

    @classmethod
    def of(cls, scene: Scene, object_albedo: np.ndarray, rendered, seed: int) -> _BouncePowers | None:
        """Render the planes (direct, bounce 1, ..., `rendered(factor, seed)`) where the
        scene allows it; else None."""
        largest = float(object_albedo.max(initial=0.0))
        if scene.floor is not None or scene.environment is not None or not largest > 0:
            return None
        unclipped = 1.0 / largest
        return cls(planes=rendered(unclipped, seed), unclipped=unclipped)

    def at(self, factor: float) -> np.ndarray | None:
        """The planes at `factor`, or None where the polynomial does not hold."""
        if factor > self.unclipped:
            return None
        powers = (factor / self.unclipped) ** np.arange(len(self.planes), dtype=np.float32)
        return self.planes * powers[:, None, None, None]


def _grid(mask: np.ndarray, count: int) -> np.ndarray:
    """Flat indices of the pixels of `mask` on a regular grid of about `count` of them."""
    pixels = np.flatnonzero(mask)
    if len(pixels) <= count:
        return pixels
    step = int(np.ceil(np.sqrt(len(pixels) / count)))
    rows, cols = np.indices(mask.shape)
    return np.flatnonzero(mask & (rows % step == 0) & (cols % step == 0))
