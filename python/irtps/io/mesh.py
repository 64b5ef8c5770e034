"""A height field as a triangle mesh (contract §1–§2), written as PLY or OBJ.

The mesh is the contract's object surface without its skirt: one vertex per masked
pixel that some triangle uses, at the pixel centre ``x = (j + 0.5 − W/2)·s``,
``y = (H/2 − i − 0.5)·s``, ``z = h[i, j]``; and for each 2×2 block of masked pixels the
triangles ``(i,j) (i+1,j) (i,j+1)`` and ``(i,j+1) (i+1,j) (i+1,j+1)``, which wind
counter-clockwise seen from +z (they face the camera).

Conventions of the files, for MeshLab, Blender and other viewers:

- Coordinates are the contract's world frame, in world units (a pixel is
  ``camera.pixel_size`` wide): x to the right, y up in the image, z (the height)
  toward the camera. This is the "Y up" frame that OBJ importers assume by default,
  so MeshLab's initial view and Blender's front view (importer defaults: forward −Z,
  up Y) show the object as the camera saw it.
- Triangles wind counter-clockwise seen from the camera (+z), so the face normals
  that viewers compute from the winding point out of the surface, toward the camera,
  and agree with the vertex normals written from the reconstructed normals.
- ``mesh.ply`` also carries per-vertex albedo colours; ``mesh.obj`` has vertex
  positions and normals only (OBJ has no standard vertex colour).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from irtps._shared.checks import check_array, check_finite, check_image, check_mask, check_positive
from irtps._shared.atomic import atomic_write_bytes
from irtps.errors import ArgumentError
from irtps.geometry.surface import meshed_blocks
from irtps.model.camera import Camera

__all__ = ["height_field_mesh", "pinhole_mesh", "write_glb", "write_obj", "write_ply"]


def height_field_mesh(
    height: np.ndarray,
    mask: np.ndarray,
    pixel_size: float = 1.0,
    albedo: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Triangulate a height field as the scene contract does.

    Only pixels used by at least one triangle become vertices, numbered in row-major
    pixel order; the two triangles of each block follow each other, blocks in
    row-major order.

    Parameters
    ----------
    height : numpy.ndarray
        (H, W) heights (world z) at the pixel centres.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    pixel_size : float
        World size ``s`` of a pixel.
    albedo : numpy.ndarray, optional
        (H, W, 3) RGB albedo, turned into vertex colours (clipped to [0, 1], times 255,
        rounded).
    normals : numpy.ndarray, optional
        (H, W, 3) per-pixel normals, turned into unit vertex normals (zero stays zero).

    Returns
    -------
    vertices : numpy.ndarray
        float32 (V, 3) world coordinates.
    faces : numpy.ndarray
        int32 (F, 3) vertex indices, counter-clockwise seen from +z.
    colors : numpy.ndarray or None
        uint8 (V, 3) vertex colours, None without ``albedo``.
    vertex_normals : numpy.ndarray or None
        float32 (V, 3), None without ``normals``.

    Raises
    ------
    ArgumentError
        (an `IrtpsError`) naming the argument whose shape disagrees with ``height``,
        a ``pixel_size`` that is not positive, or values that are not finite on a vertex.

    Examples
    --------
    >>> import numpy as np
    >>> mask = np.array([[1, 1, 0], [1, 1, 1]], bool)
    >>> v, f, c, n = height_field_mesh(np.zeros((2, 3)), mask, pixel_size=2.0)
    >>> v.tolist()
    [[-2.0, 1.0, 0.0], [0.0, 1.0, 0.0], [-2.0, -1.0, 0.0], [0.0, -1.0, 0.0]]
    >>> f.tolist(), c, n
    ([[0, 2, 1], [1, 2, 3]], None, None)
    """
    height = check_array("height", height, (None, None))
    rows, cols = height.shape
    mask = check_mask(mask, height.shape, match="height")
    albedo = None if albedo is None else check_image("albedo", albedo, mask, finite=False)
    normals = None if normals is None else check_image("normals", normals, mask, finite=False)
    s = check_positive("pixel_size", pixel_size)

    def positions(i: np.ndarray, j: np.ndarray) -> np.ndarray:
        check_finite("height", height, used)
        x = (j + 0.5 - cols / 2.0) * s
        y = (rows / 2.0 - i - 0.5) * s
        return np.stack([x, y, height[used]], axis=1)

    block = meshed_blocks(mask)
    used = _used_pixels(block)
    return _grid_mesh(block, used, positions, albedo, normals)


