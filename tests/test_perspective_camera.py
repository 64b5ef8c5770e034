"""The perspective camera of contract §1b: the model (rays, intrinsics, the orthographic
stand-in), scene.json, ground-truth depth, intrinsics files (DiLiGenT's ``K.txt`` and
``--intrinsics``), and the shared perspective scenes."""

import dataclasses
import json
import math
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage
from cli_helpers import refused

import irtps
from irtps import Camera, DatasetError, IrtpsWarning, Scene
from irtps.cli.main import main
from irtps.io.dataset_files import dataset_inputs
from irtps.io.diligent import diligent_ground_truth_inputs, load_diligent_ground_truth
from irtps.io.intrinsics import read_intrinsics, with_intrinsics
from irtps.model.camera import intrinsics_problem
from irtps.geometry.boundary import mask_boundary
from irtps.geometry.placement import raised
from irtps.irt.pipeline import pinhole_relief
from irtps.model.scene import (
    STAND_IN_WARNING,
    load_scene,
    orthographic_scene,
    parse_scene,
    scene_to_dict,
    write_scene,
)

DATA = Path(__file__).resolve().parent / "data"
FIXTURE = DATA / "mitsuba_persp_small" / "cap_persp_cornell"
BALL = DATA / "diligent_ball_small"
ORTHOGRAPHIC = DATA / "mitsuba_small" / "cap_cornell"
SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
MITSUBA = SHARED / "mitsuba"
needs_shared = pytest.mark.skipif(not MITSUBA.is_dir(), reason="shared Mitsuba scenes not available")
#: The start of the warning of every step that runs on a perspective camera's stand-in.
STAND_IN = STAND_IN_WARNING
#: DiLiGenT's intrinsics of readingPNG (612x512 images).
DILIGENT_K = "3772.08 0 305.875\n0 3759.01 255.125\n0 0 1\n"


def _perspective(width=4, height=3, fx=2.0, fy=4.0, cx=1.5, cy=1.0, zc=10.0) -> Camera:
    return Camera(width, height, projection="perspective", fx=fx, fy=fy, cx=cx, cy=cy, optical_center=(0, 0, zc))


def _light(direction) -> irtps.Light:
    return irtps.Light(direction=np.array(direction) / np.linalg.norm(direction), irradiance=(np.pi,) * 3)


def _scene(camera: Camera, floor: irtps.Floor | None = None) -> Scene:
    return Scene(camera, [_light([0, 0, 1]), _light([1, 0, 2]), _light([0, 1, 2])], floor=floor)


def _write_k(folder: Path, text: str) -> Path:
    path = folder / "K.txt"
    path.write_text(text)
    return path


# The model


def test_centre_rays_follow_the_contract_for_a_hand_made_camera():
    camera = _perspective()
    rays = camera.ray_directions()
    assert rays.shape == (3, 4, 3)
    # ((j + 0.5 - cx) / fx, -(i + 0.5 - cy) / fy, -1) with fx 2, fy 4, cx 1.5, cy 1
    assert rays[0, 0].tolist() == [-0.5, 0.125, -1.0]
    assert rays[2, 3].tolist() == [1.0, -0.375, -1.0]
    assert rays[1, 1].tolist() == [0.0, -0.125, -1.0]
    np.testing.assert_array_equal(camera.intrinsics(), [[2.0, 0.0, 1.5], [0.0, 4.0, 1.0], [0.0, 0.0, 1.0]])
    # The point at depth d along the optical axis lies at height zc - d.
    point = np.array(camera.optical_center) + 3.0 * rays[2, 3]
    assert point.tolist() == [3.0, -1.125, 7.0]


def test_the_principal_point_projects_back_onto_its_pixel():
    camera = _perspective(width=8, height=6, fx=5.0, fy=7.0, cx=2.3, cy=4.1)
    rays = camera.ray_directions()
    u = camera.intrinsics() @ np.array([rays[4, 6, 0], -rays[4, 6, 1], 1.0])  # camera frame: y down, z forward
    assert u.tolist() == pytest.approx([6.5, 4.5, 1.0])


