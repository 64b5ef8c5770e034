"""scene.json: parsing, validation, round trips and the camera geometry."""

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from irtps import Camera, CornellBox, DatasetError, Floor, IrtpsError, Light, Scene, load_scene
from irtps.model.scene import parse_scene, scene_to_dict, write_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
MITSUBA = SHARED / "data" / "mitsuba"
needs_shared = pytest.mark.skipif(not MITSUBA.is_dir(), reason="shared reference data not available")


def valid_scene_dict():
    """A valid scene.json object with a floor and a Cornell box, 4 lights."""
    return {
        "format": "irtps.scene/1",
        "camera": {"projection": "orthographic", "width": 8, "height": 6, "pixel_size": 0.5},
        "lights": [
            {"direction": [0.0, 0.0, 1.0], "irradiance": [3.0, 3.0, 3.0]},
            {"direction": [0.6, 0.0, 0.8], "irradiance": [1.0, 2.0, 3.0]},
            {"direction": [0.0, -0.6, 0.8], "irradiance": [0.5, 0.5, 0.5]},
            {"direction": [-0.48, 0.36, 0.8], "irradiance": [0.0, 1.0, 0.0]},
        ],
        "floor": {"height": 0.0, "albedo": [0.8, 0.8, 0.8]},
        "environment": {
            "type": "cornell_box",
            "x": [-10.0, 10.0],
            "y": [-8.0, 8.0],
            "z_top": 5.0,
            "albedo": {
                "left": [0.63, 0.065, 0.05],
                "right": [0.14, 0.45, 0.091],
                "back": [0.725, 0.71, 0.68],
                "front": [0.725, 0.71, 0.68],
            },
        },
    }


def test_parse_valid_scene_builds_every_field():
    scene = parse_scene(valid_scene_dict(), "scene.json")
    assert scene.camera == Camera(width=8, height=6, pixel_size=0.5)
    assert len(scene.lights) == 4
    np.testing.assert_array_equal(scene.lights[1].direction, [0.6, 0.0, 0.8])
    np.testing.assert_array_equal(scene.lights[1].irradiance, [1.0, 2.0, 3.0])
    assert scene.floor == Floor(height=0.0, albedo=(0.8, 0.8, 0.8))
    assert scene.environment == CornellBox(
        x=(-10.0, 10.0),
        y=(-8.0, 8.0),
        z_top=5.0,
        albedo_left=(0.63, 0.065, 0.05),
        albedo_right=(0.14, 0.45, 0.091),
        albedo_back=(0.725, 0.71, 0.68),
        albedo_front=(0.725, 0.71, 0.68),
    )


def test_light_arrays_stack_in_light_order():
    scene = parse_scene(valid_scene_dict(), "scene.json")
    assert scene.light_directions.shape == (4, 3)
    assert scene.light_irradiance.shape == (4, 3)
    np.testing.assert_array_equal(scene.light_directions[3], [-0.48, 0.36, 0.8])
    np.testing.assert_array_equal(scene.light_irradiance[:, 1], [3.0, 2.0, 0.5, 1.0])


def test_no_floor_and_no_environment_are_none():
    obj = valid_scene_dict()
    obj["floor"] = None
    obj["environment"] = {"type": "none"}
    scene = parse_scene(obj, "scene.json")
    assert scene.floor is None
    assert scene.environment is None
    assert scene_to_dict(scene) == obj


def test_scene_to_dict_inverts_parse_scene_exactly():
    obj = valid_scene_dict()
    scene = parse_scene(obj, "scene.json")
    assert scene_to_dict(scene) == obj
    assert parse_scene(scene_to_dict(scene), "again") == scene
    json.dumps(scene_to_dict(scene))


def test_integer_numbers_are_accepted_and_written_back_equal():
    obj = valid_scene_dict()
    obj["camera"]["pixel_size"] = 1
    obj["lights"][0]["direction"] = [0, 0, 1]
    scene = parse_scene(obj, "scene.json")
    assert scene.camera.pixel_size == 1.0
    assert scene_to_dict(scene) == obj


