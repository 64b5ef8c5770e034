"""The HTML page of a report: one self-contained file, figures embedded as data URIs.

The page loads nothing from elsewhere (the icon is an empty data URI, so a browser does not
ask for ``favicon.ico`` either); its one script, the 3-D view's, is inline with its meshes
(`irtps.report.shape_view`). It can be mailed or archived as it is, and works offline.
"""

from __future__ import annotations

import base64
import json
from html import escape
from typing import TYPE_CHECKING

import numpy as np

from irtps.errors import ArgumentError
from irtps.model.metrics import format_metrics
from irtps.ps.image_agreement import ImageAgreement, format_image_agreement
from irtps.io.image_selection import format_images_fitted
from irtps.geometry.placement import format_placement
from irtps.ps.fit import format_lobe_share
from irtps.render.radiometry import format_albedo_scale
from irtps._shared.records import REPORT_MARKER

if TYPE_CHECKING:
    from irtps.report.build import Report, ReportFigure

__all__ = ["recorded_agreement", "report_html"]

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 80em; padding: 0 1em; color: #222; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; margin-top: 2em; border-bottom: 1px solid #ccc; }
.grid { display: grid; grid-template-columns: repeat(auto-fill, minmax(24em, 1fr)); gap: 1.5em; }
.grid figure.wide { grid-column: 1 / -1; }
figure { margin: 0; }
figure img { width: 100%; height: auto; display: block; }
figure.wide img { width: auto; max-width: 100%; }
figcaption { font-size: 0.9em; color: #444; margin-top: 0.3em; }
table { border-collapse: collapse; }
td, th { padding: 0.2em 0.8em; border-bottom: 1px solid #eee; text-align: left; vertical-align: top; }
pre { background: #f6f6f6; padding: 0.8em; overflow-x: auto; }
.notes { background: #fff6d8; padding: 0.6em 2em; }
.controls { margin-top: 0.4em; font-size: 0.9em; }
"""


def report_html(report: Report) -> str:
    """The report's page as HTML text.

    Parameters
    ----------
    report : irtps.report.build.Report

    Returns
    -------
    str
        A complete HTML5 document: a summary of the run, every figure with its caption,
        the errors against ground truth (or why there are none), the IRT-PS iterations,
        the parameters, timings, photometric-stereo flags and versions from ``run.json``.

    Examples
    --------
    >>> from pathlib import Path
    >>> from irtps.report.build import Report, ReportFigure
    >>> record = {"source": None, "parameters": {"method": "ps"}, "timings_s": {}, "flags": {}, "history": []}
    >>> report = Report(Path("out"), record, (2, 3), 5, (slice(0, 2), slice(0, 3)),
    ...                 [ReportFigure("normal", "Normals", "n", b"png")], ground_truth="None.")
    >>> page = report_html(report)
    >>> page.startswith("<!DOCTYPE html>"), 'src="data:image/png;base64,cG5n"' in page
    (True, True)
    """
    record = report.record
    name = report.run_dir.resolve().name
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        REPORT_MARKER,
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        '<link rel="icon" href="data:,">',
        f"<title>irtps report: {escape(name)}</title>",
        f"<style>{_STYLE}</style>",
        "</head>",
        "<body>",
        f"<h1>irtps report: {escape(name)}</h1>",
        f"<p>{escape(_summary(report))}</p>",
    ]
    if report.notes:
        parts.append('<ul class="notes">' + "".join(f"<li>{escape(note)}</li>" for note in report.notes) + "</ul>")
    rows, cols = report.window
    parts += ['<section id="figures">', "<h2>Figures</h2>"]
    parts.append(
        f"<p>The maps are cropped to the object: rows {rows.start}–{rows.stop - 1}, columns {cols.start}–{cols.stop - 1} of the image.</p>"
    )
    parts.append('<div class="grid">')
    parts += [_figure(figure) for figure in report.figures]
    parts += ["</div>", "</section>"]
    if report.shape_view is not None:
        parts += ['<section id="shape">', "<h2>Shape in 3-D</h2>", report.shape_view, "</section>"]
    parts += [
        '<section id="errors">',
        "<h2>Errors against ground truth</h2>",
        f"<p>Ground truth: {escape(report.ground_truth)}</p>",
    ]
    if report.metrics is not None:
        parts.append(f"<pre>{escape(format_metrics(report.metrics))}</pre>")
    parts.append("</section>")
    if record["history"]:
        parts += [
            '<section id="iterations">',
            "<h2>Iterations</h2>",
            _history_table(record["history"], record.get("chosen_pass")),
            "</section>",
        ]
    for anchor, title, values in (
        ("parameters", "Parameters", record["parameters"]),
        ("timings", "Timings (seconds)", {stage: f"{seconds:.3f}" for stage, seconds in record["timings_s"].items()}),
        ("flags", "Photometric-stereo flags (pixels)", record["flags"]),
        ("versions", "Versions", {key: record[key] for key in ("irtps", "python", "numpy") if key in record}),
    ):
        parts += [f'<section id="{anchor}">', f"<h2>{title}</h2>", _key_value_table(values), "</section>"]
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


def _summary(report: Report) -> str:
    record = report.record
    parameters = record["parameters"]
    robust = "" if record.get("robust_used") is None else f"robust mode {record['robust_used']}"
    if parameters.get("method") == "irtps":
        corrections = max(len(record["history"]) - 1, 0)
        chosen = record.get("chosen_pass")
        result = (
            ""
            if chosen is None
            else f"; the result is pass {chosen}" + (" (classic photometric stereo)" if chosen == 0 else "")
        )
        method = f"IRT-PS ({parameters.get('bounces')} bounces estimated, {corrections} corrections{result}{'; ' + robust if robust else ''})"
        stop = record.get("stop")
        if isinstance(stop, dict) and isinstance(stop.get("message"), str):
            method += f". The loop stopped after pass {stop.get('after_pass')}: {stop['message']}"
    else:
        method = "Classic photometric stereo" + (f" ({robust})" if robust else "")
    source = record["source"] or "an unrecorded data set"
    rows, cols = report.size
    pixel_size = record.get("pixel_size")
    scale = "" if pixel_size is None else f", pixel size {pixel_size:g} (world units)"
    placement = "" if record.get("placement") is None else f" Placement: {format_placement(record['placement'])}."
    if record.get("albedo_scale") is not None:
        placement += f" {format_albedo_scale(record['albedo_scale']).capitalize()}."
    if record.get("lobe_share") is not None:
        placement += f" {format_lobe_share(record['lobe_share'], record.get('robust_used'))}."
    placement += _estimated_strengths(record.get("estimated_irradiance"))
    if record.get("excluded_images"):
        placement += f" {_sentence(format_images_fitted(len(record.get('images', [])), record['excluded_images']))}."
    agreement = recorded_agreement(record)
    if agreement is not None:
        placement += "".join(f" {_sentence(line)}." for line in format_image_agreement(record["images"], agreement))
    return f"{method} of {source}: {cols}×{rows} pixels, {report.object_pixels} on the object{scale}.{placement} Folder: {report.run_dir}."


def _estimated_strengths(recorded: object) -> str:
    """A sentence on the lights' strengths that a run estimated (``run.json``'s
    ``estimated_irradiance``: each light's RGB), or nothing when they were given or the record
    does not hold them as numbers."""
    try:
        strengths = np.asarray(recorded, dtype=float).mean(axis=1)
    except (TypeError, ValueError, np.exceptions.AxisError):
        return ""
    if strengths.ndim != 1 or not strengths.size or not np.isfinite(strengths).all():
        return ""
    return (
        f" The lights' strengths were not given: estimated from the images (semi-calibrated), "
        f"from {strengths.min():.2f} to {strengths.max():.2f} of the median light's."
    )


def recorded_agreement(record: dict) -> ImageAgreement | None:
    """The `ImageAgreement` of a ``run.json`` record, if it holds one that fits its list of
    images."""
    if record.get("image_agreement") is None or not isinstance(record.get("images"), list):
        return None
    try:
        agreement = ImageAgreement.from_dict(record["image_agreement"])
    except ArgumentError:
        return None
    return agreement if len(agreement.brightness) == len(record["images"]) else None


def _sentence(text: str) -> str:
    """`text` with a capital first letter, the rest as it is (file names keep their case)."""
    return text[:1].upper() + text[1:]


def _figure(figure: ReportFigure) -> str:
    data = base64.b64encode(figure.png).decode("ascii")
    wide = ' class="wide"' if figure.wide else ""
    return (
        f'<figure id="{escape(figure.name)}"{wide}>'
        f'<img src="data:image/png;base64,{data}" alt="{escape(figure.title)}">'
        f"<figcaption><b>{escape(figure.title)}.</b> {escape(figure.caption)}</figcaption>"
        "</figure>"
    )


def _history_table(history: list[dict], chosen: int | None) -> str:
    rows = [
        "<tr><th>pass</th><th>residual</th><th>mean angular error (°)</th><th>mean |height change|</th><th>seconds</th></tr>"
    ]
    for step in history:
        error = (step["metrics"] or {}).get("normal_mean_angular_deg")
        residual = (step.get("residual") or {}).get("object")
        change = step["height_change"]
        seconds = sum(step["timings"].values())
        index = f"{step['index']} (result)" if step["index"] == chosen else str(step["index"])
        cells = (
            index,
            "n/a" if residual is None else f"{residual:.4f}",
            "n/a" if error is None else f"{error:.2f}",
            "n/a" if change is None else f"{change:.4g}",
            f"{seconds:.2f}",
        )
        rows.append("<tr>" + "".join(f"<td>{cell}</td>" for cell in cells) + "</tr>")
    return "<table>" + "".join(rows) + "</table>"


def _key_value_table(values: dict) -> str:
    if not values:
        return "<p>None recorded.</p>"
    rows = (
        f"<tr><th>{escape(str(key))}</th><td>{escape(value if isinstance(value, str) else json.dumps(value))}</td></tr>"
        for key, value in values.items()
    )
    return "<table>" + "".join(rows) + "</table>"
