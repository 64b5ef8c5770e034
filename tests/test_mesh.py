"""Height-field meshes: the contract's triangulation, orientation, and PLY/OBJ files read back."""

import numpy as np
import pytest
from irtps import IrtpsError
from irtps.io.mesh import height_field_mesh, write_obj, write_ply

# A non-rectangular mask: an L of three 2x2 blocks, plus an isolated pixel and a 1x2 strip
# that no triangle uses.
L_MASK = np.array(
    [
        [1, 1, 1, 0, 0],
        [1, 1, 1, 0, 1],
        [1, 1, 0, 0, 0],
        [0, 0, 0, 1, 1],
    ],
    dtype=bool,
)


def pixel_centre(i, j, shape, s):
    rows, cols = shape
    return (j + 0.5 - cols / 2) * s, (rows / 2 - i - 0.5) * s


def reference_mesh(height, mask, s):
    """The contract's triangulation, written out pixel by pixel."""
    rows, cols = mask.shape
    blocks = [
        (i, j)
        for i in range(rows - 1)
        for j in range(cols - 1)
        if mask[i, j] and mask[i + 1, j] and mask[i, j + 1] and mask[i + 1, j + 1]
    ]
    used = sorted({(i + di, j + dj) for i, j in blocks for di in (0, 1) for dj in (0, 1)})
    index = {pixel: k for k, pixel in enumerate(used)}
    vertices = [(*pixel_centre(i, j, mask.shape, s), height[i, j]) for i, j in used]
    faces = []
    for i, j in blocks:
        faces.append((index[i, j], index[i + 1, j], index[i, j + 1]))
        faces.append((index[i, j + 1], index[i + 1, j], index[i + 1, j + 1]))
    return np.array(vertices, dtype=np.float32).reshape(-1, 3), np.array(faces, dtype=np.int32).reshape(-1, 3), used