def test_an_orthographic_camera_has_parallel_rays_and_no_intrinsics():
    camera = Camera(3, 2, 0.5)
    assert camera.ray_directions().reshape(-1, 3).tolist() == [[0.0, 0.0, -1.0]] * 6
    assert camera.orthographic_stand_in(7.0) is camera
    with pytest.raises(irtps.ArgumentError, match="camera: is orthographic: it has no intrinsics"):
        camera.intrinsics()


def test_a_perspective_camera_has_no_pixel_size_nor_fixed_pixel_centres():
    camera = _perspective()
    assert camera.pixel_size is None
    with pytest.raises(irtps.ArgumentError, match="pixel centres depend on the depth"):
        camera.pixel_centers()
    with pytest.raises(irtps.ArgumentError, match="camera: is perspective"):
        camera.orthographic_pixel_size  # noqa: B018


def test_the_stand_in_has_the_pixel_footprint_at_the_depth_given():
    camera = _perspective(fx=2.0, fy=8.0)
    stand_in = camera.orthographic_stand_in(12.0)
    assert stand_in == Camera(4, 3, 3.0, pinhole=camera)  # 12 / sqrt(2 * 8)
    with pytest.raises(DatasetError, match=r"Camera\.pinhole is .*: expected the perspective camera of a 4x3 image"):
        Camera(4, 3, 3.0, pinhole=Camera(4, 3, 3.0))
    with pytest.raises(DatasetError, match="Camera.pinhole is given: only an orthographic stand-in has it"):
        dataclasses.replace(camera, pinhole=camera)
    for depth in (0.0, -1.0, math.nan, "1"):
        with pytest.raises(irtps.ArgumentError, match="depth: expected a positive finite number"):
            camera.orthographic_stand_in(depth)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"fx": 0.0}, r"Camera\.fx = 0: a focal length must be a positive finite number of pixels"),
        ({"fy": math.nan}, r"Camera\.fy = nan: a focal length"),
        ({"cx": math.inf}, r"Camera\.cx = inf: the principal point must be finite"),
        (
            {"cx": 9.0},
            r"Camera\.cx = 9 lies more than 1 image width outside the image, 4 pixels wide \(expected -4 to 8\)",
        ),
        ({"cy": -3.5}, r"Camera\.cy = -3.5 lies more than 1 image height outside the image, 3 pixels high"),
        ({"optical_center": (1.0, 0.0, 5.0)}, r"Camera\.optical_center must be \(0, 0, zc\)"),
        ({"optical_center": None}, r"Camera\.optical_center is missing: a perspective camera needs it"),
        ({"pixel_size": 1.0}, r"Camera\.pixel_size is given: a perspective camera has none"),
        ({"projection": "fisheye"}, r"Camera\.projection is 'fisheye': expected one of orthographic, perspective"),
    ],
)
def test_a_camera_refuses_what_is_not_a_perspective_camera(fields, message):
    with pytest.raises(DatasetError, match=message):
        dataclasses.replace(_perspective(), **fields)


def test_an_orthographic_camera_needs_its_pixel_size_and_nothing_of_a_pinhole():
    with pytest.raises(DatasetError, match=r"Camera\.pixel_size is missing"):
        Camera(4, 3)
    with pytest.raises(DatasetError, match=r"Camera\.fx is given: only a perspective camera has it"):
        Camera(4, 3, 1.0, fx=2.0)


def test_the_principal_point_may_lie_up_to_one_image_size_outside_the_image():
    assert intrinsics_problem(10.0, 10.0, -24.0, 48.0, (24, 24)) is None
    assert intrinsics_problem(10.0, 10.0, 12.0, 48.01, (24, 24))[0] == "cy"


def test_the_camera_must_stand_above_the_floor():
    with pytest.raises(
        DatasetError, match=r"Scene\.camera\.optical_center is at height 10, not above the object's base \(12"
    ):
        _scene(_perspective(), floor=irtps.Floor(12.0, (0.5, 0.5, 0.5)))


