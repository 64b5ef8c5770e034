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
slowly in one direction, below 1 where they oscillate (`irtps.irt.relaxation`). The loop stops
when the residual has not fallen beyond its Monte-Carlo noise over the last two passes (from
the pass two before the last to the last: a single noisy or over-relaxed pass does not stop it),
and before rendering pass 1 where that pass's fit turned the normals by less than half their
standard error (`irtps.irt.early_exit`): there the inter-reflections are below what the images
tell apart, as on a real object alone, and the result is pass 0's.

The loop's state between two passes is a `irtps.irt.loop_state.LoopState`; each step estimates
the inter-reflections and updates the images with the two strategies of `irtps.irt.update`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from irtps._shared.checks import check_instance
from irtps.errors import ArgumentError, DatasetError, IrtpsWarning
from irtps.geometry.placement import Placement
from irtps.geometry.surface import meshed_blocks
from irtps.io.dataset_files import MASK_FILE
from irtps.irt.early_exit import first_correction
from irtps.irt.loop_state import Iteration, LoopState, Stop
from irtps.irt.pipeline import (
    Pass,
    fitted_observations,
    reconstruction_pass,
    rendered_as,
    resolve_options,
    timed,
    with_chosen_robust,
)
from irtps.irt.update import RenderedPass, estimate_indirect, update_images
from irtps.model.data import Dataset, pixel_observations
from irtps.model.metrics import evaluate
from irtps.model.options import ReconstructOptions
from irtps.ps.fit import PsResult
from irtps.render.radiometry import AlbedoScale
from irtps.render.residual import Rerendering, Residual, render_with_residual

__all__ = ["InterreflectionResult", "check_traceable", "remove_interreflections"]


