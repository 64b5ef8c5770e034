"""The lines that ``irtps calibrate`` prints: the spheres, then one line per light."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from irtps.calibrate.lights import LightCalibration

__all__ = ["format_calibration"]


def format_calibration(calibration: LightCalibration, names: Sequence[str]) -> list[str]:
    """What a calibration found, as lines to print.

    Parameters
    ----------
    calibration : LightCalibration
    names : sequence of str
        The images' names.

    Returns
    -------
    list of str
        The spheres' circles and how they were had, then per light its image, direction,
        angle from the view axis, relative strength and the two spheres' disagreement, then
        the notes.
    """
    lines = []
    if calibration.chrome is not None:
        how = {
            "given": "as given",
            "outline": "fitted to its outline",
            "highlights": f"fitted to the highlights and the matte sphere's directions (outline {calibration.chrome_outline})",
        }[calibration.chrome_circle_source or "given"]
        lines.append(f"mirror sphere {calibration.chrome}, {how}")
    if calibration.matte is not None:
        lines.append(
            f"matte sphere {calibration.matte}, {'as given' if calibration.matte_given else 'fitted to its shading'}"
        )
    source = (
        "highlights on the mirror sphere" if calibration.direction_source == "chrome" else "the matte sphere's shading"
    )
    if calibration.irradiance is None:
        strengths = ""
    elif calibration.matte_albedo is None:
        strengths = (
            "; strengths from the matte sphere, relative (its albedo not given: a reconstruction finds their scale)"
        )
    else:
        strengths = f"; strengths from the matte sphere, absolute irradiances (its albedo {calibration.matte_albedo:g})"
    lines.append(f"directions from the {source}{strengths}")
    strength = None if calibration.irradiance is None else calibration.irradiance.mean(axis=1)
    for k, name in enumerate(names):
        x, y, z = calibration.directions[k]
        line = f"{k:3d} {name}: ({x:+.4f}, {y:+.4f}, {z:+.4f}), {np.degrees(np.arccos(np.clip(z, -1, 1))):.1f} deg off axis"
        if strength is not None:
            line += f", strength {strength[k] / strength.mean():.3f} x mean"
        if calibration.agreement_deg is not None and np.isfinite(calibration.agreement_deg[k]):
            line += f", spheres differ {calibration.agreement_deg[k]:.2f} deg"
        lines.append(line)
    if calibration.agreement_deg is not None and np.isfinite(calibration.agreement_deg).any():
        agreement = calibration.agreement_deg[np.isfinite(calibration.agreement_deg)]
        lines.append(
            f"the two spheres' directions differ by {agreement.mean():.2f} deg on average, {agreement.max():.2f} at most"
        )
    lines.extend(f"note: {note}" for note in calibration.notes)
    return lines