# scene.json


def test_scene_json_holds_the_perspective_camera_of_the_contract(tmp_path):
    scene = _scene(_perspective(), floor=irtps.Floor(-1.0, (0.5, 0.5, 0.5)))
    camera = scene_to_dict(scene)["camera"]
    assert camera == {
        "projection": "perspective",
        "width": 4,
        "height": 3,
        "fx": 2.0,
        "fy": 4.0,
        "cx": 1.5,
        "cy": 1.0,
        "optical_center": [0.0, 0.0, 10.0],
    }
    assert parse_scene(scene_to_dict(scene)) == scene
    write_scene(scene, tmp_path / "scene.json")
    assert load_scene(tmp_path / "scene.json") == scene


def _scene_json(**camera) -> dict:
    perspective = {"projection": "perspective", "width": 4, "height": 3, "fx": 2.0, "fy": 4.0, "cx": 1.5, "cy": 1.0}
    lights = [{"direction": [0, 0, 1], "irradiance": [1, 1, 1]}] * 3
    return {
        "format": "irtps.scene/1",
        "camera": {**perspective, "optical_center": [0, 0, 10], **camera},
        "lights": lights,
        "floor": None,
        "environment": {"type": "none"},
    }


@pytest.mark.parametrize(
    ("camera", "message"),
    [
        ({"fx": -2.0}, "scene.json: camera.fx = -2: a focal length must be a positive finite number of pixels"),
        ({"cy": 40.0}, "scene.json: camera.cy = 40 lies more than 1 image height outside the image"),
        ({"optical_center": [0, 1, 10]}, r"scene.json: camera.optical_center must be \[0, 0, zc\]"),
        (
            {"optical_center": [0, 0, -5]},
            "scene.json: camera.optical_center is at height -5, not above the object's base",
        ),
        ({"pixel_size": 1.0}, "scene.json: camera has an unknown field 'pixel_size'"),
        ({"fx": "2"}, "scene.json: camera.fx must be a number"),
        (
            {"projection": "fisheye"},
            "scene.json: camera.projection is 'fisheye': expected one of 'orthographic', 'perspective'",
        ),
    ],
)
def test_scene_json_refuses_a_bad_perspective_camera_naming_the_field(camera, message):
    with pytest.raises(DatasetError, match=message):
        parse_scene(_scene_json(**camera))


def test_scene_json_without_a_field_of_the_pinhole_names_it():
    obj = _scene_json()
    del obj["camera"]["cx"]
    with pytest.raises(DatasetError, match="scene.json: camera.cx is missing"):
        parse_scene(obj)


# The small perspective data set: ground-truth depth, reconstruction


def test_the_small_perspective_data_set_loads_with_its_depth():
    data = irtps.load_dataset(FIXTURE)
    camera = data.scene.camera
    assert (camera.projection, camera.cx, camera.optical_center) == ("perspective", 12.0, (0, 0, pytest.approx(124.8)))
    assert camera.fx == camera.fy == pytest.approx(28.8)
    depth, height, mask = data.gt.depth, data.gt.height, data.mask
    assert depth.shape == (24, 24) and (depth[mask] > 100).all() and (depth[~mask] == 0).all()
    np.testing.assert_allclose(height[mask], 124.8 - depth[mask], atol=1e-4)  # z = zc - d


def test_saved_and_read_back_the_depth_and_the_camera_are_the_same(tmp_path):
    data = irtps.load_dataset(FIXTURE)
    irtps.save_dataset(data, tmp_path / "copy")
    copy = irtps.load_dataset(tmp_path / "copy")
    assert copy.scene == data.scene
    np.testing.assert_array_equal(copy.gt.depth, data.gt.depth)
    assert irtps.load_ground_truth(tmp_path / "copy", (24, 24)).depth is not None
    unknown = data.gt.depth.copy()
    unknown[12, 12] = np.nan
    irtps.save_dataset(dataclasses.replace(data, gt=dataclasses.replace(data.gt, depth=unknown)), tmp_path / "nan")
    assert irtps.load_dataset(tmp_path / "nan").gt.depth[12, 12] == 0.0  # written as unknown, as outside the mask


