"""The light of the surroundings in the object's edge pixels.

A pixel's value averages the radiance over its square footprint (contract §1), and the
object's surface spans only the triangles between the centres of masked pixels (§2). The
footprint of a pixel at the mask's edge reaches past the last triangles: there the camera
sees the floor or the box beside or below the object, not the object. Photometric stereo
reads that light as the object's, which tilts the normals of the edge pixels toward the
floor's and brightens their albedo: on the shared pedestal_cornell (its top 20 units
above the floor) the edge pixels are tens of degrees off even without inter-reflections
(docs/method.md, Edge pixels).

IRT-PS renders its reconstruction anyway, so it renders that light too (the direct light
of the surroundings seen in each edge pixel's footprint: the reconstruction rendered with
a black object) and subtracts it with the inter-reflections. What the corrected pixel
then holds is the object's light over the part of its footprint the triangles cover
(`mesh_coverage`), whose albedo is the fitted one over that fraction.

Where the object stands low above the floor, the edge of its cast shadow crosses that part
of the footprint, and the light there depends on the shape below the pixel's size, which
the reconstruction does not resolve: on the shared cap_cornell (its edge 1 unit above the
floor) the rendered light was off by a third of the object's own light in the edge pixels
and the loop drifted away. The light of a pixel is subtracted only where moving the object
by one pixel (the data's resolution) up or down changes it, under every light, by less than
`STABILITY` of its largest; elsewhere the pixel is left as it was observed. So is a masked
pixel that no triangle touches (a stray pixel, a line one pixel wide): the whole of its
footprint is surroundings to the reconstruction, and subtracting their light would leave none
of the object's to fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irtps.render.renderer import make_renderer
from irtps.render.residual import DIRECT_SAMPLES
from irtps.model.scene import Scene
from irtps.geometry.surface import meshed_blocks

__all__ = ["STABILITY", "SurroundingsLight", "edge_pixels", "mesh_coverage", "surroundings_light"]

#: Largest change of a pixel's surroundings light under any one light (Σ over channels of
#: ‖change‖) when the object moves by one pixel up or down, relative to its light under the
#: light that shows it most, at which it is subtracted. At the true shapes of the shared
#: scenes it is 0 at nearly every edge pixel of pedestal_cornell (its cast shadows reach far
#: beyond the footprints) and above this bound at every edge pixel of cap_cornell (1
#: unit high), so the one is corrected and the other left as observed. Taken under each
#: light, not summed over the lights: a sum lets a shadow's edge under one light of eight
#: through.
STABILITY = 0.05


@dataclass
class SurroundingsLight:
    """The direct light of the surroundings seen in the object's pixels.

    Attributes
    ----------
    light : numpy.ndarray
        float32 (K, N, 3) at the mask's N pixels (row-major): the light to subtract, 0 at
        the pixels not corrected.
    corrected : numpy.ndarray
        bool (N,): the pixels whose light is subtracted.
    """

    light: np.ndarray
    corrected: np.ndarray

    def coverage(self, mask: np.ndarray) -> np.ndarray:
        """float64 (H, W): the fraction of each pixel's footprint whose light the corrected
        images hold (`mesh_coverage` at the corrected pixels), 1 elsewhere."""
        frame = np.zeros(mask.shape, dtype=bool)
        frame[mask] = self.corrected
        return np.where(frame, mesh_coverage(mask), 1.0)


def mesh_coverage(mask: np.ndarray) -> np.ndarray:
    """The fraction of each pixel's footprint that the object's triangles cover.

    The footprint of pixel (i, j) is made of four quarters, one in each 2×2 block of pixels
    that has (i, j) as a corner; the triangles span a block when its four pixels are masked
    (contract §2).

    Parameters
    ----------
    mask : numpy.ndarray
        (H, W) bool, the object's pixels.

    Returns
    -------
    numpy.ndarray
        float64 (H, W) in {0, 1/4, 1/2, 3/4, 1}; 0 outside the mask.

    Examples
    --------
    >>> import numpy as np
    >>> mesh_coverage(np.ones((3, 3), bool)).tolist()
    [[0.25, 0.5, 0.25], [0.5, 1.0, 0.5], [0.25, 0.5, 0.25]]
    """
    mask = np.asarray(mask, dtype=bool)
    meshed = meshed_blocks(mask).astype(np.float64)
    quarters = np.zeros(mask.shape)
    for rows, cols in (
        (slice(None, -1), slice(None, -1)),
        (slice(1, None), slice(1, None)),
        (slice(1, None), slice(None, -1)),
        (slice(None, -1), slice(1, None)),
    ):
        quarters[rows, cols] += meshed
    return np.where(mask, quarters / 4.0, 0.0)


def edge_pixels(mask: np.ndarray) -> np.ndarray:
    """bool (H, W): the masked pixels whose footprint the triangles do not cover whole."""
    mask = np.asarray(mask, dtype=bool)
    return mask & (mesh_coverage(mask) < 1.0)


def surroundings_light(
    scene: Scene, height: np.ndarray, albedo: np.ndarray, mask: np.ndarray, *, seed: int = 0
) -> SurroundingsLight:
    """The direct light of the floor and box seen in the object's edge pixels.

    Parameters
    ----------
    scene : Scene
        The surroundings; without floor and box there is nothing to see (all 0).
    height, albedo, mask
        The reconstruction, as for `irtps.render.renderer.render`.
    seed : int
        Seed of the footprint samples.

    Returns
    -------
    SurroundingsLight
        The light at the edge pixels where it is stable (`STABILITY`).

    Examples
    --------
    A square block 10 units high on a white floor, lit from straight above: the floor
    fills half the footprint of a pixel on the block's side and three quarters at a
    corner (here seen by 16 footprint samples); the four inner pixels see only the block.

    >>> import numpy as np
    >>> from irtps import Camera, Floor, Light, Scene
    >>> scene = Scene(Camera(8, 8, 1.0), [Light(direction=[0, 0, 1], irradiance=(np.pi,) * 3)],
    ...               floor=Floor(height=0.0, albedo=(1.0, 1.0, 1.0)))
    >>> mask = np.zeros((8, 8), bool); mask[2:6, 2:6] = True
    >>> seen = surroundings_light(scene, np.where(mask, 10.0, 0.0), np.full((8, 8, 3), 0.5), mask)
    >>> np.round(seen.light[0, :4, 0].astype(float), 2).tolist(), int(seen.corrected.sum())
    ([0.81, 0.56, 0.56, 0.81], 12)
    """
    mask = np.asarray(mask, dtype=bool)
    count = int(mask.sum())
    light = np.zeros((len(scene.lights), count, 3), dtype=np.float32)
    corrected = np.zeros(count, dtype=bool)
    if scene.floor is None and scene.environment is None:
        return SurroundingsLight(light=light, corrected=corrected)
    edge = edge_pixels(mask)
    pixels = np.flatnonzero(edge).tolist()
    black = np.zeros_like(albedo, dtype=np.float32)
    step = scene.camera.orthographic_pixel_size

    def rendered(offset: float) -> np.ndarray:
        moved = np.where(mask, np.asarray(height, dtype=np.float32) + np.float32(offset), 0).astype(np.float32)
        return make_renderer(scene, moved, black, mask).render_pixels(pixels, 0, 1, DIRECT_SAMPLES, seed, False, True)[
            0
        ]

    seen = rendered(0.0)
    change = np.maximum(*(np.abs(rendered(offset) - seen).sum(axis=2) for offset in (-step, step))).max(axis=0)
    size = np.abs(seen).sum(axis=2).max(axis=0)
    touched = mesh_coverage(mask)[edge] > 0  # a pixel no triangle touches has no object light to keep
    stable = (size > 0) & (change <= STABILITY * size) & touched
    at = edge[mask]
    light[:, at] = np.where(stable[None, :, None], seen, 0)
    corrected[at] = stable
    return SurroundingsLight(light=light, corrected=corrected)