def pinhole_mesh(
    depth: np.ndarray,
    mask: np.ndarray,
    camera: Camera,
    discontinuities: np.ndarray | None = None,
    albedo: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Triangulate a depth map seen through a pinhole, in world coordinates, without bridging
    its depth discontinuities.

    Each pixel's point lies on its centre ray at its depth along the optical axis (contract
    §1b: ``P = optical_center + depth · ray``); the 2×2 blocks of object pixels make two
    triangles each, as `height_field_mesh`'s, except the blocks that a discontinuity crosses
    (one of their four edges marked in `discontinuities`), which would be walls across the jump.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) depth along the optical axis, world units.
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.
    camera : Camera
        A perspective camera with its optical centre.
    discontinuities : numpy.ndarray, optional
        bool (H, W, 2): the edges to the right neighbour and to the pixel below that are
        depth discontinuities (`irtps.geometry.bilateral_integration`).
    albedo, normals : numpy.ndarray, optional
        As for `height_field_mesh`.

    Returns
    -------
    vertices, faces, colors, vertex_normals
        As for `height_field_mesh`; faces counter-clockwise seen from the camera.

    Examples
    --------
    >>> import numpy as np
    >>> from irtps.model.camera import Camera
    >>> camera = Camera(2, 2, projection="perspective", fx=2.0, fy=2.0, cx=1.0, cy=1.0,
    ...                 optical_center=(0.0, 0.0, 10.0))
    >>> v, f, _, _ = pinhole_mesh(np.full((2, 2), 4.0), np.ones((2, 2), bool), camera)
    >>> v.tolist()
    [[-1.0, 1.0, 6.0], [1.0, 1.0, 6.0], [-1.0, -1.0, 6.0], [1.0, -1.0, 6.0]]
    >>> cut = np.zeros((2, 2, 2), bool); cut[0, 0, 0] = True
    >>> pinhole_mesh(np.full((2, 2), 4.0), np.ones((2, 2), bool), camera, cut)[1].shape
    (0, 3)
    """
    depth = check_array("depth", depth, (None, None))
    mask = check_mask(mask, depth.shape, match="depth")
    albedo = None if albedo is None else check_image("albedo", albedo, mask, finite=False)
    normals = None if normals is None else check_image("normals", normals, mask, finite=False)
    if camera.optical_center is None:
        raise ArgumentError("camera", "a pinhole mesh needs a perspective camera with its optical centre")
    rays = camera.ray_directions()
    if rays.shape[:2] != depth.shape:
        raise ArgumentError(
            "camera",
            f"sees {rays.shape[1]}x{rays.shape[0]} pixels, the depth map has {depth.shape[1]}x{depth.shape[0]}",
        )
    block = meshed_blocks(mask)
    if discontinuities is not None:
        cut = check_array("discontinuities", discontinuities, (*depth.shape, 2)).astype(bool)
        right, down = cut[..., 0], cut[..., 1]
        block &= ~(right[:-1, :-1] | right[1:, :-1] | down[:-1, :-1] | down[:-1, 1:])
    used = _used_pixels(block)

    def positions(i: np.ndarray, j: np.ndarray) -> np.ndarray:
        check_finite("depth", depth, used)
        return np.asarray(camera.optical_center, dtype=np.float64) + depth[i, j][:, None] * rays[i, j]

    return _grid_mesh(block, used, positions, albedo, normals)


def _used_pixels(block: np.ndarray) -> np.ndarray:
    """The pixels of an (H-1, W-1) map of meshed 2×2 blocks: those a triangle uses."""
    used = np.zeros((block.shape[0] + 1, block.shape[1] + 1), dtype=bool)
    used[:-1, :-1] |= block
    used[1:, :-1] |= block
    used[:-1, 1:] |= block
    used[1:, 1:] |= block
    return used


def _grid_mesh(
    block: np.ndarray,
    used: np.ndarray,
    positions: Callable[[np.ndarray, np.ndarray], np.ndarray],
    albedo: np.ndarray | None,
    normals: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The mesh of the meshed 2×2 `block`s over a pixel grid: vertices at `positions(i, j)` of
    the `used` pixels (row-major), two triangles per block, vertex colours and normals."""
    index = np.full(used.shape, -1, dtype=np.int64)
    index[used] = np.arange(int(used.sum()))
    i, j = np.nonzero(used)
    vertices = positions(i, j).astype(np.float32)

    bi, bj = np.nonzero(block)
    first = np.stack([index[bi, bj], index[bi + 1, bj], index[bi, bj + 1]], axis=1)
    second = np.stack([index[bi, bj + 1], index[bi + 1, bj], index[bi + 1, bj + 1]], axis=1)
    faces = np.stack([first, second], axis=1).reshape(-1, 3).astype(np.int32)

    colors = None
    if albedo is not None:
        check_finite("albedo", albedo, used)
        values = albedo[used]
        colors = np.rint(np.clip(values, 0.0, 1.0) * 255.0).astype(np.uint8)

    vertex_normals = None
    if normals is not None:
        check_finite("normals", normals, used)
        values = normals[used]
        length = np.linalg.norm(values, axis=1, keepdims=True)
        values = np.divide(values, length, out=np.zeros_like(values), where=length > 0)
        vertex_normals = values.astype(np.float32)

    return vertices, faces, colors, vertex_normals


