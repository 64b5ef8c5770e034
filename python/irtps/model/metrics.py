"""Accuracy of a reconstruction against ground truth: normals, albedo and heights.

Besides the usual angular normal error, this reports the paper's metrics
(``docs/`` and the IRT-PS paper, section "Experiments and Results"):

- height error: the mean of ``|H_gt − H|`` over the evaluated pixels;
- albedo error: the mean of ``|ρ_gt − ρ|`` over the pixels, per channel, then the
  average of the R, G and B means;
- normal error: the mean of ``|n_gt − n|`` over the pixels, per component x, y, z,
  then the average of the three means.

Only pixels that are in the mask *and* have valid ground truth are evaluated: when a
ground-truth normal map is given, its zero or non-finite normals (the background of
DiLiGenT's and the contract's normal maps) are left out, and so are pixels where a
given ground-truth height or albedo is not finite. The same pixels are used for every
metric, so the metrics of one call are comparable with each other.

Nothing is rescaled: a reconstructed albedo that differs from the truth by the lights'
intensity scale is reported as it is.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from irtps._shared.checks import check_finite, check_image, check_instance, check_mask, check_number
from irtps.model.data import GroundTruth

__all__ = ["ErrorMaps", "Metrics", "angular_error_deg", "error_maps", "evaluate", "format_metrics"]


@dataclass(frozen=True)
class Metrics:
    """Accuracy of a reconstruction; a field is None when it cannot be computed.

    A metric is None when the reconstruction or the ground truth lacks the piece it
    needs, or when no pixel is evaluated.

    Attributes
    ----------
    pixels : int
        Number of evaluated pixels: in the mask and with valid ground truth.
    normal_mean_angular_deg, normal_median_angular_deg : float or None
        Mean and median angle between reconstructed and true normals, in degrees.
    normal_component_error : float or None
        The paper's normal error: mean ``|n_gt − n|`` per component x, y, z (both
        normalised to unit length first), averaged over the three components.
    albedo_error : float or None
        The paper's albedo error: mean ``|ρ_gt − ρ|`` per channel, averaged over R, G, B.
    albedo_error_rgb : tuple of float or None
        The three per-channel means (R, G, B).
    height_error : float or None
        The paper's height error: mean ``|H_gt − H|`` of the heights as reconstructed.
    height_error_aligned : float or None
        Mean ``|H_gt − H − c|`` after removing the best constant offset ``c`` for this
        error, which is the median of the differences ``H_gt − H``.
    height_rmse_aligned : float or None
        Root mean square of ``H_gt − H − c'`` with the best constant for it, ``c'`` the
        *mean* of the differences (i.e. their standard deviation).
    height_offset : float or None
        The offset ``c`` removed for `height_error_aligned`: median of ``H_gt − H``.
    """

    pixels: int = 0
    normal_mean_angular_deg: float | None = None
    normal_median_angular_deg: float | None = None
    normal_component_error: float | None = None
    albedo_error: float | None = None
    albedo_error_rgb: tuple[float, float, float] | None = None
    height_error: float | None = None
    height_error_aligned: float | None = None
    height_rmse_aligned: float | None = None
    height_offset: float | None = None

    def to_dict(self) -> dict:
        """The metrics as a JSON-ready dict (plain ints, floats, lists and None).

        Returns
        -------
        dict

        Examples
        --------
        >>> Metrics(pixels=2, albedo_error_rgb=(0.1, 0.2, 0.3)).to_dict()["albedo_error_rgb"]
        [0.1, 0.2, 0.3]
        """
        result = {}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, tuple):
                value = [float(v) for v in value]
            elif isinstance(value, (float, np.floating)):
                value = float(value)
            elif isinstance(value, (int, np.integer)):
                value = int(value)
            result[field.name] = value
        return result


@dataclass(frozen=True)
class ErrorMaps:
    """Per-pixel errors for reports: float32 (H, W) maps, NaN where not evaluated.

    The NaN-mean of each map is the matching `Metrics` field.

    Attributes
    ----------
    angular_deg : numpy.ndarray or None
        Angle between reconstructed and true normal, degrees
        (mean: `Metrics.normal_mean_angular_deg`).
    albedo : numpy.ndarray or None
        ``|ρ_gt − ρ|`` averaged over R, G, B (mean: `Metrics.albedo_error`).
    height_aligned : numpy.ndarray or None
        ``|H_gt − H − c|`` with ``c`` the median of ``H_gt − H``
        (mean: `Metrics.height_error_aligned`).
    """

    angular_deg: np.ndarray | None = None
    albedo: np.ndarray | None = None
    height_aligned: np.ndarray | None = None


def angular_error_deg(normals: np.ndarray, normals_gt: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Angle between two normal maps, per pixel, in degrees.

    Both normals are normalised first and their dot product is clipped to [−1, 1].
    A zero reconstructed normal (a pixel the reconstruction gave up on) counts as 90°.

    Parameters
    ----------
    normals : numpy.ndarray
        (H, W, 3) reconstructed normals.
    normals_gt : numpy.ndarray
        (H, W, 3) true normals.
    mask : numpy.ndarray
        (H, W) bool, the pixels to evaluate.

    Returns
    -------
    numpy.ndarray
        float32 (H, W) angles in degrees; NaN outside the mask and where the true
        normal is zero or not finite.

    Raises
    ------
    ArgumentError
        (an `IrtpsError`) naming the argument whose shape disagrees, or ``normals``
        if it is not finite on an evaluated pixel.

    Examples
    --------
    >>> import numpy as np
    >>> up = np.zeros((1, 2, 3)); up[..., 2] = 1.0
    >>> tilt = np.radians(10.0)
    >>> n = up.copy(); n[0, 0] = [np.sin(tilt), 0.0, np.cos(tilt)]
    >>> np.round(angular_error_deg(n, up, np.array([[True, False]])), 4).tolist()
    [[10.0, nan]]
    """
    mask = check_mask(mask)
    normals = check_image("normals", normals, mask, finite=False)
    normals_gt = check_image("normals_gt", normals_gt, mask, finite=False)
    valid = mask & _valid_normals(normals_gt)
    check_finite("normals", normals, valid)
    return _angular_map(normals, normals_gt, valid)


