"""Discontinuity-preserving integration (method "bilateral"), against analytic surfaces and
DiLiGenT reading's ground-truth depth (tests/data/diligent_reading_depth)."""

from pathlib import Path

import numpy as np
import pytest

import irtps
from irtps.geometry.bilateral_integration import integrate_bilateral

READING = Path(__file__).parent / "data" / "diligent_reading_depth" / "reading.npz"


def _reading():
    data = np.load(READING)
    return data["normals"].astype(np.float32), data["mask"], data["depth"], data["intrinsics"]


def _made(estimate, truth, mask):
    """BiNI's depth error: the estimate scaled by the median ratio, mean absolute difference."""
    known = mask & np.isfinite(truth)
    scale = np.median(truth[known] / estimate[known])
    return float(np.abs(scale * estimate[known] - truth[known]).mean())


def test_reading_depth_from_its_true_normals_is_within_half_a_millimetre():
    normals, mask, depth, intrinsics = _reading()
    result = integrate_bilateral(normals, mask, intrinsics=intrinsics)
    assert result.converged
    # Every second pixel of the object (1.6 mm footprints); least squares joins the folds and
    # the book with ramps (7.0 mm, below), the bilateral weights cut them (0.44 mm measured).
    assert _made(result.surface, depth, mask) < 0.6
    assert np.isnan(result.surface[~mask]).all() and (result.surface[mask] > 0).all()


def test_least_squares_ramps_where_reading_has_depth_jumps():
    normals, mask, depth, intrinsics = _reading()
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    unit = normals / np.where(length > 0, length, 1)
    values, _, iterations, _ = irtps._core.integrate_bilateral(
        np.ascontiguousarray(np.where(mask[..., None], unit, 0), dtype=np.float32),
        mask,
        (intrinsics[0, 0], intrinsics[1, 1], intrinsics[0, 2], intrinsics[1, 2]),
        2.0,
        1,
        1e-4,
    )
    assert iterations == 1 and _made(np.exp(values), depth, mask) > 5.0


def test_the_edges_cut_are_where_reading_jumps_in_depth():
    normals, mask, depth, intrinsics = _reading()
    cut = integrate_bilateral(normals, mask, intrinsics=intrinsics).discontinuities
    # The depth step of each edge, in pixel footprints (depth / focal length).
    footprint = np.nanmedian(depth[mask]) / intrinsics[0, 0]
    right = np.abs(depth[:, 1:] - depth[:, :-1]) / footprint
    down = np.abs(depth[1:] - depth[:-1]) / footprint
    steps = np.concatenate([right[cut[:, :-1, 0]], down[cut[:-1, :, 1]]])
    steps = steps[np.isfinite(steps)]
    assert steps.size > 100
    # Smooth edges of this object step by well under a footprint; most cut ones by several.
    assert np.median(steps) > 3.0
    smooth = np.concatenate(
        [right[mask[:, 1:] & mask[:, :-1] & ~cut[:, :-1, 0]], down[mask[1:] & mask[:-1] & ~cut[:-1, :, 1]]]
    )
    assert np.nanmedian(smooth) < 0.5


def test_an_orthographic_plane_is_integrated_exactly_and_centred():
    normal = np.array([-0.5, -0.25, 1.0]) / np.linalg.norm([-0.5, -0.25, 1.0])
    mask = np.ones((20, 30), bool)
    mask[:, 12] = False
    height = irtps.integrate_normals(np.broadcast_to(normal, (20, 30, 3)), mask, pixel_size=2.0, method="bilateral")
    assert height.dtype == np.float32 and (height[~mask] == 0).all()
    assert np.allclose(height[0, 1] - height[0, 0], 1.0, atol=1e-4)
    assert np.allclose(height[0, 0] - height[1, 0], 0.5, atol=1e-4)
    # Each part of the mask is centred on its own.
    assert abs(float(height[:, :12].mean())) < 1e-4 and abs(float(height[:, 13:].mean())) < 1e-4


@pytest.mark.parametrize(
    ("intrinsics", "message"),
    [
        (np.eye(2), "intrinsics: shape (2, 2), expected (3, 3)"),
        ([[10, 0.5, 5], [0, 10, 5], [0, 0, 1]], "intrinsics: skew"),
        ([[10, 0, 5], [0, 10, 5], [0, 0, 2]], "intrinsics: the last row is [0.0, 0.0, 2.0]"),
        ([[-10, 0, 5], [0, 10, 5], [0, 0, 1]], "intrinsics (fx): = -10: a focal length"),
        ([[10, 0, np.nan], [0, 10, 5], [0, 0, 1]], "intrinsics: non-finite value"),
        ([[10, 0, 500], [0, 10, 5], [0, 0, 1]], "intrinsics (cx): = 500 lies more than 1 image width outside"),
    ],
)
def test_intrinsics_that_are_not_a_pinholes_are_refused_by_name(intrinsics, message):
    normals = np.broadcast_to([0.0, 0.0, 1.0], (10, 10, 3))
    with pytest.raises(irtps.ArgumentError) as caught:
        irtps.integrate_normals(normals, intrinsics=intrinsics)
    assert str(caught.value).startswith(message), str(caught.value)


def test_an_orthographic_method_with_intrinsics_and_a_zero_normal_are_refused():
    normals = np.zeros((6, 6, 3))
    normals[..., 2] = 1
    K = [[10, 0, 3], [0, 10, 3], [0, 0, 1]]
    with pytest.raises(irtps.ArgumentError, match="^method: 'ls' integrates heights seen orthographically"):
        irtps.integrate_normals(normals, intrinsics=K, method="ls")
    normals[2, 3] = 0
    with pytest.raises(irtps.ArgumentError, match="^normals: zero normal at row 2, column 3"):
        irtps.integrate_normals(normals, intrinsics=K)
