"""The picture of a light calibration: what was found on the capture, and the lights."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle as CirclePatch

from irtps.calibrate.circles import Circle
from irtps.calibrate.lights import LightCalibration
from irtps.report.figures import figure_png

__all__ = ["calibration_png"]


def calibration_png(calibration: LightCalibration, mean_image: np.ndarray, names: Sequence[str]) -> bytes:
    """The capture's mean image with the spheres' circles and each light's highlight, beside a
    polar chart of the lights (angle from the view axis, azimuth; marker area by strength).

    Parameters
    ----------
    calibration : LightCalibration
    mean_image : numpy.ndarray
        (H, W, 3) the capture's mean linear image.
    names : sequence of str
        The images' names, in the order of the calibration's lights.

    Returns
    -------
    bytes
        A PNG file.
    """
    figure = Figure(figsize=(10.0, 4.6), layout="constrained")
    image_axes = figure.add_subplot(1, 2, 1)
    scale = float(np.percentile(mean_image, 99.5)) or 1.0
    shown = np.clip(mean_image / scale, 0.0, 1.0) ** (1 / 2.2)
    height, width = mean_image.shape[:2]
    image_axes.imshow(shown, extent=(0, width, height, 0))
    if calibration.chrome_outline is not None and calibration.chrome_outline != calibration.chrome:
        _draw(image_axes, calibration.chrome_outline, "tab:orange", "dashed", "mirror sphere's outline")
    if calibration.chrome is not None:
        _draw(
            image_axes, calibration.chrome, "tab:orange", "solid", f"mirror sphere ({calibration.chrome_circle_source})"
        )
    if calibration.matte is not None:
        _draw(image_axes, calibration.matte, "tab:cyan", "solid", "matte sphere")
    if calibration.highlights is not None:
        for number, (column, row) in enumerate(calibration.highlights):
            if np.isfinite(column):
                image_axes.plot(column, row, "+", color="tab:red", markersize=7)
                image_axes.annotate(
                    str(number), (column, row), xytext=(3, 3), textcoords="offset points", color="tab:red", fontsize=7
                )
    image_axes.set_title(f"mean of {len(names)} images")
    image_axes.legend(loc="lower left", fontsize=7, framealpha=0.7)
    image_axes.set_xticks([])
    image_axes.set_yticks([])
    polar = figure.add_subplot(1, 2, 2, projection="polar")
    directions = calibration.directions
    azimuth = np.arctan2(directions[:, 1], directions[:, 0])
    off_axis_deg = np.degrees(np.arccos(np.clip(directions[:, 2], -1.0, 1.0)))
    strength = np.ones(len(directions)) if calibration.irradiance is None else calibration.irradiance.mean(axis=1)
    area = 120.0 * strength / strength.max()
    polar.scatter(azimuth, off_axis_deg, s=area, c="tab:orange", edgecolors="black", linewidths=0.5)
    for number, (angle, radius) in enumerate(zip(azimuth, off_axis_deg)):
        polar.annotate(str(number), (angle, radius), xytext=(4, 4), textcoords="offset points", fontsize=7)
    polar.set_ylim(0.0, float(np.ceil((off_axis_deg.max() + 5.0) / 10.0) * 10.0))
    polar.set_title(
        "lights: degrees from the view axis, azimuth (x right, y up)"
        + ("" if calibration.irradiance is None else "; area: strength"),
        fontsize=9,
    )
    return figure_png(figure)


def _draw(axes, circle: Circle, colour: str, style: str, label: str) -> None:
    axes.add_patch(
        CirclePatch((circle.column, circle.row), circle.radius, fill=False, color=colour, linestyle=style, label=label)
    )
    axes.plot(circle.column, circle.row, "x", color=colour, markersize=5)
