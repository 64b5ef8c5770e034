"""Every function of `irtps.__all__` fed hostile arguments: a wrong type, a text for a number,
an empty array, NaN arrays. Each is refused with `irtps.ArgumentError` whose message starts
with the argument's name (`irtps.DatasetError` naming the file for a file argument), never a
bare TypeError, AttributeError or a result of NaN."""

import inspect

import irtps
import numpy as np
import pytest
from irtps.render.synth import synthesize

LIGHTS = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8]])
IRRADIANCE = np.full((4, 3), np.pi)
IMAGES = np.full((4, 4, 4, 3), 0.2)
MASK = np.ones((4, 4), bool)
NORMALS = np.dstack([np.zeros((4, 4)), np.zeros((4, 4)), np.ones((4, 4))])
HEIGHT = np.zeros((4, 4))
NAN = float("nan")
PINHOLE = irtps.Camera(4, 4, projection="perspective", fx=4.0, fy=4.0, cx=2.0, cy=2.0, optical_center=(0, 0, 10))


def _dataset():
    return synthesize("cap", size=8, lights=3, bounces=0, environment="none")[0]


def _scene():
    return _dataset().scene


def _object():
    return np.zeros((8, 8)), np.full((8, 8, 3), 0.5), np.ones((8, 8), bool)


def _render(function, height=None, albedo=None, mask=None, **settings):
    default_height, default_albedo, default_mask = _object()
    return function(
        _scene(),
        default_height if height is None else height,
        default_albedo if albedo is None else albedo,
        default_mask if mask is None else mask,
        samples=settings.pop("samples", 1),
        **settings,
    )


