"""IRT-PS: remove inter-reflections by ray tracing the recovered surface, and iterate.

Each pass is one `irtps.irt.pipeline.reconstruction_pass` (photometric stereo, integration,
placement); pass 0, on the input images A₀, is classic photometric stereo. After each pass the
reconstruction (height, albedo, placement) is rendered again in its known surroundings:
the light that reaches the camera after 1..r bounces (every path serves all K lights),
filtered along the surface (`irtps.render.denoise`), is the next estimate of the inter-reflections,
and the rendering's residual against A₀ (`irtps.render.residual`) says how well the pass explains
its images. The next pass fits the corrected images A₀ − Eₜ − Sₜ, where Sₜ is the light of
the floor and box that the object's edge pixels see past the object's last triangles
(`irtps.render.surroundings`), rendered from the same reconstruction where it does not hinge on
sub-pixel detail. The result is the pass with the lowest residual, pass 0 included: IRT-PS
never returns worse than classic photometric stereo by its own measure.

When the data set's irradiance is relative, the reconstruction is rendered with the
reflectance and irradiance of the albedo scale estimated at pass 0 (`irtps.render.radiometry`).

The estimate Eₜ moves toward each new rendering by a step that adapts to how the loop
converges (a secant estimate of its contraction): above 1 where the estimates converge
slowly in one direction, below 1 where they oscillate. The loop stops after two passes in a
row whose residual does not fall below the best so far beyond its Monte-Carlo noise.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from irtps._shared.checks import check_instance
from irtps.model.data import Dataset, pixel_observations
from irtps.io.dataset_files import MASK_FILE
from irtps.render.denoise import denoise_indirect
from irtps.errors import ArgumentError, DatasetError, IrtpsWarning
from irtps.model.metrics import evaluate
from irtps.model.options import ReconstructOptions
from irtps.irt.paper_estimator import paper_indirect
from irtps.irt.pipeline import (
    Pass,
    choose_dataset_robust,
    fitted_observations,
    reconstruction_pass,
    rendered_as,
    resolve_options,
    timed,
)
from irtps.geometry.placement import Placement
from irtps.ps.fit import PsResult
from irtps.render.radiometry import AlbedoScale
from irtps.render.residual import Residual, render_with_residual
from irtps.geometry.surface import meshed_blocks
from irtps.render.surroundings import surroundings_light

__all__ = ["InterreflectionResult", "Iteration", "check_traceable", "remove_interreflections"]

#: Bounds of the adaptive step toward each new estimate. Above 2 the Monte-Carlo noise of
#: the estimates would grow without bound; the upper bound keeps it within √3 of one
#: estimate's.
STEP_BOUNDS = (0.5, 1.9)
#: A pass improves on the best so far when its residual is lower by this many standard
#: deviations of its Monte-Carlo noise.
SIGNIFICANCE = 2.0
#: The loop stops after this many passes in a row that do not improve on the best (one
#: is not enough: an over-relaxed step can raise the residual once on the way down).
PATIENCE = 2


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


@dataclass
class InterreflectionResult:
    """The chosen pass (lowest residual): its fit, albedo (`irtps.geometry.surface.surface_albedo`
    of its fit), placed height, the estimate subtracted from the object's pixels to get its
    images ((K, N, 3) at the mask's N pixels, row-major: the inter-reflections and, in edge
    pixels, the surroundings' light, `irtps.render.surroundings`; None for pass 0), the placement,
    the albedo scale it rendered with, and every pass's record; and pass 0's fit (classic
    photometric stereo's, of the images as they are)."""

    fit: PsResult
    albedo: np.ndarray
    height: np.ndarray
    indirect: np.ndarray | None
    history: list[Iteration]
    placement: Placement
    first_fit: PsResult
    chosen: int = 0
    albedo_scale: AlbedoScale | None = None


def remove_interreflections(
    dataset: Dataset,
    options: ReconstructOptions | None = None,
    *,
    progress: bool = False,
    **settings,
) -> InterreflectionResult:
    """Run the IRT-PS loop on a data set.

    Parameters
    ----------
    dataset : Dataset
        Images, lights, mask and the known surroundings (floor, Cornell box) of the scene.
    options : ReconstructOptions, optional
        The settings (`irtps.model.options.ReconstructOptions`); its ``method`` is ignored. Those
        of the loop:

        - ``bounces``: number r of inter-reflection bounces estimated (1, 2 or 3 in the
          paper);
        - ``iterations``: largest number of corrections;
        - ``samples``: camera paths per pixel of each indirect estimate;
        - ``seed``: seed of the first estimate; pass t uses ``seed + t``;
        - ``albedo_scale``: ``"auto"`` estimates the factor from fitted albedo to
          reflectance at pass 0 when the irradiance is relative (`irtps.render.radiometry`), 1
          otherwise; a number gives it;
        - ``base_height``: ``"auto"`` estimates the placement from the floor around the
          object at pass 0 (`irtps.render.placement`) and refines it as the shape changes;
          ``"boundary"`` or a number as for `irtps.reconstruct`;
        - ``relaxation``: ``"auto"`` adapts the step toward each new estimate (see the
          module); a number in (0, 2) fixes it (1 takes each new estimate whole);
        - ``early_stop``: stop after two passes in a row whose residual does not fall
          below the best so far by twice its Monte-Carlo noise;
        - ``denoise``: filter each estimate along the surface before subtracting it
          (`irtps.render.denoise.denoise_indirect`);
        - ``update``: ``"original"``: Aₜ₊₁ = A₀ − Eₜ − Sₜ (default; Sₜ the surroundings'
          light in the edge pixels, with the ``"physical"`` estimator only);
          ``"previous"``: the paper's literal Aₜ₊₁ = Aₜ − Eₜ. Corrected images are kept
          non-negative;
        - ``integration``: default ``"footprint"``, which keeps creases, and so the
          rendered concavities as deep as the real ones;
        - ``robust``: ``"auto"`` picks the mode once, from the input images
          (`irtps.ps.fit.choose_robust`), and every pass fits with it;
        - ``stride``: 1 estimates the indirect light at every pixel; s > 1 at one pixel in
          s×s, interpolated to the rest (faster, slightly less accurate; see
          `irtps.render.renderer.render_indirect`);
        - ``estimator``: ``"physical"``: the renderer's estimate of bounces 1..r for every
          light (default); ``"paper"``: the paper's environment-colour heuristic
          (`irtps.irt.paper_estimator`), for comparison.
    progress : bool
        Show a progress bar.
    **settings
        Fields of `ReconstructOptions` that replace those of `options`.

    Returns
    -------
    InterreflectionResult
        The pass with the lowest residual.

    Warns
    -----
    IrtpsWarning
        When that is pass 0 (classic photometric stereo).

    Raises
    ------
    OptionError
        Naming the option, for a value out of range.
    DatasetError or ArgumentError
        If the mask has no 2×2 block of object pixels (`check_traceable`).
    """
    check_traceable(dataset)
    options = resolve_options(dataset, ReconstructOptions.build(options, method="irtps", **settings))
    if options.robust == "auto":
        options, _ = choose_dataset_robust(dataset, options)
    scene, mask = dataset.scene, dataset.mask
    original = dataset.images
    # After pass 0, the loop holds the mask's pixels only: photometric stereo fits nothing else.
    observed = pixel_observations(original, mask)
    saturated: np.ndarray | None = (
        None if options.saturation is None else np.any(observed >= options.saturation, axis=-1, keepdims=True)
    )
    usable = fitted_observations(dataset, options)
    images = original
    estimate_used: np.ndarray | None = None
    subtracted: np.ndarray | None = None
    coverage: np.ndarray | None = None
    step = 1.0 if options.relaxation == "auto" else float(options.relaxation)
    steps = _AdaptiveStep()
    previous_change: np.ndarray | None = None
    previous: Pass | None = None
    best: tuple[Residual, int, Pass, np.ndarray | None] | None = None
    stalled = 0
    history: list[Iteration] = []
    first_fit: PsResult | None = None
    with tqdm(total=options.iterations + 1, desc="IRT-PS", unit="pass", disable=not progress, leave=False) as bar:
        for index in range(options.iterations + 1):
            current = reconstruction_pass(
                dataset, images, options, previous=previous, usable=usable, rendered=True, coverage=coverage
            )
            if index == 0:
                first_fit = current.fit
            timings = current.timings
            render_scene, render_albedo = rendered_as(scene, current.albedo, current.albedo_scale)
            seed = options.seed + index
            with timed(timings, "rendering"):
                rerendering = render_with_residual(
                    render_scene,
                    current.height,
                    render_albedo,
                    mask,
                    original,
                    bounces=options.bounces,
                    samples=options.samples,
                    seed=seed,
                    stride=options.stride,
                    usable=usable,
                )
            residual = rerendering.residual
            change = None if previous is None else float(np.abs(current.height - previous.height)[mask].mean())
            metrics = None
            if dataset.gt is not None:
                metrics = evaluate(
                    mask=mask, normals=current.fit.normals, albedo=current.albedo, height=current.height, gt=dataset.gt
                ).to_dict()
            record = Iteration(
                index=index,
                height_change=change,
                residual=residual.to_dict(),
                base_height=current.placement.base_height,
                timings=timings,
                metrics=metrics,
            )
            history.append(record)
            improved = best is None or residual.object < best[0].object - SIGNIFICANCE * residual.noise
            stalled = 0 if improved else stalled + 1
            if best is None or residual.object < best[0].object:
                best = (residual, index, current, subtracted)
            bar.update(1)
            bar.set_postfix(_postfix(residual, metrics), refresh=False)
            if index == options.iterations or (options.early_stop and stalled == PATIENCE):
                break
            if options.estimator == "paper":
                estimate, estimate_noise = (
                    paper_indirect(
                        render_scene, current.height, render_albedo, mask, reflections=options.bounces, seed=seed
                    )[:, mask],
                    0.0,
                )
            else:
                estimate, noise_energy = rerendering.indirect, rerendering.noise_energy
                if options.denoise:
                    with timed(timings, "denoise"):
                        estimate, noise_energy = denoise_indirect(
                            estimate, noise_energy, current.height, render_albedo, mask, scene.camera.pixel_size
                        )
                estimate_noise = float(noise_energy.sum())
            del rerendering
            if options.update == "original":
                if estimate_used is None or previous_change is None:
                    change_of_estimate, taken = estimate, 1.0
                else:
                    change_of_estimate = estimate - estimate_used
                    if options.relaxation == "auto":
                        step = steps.next(change_of_estimate, previous_change)
                    taken = step
                record.step = taken
                steps.taken(taken, estimate_noise)
                estimate_used = estimate if estimate_used is None else estimate_used + taken * change_of_estimate
                previous_change = change_of_estimate
                subtracted = estimate_used
                if options.estimator == "physical":
                    with timed(timings, "surroundings"):
                        seen = surroundings_light(render_scene, current.height, render_albedo, mask, seed=seed)
                    if seen.corrected.any():
                        subtracted = estimate_used + seen.light
                    coverage = seen.coverage(mask) if seen.corrected.any() else None
                images = _corrected(observed, subtracted, observed, saturated)
            else:
                record.step = step
                estimate_used = subtracted = step * estimate
                images = _corrected(observed if index == 0 else images, estimate_used, observed, saturated)
            previous = current
    assert best is not None and first_fit is not None, "the loop runs at least one pass"
    residual, chosen, chosen_pass, subtracted = best
    if chosen == 0 and len(history) > 1:
        warnings.warn(
            f"IRT-PS: no pass explained the images better than classic photometric stereo (residual {residual.object:.4f}); "
            "the result is classic photometric stereo's",
            IrtpsWarning,
            stacklevel=2,
        )
    return InterreflectionResult(
        fit=chosen_pass.fit,
        albedo=chosen_pass.albedo,
        height=chosen_pass.height,
        indirect=subtracted,
        history=history,
        placement=chosen_pass.placement,
        chosen=chosen,
        albedo_scale=chosen_pass.albedo_scale,
        first_fit=first_fit,
    )


def check_traceable(dataset: Dataset) -> None:
    """Refuse a data set whose mask makes no surface to trace.

    The reconstruction is rendered as the contract's surface (§2): two triangles for each
    2×2 block of object pixels. A mask with no such block (one pixel, a checkerboard, a line
    one pixel wide) makes no triangle, so nothing casts a shadow or reflects light, and every
    pass would be classic photometric stereo, or worse where the surroundings' light is
    subtracted from pixels that keep no light of the object. Classic photometric stereo fits
    such a mask pixel by pixel.

    Raises
    ------
    DatasetError
        Naming the mask file of a data set read from a folder.
    ArgumentError
        Naming ``dataset.mask`` where no mask file holds it (a data set made in memory).

    Examples
    --------
    >>> import numpy as np
    >>> from irtps.render.synth import synthesize
    >>> data, _ = synthesize("cap", size=16, lights=4, bounces=0, environment="none")
    >>> data.mask = np.eye(16, dtype=bool)
    >>> check_traceable(data)
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: dataset.mask: no 2x2 block of object pixels: IRT-PS traces the surface of the mask's 2x2 blocks (two triangles each) and this mask makes none; classic photometric stereo (--method ps) fits it pixel by pixel
    """
    check_instance("dataset", dataset, Dataset)
    if meshed_blocks(dataset.mask).any():
        return
    problem = (
        "no 2x2 block of object pixels: IRT-PS traces the surface of the mask's 2x2 blocks (two triangles each) and this mask makes none; "
        "classic photometric stereo (--method ps) fits it pixel by pixel"
    )
    mask_file = None if dataset.source is None else Path(dataset.source) / MASK_FILE
    if mask_file is None or not mask_file.is_file():
        raise ArgumentError("dataset.mask", problem)
    raise DatasetError(f"{mask_file}: {problem}")


def _postfix(residual: Residual, metrics: dict | None) -> dict:
    """The progress bar's figures: the residual, and the error when ground truth is known."""
    postfix = {"residual": f"{residual.object:.4f}"}
    if metrics is not None and metrics.get("normal_mean_angular_deg") is not None:
        postfix["error"] = f"{metrics['normal_mean_angular_deg']:.2f}°"
    return postfix


class _AdaptiveStep:
    """The step toward each new estimate, from how much of the last change remains.

    For a fixed-point map that contracts by ρ, a step ω leaves a fraction q = 1 − ω(1 − ρ)
    of each change in the next; q = <change, previous> / |previous|² (on the object's
    pixels) gives 1 − ρ, and the step that would have removed it all is ω / (1 − q),
    within `STEP_BOUNDS`. Where the previous change is not above its noise, the loop has
    settled within that noise, and the step averages the running and the new estimate, each
    weighed by its inverse noise (within `STEP_BOUNDS`): a step of 1 there took the whole
    noise of one new estimate, and on pedestal_cornell the error jumped by 0.2° in the
    pass after each such step. Where the change grew, nothing says how the loop contracts,
    and the step is 1 (a plain fixed-point iteration). Both products are corrected for the Monte-Carlo noise of the estimates,
    which would otherwise pull q toward 0 (or below) once the changes are mostly noise: the
    noise energy of each new estimate is measured (its two halves), and that of the running
    estimate follows from the steps taken.
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


def _corrected(
    images: np.ndarray, estimate: np.ndarray, original: np.ndarray, saturated: np.ndarray | None
) -> np.ndarray:
    """``images − estimate``, clipped at 0, with the observations saturated in `original` put
    back as they were; one new array, the rest in place."""
    corrected = images - estimate
    np.maximum(corrected, 0.0, out=corrected)
    if saturated is not None:
        np.copyto(corrected, original, where=saturated)
    return corrected