def test_a_perspective_data_set_is_reconstructed_on_its_stand_in_with_one_warning():
    data = irtps.load_dataset(FIXTURE)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = irtps.reconstruct(data)
    stand_ins = [str(w.message) for w in caught if STAND_IN in str(w.message)]
    assert len(stand_ins) == 1 and stand_ins[0].startswith(f"{FIXTURE}: ")
    assert result.pixel_size == pytest.approx(124.8 / 28.8)
    error = irtps.evaluate(mask=result.mask, normals=result.normals, gt=data.gt).normal_mean_angular_deg
    assert error < 10.0


def test_rendering_a_perspective_scene_traces_through_its_pinhole_without_a_warning():
    # A level plate 6 below a pinhole at 16 looks the same from every pixel: a stand-in
    # would see it too; its edge and the floor beside it are where the pinhole shows.
    scene = _scene(_perspective(width=8, height=8, fx=8.0, fy=8.0, cx=4.0, cy=4.0, zc=16.0))
    mask = np.zeros((8, 8), bool)
    mask[2:6, 2:6] = True
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rendering = irtps.render(scene, np.where(mask, 10.0, 0.0), np.full((8, 8, 3), 0.5), mask, bounces=0)
    assert rendering.direct.shape == (3, 8, 8, 3)
    with pytest.warns(
        IrtpsWarning, match="2 \\(its pixel footprint at the object's base, 16 from the optical centre\\)"
    ):
        stand_in = orthographic_scene(scene, "x").camera
    assert stand_in == Camera(8, 8, 2.0, pinhole=scene.camera)


def test_a_stand_in_beyond_the_range_of_pixel_sizes_is_refused():
    scene = _scene(_perspective(width=8, height=8, fx=1e-12, fy=1e-12, cx=4.0, cy=4.0, zc=16.0))
    with pytest.raises(
        DatasetError, match=r"^x: the perspective camera's orthographic stand-in has pixel size 1\.6e\+13"
    ):
        orthographic_scene(scene, "x")


# Intrinsics files


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("28.8 0 12\n0 28.8 12\n", "expected a 3x3 intrinsic matrix (3 lines of 3 numbers), got 2 lines"),
        ("28.8 0 12 0\n0 28.8 12\n0 0 1\n", "line 1: expected 3 numbers, got 4"),
        ("28.8 0 12\n0 28.8\n0 0 1\n", "line 2: expected 3 numbers, got 2"),
        ("28.8 0 12\n0 nan 12\n0 0 1\n", "line 2: non-finite value in '0 nan 12'"),
        ("28.8 0 12\n0 28.8 twelve\n0 0 1\n", "line 2: expected 3 numbers, got '0 28.8 twelve'"),
        ("0 0 12\n0 28.8 12\n0 0 1\n", "fx = 0: a focal length must be a positive number of pixels"),
        ("28.8 0 12\n0 -28.8 12\n0 0 1\n", "fy = -28.8: a focal length must be a positive number of pixels"),
        (
            "28.8 0.5 12\n0 28.8 12\n0 0 1\n",
            "skew K[0][1] = 0.5: only cameras whose pixel rows and columns are square to each other (zero skew) are supported",
        ),
        ("28.8 0 12\n1 28.8 12\n0 0 1\n", "K[1][0] = 1: an intrinsic matrix has 0 there"),
        ("28.8 0 12\n0 28.8 12\n0 0 2\n", "the last row is 0 0 2: an intrinsic matrix ends in 0 0 1"),
    ],
)
def test_a_bad_intrinsics_file_is_refused_naming_it_and_the_problem(tmp_path, text, problem):
    path = _write_k(tmp_path, text)
    with pytest.raises(DatasetError) as raised:
        read_intrinsics(path)
    assert str(raised.value) == f"{path}: {problem}"


