"""Every public function refuses a bad argument with one kind of exception: an
`irtps.ArgumentError`, both an `irtps.IrtpsError` and a `ValueError`, whose message starts
with the argument's name (a file argument: the file, as `DatasetError`, also both)."""

import importlib
import inspect
import pickle

import numpy as np
import pytest

import irtps
from irtps import _core
from irtps.errors import ArgumentError
from irtps.model.camera import Camera
from irtps.model.options import OptionError
from irtps.render.synth import synthesize

#: The modules whose `__all__` functions take arrays, besides those `irtps` exports itself.
ARRAY_MODULES = [
    "report.display",
    "model.metrics",
    "report.figures",
    "geometry.bilateral_integration",
    "geometry.boundary",
    "geometry.integrate",
    "irt.interreflection",
    "io.mesh",
    "io.exchange",
    "ps.semi_calibrated",
    "report.shape_view",
    "calibrate.circles",
    "calibrate.spheres",
    "render.residual",
    "geometry.surface",
]
#: Functions that only format a record for printing: they take no argument to check.
FORMATTING = {"irtps.model.metrics.format_metrics"}

MASK = np.ones((4, 4), bool)
EMPTY = np.zeros((4, 4), bool)
NORMALS = np.dstack([np.zeros((4, 4)), np.zeros((4, 4)), np.ones((4, 4))])
ALBEDO = np.full((4, 4, 3), 0.5)
HEIGHT = np.zeros((4, 4))
WRONG = np.zeros((3, 5))
LIGHTS = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8]], float)


def _dataset():
    return synthesize("cap", size=8, lights=3, bounces=0, environment="none")[0]


def _scene():
    return _dataset().scene


def _public_functions() -> set[str]:
    names = {f"irtps.{name}" for name in irtps.__all__ if inspect.isfunction(getattr(irtps, name))}
    for module_name in ARRAY_MODULES:
        module = importlib.import_module(f"irtps.{module_name}")
        public = getattr(module, "__all__", [name for name in vars(module) if not name.startswith("_")])
        for name in public:
            value = getattr(module, name)
            if inspect.isfunction(value) and value.__module__ == module.__name__:
                names.add(f"{module.__name__}.{name}")
    return {_canonical(name) for name in names} - FORMATTING


def _canonical(dotted: str) -> str:
    module_name, _, name = dotted.rpartition(".")
    value = getattr(importlib.import_module(module_name), name)
    return f"{value.__module__}.{value.__name__}"