@dataclass
class InterreflectionResult:
    """The chosen pass (lowest residual): its fit, albedo (`irtps.geometry.surface.surface_albedo`
    of its fit), placed height, the estimate subtracted from the object's pixels to get its
    images ((K, N, 3) at the mask's N pixels, row-major: the inter-reflections and, in edge
    pixels, the surroundings' light, `irtps.render.surroundings`; None for pass 0), the placement,
    the albedo scale it rendered with, and every pass's record; pass 0's fit (classic
    photometric stereo's, of the images as they are), the robust mode every pass fitted
    with, and why the loop stopped."""

    fit: PsResult
    albedo: np.ndarray
    height: np.ndarray
    indirect: np.ndarray | None
    history: list[Iteration]
    placement: Placement
    first_fit: PsResult
    chosen: int = 0
    albedo_scale: AlbedoScale | None = None
    robust_used: str | None = None
    stop: Stop | None = None


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
        - ``early_stop``: stop when the residual has not fallen over the last two passes
          by twice its Monte-Carlo noise (`irtps.irt.loop_state.LoopState.stalled_out`),
          or keep pass 0 when pass 1's correction turned the normals by less than half
          their standard error (`irtps.irt.early_exit`);
        - ``denoise``: filter each estimate along the surface before subtracting it
          (`irtps.render.denoise.denoise_indirect`);
        - ``update``: ``"original"``: Aₜ₊₁ = A₀ − Eₜ − Sₜ (default; Sₜ the surroundings'
          light in the edge pixels, with the ``"physical"`` estimator only);
          ``"previous"``: the paper's literal Aₜ₊₁ = Aₜ − Eₜ. Corrected images are kept
          non-negative;
        - ``integration``: default ``"footprint"``, which keeps creases, and so the
          rendered concavities as deep as the real ones;
        - ``robust``: ``"auto"`` lets pass 0's fit of the input images pick the mode
          (`irtps.ps.fit.photometric_stereo`, `irtps.ps.fit.choose_robust`), and every later
          pass fits with it;
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
        The pass with the lowest residual, and why the loop stopped (``stop``).

    Warns
    -----
    IrtpsWarning
        When that is pass 0 (classic photometric stereo): no pass explained the images
        better, or pass 1's correction was below the normals' noise (``stop``).

    Raises
    ------
    OptionError
        Naming the option, for a value out of range.
    DatasetError or ArgumentError
        If the mask has no 2×2 block of object pixels (`check_traceable`).
    """
    check_traceable(dataset)
    options = resolve_options(dataset, ReconstructOptions.build(options, method="irtps", **settings))
    mask = dataset.mask
    # After pass 0, the loop holds the mask's pixels only: photometric stereo fits nothing else.
    observed = pixel_observations(dataset.images, mask)
    state = LoopState(
        observed=observed,
        saturated=None
        if options.saturation is None
        else np.any(observed >= options.saturation, axis=-1, keepdims=True),
        images=dataset.images,
        step=1.0 if options.relaxation == "auto" else float(options.relaxation),
    )
    usable = fitted_observations(dataset, options)
    stop = None
    with tqdm(total=options.iterations + 1, desc="IRT-PS", unit="pass", disable=not progress, leave=False) as bar:
        for index in range(options.iterations + 1):
            current = reconstruction_pass(
                dataset,
                state.images,
                options,
                previous=state.previous,
                usable=usable,
                rendered=True,
                coverage=state.coverage,
            )
            if index == 0:
                # Pass 0 fits the input images; a robust mode "auto" is chosen by that fit
                # (`irtps.ps.fit.photometric_stereo`), and every later pass fits with its choice.
                state.first_fit = current.fit
                options = with_chosen_robust(options, current.fit)
            elif index == 1 and options.early_stop and state.first_fit is not None:
                assert state.previous is not None, "pass 1 follows pass 0"
                state.correction = first_correction(
                    dataset, usable, state.first_fit, current.fit, surface=state.previous.height
                )
                stop = state.correction_stop()
                if stop is not None:
                    break
            record, rendered, rerendering = _render_pass(dataset, options, index, current, state.previous, usable)
            state.history.append(record)
            state.judge(index, current, rerendering.residual)
            bar.update(1)
            bar.set_postfix(_postfix(rerendering.residual, record.metrics), refresh=False)
            stop = state.stop(index, options.iterations, options.early_stop)
            if stop is not None:
                break
            estimate, estimate_noise = estimate_indirect(options, rendered, rerendering, record.timings)
            del rerendering
            record.step = update_images(state, options, rendered, estimate, estimate_noise, record.timings)
            state.previous = current
    best, first_fit = state.best, state.first_fit
    assert best is not None and first_fit is not None, "the loop runs at least one pass"
    if stop is not None and stop.reason == "below_noise":
        warnings.warn(f"IRT-PS: {stop.message}", IrtpsWarning, stacklevel=2)
    elif best.index == 0 and len(state.history) > 1:
        warnings.warn(
            f"IRT-PS: no pass explained the images better than classic photometric stereo (residual {best.residual.object:.4f}); "
            "the result is classic photometric stereo's",
            IrtpsWarning,
            stacklevel=2,
        )
    chosen = best.reconstruction
    return InterreflectionResult(
        fit=chosen.fit,
        albedo=chosen.albedo,
        height=chosen.height,
        indirect=best.subtracted,
        history=state.history,
        placement=chosen.placement,
        chosen=best.index,
        albedo_scale=chosen.albedo_scale,
        first_fit=first_fit,
        robust_used=options.robust,
        stop=stop,
    )


def _render_pass(
    dataset: Dataset, options: ReconstructOptions, index: int, current: Pass, previous: Pass | None, usable: np.ndarray
) -> tuple[Iteration, RenderedPass, Rerendering]:
    """Render pass `index`'s reconstruction in its surroundings: its record (residual, change,
    placement, errors against ground truth), how it was rendered, and the rendering."""
    mask, timings = dataset.mask, current.timings
    scene, albedo = rendered_as(dataset.scene, current.albedo, current.albedo_scale)
    rendered = RenderedPass(scene, current.height, albedo, mask, options.seed + index)
    with timed(timings, "rendering"):
        rerendering = render_with_residual(
            scene,
            current.height,
            albedo,
            mask,
            dataset.images,
            bounces=options.bounces,
            samples=options.samples,
            seed=rendered.seed,
            stride=options.stride,
            usable=usable,
        )
    metrics = None
    if dataset.gt is not None:
        metrics = evaluate(
            mask=mask, normals=current.fit.normals, albedo=current.albedo, height=current.height, gt=dataset.gt
        ).to_dict()
    record = Iteration(
        index=index,
        height_change=None if previous is None else float(np.abs(current.height - previous.height)[mask].mean()),
        residual=rerendering.residual.to_dict(),
        base_height=current.placement.base_height,
        timings=timings,
        metrics=metrics,
    )
    return record, rendered, rerendering


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
