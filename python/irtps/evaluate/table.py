"""The IRT-PS paper's comparison table: classic PS against IRT-PS with 1, 2 and 3 bounces."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from irtps.model.data import Dataset
from irtps.errors import ArgumentError
from irtps.model.metrics import evaluate
from irtps.io.image_selection import format_images_fitted
from irtps.model.options import PAPER_BOUNCES, ReconstructOptions, TableOptions
from irtps.irt.reconstruct import Reconstruction, reconstruct

#: Rows of the table: (label, metric key); lower is better for all of them.
ROWS = (
    ("Height", "height_error"),
    ("Height (aligned)", "height_error_aligned"),
    ("Albedo", "albedo_error"),
    ("Normal", "normal_component_error"),
    ("Angular (°)", "normal_mean_angular_deg"),
)


def method_names(bounces: Sequence[int], paper: bool = True) -> list[str]:
    """Column names: ``PS``, ``IRTPSr1`` … for each bounce count, then (with `paper`) the
    paper's estimator ``Paper-r1`` … for the counts it takes (1 to 3)."""
    return (
        ["PS"]
        + [f"IRTPSr{r}" for r in bounces]
        + ([f"Paper-r{r}" for r in bounces if r in PAPER_BOUNCES] if paper else [])
    )


def _runs(options: TableOptions) -> list[tuple[str, ReconstructOptions]]:
    """(column, reconstruction options) for each column."""
    irtps = ReconstructOptions(
        method="irtps", iterations=options.iterations, samples=options.samples, seed=options.seed
    )
    runs = [("PS", ReconstructOptions(method="ps"))]
    runs += [(f"IRTPSr{r}", dataclasses.replace(irtps, bounces=r)) for r in options.bounces]
    if options.paper:
        runs += [
            (f"Paper-r{r}", dataclasses.replace(irtps, bounces=r, estimator="paper", update="previous"))
            for r in options.bounces
            if r in PAPER_BOUNCES
        ]
    return runs


def comparison_table(
    datasets: Sequence[tuple[str, Dataset]],
    options: TableOptions | None = None,
    *,
    on_result: Callable[[str, str, Reconstruction], None] | None = None,
    **settings,
) -> dict:
    """Reconstruct each data set with classic PS and IRT-PS r1..r3 and collect the errors.

    Parameters
    ----------
    datasets : sequence of (name, Dataset)
        Data sets with ground truth, under distinct names.
    options : TableOptions, optional
        The IRT-PS variants (``bounces``: the bounce counts estimated) and their
        ``iterations``, ``samples`` and ``seed``; ``paper`` also runs the paper's own
        estimator (`irtps.irt.paper_estimator`) with its own update Aₜ₊₁ = Aₜ − Eₜ, for each
        bounce count it takes. Default `irtps.model.options.TableOptions`'s defaults.
    on_result : callable, optional
        Called as ``on_result(name, method, reconstruction)`` after each reconstruction
        (e.g. to save it or to advance a progress bar).
    **settings
        Fields of `TableOptions` that replace those of `options`.

    Returns
    -------
    dict
        ``{"methods": [...], "rows": [...], "datasets": {name: {method: metrics}},
        "overall": {method: metrics}, "images_fitted": {name: count}, "excluded_images":
        {name: [file names]}}``, metrics being `irtps.model.metrics.Metrics.to_dict`; the
        overall value of a metric is its mean over the data sets that have it; the images
        each data set fitted and those it left out (`irtps.exclude_images`).

    Raises
    ------
    ArgumentError
        Naming ``datasets``: none, two under one name, or one without ground truth;
        `OptionError` for an option out of range.
    """
    options = TableOptions.build(options, **settings)
    if not datasets:
        raise ArgumentError("datasets", "none given")
    names = [name for name, _ in datasets]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ArgumentError(
            "datasets", f"the name {repeated[0]!r} is given to more than one data set (names must be distinct)"
        )
    methods = method_names(options.bounces, options.paper)
    per_dataset: dict[str, dict[str, dict]] = {}
    for name, data in datasets:
        if data.gt is None:
            raise ArgumentError("datasets", f"{name} has no ground truth to compare with")
        per_dataset[name] = {}
        for method, run in _runs(options):
            result = reconstruct(data, options=run)
            metrics = evaluate(
                mask=result.mask, normals=result.normals, albedo=result.albedo, height=result.height, gt=data.gt
            )
            per_dataset[name][method] = metrics.to_dict()
            if on_result is not None:
                on_result(name, method, result)
    overall: dict[str, dict] = {}
    for method in methods:
        overall[method] = {}
        for _, key in ROWS:
            values = [
                per_dataset[name][method][key] for name in per_dataset if per_dataset[name][method][key] is not None
            ]
            overall[method][key] = float(np.mean(values)) if values else None
    return {
        "methods": methods,
        "rows": [key for _, key in ROWS],
        "datasets": per_dataset,
        "overall": overall,
        "images_fitted": {name: len(data.names) for name, data in datasets},
        "excluded_images": {name: list(data.excluded_images) for name, data in datasets},
    }


def format_table(table: dict) -> str:
    """The table as markdown, in the layout of the paper's Table 1; the best value of each
    row is in bold. Under it, each data set that left images out, and which."""
    methods = table["methods"]
    blocks = [(name, table["datasets"][name]) for name in table["datasets"]]
    if len(blocks) > 1:
        blocks.append(("Overall", table["overall"]))
    lines = []
    for title, results in blocks:
        lines.append(f"| **{title}** | " + " | ".join(methods) + " |")
        lines.append("|---" * (len(methods) + 1) + "|")
        for label, key in ROWS:
            values = [results[m][key] for m in methods]
            present = [v for v in values if v is not None]
            best = min(present) if present else None
            cells = ["n/a" if v is None else (f"**{v:.4g}**" if v == best else f"{v:.4g}") for v in values]
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
        lines.append("")
    text = "\n".join(lines).rstrip() + "\n"
    fitted = table.get("images_fitted", {})
    left_out = [
        f"{name}: {format_images_fitted(fitted[name], excluded)}"
        for name, excluded in table.get("excluded_images", {}).items()
        if excluded
    ]
    return text + "\n" + "\n".join(left_out) + "\n" if left_out else text
