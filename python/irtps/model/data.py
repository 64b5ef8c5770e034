"""The data classes of a data set, `Dataset` and `GroundTruth`: the arrays, checked against
the scene. Reading and writing them is `irtps.io.dataset`'s and `irtps.io.dataset_writer`'s (the
layouts), which depend on this module, never the other way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irtps.errors import DatasetError
from irtps.model.scene import Scene


@dataclass
class GroundTruth:
    """Ground truth of a data set, for evaluation only; each part is optional.

    Attributes
    ----------
    height : numpy.ndarray or None
        float32 (H, W): heights above the floor, 0 outside the mask.
    normal : numpy.ndarray or None
        float32 (H, W, 3): unit normals (nx, ny, nz), 0 outside the mask.
    albedo : numpy.ndarray or None
        float32 (H, W, 3): RGB albedo.
    direct : numpy.ndarray or None
        float32 (K, H, W, 3): the direct-light-only image for each light.
    depth : numpy.ndarray or None
        float32 (H, W), perspective cameras: each object pixel's depth along the optical axis
        (contract §1b: its point is ``optical_center + depth * ray``, at height
        ``zc - depth``), world units; 0 outside the mask, NaN where unknown (DiLiGenT's
        ``depth_gt``, in millimetres).
    """

    height: np.ndarray | None = None
    normal: np.ndarray | None = None
    albedo: np.ndarray | None = None
    direct: np.ndarray | None = None
    depth: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("height", "normal", "albedo", "direct", "depth"):
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, np.asarray(value, dtype=np.float32))


@dataclass
class Dataset:
    """Photometric-stereo images of one object with their scene.

    Attributes
    ----------
    scene : Scene
    images : numpy.ndarray
        float32 (K, H, W, 3), linear RGB radiance; image k is lit by ``scene.lights[k]``.
    mask : numpy.ndarray
        bool (H, W): True on object pixels.
    gt : GroundTruth or None
    source : str or None
        The folder the data set was read from.
    saturation : float or None
        The value at which the camera clips, where it is known: 1.0 for images read from
        PNG files (their largest code value), None for float images. `irtps.reconstruct`
        leaves out observations at or above it.
    image_names : tuple of str or None
        Each image's file name (``filenames.txt``'s for DiLiGenT, ``000.exr`` ... for the
        irtps layout); None: those `irtps.save_dataset` would write (`names`).
    excluded_images : tuple of str
        The names of the folder's images left out when it was read, or since
        (`irtps.exclude_images`).
    irradiance_known : bool
        False when the data set gave the lights' directions but not their strengths (a
        DiLiGenT folder without ``light_intensities.txt``): the scene's irradiance is then 1
        for every light, and `irtps.reconstruct` estimates the strengths from the images
        first (`irtps.ps.semi_calibrated.estimate_light_intensities`).

    Raises
    ------
    DatasetError
        On construction, if an array's shape disagrees with the scene.
    """

    scene: Scene
    images: np.ndarray
    mask: np.ndarray
    gt: GroundTruth | None = None
    source: str | None = None
    saturation: float | None = None
    image_names: tuple[str, ...] | None = None
    excluded_images: tuple[str, ...] = ()
    irradiance_known: bool = True

    def __post_init__(self) -> None:
        self.images = np.asarray(self.images, dtype=np.float32)
        self.mask = np.asarray(self.mask, dtype=bool)
        if self.image_names is not None:
            self.image_names = tuple(map(str, self.image_names))
        self.excluded_images = tuple(map(str, self.excluded_images))
        self.check_shapes()

    @property
    def names(self) -> tuple[str, ...]:
        """Each image's file name: `image_names`, or ``000.exr``, ``001.exr`` ... as
        `irtps.save_dataset` writes them."""
        if self.image_names is not None:
            return self.image_names
        return tuple(image_file_name(k) for k in range(len(self.scene.lights)))

    def check_shapes(self) -> None:
        """Raise `DatasetError` if an array's shape disagrees with the scene's lights and camera."""
        count = len(self.scene.lights)
        size = (self.scene.camera.height, self.scene.camera.width)
        _expect_shape("Dataset.images", self.images, (count, *size, 3))
        _expect_shape("Dataset.mask", self.mask, size)
        if self.image_names is not None and len(self.image_names) != count:
            raise DatasetError(
                f"Dataset.image_names has {len(self.image_names)} names, expected {count} from the scene"
            )
        if self.gt is not None:
            for name, shape in _gt_shapes(count, size).items():
                value = getattr(self.gt, name)
                if value is not None:
                    _expect_shape(f"Dataset.gt.{name}", value, shape)


def spread_pixels(mask: np.ndarray, count: int) -> np.ndarray:
    """Flat indices of `count` of the pixels of `mask`, spread evenly over them in row-major
    order (all of them when it has no more).

    Examples
    --------
    >>> spread_pixels(np.ones((2, 5), bool), 4).tolist()
    [0, 3, 6, 9]
    """
    pixels = np.flatnonzero(mask)
    if pixels.size <= count:
        return pixels
    return pixels[np.unique(np.linspace(0, pixels.size - 1, count).round().astype(np.intp))]


def coarse_to_fine(count: int) -> np.ndarray:
    """An order of ``range(count)`` whose first ``2**j`` or so entries are spread evenly over
    it, for every ``j`` (the bit-reversal permutation of the next power of two, entries past
    `count` left out): a sample that grows along it stays spread.

    Examples
    --------
    >>> coarse_to_fine(8).tolist()
    [0, 4, 2, 6, 1, 5, 3, 7]
    >>> coarse_to_fine(6).tolist()
    [0, 4, 2, 1, 5, 3]
    """
    bits = max(count - 1, 0).bit_length()
    index = np.arange(1 << bits)
    reversed_index = np.zeros_like(index)
    for bit in range(bits):
        reversed_index |= ((index >> bit) & 1) << (bits - 1 - bit)
    return reversed_index[reversed_index < count]


def image_file_name(k: int, suffix: str = ".exr") -> str:
    """The file name of image `k` (from 0) in the irtps layout: ``000.exr`` ..."""
    return f"{k:03d}{suffix}"


def _gt_shapes(count: int, size: tuple[int, int]) -> dict[str, tuple[int, ...]]:
    return {"height": size, "normal": (*size, 3), "albedo": (*size, 3), "direct": (count, *size, 3), "depth": size}


def _expect_shape(name: str, array: np.ndarray, shape: tuple[int, ...]) -> None:
    if array.shape != tuple(shape):
        raise DatasetError(f"{name} has shape {array.shape}, expected {tuple(shape)} from the scene")


def pixel_observations(images: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The observations of the pixels of `mask` (H, W) in images (K, H, W, C): (K, N, C),
    C-ordered, pixels row-major, as ``images[:, mask]`` gives them but gathered by index along
    the pixels of each image (several times faster on DiLiGenT-size images than the boolean
    selection, which also leaves the result in Fortran order; docs/benchmarks.md, IRT-PS cost).

    Examples
    --------
    >>> images = np.arange(12.0).reshape(2, 2, 3, 1)
    >>> pixel_observations(images, np.array([[True, False, False], [False, False, True]]))[..., 0].tolist()
    [[0.0, 5.0], [6.0, 11.0]]
    """
    images = np.asarray(images)
    flat = images.reshape(len(images), -1, images.shape[-1])
    return np.take(flat, np.flatnonzero(mask), axis=1)


def observation_brightness(observations: np.ndarray, irradiance: np.ndarray) -> np.ndarray:
    """Photometric stereo's brightness of observations (`irtps.ps.fit.photometric_stereo`):
    their channels over their irradiance, summed: (...) for (..., 3) observations and an
    irradiance that broadcasts to them, in their quotient's precision (float32 for float32
    observations and irradiance).

    Examples
    --------
    >>> observation_brightness(np.array([[0.5, 1.0, 1.5]]), np.array([0.5, 0.5, 0.5])).tolist()
    [6.0]
    """
    scaled = np.asarray(observations / irradiance)
    # The channels added one by one: numpy's sum over an axis of 3 is several times slower.
    return scaled[..., 0] + scaled[..., 1] + scaled[..., 2]