def test_a_missing_intrinsics_file_is_named(tmp_path):
    with pytest.raises(DatasetError, match=r"K\.txt: missing \(intrinsics: a 3x3 matrix in pixels\)"):
        read_intrinsics(tmp_path / "K.txt")


def test_intrinsics_whose_principal_point_is_far_outside_the_images_are_refused(tmp_path):
    path = _write_k(tmp_path, DILIGENT_K)
    scene = irtps.load_dataset(FIXTURE).scene
    with pytest.raises(DatasetError) as raised:
        with_intrinsics(scene, read_intrinsics(path))
    assert str(raised.value) == (
        f"{path}: cx = 305.875 lies more than 1 image width outside the image, 24 pixels wide (expected -24 to 48): "
        "intrinsics of another image size?"
    )


def test_intrinsics_keep_the_units_of_an_orthographic_data_set(tmp_path):
    path = _write_k(tmp_path, "100 0 48\n0 100 48\n0 0 1\n")
    data = irtps.load_dataset(ORTHOGRAPHIC, intrinsics=path)
    camera = data.scene.camera
    assert (camera.projection, camera.fx, camera.cx) == ("perspective", 100.0, 48.0)
    assert camera.optical_center == (0.0, 0.0, data.scene.floor.height + 1.0 * 100.0)  # pixel size 1 at the floor
    with pytest.warns(IrtpsWarning, match=f"{STAND_IN} 1 "):
        assert orthographic_scene(data.scene, "x").camera == Camera(96, 96, 1.0, pinhole=camera)


# DiLiGenT's K.txt and depth_gt.npz


@pytest.fixture
def ball(tmp_path):
    """A writable copy of the small DiLiGenT fixture, 48x44."""
    return Path(shutil.copytree(BALL, tmp_path / "ball"))


def test_a_diligent_folder_with_k_is_perspective_at_the_scale_it_had(ball):
    orthographic = irtps.load_dataset(ball)
    _write_k(ball, "3772.08 0 23.5\n0 3759.01 22.25\n0 0 1\n")
    perspective = irtps.load_dataset(ball)
    camera = perspective.scene.camera
    f = math.sqrt(3772.08 * 3759.01)
    assert (camera.fx, camera.fy, camera.cx, camera.cy) == (3772.08, 3759.01, 23.5, 22.25)
    assert camera.optical_center == (0.0, 0.0, f)
    with pytest.warns(IrtpsWarning, match=STAND_IN):
        stand_in = orthographic_scene(perspective.scene, "ball").camera
    assert stand_in == dataclasses.replace(orthographic.scene.camera, pinhole=camera)  # pixel size 1 exactly
    assert ball / "K.txt" in dataset_inputs(ball)


def test_a_diligent_folder_reconstructs_the_same_normals_and_its_height_through_the_pinhole(ball):
    before = irtps.reconstruct(irtps.load_dataset(ball))
    _write_k(ball, "3772.08 0 23.5\n0 3759.01 22.25\n0 0 1\n")
    with pytest.warns(IrtpsWarning, match=STAND_IN):
        after = irtps.reconstruct(irtps.load_dataset(ball))
    for name in ("normals", "albedo", "mask", "flags"):
        np.testing.assert_array_equal(getattr(after, name), getattr(before, name))
    assert after.pixel_size == before.pixel_size == 1.0
    # The same normals integrated along the pinhole's rays: the ball, 1/300 of the distance
    # across, differs from its orthographic integration by under 1 % of its height.
    difference = np.abs(after.height - before.height)[before.mask]
    assert 0 < difference.max() < 0.01 * before.height.max()


def test_a_diligent_k_for_other_images_is_refused(ball):
    _write_k(ball, DILIGENT_K)
    with pytest.raises(
        DatasetError, match=r"K\.txt: cx = 305\.875 lies more than 1 image width outside the image, 48 pixels"
    ):
        irtps.load_dataset(ball)