#: (function, call with one bad argument, the text the message must start with)
CASES = {
    "irtps.report.display.object_window": (lambda f: f(EMPTY), "mask: "),
    "irtps.report.display.normal_to_rgb": (lambda f: f(NORMALS[:, :, :2], MASK), "normals: "),
    "irtps.report.display.albedo_to_rgb": (lambda f: f(np.full((4, 4, 3), np.nan), MASK), "albedo: "),
    "irtps.report.display.radiance_to_rgb": (lambda f: f(ALBEDO, WRONG), "mask: "),
    "irtps.report.display.hillshade": (lambda f: f(HEIGHT, MASK, pixel_size=0), "pixel_size: "),
    "irtps.model.metrics.angular_error_deg": (lambda f: f(NORMALS, NORMALS[:3], MASK), "normals_gt: "),
    "irtps.model.metrics.evaluate": (lambda f: f(mask=MASK, height=WRONG, gt=None), "height: "),
    "irtps.model.metrics.error_maps": (lambda f: f(mask=MASK, gt=None, base_height=np.inf), "base_height: "),
    "irtps.report.figures.image_png": (lambda f: f(HEIGHT, "t"), "rgb: "),
    "irtps.report.figures.error_map_png": (lambda f: f(np.full((2, 2), np.nan), "t", "u"), "errors: "),
    "irtps.report.figures.convergence_png": (lambda f: f([0, 1], [1.0], [0.1, 0.2]), "passes: "),
    "irtps.report.figures.agreement_png": (lambda f: f(["a.png"], [np.nan], [np.nan]), "brightness: "),
    "irtps.geometry.integrate.integrate_normals": (lambda f: f(NORMALS, method="poisson"), "method: "),
    "irtps.geometry.integrate.normals_to_gradients": (lambda f: f(NORMALS, max_slope=-1), "max_slope: "),
    "irtps.geometry.boundary.place_height": (lambda f: f(HEIGHT, WRONG), "mask: "),
    "irtps.geometry.boundary.mask_boundary": (lambda f: f(np.zeros(4, bool)), "mask: "),
    "irtps.irt.interreflection.remove_interreflections": (lambda f: f(_dataset(), bounces=0), "bounces: "),
    "irtps.irt.interreflection.check_traceable": (lambda f: f({"mask": MASK}), "dataset: "),
    "irtps.geometry.surface.meshed_blocks": (lambda f: f(np.zeros(4, bool)), "mask: "),
    "irtps.io.mesh.height_field_mesh": (lambda f: f(HEIGHT, MASK, albedo=ALBEDO[:3]), "albedo: "),
    "irtps.io.mesh.pinhole_mesh": (lambda f: f(HEIGHT, MASK, Camera(4, 4, pixel_size=1.0)), "camera: "),
    "irtps.geometry.bilateral_integration.integrate_bilateral": (
        lambda f: f(NORMALS, MASK, intrinsics=np.eye(3)[:2]),
        "intrinsics: ",
    ),
    "irtps.io.mesh.write_ply": (lambda f: f("unused.ply", np.zeros((3, 3)), np.array([[0, 1, 5]])), "faces: "),
    "irtps.io.mesh.write_obj": (lambda f: f("unused.obj", np.zeros((3, 2)), np.zeros((0, 3), int)), "vertices: "),
    "irtps.io.mesh.write_glb": (lambda f: f("unused.glb", np.zeros((3, 3)), np.array([[0, 1, 3]])), "faces: "),
    "irtps.io.exchange.normal_map_image": (lambda f: f(NORMALS, MASK, "vulkan"), "convention: "),
    "irtps.ps.semi_calibrated.estimate_light_intensities": (
        lambda f: f(np.ones((3, 4, 4, 3)), LIGHTS, MASK, shadow_fraction=1.5),
        "shadow_fraction: ",
    ),
    "irtps.io.exchange.write_normal_png": (lambda f: f("unused.png", WRONG, MASK), "normals: "),
    "irtps.io.exchange.quantised_map": (lambda f: f(np.full((4, 4), np.nan), MASK), "values: "),
    "irtps.io.exchange.write_quantised_png": (lambda f: f("unused.png", HEIGHT, WRONG), "mask: "),
    "irtps.io.exchange.write_float_tiff": (lambda f: f("unused.tif", ALBEDO), "values: "),
    "irtps.report.figures.figure_png": (lambda f: f("a figure"), "figure: "),
    "irtps.report.shape_view.shape_mesh": (lambda f: f("x", Camera(4, 4, pixel_size=1.0), HEIGHT, EMPTY, {}), "mask: "),
    "irtps.report.shape_view.surface_colours": (lambda f: f(ALBEDO, WRONG, None, None), "mask: "),
    "irtps.report.shape_view.shape_view_html": (lambda f: f([], "caption"), "meshes: "),
    "irtps.calibrate.lights.calibrate_lights": (lambda f: f(np.zeros((3, 4, 4))), "images: "),
    "irtps.calibrate.circles.as_circle": (lambda f: f((1.0, 2.0, np.nan)), "circle: "),
    "irtps.calibrate.circles.find_circles": (lambda f: f(HEIGHT, 0), "count: "),
    "irtps.calibrate.circles.refine_circle": (lambda f: f(HEIGHT, (2.0, 2.0, 1.0), band=1.5), "band: "),
    "irtps.calibrate.circles.outermost_outline": (lambda f: f(HEIGHT, (2.0, 2.0, 1.0), 8.0, reach=1.0), "reach: "),
    "irtps.calibrate.circles.outline_contrast": (lambda f: f(WRONG[None, None], (2.0, 2.0, 1.0)), "image: "),
    "irtps.calibrate.circles.parse_circle": (lambda f: f("1,2,x"), "circle: "),
    "irtps.calibrate.spheres.find_spheres": (lambda f: f(np.zeros((3, 4, 4)), WRONG), "saturated: "),
    "irtps.calibrate.spheres.outline_image": (lambda f: f(np.full((3, 4, 4), np.nan)), "gray: "),
    "irtps.render.residual.compared_observations": (
        lambda f: f(np.zeros((3, 4, 4, 3)), np.ones((3, 3)), WRONG, robust=True, shadow_fraction=0.05, saturation=None),
        "mask: ",
    ),
    "irtps.render.residual.render_with_residual": (
        lambda f: f(
            _scene(),
            np.zeros((8, 8)),
            np.full((8, 8, 3), 0.5),
            np.ones((8, 8), bool),
            np.zeros((3, 8, 8, 3)),
            bounces=1,
            samples=0,
        ),
        "samples: ",
    ),
    "irtps.geometry.surface.height_to_normals": (lambda f: f(HEIGHT, WRONG), "mask: "),
    "irtps.geometry.surface.depth_to_normals": (
        lambda f: f(HEIGHT, MASK, Camera(*HEIGHT.shape[::-1], 1.0)),
        "camera: ",
    ),
    "irtps.geometry.surface.footprint_normals": (lambda f: f(HEIGHT, MASK, pixel_size=-1.0), "pixel_size: "),
    "irtps.geometry.surface.surface_albedo": (lambda f: f(ALBEDO[:, :2], HEIGHT, MASK), "albedo_ps: "),
    "irtps.ps.fit.photometric_stereo": (
        lambda f: f(np.zeros((3, 4, 4, 3)), LIGHTS, np.ones((3, 3)), robust="huber"),
        "robust: ",
    ),
    "irtps.ps.fit.lobe_share": (lambda f: f(np.zeros((3, 4, 4, 3)), LIGHTS, np.ones((3, 3)), sample=0), "sample: "),
    "irtps.ps.fit.choose_robust": (lambda f: f(1.5), "share: "),
    "irtps.ps.uncertainty.normal_standard_error": (
        lambda f: f(np.zeros((3, 4, 4, 3)), LIGHTS, np.ones((3, 3)), WRONG),
        "mask: ",
    ),
    "irtps.render.renderer.render": (
        lambda f: f(_scene(), np.zeros((8, 8)), np.full((8, 8, 3), 0.5), WRONG, bounces=1, samples=4),
        "mask: ",
    ),
    "irtps.render.renderer.render_indirect": (
        lambda f: f(_scene(), np.zeros((8, 9)), np.full((8, 8, 3), 0.5), np.ones((8, 8), bool), stride=0),
        "stride: ",
    ),
    "irtps.irt.reconstruct.reconstruct": (lambda f: f(_dataset(), method="magic"), "method: "),
    "irtps.irt.folder.save_reconstruction": (lambda f: f(_dataset(), "unused"), "result: "),
    "irtps.render.synth.synthesize": (lambda f: f("cube"), "shape: "),
    "irtps.io.dataset.load_dataset": (lambda f: f("no/such/folder"), "no/such/folder: "),
    "irtps.io.image_selection.exclude_images": (lambda f: f(_dataset(), "5-1"), "exclude_images: "),
    "irtps.io.dataset.load_ground_truth": (lambda f: f("no/such/folder", (4, 4)), "no/such/folder: "),
    "irtps.io.dataset.load_scene_object": (lambda f: f("no/such/folder"), "no/such/folder"),
    "irtps.io.dataset_writer.save_dataset": (lambda f: f(_dataset(), "unused", extra={"../x.exr": HEIGHT}), "extra: "),
    "irtps.model.scene.load_scene": (lambda f: f("no/such/scene.json"), "no/such/scene.json: "),
    "irtps.model.environment.read_environment_mesh": (
        lambda f: f("no/such/environment.ply"),
        "no/such/environment.ply: ",
    ),
}


