"""Make the small perspective fixture of tests/data from the shared Mitsuba scene.

``mitsuba_persp_small/cap_persp_cornell``: ``cap_persp_cornell`` (96x96, perspective camera)
under 4 of its 12 lights (spread over the light directions), reduced 4x to 24x24:

- images: box means of 4x4 pixels, which are exactly what the same camera with ``fx``,
  ``fy``, ``cx``, ``cy`` divided by 4 sees (each pixel the radiance averaged over its
  footprint, contract §1b);
- ``mask.png``: the pixels whose 4x4 block lies entirely inside the original mask;
- ``gt/depth.exr``: the mean depth of the block's central 2x2 pixels, whose centres
  surround the reduced pixel's centre; ``gt/height.exr`` = ``zc - depth`` (contract §1b);
- ``gt/normal.exr``: block means of the original normals, renormalised; ``gt/albedo.exr``:
  block means. Depth, heights and normals describe the finer object of the original only
  approximately.

Usage: python tests/data/make_perspective_small.py SHARED/data/mitsuba
"""

import dataclasses
import sys
from pathlib import Path

import numpy as np
from make_diligent_small import spread_lights

import irtps

HERE = Path(__file__).resolve().parent
FACTOR = 4
LIGHTS = 4


def blocks(array: np.ndarray) -> np.ndarray:
    """(..., H, W, C) -> (..., H/FACTOR, FACTOR, W/FACTOR, FACTOR, C)."""
    *lead, h, w, c = array.shape
    return array.reshape(*lead, h // FACTOR, FACTOR, w // FACTOR, FACTOR, c)


def main(shared: Path) -> None:
    data = irtps.load_dataset(shared / "cap_persp_cornell")
    camera, gt = data.scene.camera, data.gt
    chosen = spread_lights(data.scene.light_directions, LIGHTS)
    images = blocks(data.images[chosen]).mean(axis=(-4, -2))
    mask = blocks(data.mask[..., None].astype(np.float64)).min(axis=(-4, -2))[..., 0] == 1.0
    central = blocks(gt.depth[..., None])[:, 1:3, :, 1:3, 0]
    depth = np.where(mask, central.mean(axis=(1, 3)), 0.0)
    zc = camera.optical_center[2]
    normal = blocks(gt.normal).mean(axis=(-4, -2))
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    reduced = irtps.Camera(
        camera.width // FACTOR,
        camera.height // FACTOR,
        projection="perspective",
        fx=camera.fx / FACTOR,
        fy=camera.fy / FACTOR,
        cx=camera.cx / FACTOR,
        cy=camera.cy / FACTOR,
        optical_center=camera.optical_center,
    )
    scene = dataclasses.replace(data.scene, camera=reduced, lights=tuple(data.scene.lights[k] for k in chosen))
    truth = irtps.GroundTruth(
        height=np.where(mask, zc - depth, 0.0),
        normal=np.where(mask[..., None], normal, 0.0),
        albedo=blocks(gt.albedo).mean(axis=(-4, -2)),
        depth=depth,
    )
    irtps.save_dataset(
        irtps.Dataset(scene=scene, images=images, mask=mask, gt=truth),
        HERE / "mitsuba_persp_small" / "cap_persp_cornell",
    )


if __name__ == "__main__":
    main(Path(sys.argv[1]))