def test_diligent_depth_is_read_as_ground_truth_with_nan_unknown(ball):
    depth = np.full((44, 48), 1500.0, np.float32)
    depth[0, 0] = np.nan
    np.savez(ball / "depth_gt.npz", depth_gt=depth)
    truth = irtps.load_dataset(ball).gt
    assert truth.normal is not None and np.isnan(truth.depth[0, 0]) and truth.depth[1, 1] == 1500.0
    assert load_diligent_ground_truth(ball, (44, 48)).depth[1, 1] == 1500.0
    assert ball / "depth_gt.npz" in diligent_ground_truth_inputs(ball) and ball / "depth_gt.npz" in dataset_inputs(ball)


@pytest.mark.parametrize(
    ("variables", "problem"),
    [
        ({"depth": np.ones((44, 48))}, "no variable 'depth_gt' (found ['depth'])"),
        ({"depth_gt": np.ones((48, 44))}, "depth_gt has shape (48, 44), expected the images' (44, 48)"),
        ({"depth_gt": np.ones((44, 48), int)}, "depth_gt holds int64 values, expected floating-point numbers"),
        (
            {"depth_gt": np.full((44, 48), -1.0)},
            "depth_gt is -1 at row 0, column 0: a depth is positive, or NaN where unknown",
        ),
    ],
)
def test_a_bad_diligent_depth_is_refused_naming_it(ball, variables, problem):
    np.savez(ball / "depth_gt.npz", **variables)
    with pytest.raises(DatasetError) as raised:
        irtps.load_dataset(ball)
    assert str(raised.value) == f"{ball / 'depth_gt.npz'}: {problem}"


# irtps reconstruct --intrinsics


def test_reconstruct_takes_intrinsics_for_any_data_set(tmp_path, capsys):
    k = _write_k(tmp_path, "28.8 0 12\n0 28.8 12\n0 0 1\n")
    assert main(["reconstruct", str(FIXTURE), "--out", str(tmp_path / "out"), "--intrinsics", str(k), "--quiet"]) == 0
    assert f"irtps: warning: {FIXTURE}: {STAND_IN} 4.33333 " in capsys.readouterr().err
    assert json.loads((tmp_path / "out" / "run.json").read_text())["pixel_size"] == pytest.approx(124.8 / 28.8)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        (DILIGENT_K, "cx = 305.875 lies more than 1 image width outside the image, 24 pixels wide"),
        ("28.8 0 12\n0 28.8 12\n", "expected a 3x3 intrinsic matrix"),
        ("-28.8 0 12\n0 28.8 12\n0 0 1\n", "fx = -28.8: a focal length must be a positive number"),
        ("28.8 0 12\n0 28.8 nan\n0 0 1\n", "line 2: non-finite value"),
    ],
)
def test_reconstruct_refuses_bad_intrinsics_in_one_line_writing_nothing(tmp_path, capsys, text, problem):
    k = _write_k(tmp_path, text)
    out = tmp_path / "out"
    line = refused(["reconstruct", str(FIXTURE), "--out", str(out), "--intrinsics", str(k), "--quiet"], capsys)
    assert line.startswith(f"irtps: error: {k}: {problem}")
    assert not out.exists() and sorted(path.name for path in tmp_path.iterdir()) == ["K.txt"]


def test_reconstruct_never_writes_over_the_intrinsics_file(tmp_path, capsys):
    k = _write_k(tmp_path, "28.8 0 12\n0 28.8 12\n0 0 1\n")
    line = refused(["reconstruct", str(FIXTURE), "--out", str(k), "--intrinsics", str(k), "--force"], capsys)
    assert "K.txt" in line and k.read_text().startswith("28.8")


# The shared scenes


def _points(camera: Camera, depth: np.ndarray) -> np.ndarray:
    """(H, W, 3) world points of the depth map (contract §1b)."""
    return np.array(camera.optical_center) + depth[..., None].astype(np.float64) * camera.ray_directions()


