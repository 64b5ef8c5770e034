"""Rigs (contract §3b, §4b): surroundings given as a mesh and point lights in scene.json, the
PLY reader and writer, the named errors, and rendering: a floor given as a mesh renders as
the contract's floor, on either side, and a point light follows the inverse-square law."""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

import irtps
from irtps import Camera, DatasetError, Floor, Light, MeshEnvironment, PointLight, Scene
from irtps.model.environment import read_environment_mesh, view_problem, write_environment_mesh
from irtps.model.scene import load_scene, parse_scene, scene_to_dict, write_scene

RIG = Path(__file__).parent / "data" / "mitsuba_small" / "cap_rig"


def _square(z=0.0, half=1.0, albedo=(0.5, 0.5, 0.5), flip=False):
    vertices = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    return MeshEnvironment(vertices, triangles[:, ::-1] if flip else triangles, np.tile(albedo, (4, 1)))


def _ascii_ply(path, vertex_lines, face_lines, colour="uchar red\nproperty uchar green\nproperty uchar blue"):
    header = [
        "ply",
        "format ascii 1.0",
        f"element vertex {len(vertex_lines)}",
        "property float x\nproperty float y\nproperty float z",
        f"property {colour}" if colour else "",
        f"element face {len(face_lines)}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    path.write_text("\n".join(line for line in [*header, *vertex_lines, *face_lines] if line) + "\n")
    return path


# Reading and writing the mesh


def test_a_ply_with_byte_colours_and_a_quad_reads_as_triangles_with_albedo_in_0_1(tmp_path):
    path = _ascii_ply(
        tmp_path / "box.ply",
        ["0 0 0 255 0 0", "1 0 0 0 255 0", "1 1 0 0 0 255", "0 1 0 51 102 153"],
        ["4 0 1 2 3"],
    )
    mesh = read_environment_mesh(path)
    np.testing.assert_array_equal(mesh.triangles, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_allclose(mesh.albedo[3], [0.2, 0.4, 0.6])
    np.testing.assert_array_equal(mesh.vertices[2], [1, 1, 0])
    assert mesh.file == "box.ply"


def test_the_written_ply_reads_back_the_same_mesh(tmp_path):
    rng = np.random.default_rng(1)
    mesh = MeshEnvironment(rng.normal(size=(50, 3)), rng.integers(0, 50, (80, 3)), rng.random((50, 3)))
    write_environment_mesh(mesh, tmp_path / "environment.ply")
    back = read_environment_mesh(tmp_path / "environment.ply")
    np.testing.assert_array_equal(back.vertices, mesh.vertices)
    np.testing.assert_array_equal(back.triangles, mesh.triangles)
    np.testing.assert_array_equal(back.albedo, mesh.albedo)


def test_the_shared_rig_mesh_is_read_with_its_float_colours():
    mesh = read_environment_mesh(RIG / "environment.ply")
    assert mesh.vertices.shape == (1236, 3) and mesh.triangles.shape == (2210, 3)
    orange = (np.abs(mesh.albedo - [0.85, 0.62, 0.25]) < 1e-6).all(axis=1)
    assert 0 < orange.sum() < len(mesh.albedo)  # the reflector card among the light box's grey


@pytest.mark.parametrize(
    ("vertices", "faces", "colour", "message"),
    [
        (
            ["0 0 0 1 1 1", "1 0 0 1 1 1", "0 1 0 1 1 1"],
            [],
            "uchar red\nproperty uchar green\nproperty uchar blue",
            "has no faces",
        ),
        (["0 0 0", "1 0 0", "0 1 0"], ["3 0 1 2"], None, "has no colour for the albedo"),
        (["nan 0 0 9 9 9", "1 0 0 9 9 9", "0 1 0 9 9 9"], ["3 0 1 2"], None, "vertex 0 is not finite"),
        (
            ["0 0 0 0.5 1.5 0", "1 0 0 0 0 0", "0 1 0 0 0 0"],
            ["3 0 1 2"],
            "float r\nproperty float g\nproperty float b",
            r"vertex 0 has albedo \[0.5, 1.5, 0.0\]: expected RGB values in \[0, 1\]",
        ),
        (
            ["0 0 0 1 1 1", "1 0 0 1 1 1", "0 1 0 1 1 1"],
            ["3 0 1 7"],
            None,
            "triangle 0 names vertex 7, but there are 3 vertices",
        ),
        (["0 0 0 1 1 1", "1 0 0 1 1 1", "0 1 0 1 1 1"], ["2 0 1"], None, "face 0 has 2 corners"),
    ],
)
def test_a_bad_mesh_file_is_named_with_its_problem(tmp_path, vertices, faces, colour, message):
    if colour is None and len(vertices[0].split()) == 6:
        colour = "uchar red\nproperty uchar green\nproperty uchar blue"
    path = _ascii_ply(tmp_path / "environment.ply", vertices, faces, colour=colour)
    with pytest.raises(DatasetError, match=rf"environment\.ply: {message}"):
        read_environment_mesh(path)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "file not found"),
        (b"solid cube\nfacet normal 0 0 1\n", "not a readable PLY file"),
        (b"", "not a readable PLY file"),
    ],
)
def test_a_missing_or_foreign_mesh_file_is_one_named_error(tmp_path, content, message):
    path = tmp_path / "environment.ply"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(DatasetError, match=rf"environment\.ply: {message}"):
        read_environment_mesh(path)


