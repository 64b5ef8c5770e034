"""Light calibration (``irtps calibrate``, `irtps.calibrate_lights`): directions and strengths
against the truth of a Mitsuba capture (tests/data/calibration_spheres, 8-bit sRGB PNG, circles
found) and of analytic captures (a mirror sphere with each light's highlight at its half
vector, a Lambertian sphere, a dark floor, supersampled edges)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import irtps
from irtps.calibrate.circles import Circle, outermost_outline, parse_circle
from irtps.calibrate.spheres import find_spheres, outline_image
from irtps.cli.main import main
from irtps.io.imageio import srgb_to_linear, write_exr

MITSUBA = Path(__file__).parent / "data" / "calibration_spheres"
CHROME = (40.0, 36.0, 22.0)
MATTE = (104.0, 40.0, 24.0)


def _directions(count=10, seed=0):
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0, 2 * np.pi, count)
    tilt = rng.uniform(0.1, 0.6, count)
    return np.c_[tilt * np.cos(angle), tilt * np.sin(angle), np.sqrt(1 - tilt**2)]


def _capture(lights, strengths, chrome=CHROME, matte=MATTE, size=(80, 140), supersample=4, horizon=False):
    """Linear images of a mirror sphere (mirroring surroundings of radiance 0.15, and each
    light's highlight where the normal is its half vector), a Lambertian sphere of albedo 0.8
    and a floor of albedo 0.05 facing the camera; each pixel the mean of supersample^2 samples.
    With `horizon`, the mirror sphere mirrors a dark sky within 0.7 of its radius and, beyond,
    the floor behind it: its outline hardly shows, the horizon is a strong circle inside it."""
    height, width = size
    rows, columns = (np.mgrid[0 : height * supersample, 0 : width * supersample] + 0.5) / supersample
    spheres = []
    for circle in (chrome, matte):
        if circle is None:
            spheres.append(None)
            continue
        x, y = (columns - circle[0]) / circle[2], -(rows - circle[1]) / circle[2]
        spheres.append((x**2 + y**2 < 1, np.dstack([x, y, np.sqrt(np.clip(1 - x**2 - y**2, 0, 1))])))
    images = np.empty((len(lights), height * supersample, width * supersample, 3))
    for k, (light, strength) in enumerate(zip(lights, strengths)):
        image = np.broadcast_to(0.05 * strength * light[2] / np.pi, images.shape[1:]).copy()
        if spheres[1] is not None:
            inside, normals = spheres[1]
            image[inside] = 0.8 * strength * np.clip(normals[inside] @ light, 0, None)[:, None] / np.pi
        if spheres[0] is not None:
            inside, normals = spheres[0]
            half = (light + [0, 0, 1]) / np.linalg.norm(light + [0, 0, 1])
            lobe = 30.0 * np.exp(-(1 - normals[inside] @ half) / 0.0005)
            mirrored = 0.15
            if horizon:
                floor = 0.05 * strength * light[2] / np.pi
                mirrored = np.where(normals[inside][:, 2:3] > np.sqrt(0.5), 0.002, 0.9 * floor)
            image[inside] = mirrored + lobe[:, None] * strength / strength.mean()
        images[k] = image
    return images.reshape(len(lights), height, supersample, width, supersample, 3).mean(axis=(2, 4))


def _strengths(count=10, seed=0):
    return np.random.default_rng(seed + 10).uniform(2, 4, (count, 1)) * [1.0, 0.9, 0.8]


def _angles_deg(found, truth):
    return np.degrees(np.arccos(np.clip(np.sum(found * truth, axis=1), -1, 1)))


def _relative(found, truth):
    ratio = found / truth
    return np.abs(ratio / ratio.mean(axis=0) - 1)


def _truth():
    truth = json.loads((MITSUBA / "truth.json").read_text())
    return (
        np.array([light["direction"] for light in truth["lights"]]),
        np.array([light["irradiance"] for light in truth["lights"]]),
        truth,
    )


def test_the_mitsuba_capture_is_calibrated_within_the_issue_bounds(tmp_path, capsys):
    assert main(["calibrate", str(MITSUBA), "--out", str(tmp_path / "lights")]) == 0
    directions, irradiance, truth = _truth()
    lp = (tmp_path / "lights" / "lights.lp").read_text().splitlines()
    assert lp[0] == "12"
    assert [line.split()[0] for line in lp[1:]] == [f"{k:03d}.png" for k in range(12)]
    from_lp = np.array([[float(value) for value in line.split()[1:]] for line in lp[1:]])
    errors = _angles_deg(from_lp, directions)
    assert errors.mean() <= 0.5 and errors.max() <= 1.0, errors
    lights = json.loads((tmp_path / "lights" / "lights.json").read_text())["lights"]
    assert np.allclose([light["direction"] for light in lights], from_lp, atol=1e-6)
    assert _relative(np.array([light["irradiance"] for light in lights]), irradiance).max() <= 0.02
    record = json.loads((tmp_path / "lights" / "calibration.json").read_text())
    assert record["format"] == "irtps.calibration/1"
    for name, key in (("chrome_sphere", "chrome_sphere"), ("matte_sphere", "matte_sphere")):
        found, true = record[name], truth[key]
        assert np.hypot(*np.subtract(found["center_px"], true["center_px"])) < 0.25, name
        assert abs(found["radius_px"] - true["radius_px"]) < 0.5, name
    assert record["chrome_circle_source"] == "highlights" and record["matte_circle_source"] == "shading"
    assert (tmp_path / "lights" / "calibration.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    printed = capsys.readouterr().out
    assert "calibrated 12 lights" in printed and "strengths from the matte sphere" in printed
    assert "matte sphere (117.9" in printed or "matte sphere (118.0" in printed
    assert "fitted to its shading" in printed
    assert (
        f"--names-from CAPTURE (to name its images), then irtps reconstruct CAPTURE --lights {tmp_path / 'lights' / 'lights.lp'}"
        in printed
    )


def test_the_lp_file_turns_the_capture_into_an_rti_folder(tmp_path):
    assert main(["calibrate", str(MITSUBA), "--out", str(tmp_path / "lights"), "--quiet"]) == 0
    folder = tmp_path / "rti"
    folder.mkdir()
    for image in MITSUBA.glob("*.png"):
        shutil.copy(image, folder)
    shutil.copy(tmp_path / "lights" / "lights.lp", folder)
    dataset = irtps.load_dataset(folder)
    directions, irradiance, _ = _truth()
    read = np.array([light.direction for light in dataset.scene.lights])
    assert _angles_deg(read, directions).max() <= 1.0
    assert not dataset.irradiance_known
    shutil.copy(tmp_path / "lights" / "light_intensities.txt", folder)
    dataset = irtps.load_dataset(folder)
    assert dataset.irradiance_known
    assert _relative(dataset.scene.light_irradiance, irradiance).max() <= 0.02


@pytest.mark.parametrize("seed", [0, 1])
def test_an_analytic_capture_with_both_spheres(seed):
    lights, strengths = _directions(seed=seed), _strengths(seed=seed)
    calibration = irtps.calibrate_lights(_capture(lights, strengths))
    assert calibration.direction_source == "chrome" and calibration.chrome_circle_source == "highlights"
    assert _angles_deg(calibration.directions, lights).max() < 0.25
    assert _relative(calibration.irradiance, strengths).max() < 0.002
    # absolute with the matte sphere's albedo: E = pi I / (albedo n.l)
    absolute = irtps.calibrate_lights(_capture(lights, strengths), matte_albedo=0.8).irradiance
    assert np.abs(absolute / strengths - 1).max() < 0.005
    assert np.hypot(calibration.matte.column - MATTE[0], calibration.matte.row - MATTE[1]) < 0.05
    assert np.isfinite(calibration.agreement_deg).all() and calibration.agreement_deg.max() < 0.3


def test_a_mirror_sphere_alone_gives_directions_from_its_outline_and_no_strengths(tmp_path):
    lights, strengths = _directions(seed=2), _strengths(seed=2)
    images = _capture(lights, strengths, matte=None)
    calibration = irtps.calibrate_lights(images)
    assert calibration.matte is None and calibration.irradiance is None and calibration.matte_albedo is None
    assert calibration.chrome_circle_source == "outline" and calibration.notes == ()
    # an albedo given for a matte sphere that is not there is said, not silently dropped
    notes = irtps.calibrate_lights(images, matte_albedo=0.8).notes
    assert notes == (
        "the matte sphere's albedo was given, but no matte sphere was found: no strengths "
        "(give its circle with --matte COLUMN,ROW,RADIUS)",
    )
    assert np.hypot(calibration.chrome.column - CHROME[0], calibration.chrome.row - CHROME[1]) < 0.1
    assert _angles_deg(calibration.directions, lights).max() < 0.3
    capture = tmp_path / "capture"
    capture.mkdir()
    for k, image in enumerate(images):
        write_exr(capture / f"light_{k + 1}.exr", image.astype(np.float32))
    assert main(["calibrate", str(capture), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert not (tmp_path / "out" / "lights.json").exists()
    assert not (tmp_path / "out" / "light_intensities.txt").exists()
    names = [line.split()[0] for line in (tmp_path / "out" / "lights.lp").read_text().splitlines()[1:]]
    assert names == [f"light_{k + 1}.exr" for k in range(10)]  # 2 before 10: numbers in names as numbers


def test_a_mirror_sphere_on_a_floor_is_told_from_the_horizon_it_mirrors():
    lights, strengths = _directions(seed=7), _strengths(seed=7)
    images = _capture(lights, strengths, matte=None, horizon=True)
    calibration = irtps.calibrate_lights(images)
    assert abs(calibration.chrome.radius - CHROME[2]) < 0.3  # not the horizon at 0.7 of it
    assert np.hypot(calibration.chrome.column - CHROME[0], calibration.chrome.row - CHROME[1]) < 0.1
    assert _angles_deg(calibration.directions, lights).max() < 0.3
    with_matte = irtps.calibrate_lights(_capture(lights, strengths, horizon=True))
    assert with_matte.chrome_circle_source == "highlights"
    assert _angles_deg(with_matte.directions, lights).max() < 0.25


def test_a_mirror_spheres_outline_is_the_outermost_circle_about_it():
    images = _capture(_directions(seed=8), _strengths(seed=8), matte=None, horizon=True)
    outline = outline_image(images.mean(axis=-1))
    horizon = Circle(CHROME[0], CHROME[1], CHROME[2] * np.sqrt(0.5))
    assert abs(outermost_outline(outline, horizon, 8.0).radius - CHROME[2]) < 0.5
    own = Circle(*CHROME)
    assert outermost_outline(outline, own, 8.0) == own  # nothing beyond it stands out


def test_a_matte_sphere_alone_gives_directions_from_its_shading():
    lights, strengths = _directions(seed=3), _strengths(seed=3)
    calibration = irtps.calibrate_lights(_capture(lights, strengths, chrome=None))
    assert calibration.direction_source == "matte" and calibration.chrome is None
    assert _angles_deg(calibration.directions, lights).max() < 0.05
    assert _relative(calibration.irradiance, strengths).max() < 0.002


def test_given_circles_are_taken_as_they_are():
    lights, strengths = _directions(seed=4), _strengths(seed=4)
    images = _capture(lights, strengths)
    calibration = irtps.calibrate_lights(images, chrome=CHROME, matte=MATTE)
    assert calibration.chrome == CHROME and calibration.matte == MATTE
    assert calibration.chrome_circle_source == "given" and calibration.matte_given
    assert _angles_deg(calibration.directions, lights).max() < 0.25
    assert find_spheres(images.mean(axis=-1), np.zeros(images.shape[:3], bool), chrome=CHROME).chrome == CHROME


def test_clipped_8bit_images_keep_the_strengths():
    lights, strengths = _directions(seed=5), _strengths(seed=5)
    images = _capture(lights, strengths)
    codes = np.round(np.clip(images, 0, 1) ** (1 / 2.2) * 255) / 255  # clipped, like a camera
    linear = codes**2.2
    calibration = irtps.calibrate_lights(linear, saturated=(codes >= 1).any(axis=-1))
    assert _relative(calibration.irradiance, strengths).max() < 0.01


def test_a_light_without_a_highlight_takes_the_matte_spheres_direction():
    lights, strengths = _directions(seed=6), _strengths(seed=6)
    images = _capture(lights, strengths)
    images[3, 10:62, 12:68] = 0.15  # the mirror sphere shows no highlight under light 3
    calibration = irtps.calibrate_lights(images, names=[f"{k}.png" for k in range(10)])
    assert any("3.png" in note for note in calibration.notes)
    assert _angles_deg(calibration.directions, lights).max() < 0.25


def test_too_few_images_are_refused():
    with pytest.raises(irtps.ArgumentError, match="^images: 2 images: a calibration needs at least 3"):
        irtps.calibrate_lights(_capture(_directions(2), _strengths(2)))


def test_a_capture_without_spheres_is_refused():
    rng = np.random.default_rng(0)
    images = rng.uniform(0.1, 0.2, (6, 40, 60, 3))
    with pytest.raises(irtps.DatasetError, match="^capture: no mirror or matte sphere found; give their circles"):
        irtps.calibrate_lights(images)


def test_circles_are_parsed_or_refused():
    assert parse_circle("412, 380.5, 95") == (412.0, 380.5, 95.0)
    with pytest.raises(irtps.ArgumentError, match="^chrome: expected COLUMN,ROW,RADIUS"):
        parse_circle("1,2", "chrome")
    with pytest.raises(irtps.ArgumentError, match="^matte: the radius must be positive"):
        parse_circle("1,2,-3", "matte")


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--chrome", "1,2"], "irtps: error: --chrome: expected COLUMN,ROW,RADIUS in pixels, got '1,2'"),
        (["--matte-albedo", "0"], "irtps: error: --matte-albedo: must be in (0, 1], got 0.0"),
        (["--encoding", "srgb"], None),
    ],
)
def test_cli_refuses_bad_arguments_in_one_line(tmp_path, capsys, extra, message):
    status = main(["calibrate", str(MITSUBA), "--out", str(tmp_path / "out"), "--quiet", *extra])
    if message is None:
        assert status == 0
        return
    assert status == 2
    error = capsys.readouterr().err
    assert error.strip() == message
    assert not (tmp_path / "out").exists()


def test_cli_names_the_lp_lines_after_another_folder(tmp_path, capsys):
    other = tmp_path / "object"
    other.mkdir()
    for k in range(12):
        (other / f"IMG_{k + 1:04d}.JPG").write_bytes(b"")
    out = tmp_path / "out"
    assert main(["calibrate", str(MITSUBA), "--out", str(out), "--quiet", "--names-from", str(other)]) == 0
    names = [line.split()[0] for line in (out / "lights.lp").read_text().splitlines()[1:]]
    assert names == [f"IMG_{k + 1:04d}.JPG" for k in range(12)]
    (other / "IMG_0013.JPG").write_bytes(b"")
    assert main(["calibrate", str(MITSUBA), "--out", str(out), "--quiet", "--names-from", str(other)]) == 2
    assert "object: 13 images, but the capture" in capsys.readouterr().err


def test_cli_protects_the_capture_and_refuses_mixed_folders(tmp_path, capsys):
    capture = tmp_path / "capture"
    shutil.copytree(MITSUBA, capture)
    before = sorted(path.name for path in capture.iterdir())
    assert main(["calibrate", str(capture), "--out", str(capture / "out"), "--quiet"]) == 2
    assert "capture" in capsys.readouterr().err
    assert sorted(path.name for path in capture.iterdir()) == before
    write_exr(capture / "extra.exr", np.zeros((96, 160, 3), np.float32))
    assert main(["calibrate", str(capture), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "holds images of several kinds (EXR, PNG)" in capsys.readouterr().err


def test_srgb_to_linear_is_what_the_reader_applies():
    # The capture's PNG files are 8-bit sRGB: read by default as sRGB, their highlights clip.
    from irtps.io.capture import read_capture

    capture = read_capture(sorted(MITSUBA.glob("*.png")))
    assert capture.saturated.any()
    from PIL import Image

    first = np.asarray(Image.open(MITSUBA / "000.png")).astype(np.float64) / 255
    assert np.allclose(capture.images[0], srgb_to_linear(first[..., :3]), atol=1e-6)
