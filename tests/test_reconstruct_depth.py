"""`irtps reconstruct` of a data set seen through a pinhole writes its depth along the optical
axis (depth.exr) and its discontinuities (discontinuities.png), checked against the depth
Mitsuba rendered (tests/data/mitsuba_persp_small, 24x24, 4 lights)."""

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

import irtps
from irtps import _core
from irtps.cli.main import main
from irtps.geometry.boundary import mask_boundary, place_height
from irtps.io.mesh import pinhole_mesh
from irtps.report.build import build_report

DATA = Path(__file__).parent / "data"
PINHOLE = DATA / "mitsuba_persp_small" / "cap_persp_cornell"
ORTHOGRAPHIC = DATA / "mitsuba_small" / "cap_cornell"
MITSUBA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mitsuba"
needs_shared = pytest.mark.skipif(not MITSUBA.is_dir(), reason="shared Mitsuba scenes not available")


def _made(estimate, truth, mask):
    """Mean absolute depth error after the median-ratio scale (BiNI's protocol)."""
    known = mask & np.isfinite(truth) & (estimate > 0)
    scale = np.median(truth[known] / estimate[known])
    return float(np.abs(scale * estimate[known] - truth[known]).mean())


@pytest.fixture(scope="module")
def pinhole():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irtps.IrtpsWarning)
        dataset = irtps.load_dataset(PINHOLE)
        return dataset, irtps.reconstruct(dataset)


def test_the_depth_and_the_heights_of_a_pinhole_agree_with_the_truth_and_each_other(pinhole):
    dataset, result = pinhole
    mask, truth = dataset.mask, dataset.gt.depth
    below_centre = dataset.scene.camera.optical_center[2] - result.height
    # Both integrate along the pinhole's rays (depth.exr keeping discontinuities, the heights
    # by IRT-PS's integration of the depth's logarithm); the object is 13 pixels across.
    assert _made(result.depth, truth, mask) < 0.7 and _made(below_centre, truth, mask) < 0.7
    assert _made(result.depth, below_centre, mask) < 0.2
    # Its scale is the placed heights': the same median depth below the optical centre.
    assert np.median(result.depth[mask]) == pytest.approx(np.median(below_centre[mask]), rel=1e-5)
    assert (result.depth[~mask] == 0).all() and result.discontinuities.shape == (*mask.shape, 2)


@needs_shared
@pytest.mark.parametrize("name", ["cap_persp_cornell", "grooves_persp_dark"])
def test_on_the_shared_pinhole_scenes_both_depths_beat_the_orthographic_stand_ins(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irtps.IrtpsWarning)
        dataset = irtps.load_dataset(MITSUBA / name)
        result = irtps.reconstruct(dataset)
    mask, truth = dataset.mask, dataset.gt.depth
    center = dataset.scene.camera.optical_center[2]
    stand_in = irtps.integrate_normals(result.normals, mask, pixel_size=result.pixel_size, method="footprint")
    stand_in = place_height(stand_in, mask, base_height=float(np.median(result.height[mask_boundary(mask)])))
    orthographic = _made(center - stand_in, truth, mask)
    assert _made(result.depth, truth, mask) < 0.9 * orthographic
    assert _made(center - result.height, truth, mask) < 0.9 * orthographic


def test_the_command_writes_depth_and_discontinuities_for_a_pinhole_only(pinhole, tmp_path):
    _, result = pinhole
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irtps.IrtpsWarning)
        assert main(["reconstruct", str(PINHOLE), "--out", str(tmp_path / "pinhole"), "--quiet"]) == 0
    assert np.array_equal(_core.read_exr(str(tmp_path / "pinhole" / "depth.exr")), result.depth)
    edges, bits = _core.read_png(str(tmp_path / "pinhole" / "discontinuities.png"))
    assert bits == 8 and edges.shape[:2] == result.depth.shape and set(np.unique(edges)) <= {0.0, 1.0}
    figures = {figure.name: figure for figure in build_report(tmp_path / "pinhole").figures}
    assert f"{int((edges > 0).sum())} pixels on an edge" in figures["discontinuities"].caption
    assert main(["reconstruct", str(ORTHOGRAPHIC), "--out", str(tmp_path / "flat"), "--quiet"]) == 0
    assert "discontinuities" not in [figure.name for figure in build_report(tmp_path / "flat").figures]
    assert not (tmp_path / "flat" / "depth.exr").exists()
    assert not (tmp_path / "flat" / "discontinuities.png").exists()


def test_the_pinhole_mesh_stands_on_the_rays_and_leaves_cut_blocks_out(pinhole):
    dataset, result = pinhole
    camera, mask = dataset.scene.camera, dataset.mask
    vertices, faces, _, _ = pinhole_mesh(result.depth, mask, camera)
    rays = camera.ray_directions()
    # Every vertex is a pixel's point on its centre ray, at its depth along the axis (§1b).
    depth_of_vertex = camera.optical_center[2] - vertices[:, 2]
    assert np.allclose(sorted(depth_of_vertex), sorted(result.depth[mask]), rtol=1e-5)
    assert np.allclose(rays[..., 2], -1.0)
    # A cut edge takes out the two 2x2 blocks it belongs to (four triangles inside the mask).
    cut = np.zeros((*mask.shape, 2), bool)
    rows, columns = np.nonzero(ndimage.binary_erosion(mask, np.ones((3, 3), bool)))
    row, column = rows[len(rows) // 2], columns[len(columns) // 2]
    cut[row, column, 1] = True  # the edge from (row, column) down to (row + 1, column)
    _, fewer, _, _ = pinhole_mesh(result.depth, mask, camera, cut)
    assert len(faces) - len(fewer) == 4
