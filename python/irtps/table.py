"""The IRT-PS paper's comparison table: classic PS against IRT-PS with 1, 2 and 3 bounces."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from irtps.dataset import Dataset
from irtps.errors import IrtpsError
from irtps.evaluate import evaluate
from irtps.paper_estimator import PAPER_SCALE
from irtps.reconstruct import Reconstruction, reconstruct

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
    return ["PS"] + [f"IRTPSr{r}" for r in bounces] + ([f"Paper-r{r}" for r in bounces if r in PAPER_SCALE] if paper else [])


def _runs(bounces: Sequence[int], paper: bool) -> list[tuple[str, dict | None]]:
    """(column, reconstruct settings) for each column; None is classic PS."""
    runs: list[tuple[str, dict | None]] = [("PS", None)]
    runs += [(f"IRTPSr{r}", {"bounces": r}) for r in bounces]
    if paper:
        runs += [(f"Paper-r{r}", {"bounces": r, "estimator": "paper", "update": "previous"}) for r in bounces if r in PAPER_SCALE]
    return runs


def comparison_table(
    datasets: Sequence[tuple[str, Dataset]],
    *,
    bounces: Sequence[int] = (1, 2, 3),
    iterations: int = 8,
    samples: int = 256,
    seed: int = 0,
    paper: bool = True,
    on_result: Callable[[str, str, Reconstruction], None] | None = None,
) -> dict:
    """Reconstruct each data set with classic PS and IRT-PS r1..r3 and collect the errors.

    Parameters
    ----------
    datasets : sequence of (name, Dataset)
        Data sets with ground truth.
    bounces : sequence of int
        The IRT-PS variants (bounces estimated).
    iterations, samples, seed
        IRT-PS settings, as for `irtps.reconstruct`.
    paper : bool
        Also run the paper's own estimator (`irtps.paper_estimator`) with its own update
        Aₜ₊₁ = Aₜ − Eₜ, for each bounce count it takes.
    on_result : callable, optional
        Called as ``on_result(name, method, reconstruction)`` after each reconstruction
        (e.g. to save it or to advance a progress bar).

    Returns
    -------
    dict
        ``{"methods": [...], "rows": [...], "datasets": {name: {method: metrics}},
        "overall": {method: metrics}}``, metrics being `irtps.evaluate.Metrics.to_dict`;
        the overall value of a metric is its mean over the data sets that have it.
    """
    if not datasets:
        raise IrtpsError("datasets: none given")
    methods = method_names(bounces, paper)
    per_dataset: dict[str, dict[str, dict]] = {}
    for name, data in datasets:
        if data.gt is None:
            raise IrtpsError(f"{name}: has no ground truth to compare with")
        per_dataset[name] = {}
        for method, settings in _runs(bounces, paper):
            if settings is None:
                result = reconstruct(data, "ps")
            else:
                result = reconstruct(data, "irtps", iterations=iterations, samples=samples, seed=seed, **settings)
            metrics = evaluate(mask=result.mask, normals=result.normals, albedo=result.albedo, height=result.height, gt=data.gt)
            per_dataset[name][method] = metrics.to_dict()
            if on_result is not None:
                on_result(name, method, result)
    overall = {}
    for method in methods:
        overall[method] = {}
        for _, key in ROWS:
            values = [per_dataset[name][method][key] for name in per_dataset if per_dataset[name][method][key] is not None]
            overall[method][key] = float(np.mean(values)) if values else None
    return {"methods": methods, "rows": [key for _, key in ROWS], "datasets": per_dataset, "overall": overall}


def format_table(table: dict) -> str:
    """The table as markdown, in the layout of the paper's Table 1; the best value of each
    row is in bold."""
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
    return "\n".join(lines).rstrip() + "\n"
