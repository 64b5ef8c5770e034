"""The files other tools read (`irtps.io.exchange`, `irtps.io.mesh.write_glb`), each read back by
a library independent of the one that wrote it: the normal map and the 16-bit maps by pypng,
the float TIFF by Pillow, the glTF binary by pygltflib."""

import json

import numpy as np
import png
import pygltflib
import pytest
from PIL import Image
from plyfile import PlyData

import irtps
from irtps.cli.main import main
from irtps.io.dataset_writer import save_dataset
from irtps.io.mesh import write_glb
from irtps.render.synth import synthesize


@pytest.fixture(scope="module")
def reconstruction():
    data, _ = synthesize("cap", size=24, lights=6, bounces=0, environment="none")
    return data, irtps.reconstruct(data)


def _png16(path):
    """(H, W, planes) uint16 levels of a 16-bit PNG, as pypng reads them."""
    width, height, rows, info = png.Reader(filename=str(path)).asDirect()
    assert info["bitdepth"] == 16
    return np.vstack([np.asarray(row, dtype=np.uint16) for row in rows]).reshape(height, width, info["planes"])


def _accessor(gltf, index):
    """The values of accessor `index` of a GLB's binary buffer."""
    accessor = gltf.accessors[index]
    view = gltf.bufferViews[accessor.bufferView]
    dtype = {5121: np.uint8, 5125: np.uint32, 5126: np.float32}[accessor.componentType]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[accessor.type]
    start = view.byteOffset + (accessor.byteOffset or 0)
    data = gltf.binary_blob()[start : start + accessor.count * width * np.dtype(dtype).itemsize]
    return np.frombuffer(data, dtype=dtype).reshape(accessor.count, width)


def test_the_normal_map_decodes_to_the_normals_in_either_convention(reconstruction, tmp_path):
    _, result = reconstruction
    irtps.save_reconstruction(result, tmp_path / "gl")
    irtps.save_reconstruction(result, tmp_path / "dx", normal_map="directx")
    opengl, directx = (_png16(tmp_path / name / "normal.png") for name in ("gl", "dx"))
    decoded = opengl / 65535.0 * 2 - 1
    mask = result.mask
    assert np.abs(decoded[mask] - result.normals[mask]).max() < 2e-5
    # Outside the object, the flat normal; DirectX turns green upside down, nothing else.
    assert (opengl[~mask] == [32768, 32768, 65535]).all()
    assert np.abs(directx[..., 1].astype(int) + opengl[..., 1] - 65535).max() <= 1
    assert (directx[..., [0, 2]] == opengl[..., [0, 2]]).all()
    records = [json.loads((tmp_path / name / "run.json").read_text())["exports"] for name in ("gl", "dx")]
    assert [record["normal.png"]["convention"] for record in records] == ["opengl", "directx"]


def test_the_height_maps_give_back_the_heights(reconstruction, tmp_path):
    _, result = reconstruction
    irtps.save_reconstruction(result, tmp_path / "out")
    folder = tmp_path / "out"
    mask = result.mask
    tiff = np.asarray(Image.open(folder / "height.tif"))
    assert tiff.dtype == np.float32
    assert np.array_equal(tiff[mask], result.height[mask].astype(np.float32))
    scale = json.loads((folder / "run.json").read_text())["exports"]["height.png"]
    levels = _png16(folder / "height.png")[..., 0]
    assert (levels[~mask] == scale["no_data"]).all() and (levels[mask] > 0).all()
    heights = scale["offset"] + (levels[mask] - 1.0) * scale["step"]
    assert np.abs(heights - result.height[mask]).max() <= scale["step"] / 2 + 1e-9
    assert levels[mask].min() == 1 and levels[mask].max() == 65535


def test_the_glb_holds_the_ply_mesh_with_its_colours_and_normals(reconstruction, tmp_path):
    _, result = reconstruction
    irtps.save_reconstruction(result, tmp_path / "out")
    ply = PlyData.read(tmp_path / "out" / "mesh.ply")
    vertex = ply["vertex"]
    positions = np.c_[vertex["x"], vertex["y"], vertex["z"]]
    gltf = pygltflib.GLTF2().load_binary(str(tmp_path / "out" / "mesh.glb"))
    attributes = gltf.meshes[0].primitives[0].attributes
    assert np.array_equal(_accessor(gltf, attributes.POSITION), positions)
    colours = _accessor(gltf, attributes.COLOR_0)
    assert np.array_equal(colours[:, :3], np.c_[vertex["red"], vertex["green"], vertex["blue"]])
    normals = _accessor(gltf, attributes.NORMAL)
    assert np.allclose(normals, np.c_[vertex["nx"], vertex["ny"], vertex["nz"]], atol=1e-6)
    faces = _accessor(gltf, gltf.meshes[0].primitives[0].indices).reshape(-1, 3)
    assert np.array_equal(faces, np.vstack(ply["face"]["vertex_indices"]))


@pytest.mark.filterwarnings("ignore:.*orthographic camera of pixel size")
def test_a_perspective_reconstruction_writes_its_depth_maps_too(tmp_path):
    data, _ = synthesize("cap", size=24, lights=6, bounces=0, environment="none", camera="perspective")
    result = irtps.reconstruct(data)
    irtps.save_reconstruction(result, tmp_path / "out")
    exports = json.loads((tmp_path / "out" / "run.json").read_text())["exports"]
    assert set(exports) == {"normal.png", "height.png", "depth.png"}
    mask = result.mask
    tiff = np.asarray(Image.open(tmp_path / "out" / "depth.tif"))
    assert np.array_equal(tiff[mask], result.depth[mask].astype(np.float32))
    levels = _png16(tmp_path / "out" / "depth.png")[..., 0]
    depths = exports["depth.png"]["offset"] + (levels[mask] - 1.0) * exports["depth.png"]["step"]
    assert np.abs(depths - result.depth[mask]).max() <= exports["depth.png"]["step"] / 2 + 1e-9


def test_the_command_line_takes_the_normal_map_convention(reconstruction, tmp_path, capsys):
    data, _ = reconstruction
    save_dataset(data, tmp_path / "cap")
    assert main(["reconstruct", str(tmp_path / "cap"), "--out", str(tmp_path / "out"), "--normal-map", "directx"]) == 0
    record = json.loads((tmp_path / "out" / "run.json").read_text())
    assert record["exports"]["normal.png"]["convention"] == "directx"
    with pytest.raises(SystemExit) as exited:
        main(["reconstruct", str(tmp_path / "cap"), "--out", str(tmp_path / "other"), "--normal-map", "vulkan"])
    assert exited.value.code == 2 and "--normal-map" in capsys.readouterr().err
    assert not (tmp_path / "other").exists()


def test_a_bad_convention_is_refused_before_anything_is_written(reconstruction, tmp_path):
    _, result = reconstruction
    with pytest.raises(irtps.ArgumentError, match="^normal_map: 'Vulkan' is not one of opengl, directx$"):
        irtps.save_reconstruction(result, tmp_path / "out", normal_map="Vulkan")
    assert not (tmp_path / "out").exists()


def test_a_mesh_without_vertices_is_a_glb_of_an_empty_scene(tmp_path):
    none = np.zeros((0, 3))
    write_glb(tmp_path / "empty.glb", none, np.zeros((0, 3), int), np.zeros((0, 3), np.uint8), none)
    gltf = pygltflib.GLTF2().load_binary(str(tmp_path / "empty.glb"))
    assert gltf.meshes == [] and gltf.accessors == []
