"""The IRT-PS paper's own estimate of the inter-reflected light, for comparison.

As the paper describes it (§4): from the surface point seen by each pixel, a ray is
reflected once at random toward the surroundings, and again from where it lands, up to r
times, with a single sample per pixel. The colours (albedos) met are multiplied — c1,
c1·c2, c1·c2·c3 — into an "environment colour"; pixels whose ray escaped before r
reflections have no value and are filled by non-uniform (scattered-data) interpolation. The
result, scaled by a constant per reflection depth, is subtracted from every image alike.

The paper leaves the scale open. `PAPER_SCALE` holds the value picked on the shared Mitsuba
scenes (cap_cornell and grooves_dark): a grid search over 0, 0.02, 0.05, 0.1, 0.2 and 0.4,
for the lowest mean angular error after 6 passes of the paper's own update
(Aₜ₊₁ = Aₜ − Eₜ), chose 0.05 for r = 1, 2 and 3 alike (see docs/method.md). The estimate ignores the lights, the
Lambert cosine and the light's path, which is what the physically based estimator
(`irtps.render.renderer.render_indirect`) adds.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator

from irtps.model.options import PAPER_BOUNCES
from irtps.render.renderer import make_renderer
from irtps.model.scene import Scene

#: Scale of the environment colour per reflection depth r (picked on the shared scenes).
PAPER_SCALE = dict.fromkeys(PAPER_BOUNCES, 0.05)


def paper_environment_colour(
    scene: Scene, height: np.ndarray, albedo: np.ndarray, mask: np.ndarray, *, reflections: int, seed: int = 0
) -> np.ndarray:
    """The paper's environment colour: albedos met along one random path per pixel.

    Parameters
    ----------
    scene, height, albedo, mask
        The surface in its surroundings, as for `irtps.render`.
    reflections : int
        r: how many times the ray is reflected (1, 2 or 3).
    seed : int
        Seed of the random directions.

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3): c1·…·cr per masked pixel (interpolated where the ray escaped),
        0 outside the mask.
    """
    renderer = make_renderer(scene, height, albedo, mask)
    positions, triangles, vertex_albedo, normals = renderer.mesh_arrays()
    rng = np.random.default_rng(seed)
    rows, cols = np.nonzero(mask)
    xs, ys = scene.camera.pixel_centers()
    point = np.column_stack([xs[rows, cols], ys[rows, cols], np.asarray(height, np.float64)[rows, cols]])
    normal = _height_field_normals(height, mask, scene.camera.orthographic_pixel_size)[rows, cols]
    colour = np.ones((len(rows), 3))
    alive = np.ones(len(rows), dtype=bool)
    offset = 1e-3 * scene.camera.orthographic_pixel_size
    for _ in range(reflections):
        direction = _cosine_directions(normal, rng)
        t, triangle = renderer.intersect((point + offset * normal).astype(np.float32), direction.astype(np.float32))
        alive &= triangle >= 0
        hit = np.where(alive)[0]
        tri = triangle[hit]
        point[hit] = point[hit] + offset * normal[hit] + t[hit, None] * direction[hit]
        colour[hit] *= _albedo_at(point[hit], positions[triangles[tri]], vertex_albedo[triangles[tri]])
        normal[hit] = normals[tri]
    out = np.zeros((*mask.shape, 3), dtype=np.float32)
    known = np.column_stack([rows[alive], cols[alive]])
    values = colour[alive]
    out[rows[alive], cols[alive]] = values
    missing = np.column_stack([rows[~alive], cols[~alive]])
    if len(missing) and len(known):
        filled = LinearNDInterpolator(known, values)(missing) if len(known) >= 3 else np.full((len(missing), 3), np.nan)
        holes = np.isnan(filled).any(axis=1)
        if holes.any():
            filled[holes] = NearestNDInterpolator(known, values)(missing[holes])
        out[missing[:, 0], missing[:, 1]] = filled
    return out


def paper_indirect(
    scene: Scene, height: np.ndarray, albedo: np.ndarray, mask: np.ndarray, *, reflections: int, seed: int = 0
) -> np.ndarray:
    """The paper's estimate ``E^r``: the scaled environment colour, the same for every light.

    Returns
    -------
    numpy.ndarray
        float32 (K, H, W, 3).
    """
    colour = paper_environment_colour(scene, height, albedo, mask, reflections=reflections, seed=seed)
    estimate = PAPER_SCALE[reflections] * colour
    return np.broadcast_to(estimate, (len(scene.lights), *estimate.shape)).astype(np.float32)


def _height_field_normals(height, mask, pixel_size):
    from irtps.geometry.surface import height_to_normals

    return height_to_normals(height, mask, pixel_size).astype(np.float64)


def _cosine_directions(normal: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Cosine-weighted directions around each unit normal."""
    u1, u2 = rng.random(len(normal)), rng.random(len(normal))
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    local = np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)])
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangent = np.cross(helper, normal)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    bitangent = np.cross(normal, tangent)
    return local[:, :1] * tangent + local[:, 1:2] * bitangent + local[:, 2:] * normal


def _albedo_at(point: np.ndarray, corners: np.ndarray, corner_albedo: np.ndarray) -> np.ndarray:
    """Barycentric interpolation of per-vertex albedo at points on their triangles."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    v0, v1, v2 = b - a, c - a, point - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    denominator = np.where(np.abs(d00 * d11 - d01 * d01) > 0, d00 * d11 - d01 * d01, 1.0)
    v = (d11 * d20 - d01 * d21) / denominator
    w = (d00 * d21 - d01 * d20) / denominator
    u = 1.0 - v - w
    weights = np.clip(np.column_stack([u, v, w]), 0.0, 1.0)
    weights /= np.maximum(weights.sum(1, keepdims=True), 1e-12)
    return (weights[:, :, None] * corner_albedo).sum(1)