# scene.json


def _rig_json():
    return {
        "format": "irtps.scene/1",
        "camera": {
            "projection": "perspective",
            "width": 16,
            "height": 16,
            "fx": 20.0,
            "fy": 20.0,
            "cx": 8.0,
            "cy": 8.0,
            "optical_center": [0, 0, 50],
        },
        "lights": [
            {"type": "point", "position": [10.0 * np.cos(a), 10.0 * np.sin(a), 20.0], "intensity": [400.0] * 3}
            for a in (0, 2, 4)
        ],
        "floor": None,
        "environment": {"type": "mesh", "file": "environment.ply"},
    }


def test_a_rig_scene_round_trips_through_scene_json_with_its_mesh_beside_it(tmp_path):
    write_environment_mesh(_square(half=30.0, albedo=(0.2, 0.4, 0.6)), tmp_path / "environment.ply")
    scene = parse_scene(_rig_json(), str(tmp_path / "scene.json"))
    assert scene.has_point_lights and isinstance(scene.lights[0], PointLight)
    np.testing.assert_allclose(scene.light_positions[1], [10 * np.cos(2), 10 * np.sin(2), 20])
    np.testing.assert_array_equal(scene.light_emission, np.full((3, 3), 400.0))
    out = tmp_path / "copy"
    out.mkdir()
    write_scene(scene, out / "scene.json")
    assert load_scene(out / "scene.json") == scene
    assert json.loads((out / "scene.json").read_text()) == scene_to_dict(scene)
    assert (out / "environment.ply").read_bytes() == (tmp_path / "environment.ply").read_bytes()


def test_a_point_light_has_no_single_direction_for_distant_light_steps(tmp_path):
    write_environment_mesh(_square(half=30.0), tmp_path / "environment.ply")
    scene = parse_scene(_rig_json(), str(tmp_path / "scene.json"))
    with pytest.raises(DatasetError, match=r"lights\[0\] is a point light .*distant lights only"):
        scene.light_directions


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            {"lights": [{"type": "spot", "position": [0, 0, 1], "intensity": [1, 1, 1]}] * 3},
            r"lights\[0\]\.type is 'spot': expected 'point'",
        ),
        (
            {"lights": [{"type": "point", "position": [0, 0], "intensity": [1, 1, 1]}] * 3},
            r"lights\[0\]\.position must have 3 numbers",
        ),
        (
            {"lights": [{"type": "point", "position": [0, 0, 1], "intensity": [-1, 1, 1]}] * 3},
            r"lights\[0\]\.intensity must not be negative",
        ),
        ({"lights": [{"type": "point", "position": [0, 0, 1]}] * 3}, r"lights\[0\]\.intensity is missing"),
        ({"environment": {"type": "mesh"}}, r"environment\.file is missing"),
        (
            {"environment": {"type": "mesh", "file": "../environment.ply"}},
            r"environment\.file is '../environment.ply': expected a file name",
        ),
        ({"environment": {"type": "mesh", "file": "gone.ply"}}, r"gone\.ply: file not found"),
    ],
)
def test_a_bad_rig_field_is_named(tmp_path, change, message):
    write_environment_mesh(_square(half=30.0), tmp_path / "environment.ply")
    with pytest.raises(DatasetError, match=message):
        parse_scene(_rig_json() | change, str(tmp_path / "scene.json"))


def test_a_mesh_that_roofs_the_object_or_encloses_the_camera_is_refused(tmp_path):
    roof = _square(z=30.0, half=30.0)
    assert "lies between the camera and the object" in view_problem(roof, 50.0, 0.0)
    assert "lies between the camera and the object" in view_problem(roof, None, 0.0)
    cube = np.array([[x, y, z] for x in (-100, 100) for y in (-100, 100) for z in (-100, 100)], float)
    faces = [
        [0, 1, 3],
        [0, 3, 2],
        [4, 6, 7],
        [4, 7, 5],
        [0, 4, 5],
        [0, 5, 1],
        [2, 3, 7],
        [2, 7, 6],
        [0, 2, 6],
        [0, 6, 4],
        [1, 5, 7],
        [1, 7, 3],
    ]
    room = MeshEnvironment(cube, faces, np.full((8, 3), 0.5))
    # Around a camera 50 above the object: the axis below it meets the room's floor only at -100.
    assert "encloses the camera" in view_problem(room, 50.0, 0.0)
    assert view_problem(_square(half=30.0), 50.0, 0.0) is None  # a floor under the object
    write_environment_mesh(roof, tmp_path / "environment.ply")
    with pytest.raises(DatasetError, match=r"environment\.ply: lies between the camera and the object"):
        parse_scene(_rig_json(), str(tmp_path / "scene.json"))


