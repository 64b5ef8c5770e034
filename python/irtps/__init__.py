"""irtps: Iterative Ray Tracing Photometric Stereo."""

# The subpackage `irtps.evaluate` is loaded before the function `evaluate` is bound below: a
# subpackage first loaded later (by `irtps.evaluate.table`'s import) would take its name.
from irtps import evaluate as _evaluate_subpackage

from irtps.model.data import Dataset, GroundTruth
from irtps.io.dataset import load_dataset, load_ground_truth, load_scene_object
from irtps.io.dataset_writer import save_dataset
from irtps.errors import ArgumentError, DatasetError, IrtpsError, IrtpsWarning
from irtps.model.metrics import Metrics, angular_error_deg, evaluate
from irtps.io.image_selection import exclude_images
from irtps.geometry.integrate import integrate_normals
from irtps.geometry.boundary import place_height
from irtps.ps.fit import PsResult, choose_robust, lobe_share, photometric_stereo
from irtps.ps.uncertainty import normal_standard_error
from irtps.calibrate.lights import LightCalibration, calibrate_lights
from irtps.irt.folder import save_reconstruction
from irtps.irt.reconstruct import Reconstruction, reconstruct
from irtps._shared.records import irtps_version
from irtps.render.renderer import Rendering, render, render_indirect
from irtps.model.environment import MeshEnvironment, read_environment_mesh
from irtps.model.scene import Camera, CornellBox, Floor, Light, PointLight, Scene, load_scene
from irtps.geometry.surface import depth_to_normals, height_to_normals
from irtps.render.synth import synthesize

del _evaluate_subpackage
__version__ = irtps_version()

__all__ = [
    "ArgumentError",
    "Camera",
    "CornellBox",
    "Dataset",
    "DatasetError",
    "Floor",
    "GroundTruth",
    "IrtpsError",
    "IrtpsWarning",
    "Light",
    "LightCalibration",
    "MeshEnvironment",
    "Metrics",
    "PointLight",
    "PsResult",
    "Reconstruction",
    "Rendering",
    "Scene",
    "__version__",
    "angular_error_deg",
    "calibrate_lights",
    "choose_robust",
    "depth_to_normals",
    "evaluate",
    "exclude_images",
    "height_to_normals",
    "integrate_normals",
    "load_dataset",
    "load_ground_truth",
    "load_scene",
    "load_scene_object",
    "lobe_share",
    "normal_standard_error",
    "photometric_stereo",
    "read_environment_mesh",
    "place_height",
    "reconstruct",
    "render",
    "render_indirect",
    "save_dataset",
    "save_reconstruction",
    "synthesize",
]