def test_every_public_function_has_a_bad_argument_case():
    assert set(CASES) == _public_functions()


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_bad_argument_raises_one_kind_of_error_naming_it(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    module_name, _, function_name = name.rpartition(".")
    call, start = CASES[name]
    with pytest.raises(irtps.IrtpsError) as caught:
        call(getattr(importlib.import_module(module_name), function_name))
    assert isinstance(caught.value, ValueError)
    assert str(caught.value).startswith(start)
    assert not list(tmp_path.iterdir()), "a refused call wrote something"


def test_the_core_raises_argument_errors_itself():
    with pytest.raises(ArgumentError, match="^light_irradiance: needs one row per light direction$"):
        _core.check_lights(LIGHTS.astype(np.float32), np.ones((2, 3), np.float32))
    with pytest.raises(ArgumentError, match=r"^lights\b"):
        _core.check_lights(LIGHTS[:2].astype(np.float32), np.ones((2, 3), np.float32))


def test_argument_errors_keep_the_argument_through_pickling():
    for error in (ArgumentError("mask", "empty"), OptionError("samples", "0 is out of range")):
        copy = pickle.loads(pickle.dumps(error))
        assert (type(copy), str(copy), copy.argument, copy.problem) == (
            type(error),
            str(error),
            error.argument,
            error.problem,
        )
    assert pickle.loads(pickle.dumps(OptionError("seed", "-1"))).option == "seed"
