"""Data sets in the irtps layout: loading, saving, and rejecting malformed folders."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from irtps import (
    ArgumentError,
    Camera,
    Dataset,
    DatasetError,
    GroundTruth,
    Light,
    Scene,
    _core,
    load_dataset,
    save_dataset,
)
from irtps.io.imageio import read_exr, read_image, read_images, read_mask, read_png, write_exr, write_png
from irtps.model.scene import scene_to_dict

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
MITSUBA = SHARED / "data" / "mitsuba"
needs_shared = pytest.mark.skipif(not MITSUBA.is_dir(), reason="shared reference data not available")

LIGHT_COUNT, HEIGHT, WIDTH = 4, 5, 7


def make_dataset(seed=0):
    """A small consistent data set with every ground-truth part; the mask misses a border."""
    rng = np.random.default_rng(seed)
    directions = [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, -0.6, 0.8], [-0.48, 0.36, 0.8]]
    lights = tuple(Light(direction=d, irradiance=[np.pi, 2.0, 1.0]) for d in directions)
    scene = Scene(camera=Camera(width=WIDTH, height=HEIGHT, pixel_size=0.25), lights=lights)
    mask = np.zeros((HEIGHT, WIDTH), dtype=bool)
    mask[1:-1, 1:-1] = True
    normal = rng.normal(size=(HEIGHT, WIDTH, 3)).astype(np.float32)
    normal[..., 2] = np.abs(normal[..., 2])
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    gt = GroundTruth(
        height=np.where(mask, rng.uniform(0.5, 2.0, (HEIGHT, WIDTH)), 0.0),
        normal=normal * mask[..., None],
        albedo=rng.uniform(0.0, 1.0, (HEIGHT, WIDTH, 3)),
        direct=rng.uniform(0.0, 1.0, (LIGHT_COUNT, HEIGHT, WIDTH, 3)),
    )
    images = gt.direct + rng.uniform(0.0, 0.1, gt.direct.shape)
    return Dataset(scene=scene, images=images, mask=mask, gt=gt)


@pytest.fixture
def folder(tmp_path):
    """A valid data set folder written by save_dataset."""
    path = tmp_path / "set"
    save_dataset(make_dataset(), path)
    return path


def assert_same_dataset(loaded, original):
    assert loaded.scene == original.scene
    np.testing.assert_array_equal(loaded.images, original.images)
    np.testing.assert_array_equal(loaded.mask, original.mask)
    for name in ("height", "normal", "albedo", "direct"):
        np.testing.assert_array_equal(getattr(loaded.gt, name), getattr(original.gt, name), err_msg=name)


def test_save_writes_the_contract_layout(folder):
    names = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())
    assert names == [
        "gt/albedo.exr",
        "gt/direct/000.exr",
        "gt/direct/001.exr",
        "gt/direct/002.exr",
        "gt/direct/003.exr",
        "gt/height.exr",
        "gt/normal.exr",
        "images/000.exr",
        "images/001.exr",
        "images/002.exr",
        "images/003.exr",
        "mask.png",
        "scene.json",
    ]
    assert json.loads((folder / "scene.json").read_text()) == scene_to_dict(make_dataset().scene)
    assert read_exr(folder / "gt" / "height.exr").shape == (HEIGHT, WIDTH)
    assert read_exr(folder / "gt" / "normal.exr").shape == (HEIGHT, WIDTH, 3)
    mask_values, bit_depth = read_png(folder / "mask.png")
    assert bit_depth == 8
    assert mask_values.shape == (HEIGHT, WIDTH)
    assert set(np.unique(mask_values)) == {0.0, 1.0}
    assert [p.name for p in folder.parent.iterdir()] == ["set"]


def test_save_then_load_round_trips_exactly(folder):
    loaded = load_dataset(folder)
    original = make_dataset()
    assert_same_dataset(loaded, original)
    assert loaded.images.dtype == np.float32 and loaded.images.shape == (LIGHT_COUNT, HEIGHT, WIDTH, 3)
    assert loaded.mask.dtype == bool
    assert loaded.source == str(folder)


def test_save_replaces_an_existing_data_set(folder):
    replacement = make_dataset(seed=1)
    replacement.gt = None
    save_dataset(replacement, folder)
    loaded = load_dataset(folder)
    np.testing.assert_array_equal(loaded.images, replacement.images)
    assert loaded.gt is None
    assert not (folder / "gt").exists()


def test_save_writes_extra_files_in_the_same_transaction(tmp_path):
    bounce = np.full((HEIGHT, WIDTH, 3), 0.25, dtype=np.float32)
    save_dataset(make_dataset(), tmp_path / "set", extra={"gt/bounce1/000.exr": bounce, "notes/y.exr": bounce[..., 0]})
    np.testing.assert_array_equal(read_exr(tmp_path / "set" / "gt" / "bounce1" / "000.exr"), bounce)
    assert read_exr(tmp_path / "set" / "notes" / "y.exr").shape == (HEIGHT, WIDTH)
    assert load_dataset(tmp_path / "set").gt.direct.shape == (LIGHT_COUNT, HEIGHT, WIDTH, 3)


@pytest.mark.parametrize(
    "key, expected",
    [
        ("../escape.exr", "must be a relative POSIX path"),
        ("/abs/x.exr", "must be a relative POSIX path"),
        ("gt/bounce1/000.png", "ending in .exr"),
        ("", "must be a relative POSIX path"),
        ("images/000.exr", "'images/000.exr' would overwrite a file of the data set"),
        ("gt/height.exr", "'gt/height.exr' would overwrite"),
    ],
)
def test_bad_extra_is_rejected_and_the_old_data_set_survives(folder, key, expected):
    before = read_images([folder / "images" / "000.exr"])
    with pytest.raises(ArgumentError, match="^extra: ") as info:
        save_dataset(make_dataset(seed=2), folder, extra={key: np.zeros((HEIGHT, WIDTH), np.float32)})
    assert expected in str(info.value)
    np.testing.assert_array_equal(read_images([folder / "images" / "000.exr"]), before)
    assert [p.name for p in folder.parent.iterdir()] == ["set"]


def test_save_rejects_an_extra_that_is_not_an_image(tmp_path):
    with pytest.raises(ArgumentError, match=r"^extra: 'gt/x\.exr' has shape \(4, 5, 7, 3\)"):
        save_dataset(make_dataset(), tmp_path / "set", extra={"gt/x.exr": np.zeros((4, HEIGHT, WIDTH, 3))})
    assert list(tmp_path.iterdir()) == []


def test_save_rejects_an_empty_mask(tmp_path):
    dataset = make_dataset()
    dataset.mask[:] = False
    with pytest.raises(DatasetError, match=r"Dataset\.mask is empty"):
        save_dataset(dataset, tmp_path / "set")
    assert list(tmp_path.iterdir()) == []


def test_save_rejects_non_finite_pixels_and_writes_nothing(tmp_path):
    dataset = make_dataset()
    dataset.images[2, 3, 4, 1] = np.nan
    with pytest.raises(DatasetError, match=r"Dataset.images\[2\]: non-finite value nan at row 3, column 4"):
        save_dataset(dataset, tmp_path / "set")
    assert list(tmp_path.iterdir()) == []


def test_dataset_rejects_arrays_that_disagree_with_the_scene():
    dataset = make_dataset()
    with pytest.raises(DatasetError, match=r"Dataset.images has shape \(3, 5, 7, 3\), expected \(4, 5, 7, 3\)"):
        Dataset(scene=dataset.scene, images=dataset.images[:3], mask=dataset.mask)
    with pytest.raises(DatasetError, match=r"Dataset\.mask has shape"):
        Dataset(scene=dataset.scene, images=dataset.images, mask=dataset.mask.T)
    with pytest.raises(DatasetError, match=r"Dataset\.gt\.height has shape"):
        Dataset(scene=dataset.scene, images=dataset.images, mask=dataset.mask, gt=GroundTruth(height=np.zeros((3, 3))))


def test_a_scene_json_with_a_byte_order_mark_loads_the_same(folder):
    original = load_dataset(folder)
    scene = folder / "scene.json"
    scene.write_bytes(b"\xef\xbb\xbf" + scene.read_bytes())
    assert load_dataset(folder).scene == original.scene


def test_missing_mask_means_every_pixel(folder):
    (folder / "mask.png").unlink()
    assert load_dataset(folder).mask.all()


def test_ground_truth_is_optional(folder):
    assert load_dataset(folder, ground_truth=False).gt is None
    shutil.rmtree(folder / "gt" / "direct")
    (folder / "gt" / "albedo.exr").unlink()
    gt = load_dataset(folder).gt
    assert gt.direct is None and gt.albedo is None and gt.height is not None
    shutil.rmtree(folder / "gt")
    assert load_dataset(folder).gt is None


def test_rgb_height_with_equal_channels_is_accepted(folder):
    height = make_dataset().gt.height
    _core.write_exr(str(folder / "gt" / "height.exr"), np.repeat(height[..., None], 3, axis=2))
    np.testing.assert_array_equal(load_dataset(folder).gt.height, height)


def test_png_images_are_read_as_linear_values(folder):
    expected = np.clip(make_dataset().images, 0.0, 1.0)
    for k in range(LIGHT_COUNT):
        (folder / "images" / f"{k:03d}.exr").unlink()
        bit_depth = 16 if k % 2 else 8
        _core.write_png(str(folder / "images" / f"{k:03d}.png"), expected[k], bit_depth)
    gray = np.linspace(0.0, 1.0, HEIGHT * WIDTH, dtype=np.float32).reshape(HEIGHT, WIDTH)
    (folder / "images" / "002.png").unlink()
    _core.write_png(str(folder / "images" / "002.png"), gray, 16)
    images = load_dataset(folder).images
    np.testing.assert_allclose(images[0], expected[0], atol=0.5 / 255 + 1e-7)
    np.testing.assert_allclose(images[1], expected[1], atol=0.5 / 65535 + 1e-7)
    np.testing.assert_allclose(images[2], np.repeat(gray[..., None], 3, axis=2), atol=0.5 / 65535 + 1e-7)
    np.testing.assert_allclose(np.round(images[0] * 255), images[0] * 255, atol=1e-3)


def test_read_image_replicates_a_y_exr_and_read_mask_takes_any_channel(tmp_path):
    _core.write_exr(str(tmp_path / "y.exr"), np.arange(6, dtype=np.float32).reshape(2, 3))
    image = read_image(tmp_path / "y.exr")
    assert image.shape == (2, 3, 3)
    np.testing.assert_array_equal(image[..., 0], image[..., 2])
    rgb = np.zeros((2, 3, 3), np.float32)
    rgb[0, 1, 2] = 1.0
    _core.write_png(str(tmp_path / "m.png"), rgb, 8)
    np.testing.assert_array_equal(read_mask(tmp_path / "m.png", (2, 3)), [[False, True, False], [False, False, False]])


def test_image_wrappers_turn_core_errors_into_dataset_errors(tmp_path):
    with pytest.raises(DatasetError, match=r"missing\.exr: no such file"):
        read_exr(tmp_path / "missing.exr")
    (tmp_path / "broken.png").write_bytes(b"broken")
    with pytest.raises(DatasetError, match=r"broken\.png: not a readable PNG file"):
        read_png(tmp_path / "broken.png")
    with pytest.raises(DatasetError, match=r"photo\.jpg: unknown image type '\.jpg'"):
        read_image(tmp_path / "photo.jpg")
    with pytest.raises(DatasetError, match="no image files given"):
        read_images([])
    with pytest.raises(DatasetError, match=r"out\.png: PNG bit depth must be 8 or 16, got 12"):
        write_png(tmp_path / "out.png", np.zeros((2, 2), np.float32), bit_depth=12)
    with pytest.raises(DatasetError, match=r"out\.exr: cannot write an array of shape \(2, 2, 4\)"):
        write_exr(tmp_path / "out.exr", np.zeros((2, 2, 4)))
    with pytest.raises(DatasetError, match="nowhere"):
        write_exr(tmp_path / "nowhere" / "out.exr", np.zeros((2, 2)))


def test_image_wrappers_round_trip_any_float_array(tmp_path):
    ramp = np.linspace(-1.0, 2.0, 12).reshape(2, 2, 3)
    write_exr(tmp_path / "ramp.exr", ramp)
    np.testing.assert_array_equal(read_exr(tmp_path / "ramp.exr"), ramp.astype(np.float32))
    write_png(tmp_path / "ramp.png", ramp, bit_depth=16)
    values, bit_depth = read_png(tmp_path / "ramp.png")
    assert bit_depth == 16
    np.testing.assert_allclose(values, np.clip(ramp, 0.0, 1.0), atol=0.5 / 65535)


def test_public_api_is_exported():
    import irtps

    assert isinstance(irtps.__version__, str) and irtps.__version__
    for name in irtps.__all__:
        assert hasattr(irtps, name), name


def _write(path, array):
    _core.write_exr(str(path), np.asarray(array, dtype=np.float32))


def _edit_scene(folder, edit):
    obj = json.loads((folder / "scene.json").read_text())
    edit(obj)
    (folder / "scene.json").write_text(json.dumps(obj))


def _rgb(height=HEIGHT, width=WIDTH, value=0.5):
    return np.full((height, width, 3), value, dtype=np.float32)


def _nan_pixel(path):
    image = _rgb()
    image[2, 3, 0] = np.nan
    _write(path, image)


def _inf_pixel(path):
    image = _rgb()
    image[4, 6, 2] = np.inf
    _write(path, image)


def _replace_lights(obj, count):
    obj["lights"] = obj["lights"][:count]


MALFORMED = {
    "no scene.json": (
        lambda f: (f / "scene.json").unlink(),
        "neither scene.json (irtps layout) nor light_directions.txt",
    ),
    "unknown format": (
        lambda f: _edit_scene(f, lambda o: o.update(format="irtps.scene/9")),
        "scene.json: format is 'irtps.scene/9': unknown format",
    ),
    "invalid JSON": (
        lambda f: (f / "scene.json").write_text('{"format": "irtps.scene/1",\n\n  oops}'),
        "scene.json: invalid JSON at line 3",
    ),
    "wrong JSON type": (
        lambda f: _edit_scene(f, lambda o: o["camera"].update(width="7")),
        "scene.json: camera.width must be a positive integer, got the string '7'",
    ),
    "too few lights": (lambda f: _edit_scene(f, lambda o: _replace_lights(o, 2)), "scene.json: lights has 2 lights"),
    "downward light": (
        lambda f: _edit_scene(f, lambda o: o["lights"][1].update(direction=[0.6, 0.0, -0.8])),
        "scene.json: lights[1].direction must point toward the camera side (z > 0)",
    ),
    "non-unit light": (
        lambda f: _edit_scene(f, lambda o: o["lights"][3].update(direction=[0.0, 0.72, 0.96])),
        "scene.json: lights[3].direction is not a unit vector (norm 1.2)",
    ),
    "more lights than images": (
        lambda f: _edit_scene(f, lambda o: o["lights"].append(o["lights"][0])),
        "images/004.exr: missing (scene.json has 5 lights, one image each)",
    ),
    "missing image": (
        lambda f: (f / "images" / "002.exr").unlink(),
        "images/002.exr: missing (scene.json has 4 lights, one image each)",
    ),
    "missing images folder": (lambda f: shutil.rmtree(f / "images"), "images: missing folder"),
    "more images than lights": (
        lambda f: _write(f / "images" / "004.exr", _rgb()),
        "images: 5 images for 4 lights in scene.json (004.exr has no light)",
    ),
    "both EXR and PNG": (
        lambda f: _core.write_png(str(f / "images" / "001.png"), _rgb(), 8),
        "images: both 001.exr and 001.png exist",
    ),
    "one image of another size": (
        lambda f: _write(f / "images" / "003.exr", _rgb(width=8)),
        "images/003.exr: size 8x5 differs from",
    ),
    "images disagree with camera": (
        lambda f: _edit_scene(f, lambda o: o["camera"].update(width=9)),
        "images/000.exr: size 7x5 does not match the camera in scene.json (9x5)",
    ),
    "NaN pixel": (
        lambda f: _nan_pixel(f / "images" / "001.exr"),
        "images/001.exr: non-finite value",
        "at row 2, column 3",
    ),
    "infinite pixel": (
        lambda f: _inf_pixel(f / "images" / "003.exr"),
        "images/003.exr: non-finite value inf at row 4, column 6",
    ),
    "corrupt image": (lambda f: (f / "images" / "002.exr").write_bytes(b"not an exr"), "images/002.exr:"),
    "mask of another size": (
        lambda f: _core.write_png(str(f / "mask.png"), np.ones((HEIGHT, 6), np.float32), 8),
        "mask.png: size 6x5 does not match the images (7x5)",
    ),
    "empty mask": (
        lambda f: _core.write_png(str(f / "mask.png"), np.zeros((HEIGHT, WIDTH), np.float32), 8),
        "mask.png: the mask is empty",
    ),
    "corrupt mask": (lambda f: (f / "mask.png").write_bytes(b"\x89PNG broken"), "mask.png:"),
    "gt normal of another size": (
        lambda f: _write(f / "gt" / "normal.exr", _rgb(height=4)),
        "gt/normal.exr: size 7x4 does not match the images (7x5)",
    ),
    "gt normal with one channel": (
        lambda f: _write(f / "gt" / "normal.exr", _rgb()[..., 0]),
        "gt/normal.exr: has a single Y channel",
    ),
    "gt height with different channels": (
        lambda f: _write(f / "gt" / "height.exr", np.dstack([_rgb()[..., 0], _rgb()[..., 0], _rgb()[..., 0] + 1])),
        "gt/height.exr: R, G and B differ",
    ),
    "NaN gt height": (
        lambda f: _write(f / "gt" / "height.exr", np.full((HEIGHT, WIDTH), np.nan)),
        "gt/height.exr: non-finite value nan at row 0, column 0",
    ),
    "gt albedo of another size": (
        lambda f: _write(f / "gt" / "albedo.exr", _rgb(width=3)),
        "gt/albedo.exr: size 3x5 does not match the images (7x5)",
    ),
    "missing gt direct image": (lambda f: (f / "gt" / "direct" / "003.exr").unlink(), "gt/direct/003.exr: missing"),
    "gt direct image of another size": (
        lambda f: _write(f / "gt" / "direct" / "002.exr", _rgb(height=6)),
        "gt/direct/002.exr: size 7x6 differs from",
    ),
    "gt direct images all of another size": (
        lambda f: [_write(f / "gt" / "direct" / f"{k:03d}.exr", _rgb(height=6)) for k in range(LIGHT_COUNT)],
        "gt/direct/000.exr: size 7x6 does not match the images (7x5)",
    ),
}


@pytest.mark.parametrize("name", list(MALFORMED))
def test_malformed_data_set_is_rejected_naming_the_file(folder, name):
    damage, *expected = MALFORMED[name]
    damage(folder)
    with pytest.raises(DatasetError) as info:
        load_dataset(folder)
    message = str(info.value)
    assert message.startswith(str(folder)), message
    for part in expected:
        assert part in message, message


def test_missing_folder_is_named(tmp_path):
    with pytest.raises(DatasetError, match="nowhere: no such data set folder"):
        load_dataset(tmp_path / "nowhere")
    (tmp_path / "file").write_text("x")
    with pytest.raises(DatasetError, match="file: not a folder"):
        load_dataset(tmp_path / "file")


def test_ground_truth_is_not_read_when_not_asked(folder):
    (folder / "gt" / "normal.exr").write_bytes(b"broken")
    assert load_dataset(folder, ground_truth=False).gt is None


@needs_shared
@pytest.mark.parametrize("name", ["cap_cornell", "grooves_dark"])
def test_reference_data_sets_load_and_round_trip(tmp_path, name):
    dataset = load_dataset(MITSUBA / name)
    assert dataset.images.shape == (12, 96, 96, 3)
    assert 0 < dataset.mask.sum() < 96 * 96
    assert dataset.images.max() > 0.0
    gt = dataset.gt
    assert gt.height.shape == (96, 96) and gt.direct.shape == (12, 96, 96, 3)
    assert np.all(gt.height[~dataset.mask] == 0.0)
    norms = np.linalg.norm(gt.normal[dataset.mask], axis=1)
    np.testing.assert_allclose(norms, 1.0, atol=1e-4)
    assert np.all(gt.normal[dataset.mask][:, 2] > 0.0)
    save_dataset(dataset, tmp_path / name)
    assert_same_dataset(load_dataset(tmp_path / name), dataset)


def _shift_exr_data_window(path, dx):
    """Move the data window of an EXR written by `write_exr` `dx` columns right, leaving its
    display window (and the file's scanlines, which only hold their row) where they were."""
    data = bytearray(path.read_bytes())
    window = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    x0, y0, x1, y1 = np.frombuffer(bytes(data[window : window + 16]), "<i4")
    data[window : window + 16] = np.array([x0 + dx, y0, x1 + dx, y1], "<i4").tobytes()
    path.write_bytes(bytes(data))


def test_an_exr_data_window_is_placed_in_its_display_window(tmp_path):
    path = tmp_path / "offset.exr"
    image = np.arange(3 * 4 * 3, dtype=np.float32).reshape(3, 4, 3) + 1
    write_exr(path, image)
    _shift_exr_data_window(path, 2)
    read = read_exr(path)
    assert read.shape == (3, 4, 3)
    np.testing.assert_array_equal(read[:, :2], 0)
    np.testing.assert_array_equal(read[:, 2:], image[:, :2])
    _shift_exr_data_window(path, -3)  # one column left of the display window
    np.testing.assert_array_equal(
        read_exr(path), np.concatenate([image[:, 1:], np.zeros((3, 1, 3), np.float32)], axis=1)
    )


@pytest.mark.parametrize("compression, code", [("zip", 3), ("rle", 1)])
def test_exr_compression_is_as_asked_and_lossless(tmp_path, compression, code):
    image = np.zeros((40, 30, 3), np.float32)
    image[10:20, 5:25] = np.random.default_rng(0).random((10, 20, 3), dtype=np.float32)
    path = tmp_path / f"{compression}.exr"
    write_exr(path, image, compression)
    np.testing.assert_array_equal(read_exr(path), image)
    # OpenEXR's header: attribute "compression" of type "compression", 1 byte (1 RLE, 3 ZIP).
    header = path.read_bytes()[:1000]
    marker = b"compression\x00compression\x00\x01\x00\x00\x00"
    assert header[header.index(marker) + len(marker)] == code


def test_an_unknown_exr_compression_is_named(tmp_path):
    with pytest.raises(ArgumentError, match="compression"):
        write_exr(tmp_path / "x.exr", np.zeros((2, 2, 3)), "piz")
    assert not (tmp_path / "x.exr").exists()
