"""Damage done to a copy of a fixture folder: the edits that tests/test_hard_inputs.py's
matrix makes to scene files, images and records before running the command on them."""

import json
import struct
import zlib

import numpy as np
from irtps import _core


def edit_scene(folder, edit):
    scene = json.loads((folder / "scene.json").read_text())
    edit(scene)
    (folder / "scene.json").write_text(json.dumps(scene))


def edit_exr(path, edit):
    image = _core.read_exr(str(path))
    edit(image)
    _core.write_exr(str(path), image)


def set_pixels(value, where=(slice(3, 5), slice(4, 6))):
    return lambda image: image.__setitem__(where, value)


def light_directions(*directions):
    def edit(scene):
        for light, direction in zip(scene["lights"], directions, strict=True):
            light["direction"] = direction

    return edit


def edit_scene_text(folder, edit):
    (folder / "scene.json").write_text(edit((folder / "scene.json").read_text()))


def edit_run_text(folder, edit):
    text = (folder / "run.json").read_text()
    assert edit(text) != text
    (folder / "run.json").write_text(edit(text))


def two_lights(folder):
    edit_scene(folder, lambda scene: scene.update(lights=scene["lights"][:2]))
    (folder / "images" / "002.exr").unlink()


def truncate(path, keep):
    path.write_bytes(path.read_bytes()[:keep])


def rename_exr_channel(path, old, new):
    """Rename a channel in the header of an EXR file (same length, so the file stays valid)."""
    data = path.read_bytes()
    start = data.index(b"chlist")
    at = data.index(old + b"\0", start)
    path.write_bytes(data[:at] + new + data[at + len(old) :])


def claim_exr_size(path, width, height):
    """Rewrite the data window of an EXR header to claim width x height pixels."""
    data = bytearray(path.read_bytes())
    window = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    data[window + 8 : window + 16] = struct.pack("<ii", width - 1, height - 1)
    path.write_bytes(bytes(data))


def claim_png_size(path, width, height):
    """Rewrite the IHDR of a PNG to claim width x height pixels (with a valid CRC)."""
    data = bytearray(path.read_bytes())
    data[16:24] = struct.pack(">II", width, height)
    data[29:33] = struct.pack(">I", zlib.crc32(bytes(data[12:29])))
    path.write_bytes(bytes(data))


def ball_image(folder, index):
    return folder / (folder / "filenames.txt").read_text().split()[index]


def write_png(path, array, bits=8):
    _core.write_png(str(path), np.asarray(array, dtype=np.float32), bits)


def replace_line(path, number, text):
    lines = path.read_text().splitlines()
    lines[number - 1] = text
    path.write_text("\n".join(lines) + "\n")


def coplanar_diligent(folder):
    lines = ["0.6 0 0.8", "-0.6 0 0.8", "0 0 1", "0.28 0 0.96"] * 2
    (folder / "light_directions.txt").write_text("\n".join(lines) + "\n")


def out_under_a_file(tmp_path):
    (tmp_path / "blocker").write_text("a file, not a folder")
    return tmp_path / "blocker" / "out"
