"""The meshes of a reconstruction folder, read back by an independent reader (trimesh)."""

import dataclasses
import json

import numpy as np
import pytest
import trimesh

from irtps import reconstruct, save_reconstruction
from irtps.irt.folder import load_reconstruction
from irtps.render.synth import synthesize

PIXEL_SIZE = 0.25


@pytest.fixture(scope="module")
def cap_folder(tmp_path_factory):
    """A cap reconstructed at a pixel size of 0.25 world units."""
    data, _ = synthesize("cap", size=32, lights=8, bounces=0, environment="none")
    data.scene = dataclasses.replace(data.scene, camera=dataclasses.replace(data.scene.camera, pixel_size=PIXEL_SIZE))
    out = tmp_path_factory.mktemp("cap") / "out"
    save_reconstruction(reconstruct(data), out)
    return out


@pytest.fixture(scope="module")
def meshes(cap_folder):
    ply = trimesh.load(cap_folder / "mesh.ply", process=False)
    obj = trimesh.load(cap_folder / "mesh.obj", process=False, maintain_order=True)
    return ply, obj


def _used_pixels(mask: np.ndarray) -> np.ndarray:
    """Pixels that are a corner of a fully masked 2x2 block (written out pixel by pixel)."""
    used = np.zeros_like(mask)
    rows, cols = mask.shape
    for i in range(rows - 1):
        for j in range(cols - 1):
            if mask[i : i + 2, j : j + 2].all():
                used[i : i + 2, j : j + 2] = True
    return used


def test_both_files_hold_the_same_mesh(meshes):
    ply, obj = meshes
    np.testing.assert_allclose(obj.vertices, ply.vertices, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(obj.faces, ply.faces)
    np.testing.assert_allclose(obj.vertex_normals, ply.vertex_normals, atol=1e-6)


def test_one_vertex_per_used_pixel_at_its_centre_and_height(cap_folder, meshes):
    _, _, height, mask = load_reconstruction(cap_folder)
    assert json.loads((cap_folder / "run.json").read_text())["pixel_size"] == PIXEL_SIZE
    used = _used_pixels(mask)
    rows, cols = mask.shape
    i, j = np.nonzero(used)
    expected = np.stack([(j + 0.5 - cols / 2) * PIXEL_SIZE, (rows / 2 - i - 0.5) * PIXEL_SIZE, height[used]], axis=1)
    for mesh in meshes:
        assert len(mesh.vertices) == used.sum()
        np.testing.assert_allclose(mesh.vertices, expected, rtol=1e-6, atol=1e-6)
        lower, upper = mesh.bounds
        np.testing.assert_allclose(
            lower,
            [(j.min() + 0.5 - cols / 2) * PIXEL_SIZE, (rows / 2 - i.max() - 0.5) * PIXEL_SIZE, height[used].min()],
            rtol=1e-6,
        )
        np.testing.assert_allclose(
            upper,
            [(j.max() + 0.5 - cols / 2) * PIXEL_SIZE, (rows / 2 - i.min() - 0.5) * PIXEL_SIZE, height[used].max()],
            rtol=1e-6,
        )


def test_faces_face_the_camera_and_agree_with_the_stored_normals(cap_folder, meshes):
    normals, _, _, mask = load_reconstruction(cap_folder)
    stored = normals[_used_pixels(mask)]
    stored /= np.linalg.norm(stored, axis=1, keepdims=True)
    for mesh in meshes:
        np.testing.assert_allclose(mesh.vertex_normals, stored, atol=1e-6)  # read from the file, not recomputed
        assert (mesh.face_normals[:, 2] > 0).all()  # counter-clockwise seen from +z, the camera
        agreement = np.einsum("fk,fk->f", mesh.face_normals, stored[mesh.faces].mean(axis=1))
        assert (agreement > 0.9).all()
