"""Make the small DiLiGenT fixtures of tests/data from the shared objects.

Each fixture is a crop around the object, reduced by box averaging, under some of the 96
lights (spread over the light directions). Images stay 16-bit PNG; the text files keep the
original lines of those lights; the mask keeps the pixels whose block is entirely in the
object; the normals are block means, renormalised, 0 outside the mask.

- ``diligent_ball_small``: ballPNG rows 176..351, columns 212..403, reduced 4x, 8 lights.
- ``diligent_reading_small``: readingPNG rows 132..355, columns 200..411, reduced 4x,
  24 lights (enough for the robust fits to set shadows and highlights aside).

Usage: python tests/data/make_diligent_small.py SHARED/data/diligent
"""

import sys
from pathlib import Path

import numpy as np
import scipy.io
from irtps import _core

HERE = Path(__file__).resolve().parent
FACTOR = 4
#: fixture: (source object, rows, columns, number of lights)
FIXTURES = {
    "diligent_ball_small": ("ballPNG", slice(176, 352), slice(212, 404), 8),
    "diligent_reading_small": ("readingPNG", slice(132, 356), slice(200, 412), 24),
}


def spread_lights(directions: np.ndarray, count: int) -> list[int]:
    """Farthest-point choice of ``count`` light indices, starting with the most frontal one."""
    chosen = [int(np.argmax(directions[:, 2]))]
    while len(chosen) < count:
        distance = np.min(np.linalg.norm(directions[:, None] - directions[chosen][None], axis=2), axis=1)
        chosen.append(int(np.argmax(distance)))
    return sorted(chosen)


def reduce(image: np.ndarray, rows: slice, columns: slice) -> np.ndarray:
    """Crop and box-average by FACTOR: (H, W, C) -> (H/FACTOR, W/FACTOR, C)."""
    crop = image[rows, columns]
    h, w = crop.shape[0] // FACTOR, crop.shape[1] // FACTOR
    return crop.reshape(h, FACTOR, w, FACTOR, -1).mean(axis=(1, 3))


def make(source: Path, out: Path, rows: slice, columns: slice, light_count: int) -> None:
    lines = {
        name: (source / name).read_text().splitlines()
        for name in ("filenames.txt", "light_directions.txt", "light_intensities.txt")
    }
    directions = np.loadtxt(source / "light_directions.txt")
    chosen = spread_lights(directions, light_count)
    out.mkdir(exist_ok=True)
    for name, text in lines.items():
        (out / name).write_text("".join(text[k] + "\n" for k in chosen))
    for k in chosen:
        name = lines["filenames.txt"][k]
        image, bits = _core.read_png(str(source / name))
        assert bits == 16
        _core.write_png(str(out / name), reduce(image, rows, columns).astype(np.float32), 16)
    mask_image, _ = _core.read_png(str(source / "mask.png"))
    mask_full = np.atleast_3d(mask_image).max(axis=2) > 0
    mask = reduce(mask_full[..., None].astype(np.float64), rows, columns)[..., 0] == 1.0
    _core.write_png(str(out / "mask.png"), mask.astype(np.float32), 8)
    normals = reduce(scipy.io.loadmat(source / "Normal_gt.mat")["Normal_gt"], rows, columns)
    normals /= np.maximum(np.linalg.norm(normals, axis=2, keepdims=True), 1e-12)
    normals[~mask] = 0.0
    scipy.io.savemat(out / "Normal_gt.mat", {"Normal_gt": normals}, do_compression=True)


def main(shared: Path) -> None:
    for name, (source, rows, columns, light_count) in FIXTURES.items():
        make(shared / source, HERE / name, rows, columns, light_count)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
