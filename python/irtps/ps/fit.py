"""Calibrated Lambertian photometric stereo (the Rust core's least-squares fit)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from irtps import _core
from irtps._shared.checks import (
    check_array,
    check_choice,
    check_finite,
    check_images_finite,
    check_mask,
    check_number,
    check_positive,
    document_choices,
)
from irtps.model.data import coarse_to_fine, spread_pixels
from irtps.errors import ArgumentError
from irtps.model.scene import MAX_IRRADIANCE, MIN_IRRADIANCE, irradiance_problem

# The robust modes (and "auto"), declared by the model (the options list them).
from irtps.model.constants import ROBUST_CHOICES, ROBUST_MODES

# The values of `PsResult.flags`, as the core writes them: the constants of ``rust/ps/kernel.rs``
# ``mod flag``, under the same names (the binding does not export them;
# tests/test_ps.py checks them against what the core writes).
#: The flag of the pixels fitted as asked (with every mode but the lobe's).
OK = 0
#: The flag of a robust fit's pixels left with too few non-coplanar observations: the full fit kept.
FULL_FIT = 1
#: The flag of the pixels no light reached: normal (0, 0, 1), albedo 0.
DARK = 2
#: The flag of the pixels outside the mask.
MASKED_OUT = 3
#: The flag of the pixels fitted with a specular lobe (robust mode ``"lobe"``).
LOBE = 4
#: Meaning of the values of `PsResult.flags`.
FLAGS = {
    OK: "fitted",
    FULL_FIT: "full fit kept (too few non-coplanar lit observations)",
    DARK: "no light",
    MASKED_OUT: "outside the mask",
    LOBE: "fitted with a specular lobe",
}


@dataclass
class PsResult:
    """Normals and albedo fitted per pixel.

    Attributes
    ----------
    normals : numpy.ndarray
        float32 (H, W, 3) unit normals, 0 outside the mask.
    albedo : numpy.ndarray
        float32 (H, W, 3) RGB albedo.
    flags : numpy.ndarray
        uint8 (H, W), see `FLAGS`.
    used : numpy.ndarray
        uint16 (H, W), observations used per pixel.
    robust_used : str or None
        With ``robust="auto"``: the mode it chose (`choose_robust`); else None.
    lobe_share : float or None
        With ``robust="auto"``: the object's `lobe_share`, by which it chose; else None.
    """

    normals: np.ndarray
    albedo: np.ndarray
    flags: np.ndarray
    used: np.ndarray
    robust_used: str | None = None
    lobe_share: float | None = None


def check_lights(light_directions: np.ndarray, light_irradiance: np.ndarray) -> None:
    """Check that lights determine a normal: at least 3, not (nearly) coplanar, irradiance
    positive in every channel.

    Parameters
    ----------
    light_directions, light_irradiance : numpy.ndarray
        (K, 3) each, as for `photometric_stereo`.

    Raises
    ------
    ArgumentError
        Naming the field (``lights`` or ``lights[k].irradiance``) and the problem.
    """
    _core.check_lights(*checked_lights(light_directions, light_irradiance))


def checked_lights(light_directions, light_irradiance, count: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """`light_directions` and `light_irradiance` as the core takes them, C-contiguous
    float32 (K, 3) arrays: K = `count` (the images') if given, finite values, each light's
    irradiance in range (`irtps.model.scene.irradiance_problem`).

    Raises
    ------
    ArgumentError
        Naming the argument, or ``light_irradiance[k]``.

    Examples
    --------
    >>> checked_lights([[0, 0, 1]], [[1e308, 1, 1]])
    Traceback (most recent call last):
    ...
    irtps.errors.ArgumentError: light_irradiance[0]: has channel 0 = 1e+308, out of range: expected 0 or a number from 1e-09 to 1e+09
    """
    match = None if count is None else "the images"
    arrays = []
    for name, value in (("light_directions", light_directions), ("light_irradiance", light_irradiance)):
        array = check_array(name, value, (count, 3), match=match)
        check_finite(name, array, unit="light")
        arrays.append(array)
    directions, irradiance = arrays
    for k, light in enumerate(irradiance):
        problem = irradiance_problem(light)
        if problem is not None:
            raise ArgumentError(f"light_irradiance[{k}]", problem)
    return np.ascontiguousarray(directions, dtype=np.float32), np.ascontiguousarray(irradiance, dtype=np.float32)


@document_choices(robust=ROBUST_CHOICES)
def photometric_stereo(
    images: np.ndarray,
    light_directions: np.ndarray,
    light_irradiance: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    robust: str = "auto",
    shadow_fraction: float = 0.05,
    saturation: float | None = None,
    views: np.ndarray | None = None,
    progress: bool = False,
) -> PsResult:
    """Fit a normal and an RGB albedo per pixel to images under known distant lights.

    Image k holds ``ρ ⊙ E_k (n·l_k) / π`` (the scene contract); each channel is divided by
    its irradiance, the normal is the least-squares fit ``(LᵀL)⁻¹Lᵀb`` over all three
    channels and each channel's albedo the least-squares scale along it.

    Parameters
    ----------
    images : numpy.ndarray
        (K, H, W, 3) linear images, one per light.
    light_directions : numpy.ndarray
        (K, 3) unit vectors toward the lights (x right, y up, z toward the camera); or
        (N, K, 3), each light's direction at each of the mask's N pixels (row-major), for
        lights whose direction changes across the object (point lights near it:
        `irtps.model.scene.lights_at` at the surface's points).
    light_irradiance : numpy.ndarray
        (K, 3) RGB irradiance of each light; or (N, K, 3), at each of the mask's pixels,
        with per-pixel directions.
    mask : numpy.ndarray, optional
        (H, W) bool; default every pixel.
    robust : str
        Which observations each pixel's fit uses. Every mode but ``"none"`` leaves saturated
        observations out.

        - ``"tukey"``: from the threshold fit, re-weight every observation that
          the fit lights by Tukey's biweight of its residual over the pixel's robust scale
          (1.4826 × the median absolute residual; weight 0 beyond 2.5 scales), until the fit
          settles. Soft and cast shadows fall below the fit, highlights above it.
        - ``"lobe"``: for glossy and metallic objects (polished metal, metallic paint,
          glazes whose highlight is broad), whose highlights are too wide to be outliers.
          From the Tukey fit, each pixel fits a Lambertian base plus one Blinn-Phong lobe
          about the half vector with the camera, ``[n·l]₊ (a + c (n·h)^p)`` (``a, c ≥ 0``,
          the best ``p`` of 1, 2, 4, …, 128), re-weighted by Tukey's biweight; the albedo
          is each channel's diffuse term, without the highlight. A pixel keeps its Tukey
          fit unless the lobe lowers Tukey's loss by more than the Bayesian information
          criterion asks for its two extra parameters, or when it lights fewer than 6
          unsaturated observations; pixels fitted with a lobe are flagged (`LOBE`).
          About two orders of magnitude slower than ``"tukey"`` (seconds on a DiLiGenT
          object; docs/accuracy.md), and worse than it on matte objects with deep folds, where it can take inter-reflected light
          for a lobe. `lobe_share` tells which objects want it, and `choose_robust` picks
          it from there (as ``"auto"`` does).
        - ``"auto"`` (default, as in ``irtps.reconstruct``): ``"lobe"`` for an object most of
          whose pixels take a specular lobe, else ``"tukey"`` (`choose_robust`), by the
          object's `lobe_share` (under per-pixel lights, of up to `LOBE_SAMPLE` pixels
          spread over the mask, fitted with their own lights). The share's first pixels are fitted beside the Tukey fit,
          on the same threads, so that a matte object costs little more than the Tukey fit
          alone; the result tells the mode chosen and the share.
        - ``"threshold"``: drop observations in shadow (channel sum below `shadow_fraction`
          of the pixel's brightest) and re-solve from the rest. The better choice on very
          rough matte surfaces (plaster, unglazed clay), whose fall-off departs from
          Lambert's on every observation.
        - ``"trim"``: keep the observations between the darkest 40 % and the brightest
          20 % of the pixel's.
        - ``"none"``: plain least squares on every observation.

        Where a selection leaves fewer than 3 non-coplanar lights, the pixel falls back to a
        wider one and is flagged (`FULL_FIT`): threshold to every observation, trim to
        every unsaturated one (then every one), Tukey's start as threshold. A re-weighting
        that leaves fewer than 4 stops, and Tukey keeps the fit before it.
    shadow_fraction : float
        Shadow threshold of the threshold mode (and the Tukey mode's start).
    saturation : float, optional
        Raw value at or above which an observation is saturated.
    views : numpy.ndarray, optional
        (H, W, 3) unit direction from each pixel's surface point toward the camera, which
        the lobe mode's half vectors take (`irtps.model.camera.Camera.view_directions`: a
        pinhole's turn pixel by pixel); default a distant camera along +z.
    progress : bool
        Show a progress bar on standard error (from half a second on): the fit runs in
        bands of rows, each pixel's fit the same as in one call. For the lobe mode, which
        takes minutes on a large capture.

    Returns
    -------
    PsResult

    Raises
    ------
    ArgumentError
        Fewer than 3 lights, coplanar lights, shapes that disagree, a
        ``shadow_fraction`` outside [0, 1), a ``saturation`` that is not positive, an
        unknown ``robust`` mode, or `views` that are not unit vectors toward the camera.

    Examples
    --------
    >>> import numpy as np
    >>> lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8]])
    >>> normal = np.array([0.0, 0.6, 0.8])
    >>> images = (0.5 * np.clip(lights @ normal, 0, None))[:, None, None, None] * np.ones((4, 1, 1, 3))
    >>> fit = photometric_stereo(images, lights, np.full((4, 3), np.pi))
    >>> print(np.round(fit.normals[0, 0], 4), np.round(fit.albedo[0, 0], 4))
    [0.  0.6 0.8] [0.5 0.5 0.5]
    """
    images = np.ascontiguousarray(
        check_array("images", images, (None, None, None, 3), dtype=np.float32, copy=False, nonempty=True)
    )
    mask = np.ascontiguousarray(check_mask(mask, images.shape[1:3], match="images"))
    check_images_finite("images", images, mask)
    check_choice("robust", robust, ROBUST_CHOICES)
    views = _checked_views(views, images.shape[1:3])
    if np.ndim(light_directions) == 3:
        return _fit_per_pixel(
            images, mask, light_directions, light_irradiance, robust, shadow_fraction, saturation, views
        )
    if robust == "auto":
        return _fit_auto(images, mask, light_directions, light_irradiance, shadow_fraction, saturation, views, progress)
    settings = _core_settings(images, light_directions, light_irradiance, robust, shadow_fraction, saturation)
    if not progress:
        return PsResult(*_core.photometric_stereo(images, mask, *settings, views=views))
    return _fit_in_bands(images, mask, settings, views)


def _fit_per_pixel(
    images: np.ndarray,
    mask: np.ndarray,
    light_directions,
    light_irradiance,
    robust: str,
    shadow_fraction: float,
    saturation: float | None,
    views: np.ndarray | None,
) -> PsResult:
    """`photometric_stereo` of float32 `images` under lights given at each of the mask's
    pixels ((N, K, 3) each); ``"auto"`` chooses by the lobe share of up to `LOBE_SAMPLE` of
    them (`choose_robust`)."""
    shape = (int(mask.sum()), len(images), 3)
    arrays = []
    for name, value in (("light_directions", light_directions), ("light_irradiance", light_irradiance)):
        array = check_array(name, value, shape, dtype=np.float32)
        check_finite(name, array, unit="light")
        arrays.append(np.ascontiguousarray(array))
    directions, irradiance = arrays
    positive = irradiance > 0
    bad = (irradiance < 0) | (positive & ((irradiance < MIN_IRRADIANCE) | (irradiance > MAX_IRRADIANCE)))
    if bad.any():
        pixel, k, channel = np.argwhere(bad)[0]
        raise ArgumentError(
            f"light_irradiance[{pixel}, {k}]",
            f"channel {channel} = {irradiance[pixel, k, channel]:g}: expected 0 or a number from "
            f"{MIN_IRRADIANCE:g} to {MAX_IRRADIANCE:g}",
        )
    _, _, _, shadow_fraction, saturation = _core_settings(
        images, directions[0], irradiance[0], "lobe" if robust == "auto" else robust, shadow_fraction, saturation
    )
    if robust != "auto":
        return PsResult(
            *_core.photometric_stereo_per_pixel(
                images, mask, directions, irradiance, robust, shadow_fraction, saturation, views=views
            )
        )
    # The lobe share of up to LOBE_SAMPLE spread pixels, fitted as `lobe_share` fits them.
    sample = np.zeros_like(mask)
    sample.flat[spread_pixels(mask, LOBE_SAMPLE)] = True
    among = np.searchsorted(np.flatnonzero(mask), np.flatnonzero(sample))
    flags = _core.photometric_stereo_per_pixel(
        images,
        sample,
        np.ascontiguousarray(directions[among]),
        np.ascontiguousarray(irradiance[among]),
        "lobe",
        shadow_fraction,
        saturation,
        lobe_rounds=LOBE_CHECK_ROUNDS,
        views=views,
    )[2]
    share = float((flags[sample] == LOBE).mean())
    chosen = choose_robust(share)
    fit = _core.photometric_stereo_per_pixel(
        images, mask, directions, irradiance, chosen, shadow_fraction, saturation, views=views
    )
    return PsResult(*fit, robust_used=chosen, lobe_share=share)


def _checked_views(views, size: tuple[int, int]) -> np.ndarray | None:
    """`views` as C-contiguous float32 (H, W, 3) of images of `size`, or None; an
    `ArgumentError` naming them unless each is a unit vector toward the camera (z > 0)."""
    if views is None:
        return None
    views = np.ascontiguousarray(check_array("views", views, (*size, 3), dtype=np.float32, match="the images"))
    check_finite("views", views)
    length = np.linalg.norm(views, axis=-1)
    bad = (np.abs(length - 1) > 1e-3) | (views[..., 2] <= 0)
    if bad.any():
        row, column = np.argwhere(bad)[0]
        raise ArgumentError(
            "views",
            f"{views[row, column].tolist()} at row {row}, column {column} is not a unit vector toward the camera (z > 0)",
        )
    return views


def _fit_auto(
    images: np.ndarray,
    mask: np.ndarray,
    light_directions: np.ndarray,
    light_irradiance: np.ndarray,
    shadow_fraction: float,
    saturation: float | None,
    views: np.ndarray | None,
    progress: bool,
) -> PsResult:
    """`photometric_stereo` of float32 `images` with ``robust="auto"``: the Tukey fit and,
    beside it in the same call, `lobe_share`'s first pixels; then the rest of the check, if
    those leave the share undecided, and the lobe fit, if it is chosen."""
    settings = _core_settings(images, light_directions, light_irradiance, "lobe", shadow_fraction, saturation)
    directions, irradiance, _, shadow_fraction, saturation = settings
    check = _LobeCheck(mask, LOBE_SAMPLE)
    tukey, flags = _core.tukey_with_lobe_check(
        images,
        mask,
        check.next_indices(mask.shape[1]),
        directions,
        irradiance,
        shadow_fraction,
        saturation,
        LOBE_CHECK_ROUNDS,
        views=views,
    )
    check.record(flags)
    while not check.done(stop_early=True):
        check.fit_next(images, settings, views)
    chosen = choose_robust(check.share)
    if chosen == "tukey":
        return PsResult(*tukey, robust_used=chosen, lobe_share=check.share)
    fit = photometric_stereo(
        images,
        directions,
        irradiance,
        mask,
        robust=chosen,
        shadow_fraction=shadow_fraction,
        saturation=saturation,
        views=views,
        progress=progress,
    )
    return dataclasses.replace(fit, robust_used=chosen, lobe_share=check.share)


#: The arguments of `_core.photometric_stereo` after the images and the mask: directions,
#: irradiance, robust mode, shadow fraction, saturation.
_CoreSettings = tuple[np.ndarray, np.ndarray, str, float, float | None]


def _core_settings(
    images: np.ndarray,
    light_directions: np.ndarray,
    light_irradiance: np.ndarray,
    robust: str,
    shadow_fraction: float,
    saturation: float | None,
) -> _CoreSettings:
    """The arguments of `_core.photometric_stereo` after `images` and the mask, checked."""
    directions, irradiance = checked_lights(light_directions, light_irradiance, len(images))
    check_choice("robust", robust, ROBUST_MODES)
    shadow_fraction = check_number("shadow_fraction", shadow_fraction, what="a number in [0, 1)")
    if not 0 <= shadow_fraction < 1:
        raise ArgumentError("shadow_fraction", f"{shadow_fraction} is not in [0, 1)")
    if saturation is not None:
        saturation = check_positive("saturation", saturation)
    return (directions, irradiance, robust, shadow_fraction, saturation)


#: Bands of rows a fit with a progress bar runs in.
PROGRESS_BANDS = 50


def _fit_in_bands(images: np.ndarray, mask: np.ndarray, settings: _CoreSettings, views: np.ndarray | None) -> PsResult:
    """`_core.photometric_stereo` of `images` and `mask` with `settings` and `views`, band of
    rows by band of rows under a progress bar (counting the mask's pixels), joined."""
    rows = images.shape[1]
    band = -(-rows // PROGRESS_BANDS)
    parts = []
    with tqdm(total=int(mask.sum()), unit="px", desc="photometric stereo", leave=False, delay=0.5) as bar:
        for start in range(0, rows, band):
            rows_here = slice(start, min(start + band, rows))
            parts.append(
                _core.photometric_stereo(
                    np.ascontiguousarray(images[:, rows_here]),
                    np.ascontiguousarray(mask[rows_here]),
                    *settings,
                    views=None if views is None else np.ascontiguousarray(views[rows_here]),
                )
            )
            bar.update(int(mask[rows_here].sum()))
    normals, albedo, flags, used = (np.concatenate(arrays) for arrays in zip(*parts))
    return PsResult(normals, albedo, flags, used)


#: Object pixels `lobe_share` fits at most, by default.
LOBE_SAMPLE = 1000
#: Object pixels `lobe_share` fits first; it doubles them until the share is clearly on one
#: side of `LOBE_ADVISED` (`share_is_decided`) or `LOBE_SAMPLE` are fitted.
LOBE_FIRST = 64
#: Rounds of each exponent's fit, from each start, in `lobe_share`'s fits (the lobe mode's
#: own fit has 15): half the cost per pixel. The shares come out a few points lower than
#: after 15 rounds, some pixels taking a lobe only in later rounds, and the real and rendered
#: objects of docs/benchmarks.md (Photometric stereo on rendered materials) fall on the same
#: side of `LOBE_ADVISED` either way (tests/test_ps.py checks a metal under 24 lights).
LOBE_CHECK_ROUNDS = 5
#: Standard deviations of the Wilson score interval by which `share_is_decided` judges a share
#: clearly on one side of `LOBE_ADVISED`: about one chance in 740 per look that a binomial
#: sample so far off the line comes from a share on its other side.
LOBE_DECIDED_Z = 3.0
#: From this `lobe_share` on, most of the object reflects a broad highlight: `choose_robust`
#: fits it with ``robust="lobe"``, and a run with another mode advises that one.
LOBE_ADVISED = 0.5


def choose_robust(share: float) -> str:
    """The robust mode for an object whose `lobe_share` is `share` (the choice of
    ``irtps reconstruct --robust auto``, the default).

    ``"lobe"`` from `LOBE_ADVISED` on (most of the object reflects a broad highlight, as
    metal, metallic paint and broad glazes do), else ``"tukey"``: the lobe mode is the better
    fit of such objects and the slower and worse one of matte objects with deep folds
    (docs/benchmarks.md, Photometric stereo on rendered materials).

    Parameters
    ----------
    share : float
        The object's `lobe_share`, in [0, 1].

    Returns
    -------
    str
        A robust mode of `photometric_stereo`.

    Raises
    ------
    ArgumentError
        If `share` is not a number in [0, 1].

    Examples
    --------
    >>> choose_robust(0.87), choose_robust(0.5), choose_robust(0.12)
    ('lobe', 'lobe', 'tukey')
    """
    fraction = check_number("share", share, what="a number in [0, 1]")
    if not 0 <= fraction <= 1:
        raise ArgumentError("share", f"expected a number in [0, 1], got {share!r}")
    return "lobe" if fraction >= LOBE_ADVISED else "tukey"


def format_lobe_share(share: float, robust_used: str | None = None, *, auto: bool = False) -> str:
    """One sentence on a `lobe_share` and on what it made of the fit.

    Parameters
    ----------
    share : float
        The object's `lobe_share`.
    robust_used : str, optional
        The robust mode the fit used: a ``"lobe"`` fit is said to be one; another mode gets
        the advice from `LOBE_ADVISED` on.
    auto : bool
        The share chose the mode (`choose_robust`): the sentence gives the line instead.

    Examples
    --------
    >>> format_lobe_share(0.87)
    "87 % of the object's pixels take a specular lobe: robust mode 'lobe' (--robust lobe) is advised"
    >>> format_lobe_share(0.87, "lobe")
    "87 % of the object's pixels take a specular lobe: fitted with robust mode 'lobe'"
    >>> format_lobe_share(0.12, "tukey")
    "12 % of the object's pixels take a specular lobe"
    >>> format_lobe_share(0.12, auto=True)
    "12 % of the object's pixels take a specular lobe (lobe from 50 %)"
    """
    sentence = f"{100 * share:.0f} % of the object's pixels take a specular lobe"
    if auto:
        return f"{sentence} (lobe from {100 * LOBE_ADVISED:.0f} %)"
    if robust_used == "lobe":
        return sentence + ": fitted with robust mode 'lobe'"
    return sentence + (": robust mode 'lobe' (--robust lobe) is advised" if share >= LOBE_ADVISED else "")


def lobe_share(
    images: np.ndarray,
    light_directions: np.ndarray,
    light_irradiance: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    sample: int = LOBE_SAMPLE,
    stop_early: bool = True,
    shadow_fraction: float = 0.05,
    saturation: float | None = None,
    views: np.ndarray | None = None,
) -> float:
    """The share of the object's pixels that the lobe mode's fit, cut short, gives a
    specular lobe.

    Up to `sample` of the mask's pixels, spread evenly over it (all of them when fewer), are
    fitted as ``robust="lobe"`` fits them, but with `LOBE_CHECK_ROUNDS` rounds per exponent
    instead of 15: first `LOBE_FIRST` of them, spread over the mask too, then twice as many
    at each step, until the share of those fitted is clearly on one side of `LOBE_ADVISED`
    (`share_is_decided`), which is all that `choose_robust` asks of it. So a matte object is
    told from a metal on 64 pixels, and an object near the line is measured on all `sample`,
    with the same share as in one fit of them all.

    A broad highlight that covers many lights (metal, metallic paint, a broad glaze) is what
    the lobe explains; on a matte object with shadows and inter-reflection few pixels take
    one: Lambertian surfaces and DiLiGenT's matte objects stay well below `LOBE_ADVISED`,
    broad plastics and rough metals above it (the measured shares of real objects and of
    renders in six materials are in docs/accuracy.md). Where most pixels take one, the
    lobe mode fits the object better than the Tukey fit.

    Parameters
    ----------
    images, light_directions, light_irradiance, mask
        As for `photometric_stereo`.
    sample : int
        Most pixels fitted.
    stop_early : bool
        Stop once the share is clearly on one side of `LOBE_ADVISED`; ``False`` measures it
        on all `sample` pixels.
    shadow_fraction, saturation, views
        As for `photometric_stereo`.

    Returns
    -------
    float
        In [0, 1]; 0 for an empty mask.

    Raises
    ------
    ArgumentError
        As `photometric_stereo`, or a `sample` below 1.

    Examples
    --------
    >>> import numpy as np
    >>> lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8], [0, -0.6, 0.8]])
    >>> images = (0.5 * np.clip(lights @ [0.0, 0.6, 0.8], 0, None))[:, None, None, None] * np.ones((5, 1, 1, 3))
    >>> lobe_share(images, lights, np.full((5, 3), np.pi))  # a matte pixel takes no lobe
    0.0
    """
    images = check_array("images", images, (None, None, None, 3), dtype=None, nonempty=True)
    mask = check_mask(mask, images.shape[1:3], match="images")
    check_images_finite("images", images, mask)
    if isinstance(sample, bool) or not (isinstance(sample, (int, np.integer)) and sample >= 1):
        raise ArgumentError("sample", f"{sample!r} is not a positive integer")
    settings = _core_settings(images, light_directions, light_irradiance, "lobe", shadow_fraction, saturation)
    views = _checked_views(views, images.shape[1:3])
    check = _LobeCheck(mask, int(sample))
    while not check.done(stop_early):
        check.fit_next(images, settings, views)
    return check.share


class _LobeCheck:
    """`lobe_share`'s look at the pixels of a mask, batch by batch: which pixels it fits, in
    which order, and what it has counted so far."""

    def __init__(self, mask: np.ndarray, sample: int) -> None:
        chosen = spread_pixels(mask, sample)
        self.rows, self.cols = np.unravel_index(chosen[coarse_to_fine(chosen.size)], mask.shape)
        self.fitted = self.lobes = self.batch = 0

    def done(self, stop_early: bool) -> bool:
        """Whether every chosen pixel is fitted, or (`stop_early`) the share is decided."""
        if self.fitted == self.rows.size:
            return True
        return stop_early and self.fitted > 0 and share_is_decided(self.lobes, self.fitted)

    def fit_next(self, images: np.ndarray, settings: _CoreSettings, views: np.ndarray | None = None) -> None:
        """Fit the next batch's pixels of `images` (seen along `views`) in the lobe mode with
        `LOBE_CHECK_ROUNDS` rounds, the other `_core.photometric_stereo` arguments
        `settings`, and count them."""
        rows, cols = self._next()
        observed = np.ascontiguousarray(
            images[:, rows, cols][:, None], dtype=np.float32
        )  # (K, 1, N, 3): one row of pixels
        seen = None if views is None else np.ascontiguousarray(views[rows, cols][None])
        flags = _core.photometric_stereo(
            observed, np.ones(observed.shape[1:3], bool), *settings, LOBE_CHECK_ROUNDS, views=seen
        )[2][0]
        self.record(flags)

    def next_indices(self, width: int) -> list[int]:
        """The flat indices of the next batch's pixels, in images `width` pixels wide, for a
        fit elsewhere (`record` its flags)."""
        rows, cols = self._next()
        return (rows * width + cols).tolist()

    def _next(self) -> tuple[np.ndarray, np.ndarray]:
        """The rows and columns of the next batch: `LOBE_FIRST` pixels, then as many as are
        fitted already (all that are left at most)."""
        upto = min(max(LOBE_FIRST, 2 * self.fitted), self.rows.size)
        self.batch = upto - self.fitted
        return self.rows[self.fitted : upto], self.cols[self.fitted : upto]

    def record(self, flags: np.ndarray) -> None:
        """Count the next batch's flags (N,)."""
        self.lobes += int((flags == LOBE).sum())
        self.fitted += self.batch

    @property
    def share(self) -> float:
        """The share of the pixels fitted so far that took a lobe (0 before any)."""
        return self.lobes / self.fitted if self.fitted else 0.0


def share_is_decided(lobes: int, fitted: int) -> bool:
    """Whether `lobes` pixels with a lobe among `fitted` (spread over the object) put its
    `lobe_share` clearly on one side of `LOBE_ADVISED`: the Wilson score interval of
    `LOBE_DECIDED_Z` standard deviations does not hold the line.

    Examples
    --------
    >>> share_is_decided(13, 64), share_is_decided(25, 64), share_is_decided(90, 256)
    (True, False, True)
    """
    share, z2 = lobes / fitted, LOBE_DECIDED_Z**2
    centre = (share + z2 / (2 * fitted)) / (1 + z2 / fitted)
    half_width = LOBE_DECIDED_Z * np.sqrt(share * (1 - share) / fitted + z2 / (4 * fitted**2)) / (1 + z2 / fitted)
    return bool(abs(centre - LOBE_ADVISED) > half_width)