def _neighboured(mask: np.ndarray, axis: int) -> np.ndarray:
    """The pixels of `mask` with a neighbour in it along `axis`."""
    padded = np.pad(mask, [(1, 1) if a == axis else (0, 0) for a in range(2)])
    ahead, behind = (np.take(padded, range(start, start + mask.shape[axis]), axis=axis) for start in (2, 0))
    return mask & (ahead | behind)


def _masked_difference(points: np.ndarray, mask: np.ndarray, axis: int) -> np.ndarray:
    """Central differences between masked neighbours along `axis`, one-sided at the mask's edge."""
    ahead, behind = np.zeros_like(mask), np.zeros_like(mask)
    forward, backward = np.zeros_like(points), np.zeros_like(points)
    inner = [slice(None)] * 2
    inner[axis], after, before = slice(1, -1), [slice(None)] * 2, [slice(None)] * 2
    after[axis], before[axis] = slice(1, None), slice(None, -1)
    ahead[tuple(before)] = mask[tuple(after)]
    behind[tuple(after)] = mask[tuple(before)]
    forward[tuple(before)] = points[tuple(after)] - points[tuple(before)]
    backward[tuple(after)] = points[tuple(after)] - points[tuple(before)]
    both = (ahead & behind)[..., None]
    return np.where(both, (forward + backward) / 2, np.where(ahead[..., None], forward, backward))