def test_light_is_immutable_comparable_and_hashable():
    light = Light(direction=[0.0, 0.6, 0.8], irradiance=[1.0, 1.0, 1.0])
    assert light.direction.dtype == np.float64
    with pytest.raises(ValueError):
        light.direction[0] = 1.0
    same = Light(direction=np.array([0.0, 0.6, 0.8]), irradiance=(1, 1, 1))
    assert light == same and hash(light) == hash(same)
    assert light != Light(direction=[0.0, 0.0, 1.0], irradiance=[1.0, 1.0, 1.0])
    with pytest.raises(DatasetError, match=r"Light\.direction must have 3 components"):
        Light(direction=[0.0, 1.0], irradiance=[1.0, 1.0, 1.0])


def test_pixel_centers_follow_the_contract():
    camera = Camera(width=4, height=2, pixel_size=0.5)
    x, y = camera.pixel_centers()
    assert x.shape == y.shape == (2, 4)
    np.testing.assert_allclose(x[0], [-0.75, -0.25, 0.25, 0.75])
    np.testing.assert_allclose(x[1], x[0])
    np.testing.assert_allclose(y[:, 0], [0.25, -0.25])
    np.testing.assert_allclose(y[:, 3], y[:, 0])


def test_pixel_centers_odd_size_put_the_middle_pixel_on_the_axis():
    x, y = Camera(width=3, height=5, pixel_size=2.0).pixel_centers()
    assert x[2, 1] == 0.0 and y[2, 1] == 0.0
    assert y[0, 0] == 4.0 and x[0, 0] == -2.0


def test_write_then_load_scene_round_trips(tmp_path):
    scene = parse_scene(valid_scene_dict(), "scene.json")
    path = tmp_path / "scene.json"
    write_scene(scene, path)
    assert load_scene(path) == scene
    assert path.read_text().endswith("}\n")
    assert json.loads(path.read_text()) == valid_scene_dict()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]


def test_write_scene_rejects_an_invalid_scene_and_writes_nothing(tmp_path):
    scene = parse_scene(valid_scene_dict(), "scene.json")
    lights = scene.lights[:2]
    bad = Scene(camera=scene.camera, lights=lights, floor=scene.floor, environment=scene.environment)
    path = tmp_path / "scene.json"
    with pytest.raises(DatasetError, match="lights has 2 lights"):
        write_scene(bad, path)
    assert not path.exists()


def test_load_scene_reports_json_syntax_errors_with_file_and_line(tmp_path):
    path = tmp_path / "scene.json"
    path.write_text('{\n "format": "irtps.scene/1",\n "camera": {,\n}\n')
    with pytest.raises(DatasetError) as info:
        load_scene(path)
    message = str(info.value)
    assert message.startswith(f"{path}: invalid JSON at line 3")


def test_load_scene_missing_file_names_it(tmp_path):
    path = tmp_path / "nowhere" / "scene.json"
    with pytest.raises(DatasetError, match=r"scene\.json: file not found"):
        load_scene(path)


def test_load_scene_rejects_duplicate_keys(tmp_path):
    path = tmp_path / "scene.json"
    text = json.dumps(valid_scene_dict())
    path.write_text(text[:-1] + ', "floor": null}')
    with pytest.raises(DatasetError, match="duplicate key 'floor'"):
        load_scene(path)


def test_load_scene_prefixes_field_errors_with_the_path(tmp_path):
    obj = valid_scene_dict()
    obj["lights"][2]["direction"] = [0.0, 0.0, 1.2]
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(obj))
    with pytest.raises(DatasetError) as info:
        load_scene(path)
    assert str(info.value) == f"{path}: lights[2].direction is not a unit vector (norm 1.2)"


def test_dataset_error_is_a_value_error_and_an_irtps_error():
    assert issubclass(DatasetError, ValueError)
    assert issubclass(DatasetError, IrtpsError)


