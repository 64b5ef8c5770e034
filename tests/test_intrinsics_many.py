"""``--intrinsics`` for the commands of many data sets (``irtps batch``, ``irtps table``) and
its record in ``run.json``, which a resumed batch compares."""

import json
import shutil
from pathlib import Path

import pytest

import irtps
from irtps.batch.cluster import local_cluster
from irtps.cli.main import main
from irtps._shared.by_name import files_by_name

DATA = Path(__file__).parent / "data"
#: Pinholes about 18 degrees across the small cap's 96 pixels (tests/data/mitsuba_small).
K_FIXTURE = "300 0 48\n0 300 48\n0 0 1\n"
K_OTHER = "320 0 48\n0 320 48\n0 0 1\n"


@pytest.fixture(scope="module")
def cluster():
    with local_cluster(1, processes=False) as client:
        yield client


@pytest.fixture
def two_sets(tmp_path):
    """Two copies of the small orthographic cap (96 x 96 pixels) and two intrinsics files."""
    sets = [shutil.copytree(DATA / "mitsuba_small" / "cap_cornell", tmp_path / "in" / name) for name in ("a", "b")]
    (tmp_path / "K.txt").write_text(K_FIXTURE)
    (tmp_path / "K_b.txt").write_text(K_OTHER)
    return sets


def test_files_by_name_go_to_their_data_sets_and_one_for_all_to_the_rest():
    assert files_by_name("intrinsics", ["K.txt", "b=other.txt"], ["a", "b"]) == {
        "a": Path("K.txt"),
        "b": Path("other.txt"),
    }
    assert files_by_name("intrinsics", ["b=other.txt"], ["a", "b"]) == {"a": None, "b": Path("other.txt")}
    with pytest.raises(irtps.ArgumentError, match="intrinsics: 'L.txt' and 'K.txt' are both for every data set"):
        files_by_name("intrinsics", ["K.txt", "L.txt"], ["a"])
    with pytest.raises(irtps.ArgumentError, match="intrinsics: a is given two files, 'K.txt' and 'a=L.txt'"):
        files_by_name("intrinsics", ["a=K.txt", "a=L.txt"], ["a", "b"])


def test_reconstruct_records_its_intrinsics_and_camera(two_sets, tmp_path):
    out = tmp_path / "out"
    assert (
        main(["reconstruct", str(two_sets[0]), "--out", str(out), "--intrinsics", str(tmp_path / "K.txt"), "--quiet"])
        == 0
    )
    run = json.loads((out / "run.json").read_text())
    assert run["intrinsics"] == str(tmp_path / "K.txt")
    assert run["camera"]["projection"] == "perspective" and run["camera"]["fx"] == 300.0
    assert main(["reconstruct", str(two_sets[0]), "--out", str(tmp_path / "plain"), "--quiet"]) == 0
    plain = json.loads((tmp_path / "plain" / "run.json").read_text())
    assert plain["intrinsics"] is None and plain["camera"]["projection"] == "orthographic"


def test_a_batch_gives_each_data_set_its_camera_and_resumes_only_while_it_is_the_same(cluster, two_sets, tmp_path):
    out = tmp_path / "out"
    argv = ["batch", *map(str, two_sets), "--out", str(out), "--scheduler", cluster.scheduler.address, "--quiet"]
    argv += ["--intrinsics", str(tmp_path / "K.txt"), "--intrinsics", f"b={tmp_path / 'K_b.txt'}"]
    assert main(argv) == 0
    runs = {name: json.loads((out / name / "run.json").read_text()) for name in ("a", "b")}
    assert (runs["a"]["camera"]["fx"], runs["b"]["camera"]["fx"]) == (300.0, 320.0)
    assert runs["b"]["intrinsics"] == str(tmp_path / "K_b.txt")
    assert main([*argv, "--resume"]) == 0
    summary = json.loads((out / "batch.json").read_text())
    assert [row["status"] for row in summary["datasets"]] == ["reused", "reused"]
    (tmp_path / "K_b.txt").write_text("310 0 48\n0 310 48\n0 0 1\n")  # b's camera changed since
    assert main([*argv, "--resume"]) == 0
    summary = json.loads((out / "batch.json").read_text())
    assert [row["status"] for row in summary["datasets"]] == ["reused", "ok"]
    assert json.loads((out / "b" / "run.json").read_text())["camera"]["fx"] == 310.0


def test_a_bad_intrinsics_file_stops_a_batch_before_anything_is_written(cluster, two_sets, tmp_path, capsys):
    (tmp_path / "bad.txt").write_text("300 0 48\n0 300 48\n")
    out = tmp_path / "out"
    argv = ["batch", *map(str, two_sets), "--out", str(out), "--scheduler", cluster.scheduler.address]
    assert main([*argv, "--intrinsics", f"a={tmp_path / 'bad.txt'}"]) == 2
    assert f"{tmp_path / 'bad.txt'}: expected a 3x3 intrinsic matrix" in capsys.readouterr().err
    assert not out.exists()
    assert main([*argv, "--intrinsics", f"c={tmp_path / 'K.txt'}"]) == 2  # c is no data set: a file path
    assert "c=" in capsys.readouterr().err and not out.exists()


def test_a_table_sees_its_data_sets_through_their_intrinsics(two_sets, tmp_path, capsys):
    argv = ["table", str(two_sets[0]), "--bounces", "1", "--iterations", "1", "--samples", "4", "--quiet"]
    assert main(argv) == 0
    orthographic = capsys.readouterr().out
    assert main([*argv, "--intrinsics", f"a={tmp_path / 'K.txt'}"]) == 0
    pinhole = capsys.readouterr().out
    # The same classic fit (normals do not depend on the camera), other heights and IRT-PS.
    row = [line for line in orthographic.splitlines() if line.startswith("| Angular")][0]
    assert row.split("|")[2] == [line for line in pinhole.splitlines() if line.startswith("| Angular")][0].split("|")[2]
    assert pinhole.startswith("| **a** |") and pinhole != orthographic
