"""The report's 3-D view (`irtps.report.shape_view`): its meshes against the camera's surface
points, the sampling that keeps a large map small, the discontinuities left open, and the
page's payload (decoded back)."""

import base64
import json
import re

import numpy as np

from irtps.model.camera import Camera
from irtps.report.shape_view import MAX_VERTICES, shape_mesh, shape_view_html, surface_colours


def _bowl(size):
    rows, columns = np.mgrid[0:size, 0:size]
    return 0.01 * ((rows - size / 2) ** 2 + (columns - size / 2) ** 2)


def test_a_small_map_is_meshed_pixel_by_pixel_at_its_surface_points():
    camera = Camera(6, 6, pixel_size=0.5)
    height, mask = _bowl(6), np.ones((6, 6), bool)
    colours = surface_colours(np.full((6, 6, 3), 0.5), mask, None, None)
    mesh = shape_mesh("r", camera, height, mask, colours)
    assert mesh.positions.shape == (36, 3) and len(mesh.triangles) == 2 * 5 * 5
    assert np.allclose(mesh.positions, camera.surface_points(height).reshape(-1, 3), atol=1e-6)
    assert mesh.colours["albedo"].dtype == np.uint8 and (mesh.colours["error"] == 180).all()  # grey: no truth


def test_a_pinhole_mesh_lies_on_the_camera_rays():
    camera = Camera(8, 8, projection="perspective", fx=10.0, fy=10.0, cx=4.0, cy=4.0, optical_center=(0, 0, 50))
    height = np.full((8, 8), 5.0)
    mesh = shape_mesh(
        "r", camera, height, np.ones((8, 8), bool), surface_colours(None, np.ones((8, 8), bool), None, None)
    )
    assert np.allclose(mesh.positions[:, 2], 5.0, atol=1e-5)  # the plane z = 5, seen through the pinhole
    assert np.ptp(mesh.positions[:, 0]) == np.float32(45.0 * 7 / 10)  # 7 pixel steps at depth 45, fx 10


def test_a_large_map_is_sampled_under_the_vertex_bound():
    size = 400
    mask = np.ones((size, size), bool)
    mesh = shape_mesh(
        "r", Camera(size, size, pixel_size=1.0), _bowl(size), mask, surface_colours(None, mask, None, None)
    )
    assert len(mesh.positions) <= MAX_VERTICES and len(mesh.positions) > MAX_VERTICES // 4
    assert mesh.triangles.dtype == np.uint16 and mesh.triangles.max() < len(mesh.positions)


def test_no_triangle_spans_a_discontinuity():
    mask = np.ones((6, 6), bool)
    breaks = np.zeros((6, 6), bool)
    breaks[:, 2:4] = True  # both pixels of each edge between columns 2 and 3
    mesh = shape_mesh("r", Camera(6, 6, pixel_size=1.0), _bowl(6), mask, {}, breaks=breaks)
    columns = np.round(mesh.positions[:, 0] + 3 - 0.5).astype(int)[mesh.triangles]
    assert not ((columns.min(axis=1) <= 2) & (columns.max(axis=1) >= 3)).any()
    assert len(mesh.triangles) == 2 * 5 * 2  # columns 0-1 and 4-5 keep theirs
    assert shape_mesh("r", Camera(6, 6, pixel_size=1.0), _bowl(6), np.eye(6, dtype=bool), {}) is None


def test_the_page_payload_decodes_to_the_meshes():
    mask = np.ones((5, 5), bool)
    colours = surface_colours(np.full((5, 5, 3), 0.25), mask, np.full((5, 5), 3.0), 6.0)
    mesh = shape_mesh("reconstruction", Camera(5, 5, pixel_size=1.0), _bowl(5), mask, colours)
    page = shape_view_html([mesh], "caption </script> & more")
    data = json.loads(re.search(r'id="irtps-shape-data">(.*?)</script>', page, re.S).group(1).replace("<\\/", "</"))
    (shown,) = data["meshes"]
    positions = np.frombuffer(base64.b64decode(shown["positions"]), "<f4").reshape(-1, 3)
    assert np.array_equal(positions, mesh.positions)
    error = np.frombuffer(base64.b64decode(shown["colours"]["error"]), np.uint8).reshape(-1, 3)
    assert np.array_equal(error, mesh.colours["error"])
    assert "caption &lt;/script&gt; &amp; more" in page  # escaped: the caption cannot end the script