#: (function, call, expected error type, start of the message); one function may have many.
CASES = [
    # photometric_stereo
    (
        "photometric_stereo",
        lambda f: f(IMAGES, LIGHTS, IRRADIANCE, shadow_fraction="0.1"),
        irtps.ArgumentError,
        "shadow_fraction: ",
    ),
    (
        "photometric_stereo",
        lambda f: f(IMAGES, LIGHTS, IRRADIANCE, saturation="1"),
        irtps.ArgumentError,
        "saturation: ",
    ),
    ("photometric_stereo", lambda f: f("images", LIGHTS, IRRADIANCE), irtps.ArgumentError, "images: "),
    ("photometric_stereo", lambda f: f(np.zeros((4, 0, 4, 3)), LIGHTS, IRRADIANCE), irtps.ArgumentError, "images: "),
    (
        "photometric_stereo",
        lambda f: f(np.full_like(IMAGES, NAN), LIGHTS, IRRADIANCE),
        irtps.ArgumentError,
        "images[0]: ",
    ),
    (
        "photometric_stereo",
        lambda f: f(IMAGES, np.full_like(LIGHTS, NAN), IRRADIANCE),
        irtps.ArgumentError,
        "light_directions: ",
    ),
    (
        "photometric_stereo",
        lambda f: f(IMAGES, LIGHTS, np.full_like(IRRADIANCE, NAN)),
        irtps.ArgumentError,
        "light_irradiance: ",
    ),
    (
        "photometric_stereo",
        lambda f: f(IMAGES, LIGHTS, np.full_like(IRRADIANCE, 1e308)),
        irtps.ArgumentError,
        "light_irradiance[0]: ",
    ),
    ("photometric_stereo", lambda f: f(IMAGES, LIGHTS[:3], IRRADIANCE[:3]), irtps.ArgumentError, "light_directions: "),
    ("photometric_stereo", lambda f: f(IMAGES, LIGHTS, IRRADIANCE, mask="all"), irtps.ArgumentError, "mask: "),
    # numpy.ma hides masked values, which np.asarray would hand over as data
    (
        "photometric_stereo",
        lambda f: f(np.ma.masked_greater(IMAGES + np.arange(4)[:, None, None, None], 2), LIGHTS, IRRADIANCE),
        irtps.ArgumentError,
        "images: a masked array",
    ),
    # lobe_share
    (
        "lobe_share",
        lambda f: f(IMAGES, LIGHTS, IRRADIANCE, shadow_fraction="0.1"),
        irtps.ArgumentError,
        "shadow_fraction: ",
    ),
    ("lobe_share", lambda f: f(np.full_like(IMAGES, NAN), LIGHTS, IRRADIANCE), irtps.ArgumentError, "images[0]: "),
    (
        "lobe_share",
        lambda f: f(IMAGES, LIGHTS, np.full_like(IRRADIANCE, NAN)),
        irtps.ArgumentError,
        "light_irradiance: ",
    ),
    ("lobe_share", lambda f: f(np.zeros((0, 4, 4, 3)), LIGHTS, IRRADIANCE), irtps.ArgumentError, "images: "),
    # normal_standard_error
    (
        "normal_standard_error",
        lambda f: f(np.full_like(IMAGES, NAN), LIGHTS, IRRADIANCE, MASK),
        irtps.ArgumentError,
        "images[0]: ",
    ),
    (
        "normal_standard_error",
        lambda f: f(np.zeros((0, 4, 4, 3)), LIGHTS, IRRADIANCE, MASK),
        irtps.ArgumentError,
        "images: ",
    ),
    ("normal_standard_error", lambda f: f("images", LIGHTS, IRRADIANCE, MASK), irtps.ArgumentError, "images: "),
    (
        "normal_standard_error",
        lambda f: f(IMAGES, LIGHTS[:3], IRRADIANCE, MASK),
        irtps.ArgumentError,
        "light_directions: ",
    ),
    (
        "normal_standard_error",
        lambda f: f(IMAGES, LIGHTS, np.full_like(IRRADIANCE, NAN), MASK),
        irtps.ArgumentError,
        "light_irradiance: ",
    ),
    ("normal_standard_error", lambda f: f(IMAGES, LIGHTS, IRRADIANCE, MASK[:2]), irtps.ArgumentError, "mask: "),
    (
        "normal_standard_error",
        lambda f: f(IMAGES, LIGHTS, IRRADIANCE, MASK, np.ones((4, 4, 4, 2), bool)),
        irtps.ArgumentError,
        "usable: ",
    ),
    # choose_robust
    ("choose_robust", lambda f: f("0.5"), irtps.ArgumentError, "share: "),
    ("choose_robust", lambda f: f(NAN), irtps.ArgumentError, "share: "),
    # depth_to_normals
    ("depth_to_normals", lambda f: f(HEIGHT + 5, MASK, irtps.Camera(4, 4, 1.0)), irtps.ArgumentError, "camera: "),
    ("depth_to_normals", lambda f: f(HEIGHT + 5, MASK, "pinhole"), irtps.ArgumentError, "camera: "),
    ("depth_to_normals", lambda f: f(np.zeros((3, 4)), MASK, PINHOLE), irtps.ArgumentError, "depth: "),
    ("depth_to_normals", lambda f: f(np.full((4, 4), NAN), MASK, PINHOLE), irtps.ArgumentError, "depth: "),
    ("depth_to_normals", lambda f: f(HEIGHT - 1, MASK, PINHOLE), irtps.ArgumentError, "depth: "),
    ("depth_to_normals", lambda f: f(HEIGHT + 5, MASK[:2], PINHOLE), irtps.ArgumentError, "mask: "),
    # height_to_normals
    ("height_to_normals", lambda f: f(np.full((4, 4), NAN), MASK), irtps.ArgumentError, "height: "),
    ("height_to_normals", lambda f: f(np.zeros((0, 4)), np.zeros((0, 4), bool)), irtps.ArgumentError, "height: "),
    ("height_to_normals", lambda f: f("flat", MASK), irtps.ArgumentError, "height: "),
    ("height_to_normals", lambda f: f(HEIGHT, MASK, pixel_size="1"), irtps.ArgumentError, "pixel_size: "),
    # integrate_normals
    ("integrate_normals", lambda f: f(np.full((4, 4, 3), NAN), MASK), irtps.ArgumentError, "normals: "),
    ("integrate_normals", lambda f: f(np.zeros((0, 4, 3))), irtps.ArgumentError, "normals: "),
    ("integrate_normals", lambda f: f(NORMALS, MASK, pixel_size="1"), irtps.ArgumentError, "pixel_size: "),
    ("integrate_normals", lambda f: f(NORMALS, MASK, max_slope="10"), irtps.ArgumentError, "max_slope: "),
    ("integrate_normals", lambda f: f(NORMALS, MASK, iterations="5"), irtps.ArgumentError, "iterations: "),
    ("integrate_normals", lambda f: f([["n"]]), irtps.ArgumentError, "normals: "),
    # place_height
    ("place_height", lambda f: f(np.full((4, 4), NAN), MASK), irtps.ArgumentError, "height: "),
    ("place_height", lambda f: f(np.zeros((4, 0))), irtps.ArgumentError, "height: "),
    ("place_height", lambda f: f(HEIGHT, MASK, base_height="0"), irtps.ArgumentError, "base_height: "),
    # angular_error_deg
    ("angular_error_deg", lambda f: f(np.full((4, 4, 3), NAN), NORMALS, MASK), irtps.ArgumentError, "normals: "),
    ("angular_error_deg", lambda f: f("up", NORMALS, MASK), irtps.ArgumentError, "normals: "),
    (
        "angular_error_deg",
        lambda f: f(np.zeros((0, 4, 3)), np.zeros((0, 4, 3)), np.zeros((0, 4), bool)),
        irtps.ArgumentError,
        "mask: ",
    ),
    # evaluate
    (
        "evaluate",
        lambda f: f(mask=MASK, normals=np.full((4, 4, 3), NAN), gt=irtps.GroundTruth(normal=NORMALS)),
        irtps.ArgumentError,
        "normals: ",
    ),
    (
        "evaluate",
        lambda f: f(mask=MASK, height=HEIGHT, gt=irtps.GroundTruth(height=HEIGHT), base_height="0"),
        irtps.ArgumentError,
        "base_height: ",
    ),
    ("evaluate", lambda f: f(mask=MASK, normals=NORMALS, gt={"normal": NORMALS}), irtps.ArgumentError, "gt: "),
    ("evaluate", lambda f: f(mask="all", normals=NORMALS, gt=None), irtps.ArgumentError, "mask: "),
    # render and render_indirect
    ("render", lambda f: _render(f, height=np.full((8, 8), NAN)), irtps.ArgumentError, "height: "),
    ("render", lambda f: _render(f, albedo=np.full((8, 8, 3), NAN)), irtps.ArgumentError, "albedo: "),
    ("render", lambda f: _render(f, samples="4"), irtps.ArgumentError, "samples: "),
    ("render", lambda f: f({"camera": None}, *_object()), irtps.ArgumentError, "scene: "),
    ("render_indirect", lambda f: _render(f, height=np.full((8, 8), NAN)), irtps.ArgumentError, "height: "),
    ("render_indirect", lambda f: _render(f, stride="1"), irtps.ArgumentError, "stride: "),
    ("render_indirect", lambda f: f("scene", *_object()), irtps.ArgumentError, "scene: "),
    # reconstruct and save_reconstruction
    ("reconstruct", lambda f: f({"images": IMAGES}), irtps.ArgumentError, "dataset: "),
    ("reconstruct", lambda f: f(_dataset(), samples="4"), irtps.ArgumentError, "samples: "),
    ("save_reconstruction", lambda f: f({"normals": NORMALS}, "unused"), irtps.ArgumentError, "result: "),
    # exclude_images
    ("exclude_images", lambda f: f({"images": IMAGES}, "1"), irtps.ArgumentError, "dataset: "),
    ("exclude_images", lambda f: f(_dataset(), 1), irtps.ArgumentError, "exclude_images: "),
    # synthesize
    ("synthesize", lambda f: f("cap", size="16"), irtps.ArgumentError, "size: "),
    ("synthesize", lambda f: f("cap", base=NAN), irtps.ArgumentError, "base: "),
    ("synthesize", lambda f: f(3), irtps.ArgumentError, "shape: "),
    # files
    ("load_dataset", lambda f: f(3), irtps.ArgumentError, "path: "),
    ("load_dataset", lambda f: f(b"no/such/folder"), irtps.DatasetError, "no/such/folder: "),
    ("load_dataset", lambda f: f("no/such/folder", exclude_images=5), irtps.ArgumentError, "exclude_images: "),
    ("load_dataset", lambda f: f("no/such/folder", lights=5), irtps.ArgumentError, "lights: "),
    ("load_dataset", lambda f: f(".", lights="no/such/rig.lp"), irtps.DatasetError, "no/such/rig.lp: "),
    ("load_ground_truth", lambda f: f("no/such/folder", "4x4"), irtps.ArgumentError, "size: "),
    ("load_ground_truth", lambda f: f(None, (4, 4)), irtps.ArgumentError, "path: "),
    ("load_scene_object", lambda f: f(3.5), irtps.ArgumentError, "path: "),
    ("load_scene", lambda f: f(["scene.json"]), irtps.ArgumentError, "path: "),
    ("read_environment_mesh", lambda f: f(7), irtps.ArgumentError, "path: "),
    ("read_environment_mesh", lambda f: f("."), irtps.DatasetError, ".: not a regular file"),
    ("save_dataset", lambda f: f({"images": IMAGES}, "unused"), irtps.ArgumentError, "dataset: "),
    ("save_dataset", lambda f: f(_dataset(), 3), irtps.ArgumentError, "path: "),
    ("load_dataset", lambda f: f(type("Odd", (), {"__fspath__": lambda self: 3})()), irtps.ArgumentError, "path: "),
    # calibrate_lights
    ("calibrate_lights", lambda f: f("images"), irtps.ArgumentError, "images: "),
    ("calibrate_lights", lambda f: f(np.zeros((4, 0, 4, 3))), irtps.ArgumentError, "images: "),
    ("calibrate_lights", lambda f: f(np.full((4, 4, 4, 3), NAN)), irtps.ArgumentError, "images: "),
    ("calibrate_lights", lambda f: f(IMAGES, saturated=MASK), irtps.ArgumentError, "saturated: "),
    ("calibrate_lights", lambda f: f(IMAGES, chrome="2,2,1"), irtps.ArgumentError, "chrome: "),
    ("calibrate_lights", lambda f: f(IMAGES, matte=(2, 2, 0)), irtps.ArgumentError, "matte: "),
    ("calibrate_lights", lambda f: f(IMAGES, matte_albedo="0.8"), irtps.ArgumentError, "matte_albedo: "),
    ("calibrate_lights", lambda f: f(IMAGES, matte_albedo=NAN), irtps.ArgumentError, "matte_albedo: "),
    ("calibrate_lights", lambda f: f(IMAGES, matte_albedo=1.5), irtps.ArgumentError, "matte_albedo: "),
    ("calibrate_lights", lambda f: f(IMAGES), irtps.DatasetError, "capture: no mirror or matte sphere"),
]


def _public_functions():
    return {name for name in irtps.__all__ if inspect.isfunction(getattr(irtps, name))}


def test_every_public_function_has_hostile_cases():
    assert {name for name, *_ in CASES} == _public_functions()


@pytest.mark.parametrize(
    ("name", "call", "error", "start"),
    CASES,
    ids=[f"{case[0]}-{case[3].rstrip(': ')}-{k}" for k, case in enumerate(CASES)],
)
def test_a_hostile_argument_is_refused_by_name(name, call, error, start, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(error) as caught:
        call(getattr(irtps, name))
    assert str(caught.value).startswith(start), str(caught.value)
    assert not list(tmp_path.iterdir()), "a refused call wrote something"


def test_bytes_paths_are_read_as_os_reads_them():
    from pathlib import Path

    folder = Path(__file__).parent / "data" / "diligent_ball_small"
    assert irtps.load_dataset(bytes(folder)).images.shape == irtps.load_dataset(folder).images.shape
