"""Camera RAW files (irtps.io.capture, through rawpy): DNG files written by PiDNG from a known
linear scene (an RGGB mosaic of it, 12-bit codes) come back demosaiced and proportional to
the scene, with the sensor's clip marked; an RTI folder of them reconstructs a sphere."""

import numpy as np
import pytest

import irtps
from irtps.io.capture import read_capture, read_capture_image

pytest.importorskip("rawpy")
pidng_core = pytest.importorskip("pidng.core")
from pidng.defs import CalibrationIlluminant, CFAPattern, DNGVersion, Orientation, PhotometricInterpretation  # noqa: E402

WHITE = 4095
#: XYZ to linear sRGB: a camera whose own colours are linear sRGB's.
XYZ_TO_SRGB = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])


def write_dng(path, rgb):
    """A DNG file of the RGGB mosaic of `rgb` (linear, 1.0 at the white level)."""
    height, width, _ = rgb.shape
    mosaic = np.empty((height, width))
    mosaic[0::2, 0::2] = rgb[0::2, 0::2, 0]
    mosaic[0::2, 1::2] = rgb[0::2, 1::2, 1]
    mosaic[1::2, 0::2] = rgb[1::2, 0::2, 1]
    mosaic[1::2, 1::2] = rgb[1::2, 1::2, 2]
    codes = np.clip(np.round(mosaic * WHITE), 0, WHITE).astype(np.uint16)
    tags = pidng_core.DNGTags()
    Tag = pidng_core.Tag
    for tag, value in (
        (Tag.ImageWidth, width),
        (Tag.ImageLength, height),
        (Tag.TileWidth, width),
        (Tag.TileLength, height),
        (Tag.Orientation, Orientation.Horizontal),
        (Tag.PhotometricInterpretation, PhotometricInterpretation.Color_Filter_Array),
        (Tag.SamplesPerPixel, 1),
        (Tag.BitsPerSample, 16),
        (Tag.CFARepeatPatternDim, [2, 2]),
        (Tag.CFAPattern, CFAPattern.RGGB),
        (Tag.BlackLevel, 0),
        (Tag.WhiteLevel, WHITE),
        (Tag.ColorMatrix1, [[int(round(value * 10000)), 10000] for value in XYZ_TO_SRGB.ravel()]),
        (Tag.CalibrationIlluminant1, CalibrationIlluminant.D65),
        (Tag.AsShotNeutral, [[1, 1], [1, 1], [1, 1]]),
        (Tag.Make, "irtps"),
        (Tag.Model, "test"),
        (Tag.DNGVersion, DNGVersion.V1_4),
        (Tag.DNGBackwardVersion, DNGVersion.V1_2),
    ):
        tags.set(tag, value)
    writer = pidng_core.RAW2DNG()
    writer.options(tags, path="", compress=False)
    writer.convert(codes, filename=str(path.with_suffix("")))
    assert path.exists()
    return path


def _scene(height=32, width=48):
    rows, columns = np.mgrid[0:height, 0:width]
    return np.dstack([0.2 + 0.6 * columns / width, 0.3 + 0.4 * rows / height, np.full((height, width), 0.5)])


INSIDE = (slice(3, -3), slice(3, -3))  # demosaicing needs neighbours


def test_a_raw_file_reads_back_linear_and_unrotated(tmp_path):
    scene = _scene()
    image, integer_codes = read_capture_image(write_dng(tmp_path / "a.dng", scene))
    assert image.shape == scene.shape and image.dtype == np.float32 and integer_codes
    assert np.abs(image[INSIDE] / scene[INSIDE] - 1).max() < 0.01
    half, _ = read_capture_image(write_dng(tmp_path / "b.dng", 0.5 * scene))
    assert np.abs(half[INSIDE] / image[INSIDE] - 0.5).max() < 0.005  # no gamma, no stretch to the brightest


def test_the_sensors_clip_is_marked_saturated(tmp_path):
    scene = _scene()
    scene[10:20, 10:30] = 1.5  # beyond the white level
    capture = read_capture([write_dng(tmp_path / "a.dng", scene)])
    assert capture.saturated[0][12:18, 12:28].all()
    assert not capture.saturated[0][INSIDE][:4].any()


def test_srgb_is_refused_for_raw_files(tmp_path):
    with pytest.raises(irtps.DatasetError, match=r"a\.dng: a camera RAW file is linear"):
        read_capture_image(write_dng(tmp_path / "a.dng", _scene()), "srgb")


def test_an_rti_folder_of_raw_files_reconstructs_a_sphere(tmp_path):
    size = 40
    rows, columns = np.mgrid[0:size, 0:size] + 0.5
    x, y = (columns - size / 2) / 16, -(rows - size / 2) / 16
    inside = x**2 + y**2 < 1
    normals = np.dstack([x, y, np.sqrt(np.clip(1 - x**2 - y**2, 0, 1))])
    lights = np.array([[0, 0, 1], [0.5, 0, 0.866], [0, 0.5, 0.866], [-0.5, 0, 0.866], [0, -0.5, 0.866]])
    lines = [str(len(lights))]
    for k, light in enumerate(lights):
        shading = 0.7 * np.clip(normals @ light, 0, None) * inside
        write_dng(tmp_path / f"img_{k}.dng", np.repeat(shading[..., None], 3, axis=2))
        lines.append(f"img_{k}.dng {light[0]:.6f} {light[1]:.6f} {light[2]:.6f}")
    (tmp_path / "capture.lp").write_text("\n".join(lines) + "\n")
    dataset = irtps.load_dataset(tmp_path)
    result = irtps.photometric_stereo(dataset.images, lights, np.ones((len(lights), 3)), mask=inside)
    error = irtps.angular_error_deg(result.normals, normals, inside)
    lit = inside & (x**2 + y**2 < 0.5)
    assert np.median(error[lit]) < 1.0
