"""``--lights FILE.lp``: a folder of images given its lights by a light position file kept
elsewhere (as ``irtps calibrate`` writes it), for ``irtps reconstruct`` and ``irtps batch``;
checked against the DiLiGenT ball cut, whose calibrated lights and true normals it holds."""

import dataclasses
import hashlib
import html
import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

import irtps
from irtps._shared.by_name import files_by_name
from irtps.batch.cluster import local_cluster
from irtps.batch.run import reconstruct_many
from irtps.cli.main import main
from irtps.io.dataset_files import dataset_inputs
from irtps.io.imageio import write_png
from irtps.io.rti import light_file_record
from irtps.irt.folder import load_reconstruction
from irtps.model.scene import Light
from irtps.render.renderer import render
from irtps.render.synth import synthesize

BALL = Path(__file__).parent / "data" / "diligent_ball_small"
SPHERES = Path(__file__).parent / "data" / "calibration_spheres"


@pytest.fixture(scope="module")
def cluster():
    with local_cluster(1, processes=False) as client:
        yield client


def _tree_digest(folder: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(folder.rglob("*")):
        digest.update(str(path.relative_to(folder)).encode())
        if path.is_file():
            digest.update(path.read_bytes())
    return digest.hexdigest()


@pytest.fixture
def rig(tmp_path):
    """The ball's images and mask alone in ``capture/`` (no lights), and its calibrated lights
    as ``irtps calibrate`` writes them into ``lights/``: ``ball.lp`` and
    ``light_intensities.txt``."""
    data = irtps.load_dataset(BALL)
    capture, lights = tmp_path / "capture", tmp_path / "lights"
    capture.mkdir()
    lights.mkdir()
    for name in (*data.names, "mask.png"):
        shutil.copy(BALL / name, capture / name)
    rows = [f"{name} {d[0]:.8f} {d[1]:.8f} {d[2]:.8f}" for name, d in zip(data.names, data.scene.light_directions)]
    (lights / "ball.lp").write_text(f"{len(rows)}\n" + "\n".join(rows) + "\n")
    shutil.copy(BALL / "light_intensities.txt", lights / "light_intensities.txt")
    return data, capture, lights / "ball.lp"


def _mean_error(result, data):
    return _normal_error(result.normals, data)


def _normal_error(normals, data):
    return irtps.angular_error_deg(normals, data.gt.normal, data.mask)[data.mask].mean()


def test_a_folder_of_images_takes_the_lights_of_a_file_kept_elsewhere(rig):
    data, capture, lp = rig
    given = irtps.load_dataset(capture, lights=lp)
    assert given.names == data.names and given.irradiance_known
    assert np.allclose(given.scene.light_directions, data.scene.light_directions, atol=1e-7)
    assert np.allclose(
        [light.irradiance for light in given.scene.lights], [light.irradiance for light in data.scene.lights]
    )
    assert np.array_equal(given.images, data.images) and np.array_equal(given.mask, data.mask)
    # The same photometric stereo as the DiLiGenT folder's own lights: the same normals, as true.
    calibrated, result = irtps.reconstruct(data), irtps.reconstruct(given)
    assert np.allclose(result.normals, calibrated.normals, atol=1e-5)
    assert _mean_error(result, data) < 3.0


def test_the_file_replaces_the_folders_own_lp_and_its_intensities(rig):
    data, capture, lp = rig
    wrong = [f"{name} 0 0 1" for name in data.names]  # every light at the camera: a useless fit
    (capture / "old.lp").write_text(f"{len(wrong)}\n" + "\n".join(wrong) + "\n")
    (capture / "light_intensities.txt").write_text("1 1 1\n" * len(wrong))
    given = irtps.load_dataset(capture, lights=lp)
    assert np.allclose(given.scene.light_directions, data.scene.light_directions, atol=1e-7)
    assert np.allclose(given.scene.lights[0].irradiance, data.scene.lights[0].irradiance)
    names = {path.name for path in dataset_inputs(capture, lights=lp)}
    assert {"ball.lp", "light_intensities.txt", "mask.png", "008.png"} <= names and "old.lp" not in names


def test_without_intensities_beside_it_the_strengths_are_estimated(rig):
    data, capture, lp = rig
    (lp.parent / "light_intensities.txt").unlink()
    given = irtps.load_dataset(capture, lights=lp)
    assert not given.irradiance_known
    with pytest.warns(irtps.IrtpsWarning, match="no light intensities given"):
        result = irtps.reconstruct(given)
    assert _mean_error(result, data) < _mean_error(irtps.reconstruct(data), data) + 1.0


def test_reconstruct_records_the_file_and_changes_nothing_the_user_owns(rig, tmp_path, capsys):
    data, capture, lp = rig
    before = (_tree_digest(capture), _tree_digest(lp.parent))
    out = tmp_path / "out"
    assert main(["reconstruct", str(capture), "--out", str(out), "--lights", str(lp), "--quiet"]) == 0
    assert (_tree_digest(capture), _tree_digest(lp.parent)) == before
    record = json.loads((out / "run.json").read_text())["lights"]
    digest = hashlib.sha256(lp.read_text().encode() + b"\0" + (lp.parent / "light_intensities.txt").read_bytes())
    assert record == {"file": str(lp.resolve()), "sha256": digest.hexdigest()}
    normals = load_reconstruction(out)[0]
    assert np.allclose(normals, irtps.reconstruct(data).normals, atol=1e-5)
    assert main(["report", str(out), "--out", str(tmp_path / "report"), "--quiet"]) == 0
    page = html.unescape((tmp_path / "report" / "index.html").read_text())
    assert f"is a folder of images given its lights by {str(lp.resolve())!r}" in page


@pytest.mark.parametrize(
    ("case", "message"),
    [
        (
            "diligent",
            "lights: {data} is a data set in the DiLiGenT layout, whose light_directions.txt gives its lights",
        ),
        ("missing", "{lp}: missing (lights: a light position file (*.lp))"),
        ("unlisted", "{data}/008.png: missing (listed on line 2 of {lp} of {data}: 'irtps calibrate --names-from'"),
        ("malformed", "{lp}: line 3: expected 'filename x y z'"),
    ],
)
def test_a_bad_lights_file_or_folder_is_one_named_error_and_nothing_is_written(rig, tmp_path, capsys, case, message):
    data, capture, lp = rig
    if case == "diligent":
        capture = shutil.copytree(BALL, tmp_path / "ballPNG")
    elif case == "missing":
        lp = lp.with_name("none.lp")
    elif case == "unlisted":
        (capture / "008.png").unlink()
    else:
        lines = lp.read_text().splitlines()
        lp.write_text("\n".join([*lines[:2], "009.png 0 0", *lines[3:]]) + "\n")
    out = tmp_path / "out"
    assert main(["reconstruct", str(capture), "--out", str(out), "--lights", str(lp)]) == 2
    err = capsys.readouterr().err
    assert message.format(data=capture, lp=lp) in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_files_by_name_go_to_their_data_sets_and_one_for_all_to_the_rest():
    assert files_by_name("lights", ["a.lp", "b=b.lp"], ["a", "b"]) == {"a": Path("a.lp"), "b": Path("b.lp")}
    with pytest.raises(irtps.ArgumentError, match="lights: 'c.lp' and 'a.lp' are both for every data set"):
        files_by_name("lights", ["a.lp", "c.lp"], ["a"])


def test_a_batch_gives_its_data_sets_the_file_and_resumes_only_while_it_reads_the_same(cluster, rig, tmp_path):
    data, capture, lp = rig
    second = shutil.copytree(capture, tmp_path / "capture_2")
    out = tmp_path / "out"
    argv = ["batch", str(capture), str(second), "--out", str(out), "--lights", str(lp)]
    argv += ["--scheduler", cluster.scheduler.address, "--quiet"]
    assert main(argv) == 0
    first = load_reconstruction(out / "capture_2")[0]
    assert np.allclose(first, irtps.reconstruct(data).normals, atol=1e-5)
    assert main([*argv, "--resume"]) == 0
    summary = json.loads((out / "batch.json").read_text())
    assert [row["status"] for row in summary["datasets"]] == ["reused", "reused"]
    intensities = lp.parent / "light_intensities.txt"
    intensities.write_text(intensities.read_text().replace("1.208", "1.3"))  # calibrated again since
    assert main([*argv, "--resume"]) == 0
    summary = json.loads((out / "batch.json").read_text())
    assert [row["status"] for row in summary["datasets"]] == ["ok", "ok"]


def test_a_batch_refuses_an_unreadable_file_before_anything_is_written(cluster, rig, tmp_path, capsys):
    _, capture, lp = rig
    out = tmp_path / "out"
    argv = ["batch", str(capture), "--out", str(out), "--scheduler", cluster.scheduler.address]
    assert main([*argv, "--lights", f"capture={lp.with_name('none.lp')}"]) == 2
    assert f"{lp.with_name('none.lp')}: missing (lights" in capsys.readouterr().err
    assert not out.exists()


def test_reconstruct_many_refuses_lights_it_cannot_place_before_anything_runs(rig, tmp_path):
    _, capture, lp = rig
    out = tmp_path / "out"
    with pytest.raises(irtps.ArgumentError, match="lights: 'other' is none of the data sets"):
        reconstruct_many([capture], out, lights={"other": lp})
    with pytest.raises(irtps.ArgumentError, match="lights: expected a .lp path or a mapping"):
        reconstruct_many([capture], out, lights=3)
    with pytest.raises(irtps.ArgumentError, match=r"lights\['capture'\]: expected a path"):
        reconstruct_many([capture], out, lights={"capture": 3})
    assert not out.exists()


def test_a_rig_calibrated_once_reconstructs_a_capture_taken_under_its_lights(tmp_path, capsys):
    """The README's steps: ``irtps calibrate SPHERES --names-from OBJECT``, then ``irtps
    reconstruct OBJECT --lights``; the object rendered here under the spheres' true lights."""
    truth = json.loads((SPHERES / "truth.json").read_text())["lights"]
    data, _ = synthesize("cap", size=32, lights=3, bounces=0, environment="none")
    lights = tuple(Light(direction=np.array(t["direction"]), irradiance=np.array(t["irradiance"])) for t in truth)
    scene = dataclasses.replace(data.scene, lights=lights)
    images = render(scene, data.gt.height, data.gt.albedo, data.mask, bounces=0, samples=16).images
    capture = tmp_path / "object"
    capture.mkdir()
    for k, image in enumerate(images):
        write_png(capture / f"IMG_{k + 1:04d}.png", image / images.max(), bit_depth=16)
    write_png(capture / "mask.png", data.mask.astype(np.float32))
    assert main(["calibrate", str(SPHERES), "--out", str(tmp_path / "rig"), "--names-from", str(capture)]) == 0
    lp = tmp_path / "rig" / "lights.lp"
    assert f"next: irtps reconstruct {capture} --lights {lp} --out RESULT" in capsys.readouterr().out
    assert main(["reconstruct", str(capture), "--lights", str(lp), "--out", str(tmp_path / "result"), "--quiet"]) == 0
    calibrated = load_reconstruction(tmp_path / "result")[0]
    exact = irtps.photometric_stereo(images, scene.light_directions, [light.irradiance for light in lights]).normals
    errors = [irtps.angular_error_deg(n, data.gt.normal, data.mask)[data.mask].mean() for n in (exact, calibrated)]
    assert errors[0] < 1.0 and errors[1] < errors[0] + 0.5, errors  # the calibration's error, no more


def _grooves_under_the_spheres_lights(folder: Path):
    """Grooves alone in the dark, their inter-reflections rendered under the calibration
    spheres' true lights, written as 16-bit linear PNG at the spheres' exposure (the rig's
    camera settings), with its mask: what ``--matte-albedo`` is for."""
    truth = json.loads((SPHERES / "truth.json").read_text())["lights"]
    data, _ = synthesize("grooves", size=48, lights=3, bounces=0, environment="none")
    lights = tuple(Light(direction=np.array(t["direction"]), irradiance=np.array(t["irradiance"])) for t in truth)
    scene = dataclasses.replace(data.scene, lights=lights)
    images = render(scene, data.gt.height, data.gt.albedo, data.mask, bounces=4, samples=64).images
    folder.mkdir()
    for k, image in enumerate(images):
        write_png(folder / f"IMG_{k + 1:04d}.png", image, bit_depth=16)
    write_png(folder / "mask.png", data.mask.astype(np.float32))
    return data, scene


def test_strengths_calibrated_with_the_spheres_albedo_are_absolute_and_irtps_takes_them(tmp_path):
    """Alone in the dark, grooves' inter-reflections are all the light there is, so IRT-PS
    cannot find the scale of relative strengths and stays at classic photometric stereo;
    ``irtps calibrate --matte-albedo`` makes them absolute, and IRT-PS removes the
    inter-reflections nearly as with the true lights."""
    capture = tmp_path / "object"
    data, scene = _grooves_under_the_spheres_lights(capture)
    errors = {}
    for kind, extra in (("absolute", ["--matte-albedo", "0.8"]), ("relative", [])):
        rig = tmp_path / kind
        assert (
            main(["calibrate", str(SPHERES), "--out", str(rig), "--names-from", str(capture), "--quiet", *extra]) == 0
        )
        out = tmp_path / f"result_{kind}"
        assert (
            main(
                [
                    "reconstruct",
                    str(capture),
                    "--lights",
                    str(rig / "lights.lp"),
                    "--method",
                    "irtps",
                    "--out",
                    str(out),
                    "--quiet",
                ]
            )
            == 0
        )
        errors[kind] = _normal_error(load_reconstruction(out)[0], data)
        assert json.loads((out / "run.json").read_text())["albedo_scale"]["source"] == (
            "absolute" if kind == "absolute" else "images"
        )
    dataset = dataclasses.replace(irtps.load_dataset(capture, lights=tmp_path / "absolute" / "lights.lp"), scene=scene)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irtps.IrtpsWarning)
        errors["true lights"] = _normal_error(irtps.reconstruct(dataset, "irtps").normals, data)
        errors["classic"] = _normal_error(irtps.reconstruct(dataset).normals, data)
    assert errors["relative"] > errors["classic"] - 0.1, errors  # IRT-PS fell back to classic PS
    assert errors["absolute"] < errors["classic"] / 2 and errors["absolute"] < errors["true lights"] + 1.0, errors


