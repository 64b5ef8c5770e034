"""PNG figures drawn with matplotlib: an image, a map of errors with its colour bar, a convergence curve,
each image's agreement with the fit.

Figures are drawn on `matplotlib.figure.Figure` objects directly (no pyplot, no global
state, no display needed) and returned as PNG bytes.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from irtps._shared.checks import check_array, check_instance
from irtps.report.display import BACKGROUND
from irtps.errors import ArgumentError

__all__ = [
    "ERROR_COLOURS",
    "ERROR_SCALE_PERCENTILE",
    "agreement_png",
    "convergence_png",
    "error_map_png",
    "figure_png",
    "image_png",
]

#: Size of a figure in inches, and its resolution.
FIGURE_SIZE = (4.8, 4.2)
DPI = 120
#: Percentile of an error map that the top of its colour scale marks.
ERROR_SCALE_PERCENTILE = 99.0
#: The colours of error maps, 0 to the top of their scale (grey where not evaluated).
ERROR_COLOURS = colormaps["viridis"].with_extremes(bad=(BACKGROUND,) * 3)


def image_png(rgb: np.ndarray, title: str) -> bytes:
    """An RGB image with a title, as PNG bytes.

    Parameters
    ----------
    rgb : numpy.ndarray
        (H, W, 3) values in [0, 1], top row first (e.g. from `irtps.report.display`).
    title : str

    Returns
    -------
    bytes
        A PNG file.

    Examples
    --------
    >>> import numpy as np
    >>> image_png(np.zeros((4, 4, 3)), "black")[:8]
    b'\\x89PNG\\r\\n\\x1a\\n'
    """
    rgb = check_array("rgb", rgb, (None, None, 3))
    figure = Figure(figsize=FIGURE_SIZE, layout="constrained")
    axes = figure.add_subplot()
    axes.imshow(np.clip(rgb, 0.0, 1.0))
    _image_axes(axes, title)
    return figure_png(figure)


def error_map_png(errors: np.ndarray, title: str, unit: str) -> bytes:
    """A map of per-pixel errors in colour, with a colour bar, as PNG bytes.

    The colour scale runs from 0 to the 99th percentile of the finite errors, so a few
    outliers do not wash out the rest; larger errors take the top colour (the bar's
    arrow). NaN pixels (not evaluated) are drawn in the background grey.

    Parameters
    ----------
    errors : numpy.ndarray
        (H, W) non-negative errors, NaN where not evaluated (as `irtps.model.metrics.error_maps`
        gives).
    title : str
    unit : str
        Label of the colour bar.

    Returns
    -------
    bytes
        A PNG file.

    Raises
    ------
    ArgumentError
        If ``errors`` is not (H, W) or has no finite value.

    Examples
    --------
    >>> import numpy as np
    >>> png = error_map_png(np.array([[0.0, 2.0], [np.nan, 1.0]]), "angle", "degrees")
    >>> png[:8]
    b'\\x89PNG\\r\\n\\x1a\\n'
    """
    errors = check_array("errors", errors, (None, None))
    finite = errors[np.isfinite(errors)]
    if finite.size == 0:
        raise ArgumentError("errors", f"the map {title!r} has no finite value")
    top = float(np.percentile(finite, ERROR_SCALE_PERCENTILE))
    figure = Figure(figsize=FIGURE_SIZE, layout="constrained")
    axes = figure.add_subplot()
    image = axes.imshow(np.ma.masked_invalid(errors), cmap=ERROR_COLOURS, vmin=0.0, vmax=top if top > 0 else 1.0)
    figure.colorbar(image, ax=axes, label=unit, extend="max" if finite.max() > top else "neither", shrink=0.85)
    _image_axes(axes, title)
    return figure_png(figure)


def convergence_png(
    passes: Sequence[int],
    angular_error_deg: Sequence[float | None],
    residual: Sequence[float | None],
    chosen: int | None = None,
    stopped: str | None = None,
) -> bytes:
    """The convergence of the IRT-PS iterations, as PNG bytes.

    Left: the mean angular error against ground truth per pass (only when some pass has
    one). Right: the relative residual of each pass's reconstruction rendered again against
    the images (`irtps.render.residual`), which needs no ground truth. The chosen pass is ringed.

    Parameters
    ----------
    passes : sequence of int
        Pass numbers (0 is classic photometric stereo).
    angular_error_deg : sequence of float or None
        Mean angular error of each pass, None where unknown.
    residual : sequence of float or None
        Relative residual on the object of each pass, None where not recorded.
    chosen : int, optional
        The pass returned.
    stopped : str, optional
        Why the loop stopped, written above the panels.

    Returns
    -------
    bytes
        A PNG file.

    Raises
    ------
    ArgumentError
        If the sequences differ in length or no pass has a residual.

    Examples
    --------
    >>> convergence_png([0, 1, 2], [9.0, 4.0, 3.5], [0.1, 0.05, 0.04], chosen=2)[:8]
    b'\\x89PNG\\r\\n\\x1a\\n'
    """
    if not len(passes) == len(angular_error_deg) == len(residual):
        raise ArgumentError(
            "passes", f"{len(passes)} passes but {len(angular_error_deg)} errors and {len(residual)} residuals"
        )
    errors = [(k, e) for k, e in zip(passes, angular_error_deg) if e is not None]
    residuals = [(k, r) for k, r in zip(passes, residual) if r is not None]
    if not residuals:
        raise ArgumentError("residual", "no pass has a residual")
    figure = Figure(figsize=(FIGURE_SIZE[0] * (2 if errors else 1), FIGURE_SIZE[1] * 0.8), layout="constrained")
    panels = figure.subplots(1, 2 if errors else 1, squeeze=False, sharex=True)[0]
    if errors:
        _curve(panels[0], errors, "mean angular error (°)", "Normal error against ground truth", chosen)
    _curve(
        panels[-1], residuals, "relative residual on the object", "Rendered reconstruction against the images", chosen
    )
    if stopped:
        figure.suptitle(stopped, fontsize="small")
    return figure_png(figure)


def agreement_png(
    names: Sequence[str],
    brightness: Sequence[float] | np.ndarray,
    spread: Sequence[float] | np.ndarray,
    labelled: int = 3,
) -> bytes:
    """How each image agrees with the fit (`irtps.ps.image_agreement`), as PNG bytes.

    Left: each image's brightness against the fit, over the median image's (1 drawn as a
    line). Right: its spread about the fit, in per cent. In each, the `labelled` images
    farthest out are ringed and listed with their figures. Images without figures (NaN)
    are left out.

    Parameters
    ----------
    names : sequence of str
        The images, in order.
    brightness, spread : sequence of float
        One per image.
    labelled : int
        Images named in each panel.

    Returns
    -------
    bytes
        A PNG file.

    Raises
    ------
    ArgumentError
        If the sequences differ in length or no image has figures.

    Examples
    --------
    >>> agreement_png(["001.png", "002.png", "003.png"], [1.0, 1.5, 0.98], [0.02, 0.02, 0.09])[:8]
    b'\\x89PNG\\r\\n\\x1a\\n'
    """
    values = [np.asarray(figures, dtype=np.float64) for figures in (brightness, spread)]
    if not len(names) == len(values[0]) == len(values[1]):
        raise ArgumentError(
            "brightness", f"{len(names)} images but {len(values[0])} brightnesses and {len(values[1])} spreads"
        )
    known = np.flatnonzero(~np.isnan(values[0]) & ~np.isnan(values[1]))
    if known.size == 0:
        raise ArgumentError("brightness", "no image has figures")
    figure = Figure(figsize=(FIGURE_SIZE[0] * 2, FIGURE_SIZE[1] * 0.8), layout="constrained")
    left, right = figure.subplots(1, 2, sharex=True)
    panels = (
        (
            left,
            values[0][known],
            np.abs(np.log(values[0][known])),
            "over the median image's",
            "Brightness against the fit",
            "{:.2f}",
        ),
        (right, 100 * values[1][known], values[1][known], "% a pixel", "Spread about the fit", "{:.1f} %"),
    )
    for axes, shown, outness, label, title, text in panels:
        axes.plot(known + 1, shown, marker="o", markersize=3, linestyle="none")
        # The images farthest out ringed and listed in a corner: names beside the points of
        # neighbouring images would overprint.
        farthest = np.argsort(-outness, kind="stable")[:labelled]
        axes.plot(
            known[farthest] + 1,
            shown[farthest],
            marker="o",
            markersize=9,
            markerfacecolor="none",
            color="C3",
            linestyle="none",
        )
        listed = "\n".join(f"{names[known[k]]} {text.format(shown[k])}" for k in farthest)
        axes.text(
            0.02,
            0.97,
            listed,
            transform=axes.transAxes,
            fontsize="x-small",
            va="top",
            bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "C3"},
        )
        axes.set_xlabel("image (1 = the first fitted)")
        axes.set_ylabel(label)
        axes.set_title(title, fontsize="medium")
        axes.xaxis.set_major_locator(MaxNLocator(integer=True))
        axes.grid(True, alpha=0.3)
    left.axhline(1.0, color="C3", linewidth=1)
    return figure_png(figure)


def _curve(axes, points: list[tuple[int, float]], label: str, title: str, chosen: int | None = None) -> None:
    x, y = zip(*points)
    axes.plot(x, y, marker="o")
    if chosen in x:
        axes.plot(
            [chosen],
            [y[x.index(chosen)]],
            marker="o",
            markersize=14,
            markerfacecolor="none",
            color="C3",
            linestyle="none",
            label="result",
        )
        axes.legend(fontsize="small")
    axes.set_xlabel("pass (0 = classic photometric stereo)")
    axes.set_ylabel(label)
    axes.set_title(title, fontsize="medium")
    axes.xaxis.set_major_locator(MaxNLocator(integer=True))
    axes.grid(True, alpha=0.3)


def _image_axes(axes, title: str) -> None:
    axes.set_title(title, fontsize="medium")
    axes.set_axis_off()


def figure_png(figure: Figure) -> bytes:
    """A matplotlib figure as PNG bytes, at `DPI`, without a software tag (the same figure gives
    the same bytes).

    Raises
    ------
    ArgumentError
        Naming `figure`: not a `matplotlib.figure.Figure`.
    """
    check_instance("figure", figure, Figure)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=DPI, metadata={"Software": None})
    return buffer.getvalue()