def read_ply(path):
    """An independent little binary PLY reader: header lines, then numpy structured data."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    lines = data[:end].decode("ascii").splitlines()
    assert lines[0] == "ply" and lines[1] == "format binary_little_endian 1.0"
    elements = []
    for line in lines[2:]:
        words = line.split()
        if words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property":
            elements[-1][2].append(words[1:])
    types = {"float": "<f4", "uchar": "u1", "int": "<i4"}
    offset, result = end, {}
    for name, count, properties in elements:
        fields = []
        for prop in properties:
            if prop[0] == "list":
                assert prop[1:3] == ["uchar", "int"]
                fields += [("count", "u1"), (prop[3], "<i4", (3,))]
            else:
                fields.append((prop[1], types[prop[0]]))
        dtype = np.dtype(fields)
        result[name] = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
        offset += count * dtype.itemsize
    assert offset == len(data), "trailing bytes after the last element"
    return [line.split() for line in lines if line.startswith("property")], result


def read_obj(path):
    v, vn, f = [], [], []
    for line in path.read_text().splitlines():
        words = line.split()
        if not words or words[0] == "#":
            continue
        if words[0] == "v":
            v.append([float(w) for w in words[1:]])
        elif words[0] == "vn":
            vn.append([float(w) for w in words[1:]])
        elif words[0] == "f":
            f.append([[int(part) if part else None for part in w.split("/")] for w in words[1:]])
        else:
            raise AssertionError(f"unexpected OBJ line {line!r}")
    return np.array(v).reshape(-1, 3), np.array(vn).reshape(-1, 3), f


def sloped(shape, s, a=0.2, b=-0.1, c=1.0):
    """Heights of the plane z = a x + b y + c at the pixel centres."""
    i, j = np.mgrid[0 : shape[0], 0 : shape[1]]
    x, y = pixel_centre(i, j, shape, s)
    return a * x + b * y + c


def test_a_non_rectangular_mask_gives_the_expected_counts_and_indices():
    height = np.arange(L_MASK.size, dtype=float).reshape(L_MASK.shape)
    vertices, faces, colors, normals = height_field_mesh(height, L_MASK, pixel_size=0.5)
    assert vertices.shape == (8, 3) and vertices.dtype == np.float32
    assert faces.shape == (6, 3) and faces.dtype == np.int32
    assert colors is None and normals is None
    expected_vertices, expected_faces, used = reference_mesh(height, L_MASK, 0.5)
    assert (1, 4) not in used and (3, 3) not in used and (3, 4) not in used
    np.testing.assert_array_equal(vertices, expected_vertices)
    np.testing.assert_array_equal(faces, expected_faces)


def test_a_random_mask_matches_the_reference_triangulation():
    rng = np.random.default_rng(5)
    mask = rng.uniform(size=(9, 11)) > 0.35
    height = rng.uniform(size=mask.shape)
    vertices, faces, _, _ = height_field_mesh(height, mask, pixel_size=0.3)
    expected_vertices, expected_faces, _ = reference_mesh(height, mask, 0.3)
    np.testing.assert_allclose(vertices, expected_vertices, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(faces, expected_faces)
    assert len(np.unique(faces)) == len(vertices)  # every vertex is used


def test_no_block_gives_an_empty_mesh():
    mask = np.eye(4, dtype=bool)
    vertices, faces, colors, normals = height_field_mesh(
        np.ones((4, 4)), mask, albedo=np.ones((4, 4, 3)), normals=np.ones((4, 4, 3))
    )
    assert vertices.shape == (0, 3) and faces.shape == (0, 3) and colors.shape == (0, 3) and normals.shape == (0, 3)


def test_faces_wind_counter_clockwise_seen_from_plus_z():
    s = 0.25
    shape = L_MASK.shape
    a, b = 0.2, -0.1
    vertices, faces, _, _ = height_field_mesh(sloped(shape, s, a, b), L_MASK, pixel_size=s)
    p = vertices[faces].astype(np.float64)
    face_normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert (face_normals[:, 2] > 0).all()
    # On a plane every face normal is the plane's normal normalize(-a, -b, 1).
    face_normals /= np.linalg.norm(face_normals, axis=1, keepdims=True)
    expected = np.array([-a, -b, 1.0]) / np.linalg.norm([-a, -b, 1.0])
    np.testing.assert_allclose(face_normals, np.broadcast_to(expected, face_normals.shape), atol=1e-5)


def test_colours_and_normals_per_vertex():
    albedo = np.zeros((*L_MASK.shape, 3))
    albedo[0, 0] = [-0.5, 0.2, 1.5]
    albedo[2, 1] = [1.0, 0.5, 0.0]
    normals = np.zeros((*L_MASK.shape, 3))
    normals[..., 2] = 2.0
    _vertices, _, colors, vertex_normals = height_field_mesh(
        np.zeros(L_MASK.shape), L_MASK, albedo=albedo, normals=normals
    )
    assert colors.dtype == np.uint8 and colors.shape == (8, 3)
    assert colors[0].tolist() == [0, 51, 255]  # pixel (0, 0), clipped to [0, 1]
    assert colors[7].tolist() == [255, 128, 0]  # pixel (2, 1), the last vertex
    assert vertex_normals.dtype == np.float32
    np.testing.assert_array_equal(vertex_normals, np.broadcast_to([0, 0, 1], (8, 3)))


@pytest.mark.parametrize("with_normals", [False, True])
def test_ply_round_trip(tmp_path, with_normals):
    s = 0.5
    shape = L_MASK.shape
    height = sloped(shape, s)
    rng = np.random.default_rng(2)
    albedo = rng.uniform(-0.1, 1.1, size=(*shape, 3))
    normals = rng.normal(size=(*shape, 3)) if with_normals else None
    vertices, faces, colors, vertex_normals = height_field_mesh(height, L_MASK, s, albedo=albedo, normals=normals)
    path = tmp_path / "out" / "mesh.ply"
    write_ply(path, vertices, faces, colors=colors, normals=vertex_normals)
    assert sorted(p.name for p in path.parent.iterdir()) == ["mesh.ply"]  # no temporary file left

    properties, elements = read_ply(path)
    names = [p[-1] for p in properties]
    expected_names = ["x", "y", "z"] + (["nx", "ny", "nz"] if with_normals else []) + ["red", "green", "blue"]
    assert names == expected_names + ["vertex_indices"]
    assert ["list", "uchar", "int", "vertex_indices"] in [p[1:] for p in properties]
    vertex, face = elements["vertex"], elements["face"]
    assert len(vertex) == 8 and len(face) == 6
    assert (face["count"] == 3).all()
    np.testing.assert_array_equal(face["vertex_indices"], faces)

    # Bounds from the contract's pixel centres: the used pixels span rows 0..2, columns 0..2.
    x_lo, y_hi = pixel_centre(0, 0, shape, s)
    x_hi, y_lo = pixel_centre(2, 2, shape, s)
    assert vertex["x"].min() == pytest.approx(x_lo) and vertex["x"].max() == pytest.approx(x_hi)
    assert vertex["y"].min() == pytest.approx(y_lo) and vertex["y"].max() == pytest.approx(y_hi)
    used = L_MASK.copy()
    used[1, 4] = used[3, 3] = used[3, 4] = False
    np.testing.assert_allclose(vertex["z"], height[used], rtol=1e-6)
    assert vertex["z"].min() == pytest.approx(height[used].min(), rel=1e-6)
    assert vertex["z"].max() == pytest.approx(height[used].max(), rel=1e-6)

    rgb = np.stack([vertex["red"], vertex["green"], vertex["blue"]], axis=1)
    np.testing.assert_array_equal(rgb, np.rint(np.clip(albedo[used], 0, 1) * 255))
    if with_normals:
        n = np.stack([vertex["nx"], vertex["ny"], vertex["nz"]], axis=1)
        expected = normals[used] / np.linalg.norm(normals[used], axis=1, keepdims=True)
        np.testing.assert_allclose(n, expected, rtol=1e-6, atol=1e-7)


def test_ply_without_colours_and_an_empty_mesh(tmp_path):
    vertices, faces, _, _ = height_field_mesh(np.ones((2, 2)), np.ones((2, 2), bool))
    write_ply(tmp_path / "plain.ply", vertices, faces)
    properties, elements = read_ply(tmp_path / "plain.ply")
    assert [p[-1] for p in properties] == ["x", "y", "z", "vertex_indices"]
    np.testing.assert_array_equal(elements["vertex"]["z"], 1.0)
    write_ply(tmp_path / "empty.ply", np.zeros((0, 3)), np.zeros((0, 3), int))
    _, elements = read_ply(tmp_path / "empty.ply")
    assert len(elements["vertex"]) == 0 and len(elements["face"]) == 0


def test_writing_replaces_an_existing_file(tmp_path):
    path = tmp_path / "mesh.ply"
    path.write_text("old")
    vertices, faces, _, _ = height_field_mesh(np.zeros((2, 2)), np.ones((2, 2), bool))
    write_ply(path, vertices, faces)
    assert read_ply(path)[1]["face"].size == 2


@pytest.mark.parametrize("with_normals", [False, True])
def test_obj_parses_back_with_the_same_counts(tmp_path, with_normals):
    s = 0.5
    normals = np.dstack([np.zeros(L_MASK.shape), np.ones(L_MASK.shape), np.ones(L_MASK.shape)])
    vertices, faces, _, vertex_normals = height_field_mesh(
        sloped(L_MASK.shape, s), L_MASK, s, normals=normals if with_normals else None
    )
    path = tmp_path / "mesh.obj"
    write_obj(path, vertices, faces, normals=vertex_normals)
    v, vn, f = read_obj(path)
    assert v.shape == (8, 3) and len(f) == 6
    np.testing.assert_array_equal(v.astype(np.float32), vertices)  # every float32 digit kept
    corners = np.array([[corner[0] for corner in face] for face in f])
    np.testing.assert_array_equal(corners, faces + 1)
    if with_normals:
        assert vn.shape == (8, 3)
        np.testing.assert_allclose(vn, vertex_normals, rtol=1e-7)
        assert all(corner[1] is None and corner[2] == corner[0] for face in f for corner in face)
    else:
        assert vn.shape == (0, 3)
        assert all(len(corner) == 1 for face in f for corner in face)


@pytest.mark.parametrize(
    "name, arguments",
    [
        ("height", {"height": np.zeros(4)}),
        ("mask", {"mask": np.ones((3, 2), bool)}),
        ("albedo", {"albedo": np.zeros((2, 3))}),
        ("normals", {"normals": np.zeros((2, 3, 4))}),
    ],
)
def test_mesh_shape_mismatches_raise_naming_the_argument(name, arguments):
    call = {"height": np.zeros((2, 3)), "mask": np.ones((2, 3), bool)}
    call.update(arguments)
    with pytest.raises(IrtpsError, match=rf"^{name}: shape"):
        height_field_mesh(**call)


def test_bad_meshes_are_rejected_before_writing(tmp_path):
    vertices, faces, colors, _ = height_field_mesh(np.zeros((2, 2)), np.ones((2, 2), bool), albedo=np.ones((2, 2, 3)))
    path = tmp_path / "mesh.ply"
    with pytest.raises(IrtpsError, match="^faces: index vertices"):
        write_ply(path, vertices, faces + 1)
    with pytest.raises(IrtpsError, match="^colors: must be uint8"):
        write_ply(path, vertices, faces, colors=colors.astype(float))
    with pytest.raises(IrtpsError, match=r"^normals: shape \(3, 3\), expected \(4, 3\) to match vertices"):
        write_obj(tmp_path / "mesh.obj", vertices, faces, normals=np.zeros((3, 3)))
    with pytest.raises(IrtpsError, match="^pixel_size: "):
        height_field_mesh(np.zeros((2, 2)), np.ones((2, 2), bool), pixel_size=0.0)
    with pytest.raises(IrtpsError, match="^height: non-finite value nan at row 0, column 0$"):
        height_field_mesh(np.full((2, 2), np.nan), np.ones((2, 2), bool))
    assert list(tmp_path.iterdir()) == []
