"""A batch's summary: the markdown table of its outcome and the files ``batch.json`` and
``batch.md`` in its output folder."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

from irtps._shared.atomic import atomic_write_text
from irtps._shared.records import BATCH, stamp
from irtps.batch.result import BatchResult

__all__ = ["SUMMARY_JSON", "SUMMARY_MARKDOWN", "summary_table", "write_summary"]

SUMMARY_JSON = "batch.json"
SUMMARY_MARKDOWN = "batch.md"


def summary_table(results: Sequence[BatchResult]) -> str:
    """The outcome of a batch as a markdown table: data set, status (with the workers
    lost while they held the data set, if any), seconds, the robust mode of its fit, mean
    angular error (when there is ground truth) and the error of a failed data set.

    Parameters
    ----------
    results : sequence of BatchResult

    Returns
    -------
    str

    Examples
    --------
    >>> print(summary_table([BatchResult("ball", "/d/ball", "ok", 1.25, metrics={"normal_mean_angular_deg": 2.5}, robust_used="tukey"),
    ...                      BatchResult("cap", "/d/cap", "failed", 0.5, error="/d/cap/scene.json: missing"),
    ...                      BatchResult("cavity", "/d/cavity", "ok", 3.0, lost_workers=1, robust_used="lobe")]), end="")
    | Data set | Status | Seconds | Robust mode | Angular error (°) | Error |
    |---|---|---|---|---|---|
    | ball | ok | 1.2 | tukey | 2.5 |  |
    | cap | failed | 0.5 | n/a | n/a | /d/cap/scene.json: missing |
    | cavity | ok (1 worker lost) | 3.0 | lobe | n/a |  |
    """
    lines = ["| Data set | Status | Seconds | Robust mode | Angular error (°) | Error |", "|---|---|---|---|---|---|"]
    for result in results:
        seconds = "n/a" if result.seconds is None else f"{result.seconds:.1f}"
        angular = "n/a" if result.mean_angular_error is None else f"{result.mean_angular_error:.4g}"
        error = (result.error or "").replace("|", "\\|").replace("\n", " ")
        status = result.status
        if result.lost_workers:
            status += f" ({result.lost_workers} worker{'s' if result.lost_workers > 1 else ''} lost)"
        lines.append(f"| {result.name} | {status} | {seconds} | {result.robust_used or 'n/a'} | {angular} | {error} |")
    return "\n".join(lines) + "\n"


def write_summary(results: Sequence[BatchResult], out: str | Path, *, settings: dict) -> None:
    """Write ``batch.json`` (settings, counts and every `BatchResult`) and ``batch.md``
    (`summary_table`) into a batch's output folder, each atomically.

    The counts: ``succeeded`` (data sets not failed, reused ones included), ``reused``
    and ``failed``.

    Parameters
    ----------
    results : sequence of BatchResult
    out : str or pathlib.Path
        The batch's output folder; created if missing.
    settings : dict
        The reconstruction settings of the batch, recorded in ``batch.json``.
    """
    folder = Path(out)
    failed = sum(result.failed for result in results)
    reused = sum(result.status == "reused" for result in results)
    summary = {
        **stamp(BATCH),
        "settings": settings,
        "succeeded": len(results) - failed,
        "reused": reused,
        "failed": failed,
        "datasets": [asdict(result) for result in results],
    }
    atomic_write_text(folder / SUMMARY_JSON, json.dumps(summary, indent=2))
    atomic_write_text(folder / SUMMARY_MARKDOWN, summary_table(results))