def _set(path, value):
    """A mutation that sets obj[path...] = value (deleting the key when value is _DELETE)."""

    def mutate(obj):
        target = obj
        for key in path[:-1]:
            target = target[key]
        if value is _DELETE:
            del target[path[-1]]
        else:
            target[path[-1]] = value
        return obj

    return mutate


_DELETE = object()

MALFORMED = [
    ("top-level array", lambda obj: [obj], "the top level must be an object, got an array"),
    ("unknown format", _set(["format"], "irtps.scene/2"), "format is 'irtps.scene/2': unknown format"),
    ("missing format", _set(["format"], _DELETE), "format is missing"),
    ("unknown top-level field", _set(["lihgts"], []), "the top level has an unknown field 'lihgts'"),
    ("missing camera", _set(["camera"], _DELETE), "camera is missing"),
    ("camera not an object", _set(["camera"], [8, 6]), "camera must be an object, got an array"),
    ("perspective camera without fx", _set(["camera", "projection"], "perspective"), "camera.fx is missing"),
    ("unknown projection", _set(["camera", "projection"], "fisheye"), "camera.projection is 'fisheye'"),
    ("zero width", _set(["camera", "width"], 0), "camera.width must be a positive integer, got 0"),
    ("fractional width", _set(["camera", "width"], 8.5), "camera.width must be a positive integer, got the number 8.5"),
    ("string height", _set(["camera", "height"], "6"), "camera.height must be a positive integer, got the string '6'"),
    ("boolean height", _set(["camera", "height"], True), "camera.height must be a positive integer, got a boolean"),
    ("negative height", _set(["camera", "height"], -6), "camera.height must be a positive integer, got -6"),
    ("zero pixel size", _set(["camera", "pixel_size"], 0.0), "camera.pixel_size must be positive"),
    ("string pixel size", _set(["camera", "pixel_size"], "1"), "camera.pixel_size must be a number"),
    ("missing pixel size", _set(["camera", "pixel_size"], _DELETE), "camera.pixel_size is missing"),
    ("lights not an array", _set(["lights"], {}), "lights must be an array, got an object"),
    ("too few lights", lambda obj: _set(["lights"], obj["lights"][:2])(obj), "lights has 2 lights"),
    ("no lights", _set(["lights"], []), "lights has 0 lights"),
    ("light not an object", _set(["lights", 1], [0.0, 0.0, 1.0]), "lights[1] must be an object, got an array"),
    ("unknown light field", _set(["lights", 0, "color"], "red"), "lights[0] has an unknown field 'color'"),
    ("missing irradiance", _set(["lights", 0, "irradiance"], _DELETE), "lights[0].irradiance is missing"),
    (
        "long direction",
        _set(["lights", 3, "direction"], [0.0, 0.72, 0.96]),
        "lights[3].direction is not a unit vector (norm 1.2)",
    ),
    (
        "short direction",
        _set(["lights", 0, "direction"], [0.0, 0.0, 0.99]),
        "lights[0].direction is not a unit vector (norm 0.99)",
    ),
    (
        "downward light",
        _set(["lights", 1, "direction"], [0.0, 0.6, -0.8]),
        "lights[1].direction must point toward the camera side (z > 0)",
    ),
    (
        "grazing light",
        _set(["lights", 1, "direction"], [1.0, 0.0, 0.0]),
        "lights[1].direction must point toward the camera side (z > 0), got z = 0",
    ),
    (
        "2-component direction",
        _set(["lights", 0, "direction"], [0.0, 1.0]),
        "lights[0].direction must have 3 numbers, got 2",
    ),
    (
        "string component",
        _set(["lights", 0, "direction", 1], "0"),
        "lights[0].direction[1] must be a number, got the string '0'",
    ),
    ("null direction", _set(["lights", 0, "direction"], None), "lights[0].direction must be an array, got null"),
    (
        "negative irradiance",
        _set(["lights", 2, "irradiance"], [1.0, -1.0, 1.0]),
        "lights[2].irradiance must not be negative",
    ),
    (
        "NaN irradiance",
        _set(["lights", 0, "irradiance", 0], float("nan")),
        "lights[0].irradiance[0] must be a finite number, got nan",
    ),
    (
        "infinite irradiance",
        _set(["lights", 0, "irradiance", 2], float("inf")),
        "lights[0].irradiance[2] must be a finite number",
    ),
    ("floor not an object", _set(["floor"], 0.0), "floor must be an object, got the number 0.0"),
    ("floor string height", _set(["floor", "height"], "0"), "floor.height must be a number, got the string '0'"),
    ("floor albedo above 1", _set(["floor", "albedo"], [1.5, 0.5, 0.5]), "floor.albedo must be RGB values in [0, 1]"),
    ("floor albedo 2 values", _set(["floor", "albedo"], [0.5, 0.5]), "floor.albedo must have 3 numbers"),
    ("missing floor", _set(["floor"], _DELETE), "floor is missing"),
    ("missing environment", _set(["environment"], _DELETE), "environment is missing"),
    ("environment null", _set(["environment"], None), "environment must be an object, got null"),
    ("environment without type", _set(["environment", "type"], _DELETE), "environment.type is missing"),
    ("unknown environment", _set(["environment", "type"], "sky"), "environment.type is 'sky'"),
    (
        "none with box fields",
        lambda obj: _set(["environment", "type"], "none")(obj),
        "environment has an unknown field 'x'",
    ),
    ("unknown box field", _set(["environment", "colour"], 1), "environment has an unknown field 'colour'"),
    ("reversed box x", _set(["environment", "x"], [10.0, -10.0]), "environment.x must be [low, high] with low < high"),
    (
        "box y with 3 values",
        _set(["environment", "y"], [-8.0, 0.0, 8.0]),
        "environment.y must be [low, high], got 3 numbers",
    ),
    (
        "box top below floor",
        _set(["environment", "z_top"], -1.0),
        "environment.z_top (-1) must be above the floor height (0)",
    ),
    (
        "missing box wall albedo",
        _set(["environment", "albedo", "front"], _DELETE),
        "environment.albedo.front is missing",
    ),
    (
        "negative wall albedo",
        _set(["environment", "albedo", "left"], [-0.1, 0.0, 0.0]),
        "environment.albedo.left must be RGB values in [0, 1]",
    ),
    (
        "box albedo not an object",
        _set(["environment", "albedo"], [0.5, 0.5, 0.5]),
        "environment.albedo must be an object",
    ),
]


@pytest.mark.parametrize("mutate, expected", [case[1:] for case in MALFORMED], ids=[case[0] for case in MALFORMED])
def test_malformed_scene_is_rejected_naming_the_field(mutate, expected):
    obj = mutate(copy.deepcopy(valid_scene_dict()))
    with pytest.raises(DatasetError) as info:
        parse_scene(obj, "scene.json")
    message = str(info.value)
    assert message.startswith("scene.json: ")
    assert expected in message


@needs_shared
@pytest.mark.parametrize("name", ["cap_cornell", "grooves_dark"])
def test_reference_scenes_load_and_round_trip(name):
    path = MITSUBA / name / "scene.json"
    scene = load_scene(path)
    assert scene.camera == Camera(width=96, height=96, pixel_size=1.0)
    assert len(scene.lights) == 12
    np.testing.assert_allclose(np.linalg.norm(scene.light_directions, axis=1), 1.0, atol=1e-9)
    assert scene_to_dict(scene) == json.loads(path.read_text())
    if name == "cap_cornell":
        assert scene.floor == Floor(height=0.0, albedo=(0.8, 0.8, 0.8))
        assert scene.environment.albedo_left == (0.63, 0.065, 0.05)
    else:
        assert scene.floor is None and scene.environment is None
