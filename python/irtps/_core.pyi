"""Types of the compiled core (rust/python/): image I/O, photometric stereo, the renderer,
the sparse Cholesky factorisation.

Errors about an input arrive as `irtps.errors.ArgumentError` (an argument) or
`irtps.errors.DatasetError` (a file: its content, and also a failure to open, read or write
it, naming the file; never as an `OSError`), a buffer that cannot be allocated as
`MemoryError` (naming it and its bytes); a value pyo3 cannot convert (a wrong dtype, a
negative count) as its `TypeError` or `OverflowError`, with a note naming the argument.
"""

from collections.abc import Sequence
from os import PathLike
from typing import final

import numpy as np
import numpy.typing as npt

from irtps.model.scene import CornellBox, Floor

__all__ = [
    "read_exr",
    "write_exr",
    "read_png",
    "write_png",
    "read_images",
    "photometric_stereo",
    "photometric_stereo_per_pixel",
    "tukey_with_lobe_check",
    "check_lights",
    "compare_rendering",
    "denoise_indirect",
    "Environment",
    "Renderer",
    "SparseCholesky",
    "integrate_bilateral",
    "MAX_IMAGE_PIXELS",
]

_F32 = npt.NDArray[np.float32]
_Path = str | PathLike[str]

#: Largest image (width × height) the core reads or renders.
MAX_IMAGE_PIXELS: int

def read_exr(path: _Path) -> _F32:
    """float32 (H, W, 3) for R, G, B or (H, W) for a single Y channel."""

def write_exr(path: _Path, array: _F32, compression: str = "zip") -> None:
    """A float32 (H, W) array as a Y channel or (H, W, 3) as R, G, B; ``"zip"`` or ``"rle"``."""

def read_png(path: _Path) -> tuple[_F32, int]:
    """(values / (2^bits − 1), (H, W) or (H, W, 3); bits) of an 8- or 16-bit PNG."""

def write_png(path: _Path, array: _F32, bit_depth: int) -> None:
    """Values in [0, 1], (H, W) gray or (H, W, 3) RGB, as an 8- or 16-bit PNG."""

def read_images(paths: Sequence[_Path]) -> _F32:
    """EXR/PNG images of one size read in parallel: float32 (K, H, W, 3)."""

def check_lights(light_directions: _F32, light_irradiance: _F32) -> None:
    """Refuse fewer than 3 lights, (nearly) coplanar lights or an irradiance not positive."""

def photometric_stereo(
    images: _F32,
    mask: npt.NDArray[np.bool_],
    light_directions: _F32,
    light_irradiance: _F32,
    robust: str = "tukey",
    shadow_fraction: float = 0.05,
    saturation: float | None = None,
    lobe_rounds: int | None = None,
    views: _F32 | None = None,
) -> tuple[_F32, _F32, npt.NDArray[np.uint8], npt.NDArray[np.uint16]]:
    """(normals (H, W, 3), albedo (H, W, 3), flags (H, W), observations used (H, W)) of
    C-contiguous float32 images (K, H, W, 3); `lobe_rounds`, the lobe mode's most rounds per
    exponent and start, at least 1 (15 by default)."""

def photometric_stereo_per_pixel(
    images: _F32,
    mask: npt.NDArray[np.bool_],
    light_directions: _F32,
    light_irradiance: _F32,
    robust: str = "tukey",
    shadow_fraction: float = 0.05,
    saturation: float | None = None,
    lobe_rounds: int | None = None,
    views: _F32 | None = None,
) -> tuple[_F32, _F32, npt.NDArray[np.uint8], npt.NDArray[np.uint16]]:
    """`photometric_stereo` under lights that differ from pixel to pixel (point lights near
    the object): `light_directions` and `light_irradiance` (N, K, 3) float32 at each of the
    mask's N pixels (row-major)."""

def tukey_with_lobe_check(
    images: _F32,
    mask: npt.NDArray[np.bool_],
    check: list[int],
    light_directions: _F32,
    light_irradiance: _F32,
    shadow_fraction: float,
    saturation: float | None,
    check_rounds: int,
    views: _F32 | None = None,
) -> tuple[tuple[_F32, _F32, npt.NDArray[np.uint8], npt.NDArray[np.uint16]], npt.NDArray[np.uint8]]:
    """The Tukey fit of `images` (as `photometric_stereo`'s) and, on the same threads, the
    lobe fit with `check_rounds` rounds of the pixels `check` (flat indices into `mask`):
    (the Tukey fit's arrays, the flag of each pixel of `check`)."""

def compare_rendering(
    direct: _F32,
    halves: Sequence[_F32],
    counts: Sequence[int],
    observed: _F32,
    keep: npt.NDArray[np.bool_] | None = None,
    first: int = 0,
) -> tuple[_F32, npt.NDArray[np.float64], tuple[float, float, float, float]]:
    """A rendering of N pixels under K lights, all (K, N, 3), against pixels `first..first + N`
    of `observed` (K, T, 3): (the halves' inter-reflected light weighted by their path
    `counts`, each pixel's Monte-Carlo noise energy (N,), (Σ|rendered − observed|,
    Σ|observed|, Σ|direct + each half − observed|)), the sums over the observations whose
    `keep` (K, T) is true."""

