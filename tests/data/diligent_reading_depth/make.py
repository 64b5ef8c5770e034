"""Makes reading.npz: DiLiGenT reading's ground-truth normals, mask and depth, every second
pixel, cropped to the object, with its intrinsics for that grid (BiNI's evaluation data;
research use, as DiLiGenT's authors allow). Run from the repository root with ../shared:
``python tests/data/diligent_reading_depth/make.py``."""

from pathlib import Path

import numpy as np
import scipy.io
from PIL import Image

SOURCE = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "diligent" / "readingPNG"
STEP = 2

normals = scipy.io.loadmat(SOURCE / "Normal_gt.mat")["Normal_gt"].astype(np.float32)[::STEP, ::STEP]
mask_image = np.asarray(Image.open(SOURCE / "mask.png"))
mask = (mask_image if mask_image.ndim == 2 else mask_image[..., 0])[::STEP, ::STEP] > 0
depth = np.load(SOURCE / "depth_gt.npz")["depth_gt"].astype(np.float32)[::STEP, ::STEP]
K = np.loadtxt(SOURCE / "K.txt")
rows, columns = np.nonzero(mask)
top, left = rows.min() - 2, columns.min() - 2
bottom, right = rows.max() + 3, columns.max() + 3
# Pixel (i, j) of the new grid is pixel (STEP i, STEP j) of the old, centred at old image
# point (STEP j + 1/2, ...) = STEP (j + 1/2) - (STEP - 1)/2: the same ray with f / STEP and
# c' = (c + (STEP - 1)/2) / STEP, less the crop.
fx, fy = K[0, 0] / STEP, K[1, 1] / STEP
cx = (K[0, 2] + (STEP - 1) / 2) / STEP - left
cy = (K[1, 2] + (STEP - 1) / 2) / STEP - top
crop = (slice(top, bottom), slice(left, right))
np.savez_compressed(
    Path(__file__).with_name("reading.npz"),
    normals=normals[crop].astype(np.float16),
    mask=mask[crop],
    depth=depth[crop],
    intrinsics=np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]]),
)
