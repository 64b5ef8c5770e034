"""Calibrating a rig's lights from a capture of calibration spheres: each light's direction
from a mirror sphere's highlight (or a matte sphere's shading, when there is no mirror sphere)
and its RGB strength from a matte sphere."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from irtps._shared.checks import check_array, check_finite, check_number
from irtps.calibrate.chrome import Highlights, circle_from_highlights, find_highlights, mirror_directions
from irtps.calibrate.circles import Circle, as_circle
from irtps.calibrate.matte import Shading, fit_shading, matte_irradiance
from irtps.calibrate.spheres import MAX_SHADING_RESIDUAL, find_spheres
from irtps.errors import ArgumentError, DatasetError
from irtps.model.scene import MIN_LIGHTS

__all__ = ["LightCalibration", "calibrate_lights"]

#: The mirror sphere's circle fitted to its highlights and the matte sphere's directions is
#: taken when the highlights lie within this fraction of its radius (RMS) of where it puts
#: them; further, the two spheres disagree (a matte sphere far from Lambertian) and the
#: outline is used.
MAX_HIGHLIGHT_RESIDUAL = 0.02
#: The fewest lights with both a highlight and a matte-sphere direction that fit the circle.
MIN_SHARED_LIGHTS = 3
#: Their half vectors must spread at least this far (in x or y) for the radius to be known.
MIN_HALF_VECTOR_SPREAD = 0.05
#: Rounds of finding the highlights on the fitted circle and fitting it again.
HIGHLIGHT_FIT_ROUNDS = 2


@dataclass(frozen=True)
class LightCalibration:
    """What `calibrate_lights` found.

    Attributes
    ----------
    directions : numpy.ndarray
        (K, 3) unit vectors toward each light (x right, y up, z toward the camera).
    irradiance : numpy.ndarray or None
        (K, 3) each light's RGB irradiance from the matte sphere; None without a matte sphere.
    matte_albedo : float or None
        The matte sphere's albedo the irradiances were taken with: they are then absolute.
        None when it was not given: they are relative, taken as from a white sphere.
    direction_source : str
        ``"chrome"`` (highlights on the mirror sphere) or ``"matte"`` (the matte sphere's shading).
    chrome : Circle or None
        The mirror sphere's circle that the directions were taken with.
    chrome_outline : Circle or None
        The mirror sphere's circle as given or fitted to its outline.
    chrome_circle_source : str or None
        ``"given"``, ``"outline"`` or ``"highlights"`` (fitted to the highlights and the matte
        sphere's directions).
    matte : Circle or None
    matte_given : bool
    highlights : numpy.ndarray or None
        (K, 2) column, row of each highlight (NaN where none was found).
    matte_directions : numpy.ndarray or None
        (K, 3) the directions of the matte sphere's shading (zero where it gave none).
    matte_residual : numpy.ndarray or None
        (K,) the relative RMS residual of the matte sphere's Lambertian fit.
    agreement_deg : numpy.ndarray or None
        (K,) the angle between the two spheres' directions (NaN where one gave none).
    notes : tuple of str
        What the user should know: a light taken from the other sphere, a circle not taken.
    """

    directions: np.ndarray
    irradiance: np.ndarray | None
    matte_albedo: float | None
    direction_source: str
    chrome: Circle | None
    chrome_outline: Circle | None
    chrome_circle_source: str | None
    matte: Circle | None
    matte_given: bool
    highlights: np.ndarray | None
    matte_directions: np.ndarray | None
    matte_residual: np.ndarray | None
    agreement_deg: np.ndarray | None
    notes: tuple[str, ...]


def calibrate_lights(
    images: np.ndarray,
    *,
    saturated: np.ndarray | None = None,
    chrome: Circle | None = None,
    matte: Circle | None = None,
    matte_albedo: float | None = None,
    names: Sequence[str] | None = None,
    where: str = "capture",
) -> LightCalibration:
    """Each light's direction and strength from images of a mirror and a matte sphere.

    The spheres not given are found (`irtps.calibrate.spheres.find_spheres`). Each light's
    direction is its highlight on the mirror sphere mirrored about the view direction
    (orthographic camera, looking down -z). The mirror sphere's outline is faint where it
    mirrors what is behind it, so with a matte sphere in the capture its circle is the one that
    puts each highlight where the matte sphere's shading says the light is (a least-squares fit
    of 3 numbers over all lights; each light's direction still comes from its own highlight),
    taken when the highlights lie within `MAX_HIGHLIGHT_RESIDUAL` of its radius (RMS) of where
    it puts them; else the outline's circle is used, and a note says so.
    Each light's RGB irradiance is the median of ``pi I / (albedo n.l)`` over the matte sphere's
    well-lit pixels. Without a mirror sphere, the directions are the matte sphere's.

    Parameters
    ----------
    images : numpy.ndarray
        (K, H, W, 3) linear images, one light each.
    saturated : numpy.ndarray, optional
        (K, H, W) bool: clipped pixels (8-bit codes at 255), left out of the matte sphere's fits.
    chrome, matte : Circle, optional
        The spheres' circles (pixels from the top-left corner), taken as given.
    matte_albedo : float, optional
        The matte sphere's albedo: the irradiances are then absolute, and photometric stereo and
        IRT-PS take them as they are. Without it they are relative (taken as from a white
        sphere), and a reconstruction finds their scale from its own images.
    names : sequence of str, optional
        The images' names, for messages.
    where : str
        What the images are (a folder), for messages.

    Returns
    -------
    LightCalibration

    Raises
    ------
    DatasetError
        Naming `where`: no sphere found (give its circle), an image with neither a highlight
        nor a direction from the matte sphere, or that lights too little of the matte sphere
        to measure its strength.
    ArgumentError
        Naming the argument: `images` not (K, H, W, 3) finite or fewer than 3 (each image's
        highlight stands out of the median of all), `saturated` of another shape,
        `matte_albedo` not in (0, 1].
    """
    images = check_array("images", images, (None, None, None, 3), dtype=np.float32, copy=False, nonempty=True)
    check_finite("images", images)
    if len(images) < MIN_LIGHTS:
        raise ArgumentError(
            "images", f"{len(images)} images: a calibration needs at least {MIN_LIGHTS}, one light each"
        )
    saturated = (
        np.zeros(images.shape[:3], dtype=bool)
        if saturated is None
        else check_array("saturated", saturated, images.shape[:3], match="images", dtype=bool)
    )
    chrome = None if chrome is None else as_circle(chrome, "chrome")
    matte = None if matte is None else as_circle(matte, "matte")
    if matte_albedo is not None:
        matte_albedo = check_number("matte_albedo", matte_albedo)
        if not 0.0 < matte_albedo <= 1.0:
            raise ArgumentError("matte_albedo", f"must be in (0, 1], got {matte_albedo!r}")
    labels = list(names) if names is not None else [f"image {k}" for k in range(len(images))]
    gray = images.mean(axis=-1, dtype=np.float32)
    spheres = find_spheres(gray, saturated, chrome=chrome, matte=matte)
    if spheres.chrome is None and spheres.matte is None:
        raise DatasetError(
            f"{where}: no mirror or matte sphere found; give their circles (--chrome, --matte COLUMN,ROW,RADIUS)"
        )
    notes: list[str] = []
    shading = fit_shading(gray, saturated, spheres.matte) if spheres.matte is not None else None
    shaded = (
        (shading.residual <= MAX_SHADING_RESIDUAL) & (np.abs(shading.directions).sum(axis=1) > 0)
        if shading is not None
        else np.zeros(len(images), dtype=bool)
    )
    if spheres.chrome is None:
        assert shading is not None
        _require(~shaded, labels, where, "is not explained by the matte sphere's shading and there is no mirror sphere")
        directions, source = shading.directions, "matte"
        circle, circle_source, highlights = None, None, None
    else:
        mirror = _mirror_directions(gray, spheres.chrome, chrome is not None, shading, shaded, labels, where)
        directions, circle, circle_source, highlights, mirror_notes = mirror
        notes.extend(mirror_notes)
        source = "chrome"
    irradiance = None
    if spheres.matte is not None:
        irradiance = matte_irradiance(
            images, saturated, spheres.matte, directions, 1.0 if matte_albedo is None else matte_albedo
        )
        _require(
            ~np.isfinite(irradiance).all(axis=1),
            labels,
            where,
            "lights too little of the matte sphere to measure its strength",
        )
    elif matte_albedo is not None:
        notes.append(
            "the matte sphere's albedo was given, but no matte sphere was found: no strengths "
            "(give its circle with --matte COLUMN,ROW,RADIUS)"
        )
    agreement = None
    if shading is not None and source == "chrome":
        cosine = np.clip(np.sum(directions * shading.directions, axis=1), -1.0, 1.0)
        agreement = np.where(shaded, np.degrees(np.arccos(cosine)), np.nan)
    return LightCalibration(
        directions=directions,
        irradiance=irradiance,
        matte_albedo=None if irradiance is None else matte_albedo,
        direction_source=source,
        chrome=circle,
        chrome_outline=spheres.chrome,
        chrome_circle_source=circle_source,
        matte=spheres.matte,
        matte_given=matte is not None,
        highlights=highlights,
        matte_directions=None if shading is None else shading.directions,
        matte_residual=None if shading is None else shading.residual,
        agreement_deg=agreement,
        notes=tuple(notes),
    )


def _mirror_directions(
    gray: np.ndarray,
    outline: Circle,
    given: bool,
    shading: Shading | None,
    shaded: np.ndarray,
    labels: list[str],
    where: str,
) -> tuple[np.ndarray, Circle, str, np.ndarray, list[str]]:
    """The lights' directions from the mirror sphere's highlights (`calibrate_lights`): the
    directions, the circle they were taken with, how it was had, the highlights and the notes."""
    notes = []
    circle, circle_source = outline, "given" if given else "outline"
    found = find_highlights(gray, circle)
    if not given and shading is not None:
        fitted = _fit_to_highlights(gray, circle, found, shading.directions, shaded)
        if fitted is None:
            notes.append(
                f"too few lights with both a highlight and a direction from the matte sphere, or too alike, "
                f"to fit the mirror sphere's circle to them: its outline {circle} is used"
            )
        elif fitted[2] <= MAX_HIGHLIGHT_RESIDUAL * fitted[0].radius:
            circle, found, circle_source = fitted[0], fitted[1], "highlights"
        else:
            notes.append(
                f"the highlights lie {fitted[2]:.2f} px (RMS) from where the matte sphere's directions put them on "
                f"the best circle, {fitted[0]}: its outline {circle} is used"
            )
    directions = mirror_directions(np.nan_to_num(found.positions), circle)
    missing = ~found.found
    _require(missing & ~shaded, labels, where, "shows no highlight on the mirror sphere")
    if missing.any():
        assert shading is not None
        directions[missing] = shading.directions[missing]
        notes.append(
            f"no highlight on the mirror sphere in {_listed(missing, labels)}: its direction is the matte sphere's"
        )
    return directions, circle, circle_source, found.positions, notes


def _fit_to_highlights(
    gray: np.ndarray, circle: Circle, found: Highlights, directions: np.ndarray, shaded: np.ndarray
) -> tuple[Circle, Highlights, float] | None:
    """The mirror sphere's circle that puts the highlights where `directions` say, found again
    on it (`HIGHLIGHT_FIT_ROUNDS` times), and the highlights' RMS distance from it; None when
    too few lights, or lights too alike, fit it."""
    residual = np.inf
    for _ in range(HIGHLIGHT_FIT_ROUNDS):
        both = found.found & shaded
        half = directions[both] + np.array([0.0, 0.0, 1.0])
        half /= np.linalg.norm(half, axis=1, keepdims=True)
        if both.sum() < MIN_SHARED_LIGHTS or np.ptp(half[:, :2], axis=0).max() < MIN_HALF_VECTOR_SPREAD:
            return None
        circle, residual = circle_from_highlights(found.positions[both], directions[both])
        found = find_highlights(gray, circle)
    return circle, found, residual


def _require(failing: np.ndarray, labels: list[str], where: str, problem: str) -> None:
    if failing.any():
        raise DatasetError(f"{where}: {_listed(failing, labels)} {problem}")


def _listed(chosen: np.ndarray, labels: list[str]) -> str:
    picked = [labels[k] for k in np.flatnonzero(chosen)]
    shown = ", ".join(picked[:5]) + (f" and {len(picked) - 5} more" if len(picked) > 5 else "")
    return shown
