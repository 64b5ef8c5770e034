"""The rig drawn around the object: a 3-D view of the reconstructed surface inside its
surroundings given as a mesh (contract §3b), with the point lights (§4b) and the camera."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from irtps.model.environment import MeshEnvironment
from irtps.model.scene import PointLight, Scene
from irtps.model.data import spread_pixels
from irtps.report.figures import DPI, figure_png

__all__ = ["rig_png", "shows_a_rig"]

#: Environment triangles and object points drawn at most (spread over them).
MAX_TRIANGLES, MAX_POINTS = 20_000, 4_000


def shows_a_rig(scene: Scene) -> bool:
    """Whether `scene` has what the rig figure draws: point lights or a mesh around the object."""
    return scene.has_point_lights or isinstance(scene.environment, MeshEnvironment)


def rig_png(scene: Scene, height: np.ndarray, mask: np.ndarray, title: str) -> bytes:
    """A 3-D view of the surface of heights `height` (H, W) at the pixels of `mask`, seen
    through the scene's camera (each pixel's point on its ray), inside the scene's mesh
    environment (triangles in their albedo, half transparent), its point lights (numbered
    stars) and a perspective camera's optical centre; as PNG bytes."""
    figure = Figure(figsize=(6.4, 5.2))
    axes = figure.add_subplot(projection="3d")
    points = scene.camera.surface_points(np.where(mask, height, 0.0))
    shown = np.zeros_like(mask)
    shown.flat[spread_pixels(mask, MAX_POINTS)] = True
    everything = [points[shown]]
    axes.scatter(*points[shown].T, s=2, c="0.35", depthshade=False, label="object")
    environment = scene.environment
    if isinstance(environment, MeshEnvironment):
        chosen = np.unique(np.linspace(0, len(environment.triangles) - 1, MAX_TRIANGLES).astype(int))
        corners = environment.vertices[environment.triangles[chosen]]
        colours = np.clip(environment.albedo[environment.triangles[chosen]].mean(axis=1), 0, 1)
        axes.add_collection3d(Poly3DCollection(corners, facecolors=colours, edgecolors="none", alpha=0.35))
        everything.append(corners.reshape(-1, 3))
    lights = [(k, light.position) for k, light in enumerate(scene.lights) if isinstance(light, PointLight)]
    if lights:
        positions = np.array([position for _, position in lights])
        axes.scatter(*positions.T, marker="*", s=80, c="gold", edgecolors="black", depthshade=False, label="lights")
        for k, position in lights:
            axes.text(*position, f" {k}", fontsize="x-small")
        everything.append(positions)
    if scene.camera.optical_center is not None:
        center = np.array(scene.camera.optical_center)
        axes.scatter(*center, marker="v", s=60, c="tab:blue", depthshade=False, label="camera")
        everything.append(center[None])
    stacked = np.concatenate(everything)
    low, high = stacked.min(axis=0), stacked.max(axis=0)
    for set_limits, a, b in zip((axes.set_xlim, axes.set_ylim, axes.set_zlim), low, high, strict=True):
        set_limits(a, b if b > a else a + 1)
    axes.set_box_aspect(np.maximum(high - low, 1e-9 * max(float((high - low).max()), 1.0)))
    axes.set_xlabel("x")
    axes.set_ylabel("y")
    axes.set_zlabel("z")
    axes.view_init(elev=25, azim=-60)
    axes.legend(loc="upper left", fontsize="x-small")
    axes.set_title(title, fontsize="medium")
    figure.set_dpi(DPI)
    return figure_png(figure)