# Rendering


def _bump(size=24):
    y, x = np.mgrid[:size, :size] - (size - 1) / 2
    height = np.clip(6.0 - (x**2 + y**2) / 8.0, 0.0, None)
    mask = height > 0.3
    return np.where(mask, height, 0.0), np.full((size, size, 3), 0.7), mask


def test_a_floor_given_as_a_mesh_renders_as_the_contract_floor_from_either_side():
    height, albedo, mask = _bump()
    camera = Camera(24, 24, 1.0)
    lights = [Light(direction=d, irradiance=(np.pi,) * 3) for d in ([0.5, 0.1, 0.86], [-0.3, -0.4, 0.866])]
    lights = [
        Light(direction=np.asarray(light.direction) / np.linalg.norm(light.direction), irradiance=light.irradiance)
        for light in lights
    ]
    settings = {"bounces": 2, "samples": 256, "seed": 5}
    floor = irtps.render(Scene(camera, lights, floor=Floor(0.0, (0.6, 0.5, 0.4))), height, albedo, mask, **settings)
    # Where the skirt meets the floor, a cached vertex lies on both surfaces: which one hides a
    # light from it is a tie, settled by float rounding; compared apart, as a mean.
    rim = mask & ~ndimage.binary_erosion(mask)
    for flip in (False, True):
        mesh = _square(half=2000.0, albedo=(0.6, 0.5, 0.4), flip=flip)
        ours = irtps.render(Scene(camera, lights, environment=mesh), height, albedo, mask, **settings)
        np.testing.assert_allclose(ours.direct[:, ~rim], floor.direct[:, ~rim], rtol=1e-3, atol=1e-4)
        np.testing.assert_allclose(ours.direct[:, rim].mean(1), floor.direct[:, rim].mean(1), rtol=0.01)
        for region in (mask, ~ndimage.binary_dilation(mask, iterations=2)):
            np.testing.assert_allclose(ours.indirect[:, region].mean(1), floor.indirect[:, region].mean(1), rtol=0.03)


def test_a_point_light_over_a_plate_gives_the_inverse_square_irradiance():
    size, pixel_size, intensity = 16, 0.5, 40.0
    position = np.array([1.0, -2.0, 6.0])
    scene = Scene(Camera(size, size, pixel_size), [PointLight(position, (intensity,) * 3)] * 3)
    rendering = irtps.render(
        scene, np.zeros((size, size)), np.full((size, size, 3), 0.5), np.ones((size, size), bool), bounces=0
    )
    i, j = np.mgrid[:size, :size]
    x, y = (j + 0.5 - size / 2) * pixel_size, (size / 2 - i - 0.5) * pixel_size
    r2 = (position[0] - x) ** 2 + (position[1] - y) ** 2 + position[2] ** 2
    expected = 0.5 * intensity * position[2] / np.sqrt(r2) / (np.pi * r2)
    # The mesh spans the pixel centres: the outer half of each edge pixel is empty.
    np.testing.assert_allclose(rendering.direct[0, 1:-1, 1:-1, 1], expected[1:-1, 1:-1], rtol=0.01)


def test_the_mesh_file_is_among_a_rig_data_sets_inputs():
    from irtps.io.dataset_files import dataset_inputs, scene_object_inputs

    assert RIG / "environment.ply" in dataset_inputs(RIG)
    assert RIG / "environment.ply" in scene_object_inputs(RIG)


def test_render_refuses_to_write_where_the_mesh_it_reads_lies(tmp_path, capsys):
    import shutil

    from irtps.cli.main import main

    rig = shutil.copytree(RIG, tmp_path / "rig", ignore=shutil.ignore_patterns("environment.ply"))
    elsewhere = tmp_path / "meshes"
    elsewhere.mkdir()
    shutil.copy(RIG / "environment.ply", elsewhere / "box.ply")
    (rig / "environment.ply").symlink_to(elsewhere / "box.ply")
    before = (elsewhere / "box.ply").read_bytes()
    assert main(["render", str(rig), "--out", str(elsewhere), "--force", "--quiet"]) == 2
    assert "environment.ply" in capsys.readouterr().err
    assert (elsewhere / "box.ply").read_bytes() == before


# Meshes as users have them: OBJ, colours per face, one albedo for the whole file


