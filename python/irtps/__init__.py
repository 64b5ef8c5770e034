"""irtps: Iterative Ray Tracing Photometric Stereo."""

from importlib.metadata import PackageNotFoundError, version

from irtps.dataset import Dataset, GroundTruth, load_dataset, save_dataset
from irtps.errors import DatasetError, IrtpsError
from irtps.scene import Camera, CornellBox, Floor, Light, Scene, load_scene

try:
    __version__ = version("irtps")
except PackageNotFoundError:
    __version__ = "0+unknown"

__all__ = [
    "Camera",
    "CornellBox",
    "Dataset",
    "DatasetError",
    "Floor",
    "GroundTruth",
    "IrtpsError",
    "Light",
    "Scene",
    "__version__",
    "load_dataset",
    "load_scene",
    "save_dataset",
]