def evaluate(
    *,
    mask: np.ndarray,
    normals: np.ndarray | None = None,
    albedo: np.ndarray | None = None,
    height: np.ndarray | None = None,
    gt: GroundTruth | None,
    base_height: float = 0.0,
) -> Metrics:
    """Compare a reconstruction with ground truth.

    Parameters
    ----------
    mask : numpy.ndarray
        (H, W) bool, the object's pixels; only these (with valid ground truth, see the
        module's description) are evaluated.
    normals : numpy.ndarray, optional
        (H, W, 3) reconstructed normals in the contract's frame.
    albedo : numpy.ndarray, optional
        (H, W, 3) reconstructed RGB albedo, compared as it is (no rescaling).
    height : numpy.ndarray, optional
        (H, W) reconstructed heights (world z).
    gt : GroundTruth or None
        The truth; None or missing parts leave the matching metrics None.
    base_height : float
        Added to the true heights before comparing, for ground truth measured from a
        base (e.g. the floor) while ``height`` is world z. 0 when both are in the same
        frame, as in the contract's data sets. Only `Metrics.height_error` (and the
        reported offset) depend on it.

    Returns
    -------
    Metrics

    Raises
    ------
    ArgumentError
        (an `IrtpsError`) naming the argument whose shape disagrees with ``mask``, or a
        reconstruction that is not finite on an evaluated pixel.

    Examples
    --------
    >>> import numpy as np
    >>> from irtps import GroundTruth
    >>> mask = np.ones((2, 2), bool)
    >>> gt = GroundTruth(height=np.array([[1.0, 2.0], [3.0, 4.0]]))
    >>> m = evaluate(mask=mask, height=gt.height + 0.5, gt=gt)
    >>> m.height_error, m.height_error_aligned, m.pixels
    (0.5, 0.0, 4)
    >>> m.normal_mean_angular_deg is None
    True
    """
    metrics, _ = _compare(mask, normals, albedo, height, gt, base_height)
    return metrics


def error_maps(
    *,
    mask: np.ndarray,
    normals: np.ndarray | None = None,
    albedo: np.ndarray | None = None,
    height: np.ndarray | None = None,
    gt: GroundTruth | None,
    base_height: float = 0.0,
) -> ErrorMaps:
    """Per-pixel error maps for reports, over the same pixels as `evaluate`.

    Parameters
    ----------
    mask, normals, albedo, height, gt, base_height
        As for `evaluate`.

    Returns
    -------
    ErrorMaps
        float32 (H, W) maps, NaN on pixels not evaluated; None where `evaluate` gives None.

    Raises
    ------
    ArgumentError
        As for `evaluate`.

    Examples
    --------
    >>> import numpy as np
    >>> from irtps import GroundTruth
    >>> gt = GroundTruth(albedo=np.full((1, 2, 3), 0.5))
    >>> maps = error_maps(mask=np.array([[True, False]]), albedo=np.full((1, 2, 3), 0.25), gt=gt)
    >>> maps.albedo.tolist(), maps.height_aligned is None
    ([[0.25, nan]], True)
    """
    _, maps = _compare(mask, normals, albedo, height, gt, base_height)
    return maps