def denoise_indirect(
    indirect: _F32,
    noise_energy: npt.NDArray[np.float64],
    mask: npt.NDArray[np.bool_],
    height_px: _F32,
    albedo: _F32,
) -> tuple[_F32, npt.NDArray[np.float64]]:
    """The inter-reflection estimate (K, N, 3) at the N pixels of `mask` and their noise
    energy (N,), filtered along the surface of heights `height_px` (H, W, in pixels) and
    `albedo` (H, W, 3)."""
@final
class Environment:
    """Surroundings given as a mesh (contract §3b), made ready for ray queries once and shared
    by every `Renderer` built with it: `vertices` (V, 3) float32 in world units, `triangles`
    (F, 3) uint32, `albedo` (V, 3) float32 in [0, 1]."""

    def __new__(cls, vertices: _F32, triangles: npt.NDArray[np.uint32], albedo: _F32) -> Environment: ...
    @property
    def triangle_count(self) -> int:
        """Number of triangles."""

    def first_hit(
        self, origin: tuple[float, float, float], direction: tuple[float, float, float], t_max: float
    ) -> float | None:
        """Distance from `origin` along the unit `direction` (world units) to the nearest
        triangle, either side, within (0, `t_max`); None if there is none."""

@final
class Renderer:
    """A scene made ready for rendering and ray queries: height-field object, optional floor,
    Cornell box and environment mesh, distant or point lights; an orthographic camera, or a pinhole ``(fx, fy, cx, cy,
    zc)`` whose ``pixel_size`` is a pixel's world size at the depth of the object's base.
    ``light_positions`` (K, 3) makes light k an isotropic point at row k (world units; its
    ``light_irradiance`` row its radiant intensity, contract §4b) where the row is not NaN;
    its direction row is then unused. ``environment_mesh`` adds surroundings given as a mesh
    that reflects on both sides (contract §3b), built once (`Environment`)."""

    def __new__(
        cls,
        height: _F32,
        mask: npt.NDArray[np.bool_],
        albedo: _F32,
        pixel_size: float,
        light_directions: _F32,
        light_irradiance: _F32,
        floor: Floor | None = None,
        cornell_box: CornellBox | None = None,
        pinhole: tuple[float, float, float, float, float] | None = None,
        light_positions: _F32 | None = None,
        environment_mesh: Environment | None = None,
    ) -> Renderer: ...
    def with_reflectance(self, albedo: _F32, light_irradiance: _F32) -> Renderer:
        """The same scene with the object's albedo (H, W, 3) and each light's irradiance
        (K, 3); the geometry, its BVH and the light visibility are kept."""

    @property
    def triangle_count(self) -> int:
        """Number of triangles in the scene."""

    @property
    def light_count(self) -> int:
        """Number of lights."""

    def render_rows(
        self,
        row_start: int,
        row_end: int,
        bounces: int,
        samples: int,
        direct_samples: int,
        seed: int,
        split_bounces: bool = True,
    ) -> _F32:
        """float32 (P, K, rows, W, 3): the direct image (when `direct_samples` > 0), then each
        bounce (`split_bounces`) or their sum."""

    def render_pixels(
        self,
        pixels: Sequence[int],
        bounces: int,
        samples: int,
        direct_samples: int,
        seed: int,
        split_bounces: bool = True,
        cached_direct: bool = False,
    ) -> _F32:
        """float32 (P, K, N, 3) for the listed pixels (row-major indices), planes as in
        `render_rows`; `cached_direct` shades the direct image from the light cache."""

    def mesh_arrays(self) -> tuple[_F32, npt.NDArray[np.uint32], _F32, _F32]:
        """(positions (V, 3), triangles (T, 3), vertex albedo (V, 3), facing unit normals (T, 3))."""

    def intersect(
        self, origins: _F32, directions: _F32, threads: int | None = None
    ) -> tuple[_F32, npt.NDArray[np.int64]]:
        """(distance (N,), inf on a miss; triangle (N,), −1 on a miss) of a batch of rays."""

@final
class SparseCholesky:
    """The Cholesky factorisation of a sparse symmetric positive definite matrix (faer),
    factored once for many solves: from its CSR (or CSC) arrays with sorted indices, of
    which only the upper triangle is read. `name` is the argument named in errors."""

    def __new__(
        cls,
        indptr: npt.NDArray[np.int64],
        indices: npt.NDArray[np.int64],
        data: npt.NDArray[np.float64],
        name: str = "matrix",
    ) -> SparseCholesky: ...
    @property
    def dim(self) -> int:
        """The matrix's dimension n."""

    @property
    def factor_len(self) -> int:
        """Number of float64 values stored in the factor L."""

    def solve(self, b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The solution x of ``A x = b`` for a float64 (n,) right-hand side."""

def integrate_bilateral(
    normals: _F32,
    mask: npt.NDArray[np.bool_],
    intrinsics: tuple[float, float, float, float] | None = None,
    sharpness: float = 2.0,
    max_iterations: int = 150,
    tolerance: float = 1e-4,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint8], int, bool]:
    """The surface of float32 (H, W, 3) `normals` at bool (H, W) `mask`'s pixels that keeps its
    depth discontinuities: float64 (H, W) log depth along the optical axis for a pinhole
    `intrinsics` (fx, fy, cx, cy), else heights in pixel units (NaN outside the mask); uint8
    (H, W) cut edges (1: to the right neighbour, 2: to the pixel below); the re-weighted
    solves done; whether they converged."""