def _depth_normals(camera: Camera, depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The normals of the contract's mesh of a depth map: central differences of the points of
    neighbouring object pixels."""
    points = _points(camera, depth)
    along_x = _masked_difference(points, mask, axis=1)
    along_y = -_masked_difference(points, mask, axis=0)  # rows run down, y up
    normals = np.cross(along_x, along_y)
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    return normals / np.where(length > 0, length, 1.0)


@needs_shared
@pytest.mark.parametrize("name", ["cap_persp_cornell", "grooves_persp_dark"])
def test_the_shared_perspective_scenes_load_with_consistent_ground_truth(name):
    data = irtps.load_dataset(MITSUBA / name)
    camera, truth, mask = data.scene.camera, data.gt, data.mask
    assert camera.projection == "perspective" and camera.fx == pytest.approx(115.2)
    zc = camera.optical_center[2]
    np.testing.assert_allclose(truth.height[mask], zc - truth.depth[mask], atol=1e-4)  # z = zc - d
    defined = _neighboured(mask, 0) & _neighboured(mask, 1)  # elsewhere the normal is unknown, 0
    assert defined.sum() > 0.99 * mask.sum() and (truth.normal[mask & ~defined] == 0).all()
    cosine = np.clip((_depth_normals(camera, truth.depth, defined) * truth.normal).sum(-1)[defined], -1, 1)
    assert np.degrees(np.arccos(cosine)).max() < 0.1


@needs_shared
def test_diligent_reading_is_perspective_with_its_depth():
    data = irtps.load_dataset(SHARED / "diligent" / "readingPNG", exclude_images="4-96")
    camera = data.scene.camera
    assert (camera.cx, camera.cy) == (305.875, 255.125)
    assert camera.optical_center == (0.0, 0.0, camera.focal_length)
    depth = data.gt.depth
    assert depth.shape == (512, 612) and 1490 < np.nanmin(depth[data.mask]) < np.nanmax(depth) < 1580


# IRT-PS's relief through a pinhole


@pytest.mark.parametrize("method", ["ls", "footprint"])
def test_the_pinhole_relief_of_a_tilted_plane_stands_on_it_along_the_rays(method):
    camera = _perspective(width=24, height=20, fx=30.0, fy=32.0, cx=11.3, cy=10.6, zc=50.0)
    normal = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    rays = camera.ray_directions()
    depth = normal @ (np.array([0.0, 0.0, 10.0]) - camera.optical_center) / (rays @ normal)
    truth = camera.optical_center[2] - depth  # the plane through (0, 0, 10), contract §1b
    mask = np.zeros((20, 24), bool)
    mask[3:17, 4:21] = True
    scene = _scene(camera.orthographic_stand_in(50.0))
    relief = pinhole_relief(scene, np.broadcast_to(normal, (20, 24, 3)), mask, method)
    base = float(np.median(truth[mask_boundary(mask)]))
    height = raised(relief, mask, base, scene)
    np.testing.assert_allclose(height[mask], truth[mask], atol=5e-3)  # 1e-4 of the depth
    # The orthographic stand-in's integration of the same normals bends the plane.
    flat = irtps.integrate_normals(np.broadcast_to(normal, (20, 24, 3)), mask, pixel_size=50.0 / camera.focal_length)
    flat = irtps.place_height(flat, mask, base_height=base)
    assert np.abs(flat - truth)[mask].max() > 0.1


# irtps synth --camera perspective


def test_synth_makes_a_pinhole_data_set_whose_direct_images_fit_its_true_normals(tmp_path):
    out = tmp_path / "cap"
    argv = ["synth", "cap", "--size", "32", "--lights", "6", "--camera", "perspective", "--bounces", "1"]
    assert main([*argv, "--samples", "4", "--out", str(out), "--quiet"]) == 0
    data = irtps.load_dataset(out)
    camera, mask, truth = data.scene.camera, data.mask, data.gt
    assert (camera.projection, camera.fx, camera.cx, camera.optical_center) == ("perspective", 38.4, 16.0, (0, 0, 38.4))
    np.testing.assert_allclose(truth.depth[mask], 38.4 - truth.height[mask], atol=1e-5)
    # The direct images, rendered through the pinhole, are those of the depth map's normals
    # (away from the rim), within the footprint's averaging over a curved 32-pixel cap; the
    # normals of the same heights seen orthographically are twice as far.
    fit = irtps.photometric_stereo(truth.direct, data.scene.light_directions, data.scene.light_irradiance, mask)
    inner = ndimage.binary_erosion(mask, iterations=2)

    def mean_angle(normals):
        cosine = np.clip((fit.normals * normals).sum(axis=-1)[inner], -1.0, 1.0)
        return float(np.degrees(np.arccos(cosine)).mean())

    assert mean_angle(truth.normal) < 1.5
    assert mean_angle(irtps.height_to_normals(truth.height, mask)) > 2 * mean_angle(truth.normal)


# The lobe fit through a pinhole


def test_the_lobe_fit_takes_each_pixels_own_view_through_a_pinhole():
    # Glossy pixels (Blinn-Phong, exponent 32) of a wide pinhole's image, rendered here with
    # the half vector of each pixel's own view: fitted from those views, the normals come
    # back; from a distant camera's, the highlights pull them off.
    camera = _perspective(width=8, height=6, fx=6.0, fy=6.0, cx=4.0, cy=3.0, zc=10.0)
    rows, cols = np.mgrid[0:6, 0:8]
    normals = np.stack([0.4 * np.sin(0.7 * cols), 0.4 * np.cos(1.3 * rows), np.ones((6, 8))], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    polar, azimuth = np.meshgrid(np.radians([15, 30, 45, 60]), np.radians(np.arange(12) * 30.0))
    lights = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], -1)
    lights = lights.reshape(-1, 3)
    views = camera.view_directions()
    half = lights[:, None, None] + views[None]
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    lit = np.clip(np.einsum("kc,hwc->khw", lights, normals), 0, None)
    lobe = 4.0 * np.clip((half * normals[None]).sum(-1), 0, None) ** 32
    images = (lit * (0.3 + lobe))[..., None] * np.ones(3)
    irradiance = np.full((len(lights), 3), np.pi)

    def mean_error(views):
        fit = irtps.photometric_stereo(images, lights, irradiance, robust="lobe", views=views)
        return float(np.degrees(np.arccos(np.clip((fit.normals * normals).sum(-1), -1, 1))).mean())

    own = mean_error(views)
    assert own < 0.1
    assert mean_error(None) > 10 * own
    with pytest.raises(
        irtps.ArgumentError, match=r"views: .* at row 0, column 0 is not a unit vector toward the camera"
    ):
        irtps.photometric_stereo(images, lights, irradiance, views=-views)
