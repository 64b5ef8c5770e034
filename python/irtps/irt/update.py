"""The two strategies of each IRT-PS step: the estimator of the inter-reflections
(`estimate_indirect`) and the update of the images the next pass fits (`update_images`).

The estimator (``options.estimator``) is the renderer's estimate of bounces 1..r for every
light (``"physical"``), filtered along the surface (`irtps.render.denoise`), or the paper's
environment-colour heuristic (``"paper"``, `irtps.irt.paper_estimator`). The update
(``options.update``) subtracts from the input images A₀ a running estimate Eₜ, moved toward
each new one by a step (`irtps.irt.relaxation`), and in the edge pixels the surroundings'
light Sₜ (``"original"``: Aₜ₊₁ = A₀ − Eₜ − Sₜ), or subtracts each new estimate from the
last images (``"previous"``: the paper's Aₜ₊₁ = Aₜ − Eₜ).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irtps.irt.loop_state import LoopState
from irtps.irt.paper_estimator import paper_indirect
from irtps.irt.pipeline import timed
from irtps.model.options import ReconstructOptions
from irtps.model.scene import Scene
from irtps.render.denoise import denoise_indirect
from irtps.render.residual import Rerendering
from irtps.render.surroundings import surroundings_light

__all__ = ["RenderedPass", "corrected", "estimate_indirect", "update_images"]


@dataclass(frozen=True)
class RenderedPass:
    """One pass's reconstruction as it is rendered: the scene (with the albedo scale's
    irradiance), the placed height, the reflectance, the mask and the pass's seed."""

    scene: Scene
    height: np.ndarray
    albedo: np.ndarray
    mask: np.ndarray
    seed: int


def estimate_indirect(
    options: ReconstructOptions, rendered: RenderedPass, rerendering: Rerendering, timings: dict[str, float]
) -> tuple[np.ndarray, float]:
    """The estimate of the inter-reflections in the object's pixels ((K, N, 3) at the mask's N
    pixels, row-major) made from one pass, and its Monte-Carlo noise energy (0 for the
    paper's estimator, which is not Monte Carlo)."""
    if options.estimator == "paper":
        paper = paper_indirect(
            rendered.scene,
            rendered.height,
            rendered.albedo,
            rendered.mask,
            reflections=options.bounces,
            seed=rendered.seed,
        )
        return paper[:, rendered.mask], 0.0
    estimate, noise_energy = rerendering.indirect, rerendering.noise_energy
    if options.denoise:
        with timed(timings, "denoise"):
            estimate, noise_energy = denoise_indirect(
                estimate,
                noise_energy,
                rendered.height,
                rendered.albedo,
                rendered.mask,
                rendered.scene.camera.orthographic_pixel_size,
            )
    return estimate, float(noise_energy.sum())


def update_images(
    state: LoopState,
    options: ReconstructOptions,
    rendered: RenderedPass,
    estimate: np.ndarray,
    estimate_noise: float,
    timings: dict[str, float],
) -> float:
    """Move `state` to the images the next pass fits, given the new `estimate` (of noise
    energy `estimate_noise`) made from the pass `rendered`; return the step taken."""
    if options.update == "previous":
        state.estimate = state.subtracted = state.step * estimate
        last = state.observed if state.previous is None else state.images
        state.images = corrected(last, state.estimate, state.observed, state.saturated)
        return state.step
    if state.estimate is None or state.previous_change is None:
        change, taken = estimate, 1.0
    else:
        change = estimate - state.estimate
        if options.relaxation == "auto":
            state.step = state.steps.next(change, state.previous_change)
        taken = state.step
    state.steps.taken(taken, estimate_noise)
    state.estimate = estimate if state.estimate is None else state.estimate + taken * change
    state.previous_change = change
    state.subtracted = state.estimate
    if options.estimator == "physical":
        with timed(timings, "surroundings"):
            seen = surroundings_light(
                rendered.scene, rendered.height, rendered.albedo, rendered.mask, seed=rendered.seed
            )
        if seen.corrected.any():
            state.subtracted = state.estimate + seen.light
        state.coverage = seen.coverage(rendered.mask) if seen.corrected.any() else None
    state.images = corrected(state.observed, state.subtracted, state.observed, state.saturated)
    return taken


def corrected(
    images: np.ndarray, estimate: np.ndarray, original: np.ndarray, saturated: np.ndarray | None
) -> np.ndarray:
    """``images − estimate``, clipped at 0, with the observations saturated in `original` put
    back as they were; one new array, the rest in place."""
    result = images - estimate
    np.maximum(result, 0.0, out=result)
    if saturated is not None:
        np.copyto(result, original, where=saturated)
    return result
