"""Writing a light calibration: ``lights.lp`` and ``light_intensities.txt`` (an RTI folder's),
``lights.json`` (the scene contract's ``lights``), ``calibration.json`` (everything found) and
``calibration.png``."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from irtps._shared.atomic import atomic_output_dir
from irtps._shared.records import CALIBRATION, stamp
from irtps.calibrate.circles import Circle
from irtps.calibrate.lights import LightCalibration
from irtps.io.rti import CALIBRATION_RECORD, INTENSITIES_FILE

__all__ = ["lp_text", "save_calibration"]

LP_FILE = "lights.lp"
LIGHTS_FILE = "lights.json"
PICTURE_FILE = "calibration.png"


def lp_text(names: Sequence[str], directions: np.ndarray) -> str:
    """A light position file (RTIBuilder, Relight): the image count, then ``name x y z`` per image.

    Parameters
    ----------
    names : sequence of str
        The images' file names.
    directions : numpy.ndarray
        (K, 3) unit vectors toward the lights.

    Returns
    -------
    str
    """
    lines = [str(len(names))] + [f"{name} {x:.6f} {y:.6f} {z:.6f}" for name, (x, y, z) in zip(names, directions)]
    return "\n".join(lines) + "\n"


def save_calibration(
    calibration: LightCalibration,
    out: str | Path,
    *,
    names: Sequence[str],
    mean_image: np.ndarray,
    source: str,
    encoding: str | None,
) -> list[str]:
    """Write a calibration to a folder, replaced atomically.

    ``lights.lp`` lists `names` with their lights' directions; ``light_intensities.txt`` their
    RGB strengths, one line each in the same order (`irtps.io.rti`), and ``lights.json`` the
    contract's ``lights`` (directions and RGB irradiances, marked ``"irradiance": "relative"``
    unless the matte sphere's albedo was given), both written only when a matte sphere gave the
    strengths; ``calibration.json`` records the circles, each light's highlight, both spheres'
    directions and their agreement, the notes, the inputs, and in ``irradiance`` whether the
    strengths are ``"absolute"`` or ``"relative"`` (which `irtps.io.rti` reads beside the
    ``.lp`` file); ``calibration.png`` is `irtps.calibrate.figure.calibration_png`.

    Parameters
    ----------
    calibration : LightCalibration
    out : str or pathlib.Path
    names : sequence of str
        The images' file names, in the order of the lights.
    mean_image : numpy.ndarray
        (H, W, 3) the capture's mean linear image, for the picture.
    source : str
        The capture's folder, recorded.
    encoding : str or None
        The encoding asked for (None: by bit depth), recorded.

    Returns
    -------
    list of str
        The files written.
    """
    files = {
        LP_FILE: lp_text(names, calibration.directions),
        CALIBRATION_RECORD: json.dumps(_record(calibration, names, source=source, encoding=encoding), indent=1) + "\n",
    }
    if calibration.irradiance is not None:
        lights = [
            {"direction": direction.tolist(), "irradiance": irradiance.tolist()}
            for direction, irradiance in zip(calibration.directions, calibration.irradiance)
        ]
        relative = {} if calibration.matte_albedo is not None else {"irradiance": "relative"}
        files[LIGHTS_FILE] = json.dumps({"lights": lights, **relative}, indent=1) + "\n"
        files[INTENSITIES_FILE] = "".join(f"{r:.6g} {g:.6g} {b:.6g}\n" for r, g, b in calibration.irradiance)
    # Imported here: matplotlib, which the picture is drawn with, would add to the start and the
    # memory of every command (the `irtps` command imports this module).
    from irtps.calibrate.figure import calibration_png

    picture = calibration_png(calibration, mean_image, names)
    with atomic_output_dir(out) as folder:
        for name, text in files.items():
            (folder / name).write_text(text)
        (folder / PICTURE_FILE).write_bytes(picture)
    return sorted([*files, PICTURE_FILE])


def _record(calibration: LightCalibration, names: Sequence[str], *, source: str, encoding: str | None) -> dict:
    lights = []
    for k, name in enumerate(names):
        light: dict = {"image": name, "direction": calibration.directions[k].tolist()}
        if calibration.irradiance is not None:
            light["irradiance"] = calibration.irradiance[k].tolist()
        if calibration.highlights is not None:
            light["highlight_px"] = _finite_or_none(calibration.highlights[k])
        if calibration.matte_directions is not None and calibration.matte_residual is not None:
            light["matte_direction"] = calibration.matte_directions[k].tolist()
            light["matte_fit_residual"] = _number(calibration.matte_residual[k])
        if calibration.agreement_deg is not None:
            light["spheres_disagree_deg"] = _number(calibration.agreement_deg[k])
        lights.append(light)
    return {
        **stamp(CALIBRATION),
        "source": source,
        "encoding": encoding or "by bit depth (8-bit sRGB, 16-bit and float linear)",
        "direction_source": calibration.direction_source,
        "chrome_sphere": _circle(calibration.chrome),
        "chrome_sphere_outline": _circle(calibration.chrome_outline),
        "chrome_circle_source": calibration.chrome_circle_source,
        "matte_sphere": _circle(calibration.matte),
        "matte_circle_source": None if calibration.matte is None else "given" if calibration.matte_given else "shading",
        "matte_albedo": calibration.matte_albedo,
        "irradiance": _irradiance_kind(calibration),
        "coordinates": "circles and highlights in pixels from the image's top-left corner (column, row); "
        "directions toward the lights, x right, y up, z toward the camera",
        "notes": list(calibration.notes),
        "lights": lights,
    }


def _irradiance_kind(calibration: LightCalibration) -> str | None:
    """``"absolute"`` when the matte sphere's albedo was given, ``"relative"`` when it was not,
    None without strengths."""
    if calibration.irradiance is None:
        return None
    return "absolute" if calibration.matte_albedo is not None else "relative"


def _circle(circle: Circle | None) -> dict | None:
    if circle is None:
        return None
    return {"center_px": [circle.column, circle.row], "radius_px": circle.radius}


def _finite_or_none(values: np.ndarray) -> list[float] | None:
    return values.tolist() if np.isfinite(values).all() else None


def _number(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None