def write_ply(
    path: str | Path,
    vertices: np.ndarray,
    faces: np.ndarray,
    colors: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> None:
    """Write a triangle mesh as binary little-endian PLY, atomically.

    Vertex properties are ``float x, y, z``, then ``float nx, ny, nz`` with normals,
    then ``uchar red, green, blue`` with colours; faces are
    ``property list uchar int vertex_indices``.

    Parameters
    ----------
    path : str or pathlib.Path
        The file to write (missing parent folders are created).
    vertices : numpy.ndarray
        (V, 3) coordinates, written as float32.
    faces : numpy.ndarray
        (F, 3) integer vertex indices in [0, V).
    colors : numpy.ndarray, optional
        uint8 (V, 3) RGB vertex colours.
    normals : numpy.ndarray, optional
        (V, 3) vertex normals, written as float32.

    Raises
    ------
    ArgumentError
        (an `IrtpsError`) naming the argument that is malformed; nothing is written then.
    DatasetError
        If the folder cannot be created or written to.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> v, f, c, _ = height_field_mesh(np.zeros((2, 2)), np.ones((2, 2), bool), albedo=np.ones((2, 2, 3)))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder) / "mesh.ply"
    ...     write_ply(path, v, f, colors=c)
    ...     data = path.read_bytes()
    >>> print(data[:data.index(b"end_header")].decode())
    ply
    format binary_little_endian 1.0
    comment written by irtps
    element vertex 4
    property float x
    property float y
    property float z
    property uchar red
    property uchar green
    property uchar blue
    element face 2
    property list uchar int vertex_indices
    <BLANKLINE>
    """
    vertices, faces, colors, normals = _check_mesh(vertices, faces, colors, normals)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    header = ["ply", "format binary_little_endian 1.0", "comment written by irtps", f"element vertex {len(vertices)}"]
    header += [f"property float {name}" for name in ("x", "y", "z")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
        header += [f"property float {name}" for name in ("nx", "ny", "nz")]
    if colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
        header += [f"property uchar {name}" for name in ("red", "green", "blue")]
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]

    vertex_data = np.empty(len(vertices), dtype=np.dtype(fields))
    for axis, name in enumerate(("x", "y", "z")):
        vertex_data[name] = vertices[:, axis]
    if normals is not None:
        for axis, name in enumerate(("nx", "ny", "nz")):
            vertex_data[name] = normals[:, axis]
    if colors is not None:
        for axis, name in enumerate(("red", "green", "blue")):
            vertex_data[name] = colors[:, axis]
    face_data = np.empty(len(faces), dtype=np.dtype([("count", "u1"), ("indices", "<i4", (3,))]))
    face_data["count"] = 3
    face_data["indices"] = faces

    data = ("\n".join(header) + "\n").encode("ascii") + vertex_data.tobytes() + face_data.tobytes()
    atomic_write_bytes(path, data)


def write_obj(path: str | Path, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None) -> None:
    """Write a triangle mesh as Wavefront OBJ text, atomically.

    Lines ``v x y z``, then ``vn nx ny nz`` with normals, then one ``f`` line per
    triangle with 1-based indices: ``f a//a b//b c//c`` with normals (vertex ``k`` has
    normal ``k``), ``f a b c`` without. Coordinates keep every float32 digit.

    Parameters
    ----------
    path : str or pathlib.Path
        The file to write (missing parent folders are created).
    vertices : numpy.ndarray
        (V, 3) coordinates.
    faces : numpy.ndarray
        (F, 3) integer vertex indices in [0, V) (0-based, as `height_field_mesh` gives).
    normals : numpy.ndarray, optional
        (V, 3) vertex normals.

    Raises
    ------
    ArgumentError
        (an `IrtpsError`) naming the argument that is malformed; nothing is written then.
    DatasetError
        If the folder cannot be created or written to.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> v, f, _, n = height_field_mesh(np.zeros((2, 2)), np.ones((2, 2), bool), normals=np.ones((2, 2, 3)))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder) / "mesh.obj"
    ...     write_obj(path, v, f, normals=n)
    ...     lines = path.read_text().splitlines()
    >>> lines[1], lines[5], lines[-1]
    ('v -0.5 0.5 0', 'vn 0.577350259 0.577350259 0.577350259', 'f 2//2 3//3 4//4')
    """
    vertices, faces, _, normals = _check_mesh(vertices, faces, None, normals)
    parts = [f"# written by irtps: {len(vertices)} vertices, {len(faces)} triangles\n"]
    parts.append(_format_rows("v %.9g %.9g %.9g\n", vertices))
    if normals is not None:
        parts.append(_format_rows("vn %.9g %.9g %.9g\n", normals))
    one_based = faces + 1
    if normals is not None:
        parts.append(_format_rows("f %d//%d %d//%d %d//%d\n", np.repeat(one_based, 2, axis=1)))
    else:
        parts.append(_format_rows("f %d %d %d\n", one_based))
    atomic_write_bytes(path, "".join(parts).encode("ascii"))


def write_glb(
    path: str | Path,
    vertices: np.ndarray,
    faces: np.ndarray,
    colors: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> None:
    """Write a triangle mesh as glTF 2.0 binary (GLB, by trimesh), atomically.

    Parameters
    ----------
    path : str or pathlib.Path
    vertices : numpy.ndarray
        (N, 3) positions.
    faces : numpy.ndarray
        (F, 3) vertex indices, counter-clockwise seen from the front.
    colors : numpy.ndarray, optional
        (N, 3) uint8 vertex colours, linear (as the albedo; glTF's ``COLOR_0`` is linear).
    normals : numpy.ndarray, optional
        (N, 3) unit vertex normals, stored as ``NORMAL``.

    Raises
    ------
    ArgumentError
        (an `IrtpsError`) naming the argument that is malformed; nothing is written then.
    DatasetError
        If the folder cannot be created or written to.
    """
    # Here, not at the top: trimesh alone would add a third to `import irtps`.
    import trimesh
    from trimesh.exchange.gltf import export_glb

    vertices, faces, colors, normals = _check_mesh(vertices, faces, colors, normals)
    if not len(vertices):  # no object (a degenerate mask): a file with an empty scene
        colors = normals = None
    vertex_colors = None
    if colors is not None:
        vertex_colors = np.c_[colors, np.full(len(colors), 255, dtype=np.uint8)]
    mesh = trimesh.Trimesh(
        vertices=vertices,
        faces=faces,
        vertex_normals=normals,
        vertex_colors=vertex_colors,
        process=False,
    )
    atomic_write_bytes(path, export_glb(mesh))


def _format_rows(line: str, rows: np.ndarray) -> str:
    """``line % row`` for every row, in one formatting call (no Python loop over rows)."""
    return (line * len(rows)) % tuple(rows.ravel().tolist())


def _check_mesh(vertices, faces, colors, normals):
    vertices = check_array("vertices", vertices, (None, 3), dtype=np.float32)
    check_finite("vertices", vertices, unit="vertex")
    count = len(vertices)
    faces = check_array("faces", faces, (None, 3), dtype=None)
    if faces.size and not np.issubdtype(faces.dtype, np.integer):
        raise ArgumentError("faces", f"must hold integer vertex indices, got dtype {faces.dtype}")
    faces = faces.astype(np.int64)
    if faces.size and (faces.min() < 0 or faces.max() >= count):
        raise ArgumentError("faces", f"index vertices {faces.min()}..{faces.max()}, but there are {count} vertices")
    if colors is not None:
        colors = check_array("colors", colors, (count, 3), match="vertices", dtype=None)
        if colors.dtype != np.uint8:
            raise ArgumentError("colors", f"must be uint8 (0..255), got dtype {colors.dtype}")
    if normals is not None:
        normals = check_array("normals", normals, (count, 3), match="vertices", dtype=np.float32)
        check_finite("normals", normals, unit="vertex")
    return vertices, faces, colors, normals
