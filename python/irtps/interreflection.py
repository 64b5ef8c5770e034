"""IRT-PS: remove inter-reflections by ray tracing the recovered surface, and iterate.

Stage 0 is the input images A₀. Each iteration then fits photometric stereo to the current
images, integrates the normals into a height map, places it in its known surroundings,
renders the light that reaches the camera after 1..r bounces (every path serves all K
lights), and subtracts that indirect estimate from the images.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from irtps.dataset import Dataset
from irtps.evaluate import evaluate
from irtps.options import ReconstructOptions
from irtps.paper_estimator import paper_indirect
from irtps.pipeline import fit_photometric_stereo, resolve_options, surface_height
from irtps.ps import PsResult
from irtps.render import render_indirect
from irtps.surface import footprint_normals

__all__ = ["InterreflectionResult", "Iteration", "remove_interreflections", "surface_albedo"]

@dataclass
class Iteration:
    """What one pass of the loop measured.

    Attributes
    ----------
    index : int
        0 is classic photometric stereo on the input images.
    height_change : float or None
        Mean absolute change of the height map from the previous pass (world units).
    timings : dict
        Seconds per stage.
    metrics : dict or None
        Errors against ground truth (`irtps.evaluate.Metrics.to_dict`), when present.
    """

    index: int
    height_change: float | None
    timings: dict[str, float] = field(default_factory=dict)
    metrics: dict | None = None


@dataclass
class InterreflectionResult:
    """The last pass's fit, albedo (`surface_albedo` of its fit) and height, the last
    indirect estimate, and the history."""

    fit: PsResult
    albedo: np.ndarray
    height: np.ndarray
    indirect: np.ndarray | None
    history: list[Iteration]


def surface_albedo(albedo_ps: np.ndarray, height: np.ndarray, mask: np.ndarray, pixel_size: float = 1.0) -> np.ndarray:
    """The albedo of the triangulated surface that explains photometric stereo's fit.

    Photometric stereo measures ``ρ·n̄``, with ``n̄`` the mean unit normal over the pixel's
    footprint (`irtps.surface.footprint_normals`); where the surface bends inside a footprint,
    ``|n̄| < 1`` and the fitted albedo reads low (by 30 % on the crease of a right-angled
    V-groove). Rendering the surface with that albedo would darken every bounce off a crease.
    This divides by ``|n̄|`` of the surface `height` (not below 0.5) and clips to [0, 1].

    Parameters
    ----------
    albedo_ps : numpy.ndarray
        (H, W, 3) albedo fitted by photometric stereo.
    height, mask, pixel_size
        The surface, as for `irtps.surface.footprint_normals`.

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3).

    Examples
    --------
    >>> import numpy as np
    >>> height = np.tile(np.abs(np.arange(5.0) - 2), (3, 1))
    >>> fitted = np.full((3, 5, 3), 0.5)
    >>> np.round(surface_albedo(fitted, height, np.ones((3, 5), bool))[1, 1:4, 0].astype(float), 4).tolist()
    [0.5, 0.7071, 0.5]
    """
    length = np.linalg.norm(footprint_normals(height, mask, pixel_size), axis=-1)
    return np.clip(albedo_ps / np.maximum(length, 0.5)[..., None], 0.0, 1.0).astype(np.float32)


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
        The settings (`irtps.options.ReconstructOptions`); its ``method`` is ignored. Those
        of the loop:

        - ``bounces``: number r of inter-reflection bounces estimated (1, 2 or 3 in the
          paper);
        - ``iterations``: largest number of corrections;
        - ``samples``: camera paths per pixel of each indirect estimate;
        - ``seed``: seed of the first estimate; pass t uses ``seed + t``;
        - ``tolerance``: stop when the mean absolute height change falls below it; default
          0.002 pixel sizes;
        - ``relaxation``: fraction of each new indirect estimate taken (1 takes it whole;
          below 1 damps the oscillation that very bright surfaces can cause);
        - ``update``: ``"original"``: Aₜ₊₁ = A₀ − Eₜ (default); ``"previous"``: the paper's
          literal Aₜ₊₁ = Aₜ − Eₜ. Corrected images are kept non-negative;
        - ``integration``: default ``"footprint"``, which keeps creases, and so the
          rendered concavities as deep as the real ones;
        - ``stride``: 1 estimates the indirect light at every pixel; s > 1 at one pixel in
          s×s, interpolated to the rest (faster, slightly less accurate; see
          `irtps.render.render_indirect`);
        - ``estimator``: ``"physical"``: the renderer's estimate of bounces 1..r for every
          light (default); ``"paper"``: the paper's environment-colour heuristic
          (`irtps.paper_estimator`), for comparison.
    progress : bool
        Show a progress bar.
    **settings
        Fields of `ReconstructOptions` that replace those of `options`.

    Returns
    -------
    InterreflectionResult

    Raises
    ------
    OptionError
        Naming the option, for a value out of range.
    """
    options = resolve_options(dataset, ReconstructOptions.build(options, method="irtps", **settings))
    scene, mask = dataset.scene, dataset.mask
    pixel_size = scene.camera.pixel_size
    original = dataset.images
    # Observations saturated in the input stay saturated: subtracting the estimate would bring
    # them under the threshold and into the fit with a clipped value.
    saturated = None if options.saturation is None else (original >= options.saturation).any(axis=-1, keepdims=True)
    images = original
    indirect = None
    previous_height = None
    history: list[Iteration] = []
    with tqdm(total=options.iterations + 1, desc="IRT-PS", unit="pass", disable=not progress, leave=False) as bar:
        for index in range(options.iterations + 1):
            timings = {}
            start = time.perf_counter()
            fit = fit_photometric_stereo(dataset, images, options)
            timings["photometric_stereo"] = time.perf_counter() - start
            start = time.perf_counter()
            height = surface_height(dataset, fit.normals, options)
            timings["integration"] = time.perf_counter() - start
            albedo = surface_albedo(fit.albedo, height, mask, pixel_size)
            change = None if previous_height is None else float(np.abs(height - previous_height)[mask].mean())
            metrics = None
            if dataset.gt is not None:
                metrics = evaluate(mask=mask, normals=fit.normals, albedo=albedo, height=height, gt=dataset.gt).to_dict()
            record = Iteration(index=index, height_change=change, timings=timings, metrics=metrics)
            history.append(record)
            bar.update(1)
            if metrics is not None and metrics.get("normal_mean_angular_deg") is not None:
                bar.set_postfix(error=f"{metrics['normal_mean_angular_deg']:.2f}°", refresh=False)
            if index == options.iterations or (change is not None and change < options.tolerance):
                break
            start = time.perf_counter()
            seed = options.seed + index
            if options.estimator == "paper":
                estimate = paper_indirect(scene, height, albedo, mask, reflections=options.bounces, seed=seed)
            else:
                estimate = render_indirect(scene, height, albedo, mask, bounces=options.bounces, samples=options.samples, seed=seed, stride=options.stride)
            timings["indirect_estimate"] = time.perf_counter() - start
            if options.update == "original":
                indirect = estimate if indirect is None else indirect + options.relaxation * (estimate - indirect)
                images = _corrected(original, indirect, original, saturated)
            else:
                indirect = estimate
                images = _corrected(images, options.relaxation * estimate, original, saturated)
            previous_height = height
    return InterreflectionResult(fit=fit, albedo=albedo, height=height, indirect=indirect, history=history)


def _corrected(images: np.ndarray, estimate: np.ndarray, original: np.ndarray, saturated: np.ndarray | None) -> np.ndarray:
    """``images − estimate``, clipped at 0, with the observations saturated in `original` put
    back as they were; one new array, the rest in place."""
    corrected = images - estimate
    np.maximum(corrected, 0.0, out=corrected)
    if saturated is not None:
        np.copyto(corrected, original, where=saturated)
    return corrected
