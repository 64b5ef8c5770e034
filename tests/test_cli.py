"""The irtps command line, run as a user would."""

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from irtps import load_dataset
from irtps.cli.main import main

SMALL = Path(__file__).parent / "data" / "mitsuba_small" / "cap_cornell"


def test_render_writes_a_complete_data_set(tmp_path):
    out = tmp_path / "render"
    assert main(["render", str(SMALL), "--out", str(out), "--bounces", "2", "--samples", "8", "--quiet"]) == 0
    for name in ["scene.json", "mask.png", "gt/height.exr", "gt/normal.exr", "gt/albedo.exr"]:
        assert (out / name).is_file(), name
    for sub in ["images", "gt/direct", "gt/bounce1", "gt/bounce2"]:
        assert sorted(p.name for p in (out / sub).iterdir()) == ["000.exr", "001.exr", "002.exr"], sub
    data = load_dataset(out)
    source = load_dataset(SMALL)
    np.testing.assert_array_equal(data.mask, source.mask)
    np.testing.assert_array_equal(data.gt.height[data.mask], source.gt.height[data.mask])
    assert data.images.sum() > data.gt.direct.sum()  # images hold the bounces too
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


@pytest.mark.parametrize("shape", ["cap", "cavity", "grooves", "relief"])
def test_synth_shapes_write_loadable_data_sets(tmp_path, shape):
    out = tmp_path / shape
    code = main(
        [
            "synth",
            shape,
            "--out",
            str(out),
            "--size",
            "24",
            "--lights",
            "4",
            "--bounces",
            "1",
            "--samples",
            "4",
            "--albedo",
            "textured",
            "--quiet",
        ]
    )
    assert code == 0
    data = load_dataset(out)
    assert data.images.shape == (4, 24, 24, 3)
    assert data.mask.any() and (data.gt.height[data.mask] > 0).all()
    normals = data.gt.normal[data.mask]
    np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-5)


def test_failed_render_names_the_file_and_writes_nothing(tmp_path, capsys):
    broken = tmp_path / "broken"
    shutil.copytree(SMALL, broken)
    (broken / "gt" / "albedo.exr").unlink()
    out = tmp_path / "out"
    assert main(["render", str(broken), "--out", str(out), "--quiet"]) == 2
    assert "albedo.exr" in capsys.readouterr().err
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["broken"]


def test_existing_output_survives_a_failed_run(tmp_path):
    out = tmp_path / "out"
    assert main(["synth", "cap", "--out", str(out), "--size", "16", "--lights", "3", "--bounces", "0", "--quiet"]) == 0
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    assert main(["render", str(tmp_path / "missing"), "--out", str(out), "--quiet"]) == 2
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before


def test_every_command_has_help_with_examples():
    for command in ([], ["render"], ["synth"], ["reconstruct"], ["evaluate"], ["table"], ["demo"], ["batch"]):
        result = subprocess.run([sys.executable, "-m", "irtps.cli", *command, "--help"], capture_output=True, text=True)
        assert result.returncode == 0
        assert "examples:" in result.stdout


BALL = Path(__file__).parent / "data" / "diligent_ball_small"


def test_reconstruct_and_evaluate_a_diligent_capture(tmp_path, capsys):
    out = tmp_path / "ball"
    assert main(["reconstruct", str(BALL), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "reconstructed" in printed and "normal angle" in printed
    assert "robust mode tukey, chosen by auto: 2 % of the object's pixels take a specular lobe" in printed
    for name in ["normal.exr", "albedo.exr", "height.exr", "mask.png", "mesh.ply", "mesh.obj", "run.json"]:
        assert (out / name).is_file(), name
    run = json.loads((out / "run.json").read_text())
    assert (
        run["parameters"]["method"] == "ps" and run["parameters"]["robust"] == "auto" and run["robust_used"] == "tukey"
    )
    assert set(run["timings_s"]) >= {"load", "photometric_stereo", "integration"}
    assert main(["evaluate", str(out), "--gt", str(BALL), "--json"]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert 0 < metrics["normal_mean_angular_deg"] < 3.5
    assert metrics["albedo_error"] is None  # DiLiGenT has no albedo ground truth


def test_reconstruct_places_a_synthetic_object_on_its_floor(tmp_path, capsys):
    data = tmp_path / "cap"
    assert (
        main(
            [
                "synth",
                "cap",
                "--out",
                str(data),
                "--size",
                "32",
                "--lights",
                "8",
                "--bounces",
                "0",
                "--environment",
                "none",
                "--quiet",
            ]
        )
        == 0
    )
    out = tmp_path / "cap_ps"
    assert main(["reconstruct", str(data), "--out", str(out), "--integration", "mestimator", "--quiet"]) == 0
    assert main(["evaluate", str(out), "--gt", str(data), "--json"]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["normal_mean_angular_deg"] < 2.0
    assert metrics["height_error"] < 0.1 * 0.22 * 32  # 10% of the cap's height, as reconstructed
    assert metrics["albedo_error"] < 0.15  # rim pixels are only partly covered by the object


def test_evaluate_rejects_a_folder_that_is_not_a_reconstruction(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path), "--gt", str(BALL)]) == 2
    assert "normal.exr" in capsys.readouterr().err


def test_evaluate_reads_only_the_ground_truth(tmp_path, capsys):
    data = tmp_path / "cap"
    assert (
        main(
            [
                "synth",
                "cap",
                "--out",
                str(data),
                "--size",
                "24",
                "--lights",
                "6",
                "--bounces",
                "0",
                "--environment",
                "none",
                "--quiet",
            ]
        )
        == 0
    )
    out = tmp_path / "cap_ps"
    assert main(["reconstruct", str(data), "--out", str(out), "--quiet"]) == 0
    shutil.rmtree(data / "images")  # evaluation must not need the images
    shutil.rmtree(data / "gt" / "direct")
    assert main(["evaluate", str(out), "--gt", str(data), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["normal_mean_angular_deg"] < 2.0


def test_evaluate_rejects_ground_truth_of_another_size(tmp_path, capsys):
    small, large = tmp_path / "small", tmp_path / "large"
    for folder, size in ((small, "16"), (large, "20")):
        assert (
            main(
                [
                    "synth",
                    "cap",
                    "--out",
                    str(folder),
                    "--size",
                    size,
                    "--lights",
                    "4",
                    "--bounces",
                    "0",
                    "--environment",
                    "none",
                    "--quiet",
                ]
            )
            == 0
        )
    out = tmp_path / "small_ps"
    assert main(["reconstruct", str(small), "--out", str(out), "--quiet"]) == 0
    assert main(["evaluate", str(out), "--gt", str(large)]) == 2
    assert "scene.json" in capsys.readouterr().err


def test_output_closed_by_its_reader_ends_the_command_quietly_keeping_what_was_written(tmp_path):
    """``irtps calibrate ... | head -1``: the reader goes before irtps prints; irtps exits as a
    command that SIGPIPE ends (141), says nothing, and its complete output stays."""
    spheres = Path(__file__).parent / "data" / "calibration_spheres"
    out = tmp_path / "rig"
    read_end, write_end = os.pipe()
    os.close(read_end)
    process = subprocess.run(
        [sys.executable, "-m", "irtps.cli", "calibrate", str(spheres), "--out", str(out)],
        stdout=write_end,
        stderr=subprocess.PIPE,
        text=True,
        check=False,
    )
    os.close(write_end)
    assert process.returncode == 128 + signal.SIGPIPE and process.stderr == "", process.stderr
    assert (out / "lights.lp").is_file() and (out / "calibration.json").is_file()