def test_the_calibration_says_whether_its_strengths_are_absolute_and_the_reader_follows_it(tmp_path, capsys):
    for kind, extra in (("absolute", ["--matte-albedo", "0.8"]), ("relative", [])):
        assert main(["calibrate", str(SPHERES), "--out", str(tmp_path / kind), *extra]) == 0
        printed = capsys.readouterr().out
        assert ("absolute irradiances (its albedo 0.8)" in printed) == (kind == "absolute"), printed
        record = json.loads((tmp_path / kind / "calibration.json").read_text())
        assert record["irradiance"] == kind and record["matte_albedo"] == (0.8 if kind == "absolute" else None)
        lights_json = json.loads((tmp_path / kind / "lights.json").read_text())
        assert lights_json.get("irradiance", "absolute") == kind
        scene = irtps.load_dataset(SPHERES, lights=tmp_path / kind / "lights.lp").scene
        assert scene.relative_irradiance == (kind == "relative")
    absolute, relative = (tmp_path / kind / "light_intensities.txt" for kind in ("absolute", "relative"))
    assert np.allclose(np.loadtxt(absolute), 1.25 * np.loadtxt(relative), rtol=1e-5)  # 1 / 0.8
    # the same intensities, said absolute or not, are another calibration for a resumed batch
    shutil.copy(absolute, relative)
    records = [light_file_record(tmp_path / kind / "lights.lp") for kind in ("absolute", "relative")]
    assert records[0]["sha256"] != records[1]["sha256"]
    # copied without the record, or beside another tool's calibration.json, the strengths are relative
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("lights.lp", "light_intensities.txt"):
        shutil.copy(tmp_path / "absolute" / name, copy / name)
    assert irtps.load_dataset(SPHERES, lights=copy / "lights.lp").scene.relative_irradiance
    (copy / "calibration.json").write_text('{"irradiance": "absolute"}')
    assert irtps.load_dataset(SPHERES, lights=copy / "lights.lp").scene.relative_irradiance


@pytest.mark.parametrize(
    ("record", "message"),
    [
        ('{"format": "irtps.calibration/1", "irradiance": "bright"}', "irradiance is 'bright': expected one of"),
        ('{"format": "irtps.calibration/1", "irradiance": ', "line 1"),
    ],
)
def test_a_calibration_record_that_cannot_say_is_one_named_error_and_nothing_is_written(
    tmp_path, capsys, record, message
):
    assert main(["calibrate", str(SPHERES), "--out", str(tmp_path / "rig"), "--matte-albedo", "0.8", "--quiet"]) == 0
    (tmp_path / "rig" / "calibration.json").write_text(record)
    out = tmp_path / "result"
    assert main(["reconstruct", str(SPHERES), "--lights", str(tmp_path / "rig" / "lights.lp"), "--out", str(out)]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and str(tmp_path / "rig" / "calibration.json") in error[0] and message in error[0], error
    assert not out.exists()
