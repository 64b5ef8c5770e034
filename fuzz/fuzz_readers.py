"""Fuzz the readers of irtps with atheris (coverage-guided libFuzzer for Python).

Targets (the first argument):

``exr``
    `irtps.io.imageio.read_image` on an ``.exr`` file holding the input bytes (the Rust
    OpenEXR reader, channel checks, the finite-value check).
``png``
    The same on a ``.png`` file (the Rust PNG reader).
``scene``
    `irtps.model.scene.load_scene` on a ``scene.json`` holding the input bytes.
``dataset``
    `irtps.load_dataset` on a tiny data set folder, irtps or DiLiGenT layout, one of
    whose files is replaced by the input: its first byte picks the file, the rest is
    the new content.

Every input must load or raise `irtps.DatasetError`. Any other exception, a crash, a
hang (``-timeout``) or too much memory (``-rss_limit_mb``) is a bug: libFuzzer stops
and writes the input to ``crash-*`` / ``oom-*`` / ``timeout-*``.

Usage::

    python fuzz/fuzz_readers.py TARGET CORPUS_DIR [libFuzzer options]
    python fuzz/fuzz_readers.py exr /tmp/corpus-exr -runs=2000 -seed=1
    python fuzz/fuzz_readers.py dataset /tmp/corpus-dataset -max_total_time=600

An empty or missing CORPUS_DIR is first filled with seeds cut from the test fixtures
(``tests/data``); libFuzzer adds the inputs that reach new code to it. Scratch files go
to a fresh folder under ``$TMPDIR``. ``tests/test_fuzz.py`` runs each target for a
bounded number of inputs.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import atheris
import numpy as np
import scipy.io

with atheris.instrument_imports(include=["irtps"]):
    from irtps import _core
    from irtps.io.dataset import load_dataset
    from irtps.errors import DatasetError
    from irtps.io.imageio import read_image
    from irtps.model.scene import load_scene

FIXTURES = Path(__file__).resolve().parents[1] / "tests" / "data"
MITSUBA = FIXTURES / "mitsuba_small" / "cap_cornell"
BALL = FIXTURES / "diligent_ball_small"
MITSUBA_CORNER, BALL_CORNER = (45, 45), (19, 20)
"""Top left pixels of the 7x6 crops kept in the tiny seeds, on the objects."""


def _crop(array: np.ndarray, corner: tuple[int, int]) -> np.ndarray:
    top, left = corner
    return np.ascontiguousarray(array[top : top + 6, left : left + 7])


def _exr_seeds(folder: Path) -> None:
    shutil.copy(MITSUBA / "images" / "000.exr", folder / "mitsuba_rgb.exr")
    shutil.copy(MITSUBA / "gt" / "height.exr", folder / "mitsuba_height.exr")
    image = _core.read_exr(str(MITSUBA / "images" / "000.exr"))
    _core.write_exr(str(folder / "crop_rgb.exr"), _crop(image, MITSUBA_CORNER))
    _core.write_exr(str(folder / "crop_y.exr"), _crop(image[..., 0], MITSUBA_CORNER))


def _png_seeds(folder: Path) -> None:
    shutil.copy(BALL / "008.png", folder / "diligent_rgb16.png")
    shutil.copy(BALL / "mask.png", folder / "diligent_mask.png")
    image, _ = _core.read_png(str(BALL / "008.png"))
    for bits in (8, 16):
        _core.write_png(str(folder / f"crop_rgb{bits}.png"), _crop(image, BALL_CORNER), bits)
        _core.write_png(str(folder / f"crop_gray{bits}.png"), _crop(image[..., 1], BALL_CORNER), bits)


def _scene_seeds(folder: Path) -> None:
    for scene in sorted(FIXTURES.glob("mitsuba_small/*/scene.json")):
        shutil.copy(scene, folder / f"{scene.parent.name}.json")
    (folder / "deep.json").write_text("[" * 4000)  # once a RecursionError, not a DatasetError


def _tiny_irtps(folder: Path) -> None:
    """The Mitsuba fixture cut down to its 7x6 crop, every file of the layout present."""
    shutil.copytree(MITSUBA, folder)
    for path in folder.rglob("*.exr"):
        _core.write_exr(str(path), _crop(_core.read_exr(str(path)), MITSUBA_CORNER))
    mask, _ = _core.read_png(str(folder / "mask.png"))
    _core.write_png(str(folder / "mask.png"), _crop(mask, MITSUBA_CORNER), 8)
    scene = (
        (folder / "scene.json").read_text().replace('"width": 96', '"width": 7').replace('"height": 96', '"height": 6')
    )
    (folder / "scene.json").write_text(scene)


def _tiny_diligent(folder: Path) -> None:
    """The DiLiGenT fixture cut down to 4 lights and a 7x6 crop."""
    folder.mkdir()
    names = (BALL / "filenames.txt").read_text().split()[:4]
    for text in ("filenames.txt", "light_directions.txt", "light_intensities.txt"):
        (folder / text).write_text("\n".join((BALL / text).read_text().splitlines()[:4]) + "\n")
    for name in [*names, "mask.png"]:
        image, bits = _core.read_png(str(BALL / name))
        _core.write_png(str(folder / name), _crop(image, BALL_CORNER), bits)
    normals = scipy.io.loadmat(BALL / "Normal_gt.mat")["Normal_gt"]
    scipy.io.savemat(folder / "Normal_gt.mat", {"Normal_gt": _crop(normals, BALL_CORNER)})


class DatasetTarget:
    """Tiny data sets under ``root``; an input replaces one of their files, then is undone."""

    def __init__(self, root: Path) -> None:
        _tiny_irtps(root / "irtps")
        _tiny_diligent(root / "diligent")
        self.files = sorted(path for path in root.rglob("*") if path.is_file())
        self.folders = [root / path.relative_to(root).parts[0] for path in self.files]
        self.originals = [path.read_bytes() for path in self.files]

    def seeds(self, folder: Path) -> None:
        for index, content in enumerate(self.originals):
            (folder / f"{index:02d}_{self.files[index].name}").write_bytes(bytes([index]) + content)

    def __call__(self, data: bytes) -> None:
        if not data:
            return
        index = data[0] % len(self.files)
        path = self.files[index]
        path.write_bytes(data[1:])
        try:
            load_dataset(self.folders[index])
        finally:
            path.write_bytes(self.originals[index])


def _file_target(path: Path, read: Callable[[Path], object]) -> Callable[[bytes], None]:
    def run(data: bytes) -> None:
        path.write_bytes(data)
        read(path)

    return run


def main(argv: list[str]) -> None:
    if len(argv) < 3 or argv[1] not in ("exr", "png", "scene", "dataset"):
        sys.exit(__doc__)
    target, corpus = argv[1], Path(argv[2])
    scratch = Path(tempfile.mkdtemp(prefix=f"irtps-fuzz-{target}-"))
    if target == "dataset":
        run = DatasetTarget(scratch)
        seed = run.seeds
    elif target == "scene":
        run, seed = _file_target(scratch / "scene.json", load_scene), _scene_seeds
    else:
        run = _file_target(scratch / f"input.{target}", read_image)
        seed = _exr_seeds if target == "exr" else _png_seeds
    corpus.mkdir(parents=True, exist_ok=True)
    if not any(corpus.iterdir()):
        seed(corpus)

    def test_one_input(data: bytes) -> None:
        try:
            run(data)
        except DatasetError:
            pass

    atheris.Setup([argv[0], *argv[3:], str(corpus)], test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main(sys.argv)