def test_an_obj_written_by_trimesh_reads_with_its_vertex_colours(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    rng = np.random.default_rng(2)
    colours = rng.integers(0, 256, (30, 3))
    mesh = trimesh.Trimesh(
        rng.normal(size=(30, 3)),
        rng.integers(0, 30, (40, 3)),
        vertex_colors=np.c_[colours, np.full(30, 255)],
        process=False,
    )
    mesh.export(tmp_path / "box.obj")
    back = read_environment_mesh(tmp_path / "box.obj")
    np.testing.assert_allclose(back.vertices, mesh.vertices, atol=1e-7)
    np.testing.assert_array_equal(back.triangles, mesh.faces)
    np.testing.assert_allclose(back.albedo, colours / 255, atol=1e-7)


def test_a_ply_coloured_per_face_gives_each_triangle_its_face_colour(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    mesh = trimesh.Trimesh(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],
        faces,
        face_colors=[[255, 0, 0, 255], [0, 51, 255, 255]],
        process=False,
    )
    mesh.export(tmp_path / "card.ply")
    back = read_environment_mesh(tmp_path / "card.ply")
    assert back.triangles.shape == (2, 3)
    np.testing.assert_array_equal(back.vertices[back.triangles], mesh.vertices[faces])
    np.testing.assert_allclose(back.albedo[back.triangles[1]], np.tile([0.0, 0.2, 1.0], (3, 1)))


def test_an_obj_takes_each_faces_material_colour_and_splits_its_quads(tmp_path):
    (tmp_path / "rig.mtl").write_text("newmtl grey\nKd 0.5 0.5 0.5\nnewmtl card  # reflector\nKd 0.85 0.62 0.25\n")
    (tmp_path / "rig.obj").write_text(
        "mtllib rig.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n"
        "usemtl grey\nf 1/1/1 2/2/1 3/3/1 4/4/1\nusemtl card\nf -5 -4 -1\n"
    )
    back = read_environment_mesh(tmp_path / "rig.obj")
    assert back.triangles.shape == (3, 3)
    np.testing.assert_allclose(back.albedo[back.triangles[2]], np.tile([0.85, 0.62, 0.25], (3, 1)))
    np.testing.assert_allclose(back.albedo[back.triangles[0]], 0.5)


@pytest.mark.parametrize(
    ("name", "text", "message"),
    [
        ("rig.stl", "solid x\n", "not a mesh file irtps reads: expected one of .ply, .obj"),
        ("rig.obj", "mtllib ../other.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "mtllib '../other.mtl' lies outside"),
        ("rig.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl none\nf 1 2 3\n", "a face's material 'none' has no Kd colour"),
        ("rig.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "line 4: vertex index 0"),
        ("rig.obj", "v 0 0\n", "line 1: a vertex needs x y z"),
        (
            "rig.obj",
            "v 0 0 0 0.5 0.5 0.5\nv 1 0 0 1 1 1\nv 0 1 0 1 1 1\nf 1 2 x\n",
            "not a readable OBJ file: ValueError",
        ),
    ],
)
def test_a_bad_obj_or_unknown_file_is_one_named_error(tmp_path, name, text, message):
    (tmp_path / name).write_text(text)
    with pytest.raises(DatasetError, match=rf"{name}: {message}"):
        read_environment_mesh(tmp_path / name)


def test_one_albedo_for_the_whole_mesh_round_trips_through_scene_json(tmp_path):
    _ascii_ply(tmp_path / "environment.ply", ["-30 -30 0", "30 -30 0", "30 30 0", "-30 30 0"], ["4 0 1 2 3"], colour="")
    obj = _rig_json()
    obj["environment"]["albedo"] = [0.2, 0.3, 0.4]
    scene = parse_scene(obj, str(tmp_path / "scene.json"))
    assert scene.environment.uniform_albedo == (0.2, 0.3, 0.4)
    np.testing.assert_array_equal(scene.environment.albedo, np.tile([0.2, 0.3, 0.4], (4, 1)))
    assert scene_to_dict(scene)["environment"] == {"type": "mesh", "file": "environment.ply", "albedo": [0.2, 0.3, 0.4]}
    with pytest.raises(irtps.ArgumentError, match=r"^albedo: must be three numbers in \[0, 1\]"):
        read_environment_mesh(tmp_path / "environment.ply", albedo=(0.2, 1.5, 0.1))


def test_a_checked_mesh_pickles_without_its_ray_structures_and_checks_again():
    import pickle

    mesh = _square(z=30.0, half=30.0)
    assert "lies between" in view_problem(mesh, 50.0, 0.0)  # builds its BVH, kept with it
    back = pickle.loads(pickle.dumps(mesh))
    assert back == mesh and "_core_environment" not in back.__dict__
    assert "lies between" in view_problem(back, 50.0, 0.0)