def format_metrics(metrics: Metrics) -> str:
    """A short human-readable table of the metrics; "n/a" for those not computed.

    Parameters
    ----------
    metrics : Metrics

    Returns
    -------
    str
        One metric a line, without a trailing newline.

    Examples
    --------
    >>> print(format_metrics(Metrics(pixels=4, height_error=0.5, height_error_aligned=0.0,
    ...                              height_rmse_aligned=0.0, height_offset=-0.5)))
    pixels evaluated          4
    normal angle (deg)        n/a
    normal error (paper)      n/a
    albedo error (paper)      n/a
    height error (paper)      0.5
    height error, aligned     0  (median offset -0.5, RMSE 0)
    """
    m = metrics
    normal_angle = "n/a"
    if m.normal_mean_angular_deg is not None:
        normal_angle = f"mean {_num(m.normal_mean_angular_deg)}, median {_num(m.normal_median_angular_deg)}"
    albedo = _num(m.albedo_error)
    if m.albedo_error_rgb is not None:
        r, g, b = (_num(v) for v in m.albedo_error_rgb)
        albedo += f"  (R {r}, G {g}, B {b})"
    aligned = _num(m.height_error_aligned)
    if m.height_error_aligned is not None:
        aligned += f"  (median offset {_num(m.height_offset)}, RMSE {_num(m.height_rmse_aligned)})"
    rows = [
        ("pixels evaluated", str(m.pixels)),
        ("normal angle (deg)", normal_angle),
        ("normal error (paper)", _num(m.normal_component_error)),
        ("albedo error (paper)", albedo),
        ("height error (paper)", _num(m.height_error)),
        ("height error, aligned", aligned),
    ]
    return "\n".join(f"{label:<25} {value}" for label, value in rows)


def _compare(mask, normals, albedo, height, gt, base_height) -> tuple[Metrics, ErrorMaps]:
    mask = check_mask(mask)
    normals = _as_optional("normals", normals, mask, 3)
    albedo = _as_optional("albedo", albedo, mask, 3)
    height = _as_optional("height", height, mask, None)
    gt = GroundTruth() if gt is None else check_instance("gt", gt, GroundTruth)
    gt_normal = _as_optional("gt.normal", gt.normal, mask, 3)
    gt_albedo = _as_optional("gt.albedo", gt.albedo, mask, 3)
    gt_height = _as_optional("gt.height", gt.height, mask, None)
    base_height = check_number("base_height", base_height)

    valid = mask.copy()
    if gt_normal is not None:
        valid &= _valid_normals(gt_normal)
    if gt_albedo is not None:
        valid &= np.isfinite(gt_albedo).all(axis=-1)
    if gt_height is not None:
        valid &= np.isfinite(gt_height)
    for name, value in (("normals", normals), ("albedo", albedo), ("height", height)):
        if value is not None:
            check_finite(name, value, valid)

    pixels = int(valid.sum())
    fields: dict = {"pixels": pixels}
    maps: dict = {}
    if pixels == 0:
        return Metrics(**fields), ErrorMaps()

    if normals is not None and gt_normal is not None:
        angles = _angular_map(normals, gt_normal, valid)
        values = angles[valid].astype(np.float64)
        fields["normal_mean_angular_deg"] = float(values.mean())
        fields["normal_median_angular_deg"] = float(np.median(values))
        difference = np.abs(_unit(gt_normal[valid]) - _unit(normals[valid]))
        fields["normal_component_error"] = float(difference.mean(axis=0).mean())
        maps["angular_deg"] = angles

    if albedo is not None and gt_albedo is not None:
        difference = np.abs(gt_albedo[valid] - albedo[valid])
        per_channel = difference.mean(axis=0)
        fields["albedo_error_rgb"] = tuple(float(v) for v in per_channel)
        fields["albedo_error"] = float(per_channel.mean())
        maps["albedo"] = _scatter(difference.mean(axis=1), valid)

    if height is not None and gt_height is not None:
        difference = (gt_height[valid] + base_height) - height[valid]
        offset = float(np.median(difference))
        aligned = np.abs(difference - offset)
        fields["height_error"] = float(np.abs(difference).mean())
        fields["height_error_aligned"] = float(aligned.mean())
        fields["height_rmse_aligned"] = float(np.sqrt(np.mean((difference - difference.mean()) ** 2)))
        fields["height_offset"] = offset
        maps["height_aligned"] = _scatter(aligned, valid)

    return Metrics(**fields), ErrorMaps(**maps)


def _angular_map(normals: np.ndarray, normals_gt: np.ndarray, valid: np.ndarray) -> np.ndarray:
    cosine = np.sum(_unit(normals[valid]) * _unit(normals_gt[valid]), axis=-1)
    return _scatter(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))), valid)


def _unit(vectors: np.ndarray) -> np.ndarray:
    """Rows of ``vectors`` scaled to unit length; zero rows stay zero."""
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.divide(vectors, length, out=np.zeros_like(vectors), where=length > 0)


def _valid_normals(normals: np.ndarray) -> np.ndarray:
    finite = np.isfinite(normals).all(axis=-1)
    return finite & (np.abs(np.where(finite[..., None], normals, 0.0)).sum(axis=-1) > 0)


def _scatter(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    out = np.full(valid.shape, np.nan, dtype=np.float32)
    out[valid] = values
    return out


def _as_optional(name: str, value, mask: np.ndarray, channels: int | None) -> np.ndarray | None:
    return None if value is None else check_image(name, value, mask, channels=channels, finite=False)


def _num(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.4g}"
