"""Batch runs on an in-process Dask cluster: outputs, failures, the summary and the command."""

import functools
import gc
import json
import logging
import shutil
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest

import irtps.batch.run
import irtps.batch.task
from irtps import evaluate, load_dataset, reconstruct
from irtps.batch.cluster import local_cluster
from irtps.batch.run import reconstruct_many
from irtps.cli.main import main
from irtps.irt.folder import load_reconstruction

from cli_helpers import saturate

DATA = Path(__file__).parent / "data"
IRTPS_OPTIONS = {"method": "irtps", "bounces": 2, "iterations": 2, "samples": 8, "seed": 3}


@pytest.fixture(scope="module")
def cluster():
    with local_cluster(2, processes=False) as client:
        yield client


@pytest.fixture
def three_sets(tmp_path):
    """Two good data sets (irtps and DiLiGenT layouts) and one with a corrupt image."""
    cap = shutil.copytree(DATA / "mitsuba_small" / "cap_cornell", tmp_path / "in" / "cap")
    ball = shutil.copytree(DATA / "diligent_ball_small", tmp_path / "in" / "ball")
    broken = shutil.copytree(DATA / "mitsuba_small" / "cap_cornell", tmp_path / "in" / "broken")
    (broken / "images" / "001.exr").write_bytes(b"not an EXR file")
    return cap, ball, broken


def test_outputs_match_a_direct_reconstruction_and_a_failure_stops_nothing(cluster, three_sets, tmp_path):
    cap, ball, broken = three_sets
    out = tmp_path / "out"
    results = reconstruct_many([cap, broken, ball], out, client=cluster, **IRTPS_OPTIONS)
    assert [(r.name, r.status) for r in results] == [("cap", "ok"), ("broken", "failed"), ("ball", "ok")]
    assert results[1].error.startswith(f"{broken / 'images' / '001.exr'}: not a readable OpenEXR file")
    assert results[1].seconds is not None and results[1].metrics is None  # reported by the worker itself
    assert sorted(p.name for p in out.iterdir()) == ["ball", "cap"]  # nothing, not even a temporary, for the failure
    for folder, result in ((cap, results[0]), (ball, results[2])):
        dataset = load_dataset(folder)
        direct = reconstruct(dataset, **IRTPS_OPTIONS)
        normals, albedo, height, mask = load_reconstruction(out / result.name)
        np.testing.assert_array_equal(mask, direct.mask)
        np.testing.assert_array_equal(normals, direct.normals)
        np.testing.assert_array_equal(albedo, direct.albedo)
        np.testing.assert_array_equal(height, direct.height)
        expected = evaluate(
            mask=direct.mask, normals=direct.normals, albedo=direct.albedo, height=direct.height, gt=dataset.gt
        )
        assert result.mean_angular_error == pytest.approx(expected.normal_mean_angular_deg)
        assert result.source == str(folder) and result.seconds > 0
        assert result.robust_used == direct.robust_used == "tukey"  # auto's choice, recorded


def test_a_task_that_dies_is_reported_and_the_others_finish(cluster, three_sets, tmp_path, monkeypatch):
    cap, ball, _ = three_sets
    real_task = irtps.batch.run.reconstruct_to_folder

    def task_losing_the_ball(source, destination, options, **settings):
        if Path(source).name == "ball":
            raise RuntimeError("worker lost")
        return real_task(source, destination, options, **settings)

    monkeypatch.setattr(irtps.batch.run, "reconstruct_to_folder", task_losing_the_ball)
    results = reconstruct_many([ball, cap], tmp_path / "out", client=cluster)
    assert [(r.status, r.error, r.seconds) for r in results][0] == ("failed", "RuntimeError: worker lost", None)
    assert results[1].status == "ok" and (tmp_path / "out" / "cap" / "normal.exr").is_file()


def test_a_batch_on_its_client_ends_while_another_client_is_the_default(cluster, three_sets, tmp_path):
    import distributed

    # A client that could not connect stays the process's default client (the newest not
    # closed) until it is garbage (here: while the error's traceback holds it), with a
    # loop of its own that never wakes for the batch's futures. A batch that tracked its
    # futures on the default client's loop waited there forever, its workers idle.
    with pytest.raises(ValueError, match="unknown address scheme") as failed:
        distributed.Client("nonsense://head-node")
    assert distributed.default_client() is not cluster
    cap, ball, _ = three_sets
    results = reconstruct_many([cap, ball], tmp_path / "out", client=cluster)
    assert [r.status for r in results] == ["ok", "ok"]
    # The failed client closed now, not by a collection inside a later client's start
    # (whose lock its closing would wait on).
    del failed
    gc.collect()


def test_bad_arguments_are_argument_errors_naming_them(tmp_path):
    with pytest.raises(irtps.ArgumentError, match="^datasets: none given$") as caught:
        reconstruct_many([], tmp_path / "out")
    assert caught.value.argument == "datasets" and isinstance(caught.value, ValueError)
    for arguments, name in [({"workers": 0}, "workers"), ({"threads_per_worker": 0}, "threads_per_worker")]:
        with pytest.raises(irtps.ArgumentError, match=f"^{name}: must be at least 1, not 0$") as caught:
            with local_cluster(**arguments):
                pass
        assert caught.value.argument == name
    assert not (tmp_path / "out").exists()


def test_unknown_options_fail_before_anything_runs(cluster, three_sets, tmp_path):
    with pytest.raises(irtps.ArgumentError, match="bounce"):
        reconstruct_many(three_sets, tmp_path / "out", client=cluster, bounce=2)
    with pytest.raises(irtps.ArgumentError, match="method"):
        reconstruct_many(three_sets, tmp_path / "out", client=cluster, method="mitsuba")
    assert not (tmp_path / "out").exists()


def test_command_runs_on_a_scheduler_and_writes_the_summary(cluster, three_sets, tmp_path, capsys):
    cap, ball, broken = three_sets
    twin = shutil.copytree(cap, tmp_path / "elsewhere" / "cap")  # same base name as `cap`
    out = tmp_path / "out"
    argv = [
        "batch",
        str(cap),
        str(twin),
        str(ball),
        str(broken),
        "--out",
        str(out),
        "--scheduler",
        cluster.scheduler.address,
    ]
    argv += ["--method", "irtps", "--iterations", "1", "--samples", "16", "--quiet"]
    assert main(argv) == 2
    printed = capsys.readouterr()
    # No progress bar; the glossy ball's warning that IRT-PS kept classic PS, then the failure.
    warning, error = printed.err.splitlines()
    assert warning.startswith("irtps: warning: ball: IRT-PS: ")
    assert warning.endswith("the result is classic photometric stereo's")
    assert error == f"irtps: error: 1 of 4 data sets failed (see {out / 'batch.md'})"
    summary = json.loads((out / "batch.json").read_text())
    assert [(s["name"], s["status"]) for s in summary["datasets"]] == [
        ("cap", "ok"),
        ("cap-2", "ok"),
        ("ball", "ok"),
        ("broken", "failed"),
    ]
    assert (summary["succeeded"], summary["failed"], summary["settings"]["samples"]) == (3, 1, 16)
    assert printed.out == (out / "batch.md").read_text()
    assert "| broken | failed |" in printed.out and "001.exr" in printed.out
    run = json.loads((out / "cap-2" / "run.json").read_text())
    assert run["source"] == str(twin) and run["parameters"]["samples"] == 16 and run["parameters"]["method"] == "irtps"


def test_command_succeeds_when_every_data_set_does(cluster, three_sets, tmp_path, capsys):
    cap, ball, _ = three_sets
    out = tmp_path / "out"
    assert main(["batch", str(cap), str(ball), "--out", str(out), "--scheduler", cluster.scheduler.address]) == 0
    printed = capsys.readouterr().out
    assert "| cap | ok |" in printed and "| ball | ok |" in printed and "| tukey |" in printed
    assert "2 data sets reconstructed" in printed


def test_resume_keeps_complete_outputs_untouched_and_redoes_the_others(cluster, three_sets, tmp_path, capsys):
    cap, ball, _ = three_sets
    out = tmp_path / "out"
    argv = ["batch", str(cap), str(ball), "--out", str(out), "--scheduler", cluster.scheduler.address]
    assert main([*argv, "--quiet"]) == 0
    first = json.loads((out / "batch.json").read_text())
    (out / "ball" / "mesh.obj").unlink()  # an output folder that lost a file
    for name in ("batch.json", "batch.md"):  # as if the batch had been stopped before its summary
        (out / name).unlink()
    kept = sorted(out.glob("cap/**/*")) + [out / "cap"]
    before = {
        path: (path.stat().st_ino, path.stat().st_mtime_ns, path.is_file() and path.read_bytes()) for path in kept
    }
    capsys.readouterr()
    assert main([*argv, "--resume"]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "batch.json").read_text())
    assert [(s["name"], s["status"]) for s in summary["datasets"]] == [("cap", "reused"), ("ball", "ok")]
    assert (summary["succeeded"], summary["reused"], summary["failed"]) == (2, 1, 0)
    assert summary["datasets"][0]["metrics"] == first["datasets"][0]["metrics"]  # evaluated again from the kept files
    assert (
        summary["datasets"][0]["robust_used"] == first["datasets"][0]["robust_used"] == "tukey"
    )  # read back from run.json
    assert {
        path: (path.stat().st_ino, path.stat().st_mtime_ns, path.is_file() and path.read_bytes()) for path in kept
    } == before
    assert (out / "ball" / "mesh.obj").stat().st_size > 0
    assert (
        "| cap | reused |" in printed
        and "1 data sets reconstructed into" in printed
        and "(1 complete from an earlier run, kept)" in printed
    )
    # Other options: no output is theirs, both are redone.
    assert main([*argv, "--resume", "--shadow-fraction", "0.1", "--quiet"]) == 0
    assert [s["status"] for s in json.loads((out / "batch.json").read_text())["datasets"]] == ["ok", "ok"]
    assert json.loads((out / "cap" / "run.json").read_text())["parameters"]["shadow_fraction"] == 0.1


@pytest.mark.parametrize(
    "damage",
    [
        lambda text: '{"format": "irtps.run/1", "x": '
        + "[" * 50_000
        + "]" * 50_000
        + "}",  # deeper than Python's recursion limit
        lambda text: text.replace(
            '"pixel_size": ', '"pixel_size": ' + "9" * 5000 + ', "was": '
        ),  # past int()'s digit limit
    ],
    ids=["nested", "huge integer"],
)
def test_resume_redoes_an_output_whose_run_json_is_past_the_parser_bounds(cluster, three_sets, tmp_path, damage):
    cap, _, _ = three_sets
    out = tmp_path / "out"
    argv = ["batch", str(cap), "--out", str(out), "--scheduler", cluster.scheduler.address, "--quiet"]
    assert main(argv) == 0
    run = out / "cap" / "run.json"
    run.write_text(damage(run.read_text()))
    assert main([*argv, "--resume"]) == 0
    assert [s["status"] for s in json.loads((out / "batch.json").read_text())["datasets"]] == ["ok"]
    assert json.loads(run.read_text())["format"] == "irtps.run/1"


def test_local_cluster_options_are_refused_with_a_scheduler(three_sets, tmp_path, capsys):
    argv = [
        "batch",
        str(three_sets[0]),
        "--out",
        str(tmp_path / "out"),
        "--scheduler",
        "tcp://head-node:8786",
        "--workers",
        "2",
    ]
    assert main(argv) == 2
    assert "--workers" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_bad_scheduler_address_is_named(three_sets, tmp_path, capsys):
    assert (
        main(["batch", str(three_sets[0]), "--out", str(tmp_path / "out"), "--scheduler", "nonsense://head-node"]) == 2
    )
    assert "nonsense://head-node: cannot reach a Dask scheduler" in capsys.readouterr().err


def test_without_dask_the_command_says_how_to_install_it(three_sets, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed now raises ImportError
    assert main(["batch", str(three_sets[0]), "--out", str(tmp_path / "out")]) == 2
    assert "pip install 'irtps[batch]'" in capsys.readouterr().err


def test_warnings_of_a_task_are_printed_with_the_data_set_name_and_recorded(cluster, three_sets, tmp_path, capsys):
    cap, ball, _ = three_sets
    saturate(ball)
    out = tmp_path / "out"
    saturated = f"{ball}: 216 observations in 6 images are saturated (a channel at or above 1); left out of the fit"
    for run in (1, 2):  # the same warning again in the same worker thread: printed again
        assert (
            main(["batch", str(ball), str(cap), "--out", str(out), "--scheduler", cluster.scheduler.address, "--quiet"])
            == 0
        )
        assert capsys.readouterr().err == f"irtps: warning: ball: {saturated}\n", run
    summary = json.loads((out / "batch.json").read_text())
    assert [(s["name"], s["warnings"]) for s in summary["datasets"]] == [("ball", [saturated]), ("cap", [])]


def test_warnings_are_kept_once_and_other_categories_keep_theirs(cluster, three_sets, tmp_path, monkeypatch):
    cap, ball, _ = three_sets
    real = irtps.batch.task.load_and_reconstruct

    def warning_twice(source, **options):
        for _ in range(2):
            warnings.warn(f"{source}: odd", irtps.IrtpsWarning)
            warnings.warn("invalid value encountered in divide", RuntimeWarning)
            warnings.warn("old option", np.exceptions.VisibleDeprecationWarning)
        return real(source, **options)

    monkeypatch.setattr(irtps.batch.task, "load_and_reconstruct", warning_twice)
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        results = reconstruct_many([cap, ball], tmp_path / "out", client=cluster)
    assert [r.status for r in results] == ["ok", "ok"]
    assert results[0].warnings == (
        f"{cap}: odd",
        "RuntimeWarning: invalid value encountered in divide",
        "numpy.exceptions.VisibleDeprecationWarning: old option",
    )
    reissued = sorted((w.category.__name__, str(w.message)) for w in shown)
    expected = [
        [
            ("IrtpsWarning", f"{name}: {folder}: odd"),
            ("RuntimeWarning", f"{name}: invalid value encountered in divide"),
            ("VisibleDeprecationWarning", f"{name}: old option"),
        ]
        for name, folder in (("cap", cap), ("ball", ball))
    ]
    assert reissued == sorted(expected[0] + expected[1])


def test_a_task_records_its_warnings_alone_while_others_run_in_other_threads(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    from irtps.batch.task_warnings import recorded_warnings

    barrier = threading.Barrier(4)

    def task(index):
        with recorded_warnings() as recorded:
            barrier.wait()
            warnings.warn(f"task {index}", irtps.IrtpsWarning)
            barrier.wait()
        return recorded

    before = (warnings.filters[:], warnings.showwarning)
    with ThreadPoolExecutor(4) as pool:
        records = list(pool.map(task, range(4)))
    assert records == [[(irtps.IrtpsWarning, f"task {index}")] for index in range(4)]
    assert (warnings.filters, warnings.showwarning) == before


def test_recording_leaves_other_threads_warnings_and_their_catch_warnings_alone():
    from concurrent.futures import ThreadPoolExecutor

    from irtps.batch.task_warnings import recorded_warnings

    recording, warned, ended = threading.Event(), threading.Event(), threading.Event()

    def task():
        with recorded_warnings() as recorded:
            recording.set()
            warned.wait()
            warnings.warn("in the task", irtps.IrtpsWarning)
        ended.set()
        return recorded

    before = (warnings.filters[:], warnings.showwarning, warnings._showwarnmsg)
    with ThreadPoolExecutor(1) as pool:
        future = pool.submit(task)
        recording.wait()
        # A catch_warnings of this thread that spans the task's end, and this thread's
        # warnings filtered as before: the same warning from the same line shown once.
        with warnings.catch_warnings(record=True) as shown:
            for _ in range(2):
                warnings.warn("in the main thread", UserWarning)
            warned.set()
            ended.wait()
        recorded = future.result()
    assert recorded == [(irtps.IrtpsWarning, "in the task")]
    assert [str(w.message) for w in shown] == ["in the main thread"]
    assert (warnings.filters, warnings.showwarning, warnings._showwarnmsg) == before


def test_a_stopping_worker_finishes_the_write_under_way_then_exits_and_starts_no_other(monkeypatch, request):
    tasks, exits, events = irtps.batch.task._Tasks(), [], []
    monkeypatch.setattr(irtps.batch.task.os, "_exit", exits.append)
    request.addfinalizer(
        functools.partial(logging.disable, logging.root.manager.disable)
    )  # exit_after_writes silences logging
    writing, release = threading.Event(), threading.Event()

    def write():
        with tasks.writing():
            writing.set()
            release.wait()
            events.append("written")

    writer = threading.Thread(target=write)
    writer.start()
    writing.wait()
    stopper = threading.Thread(target=lambda: (tasks.exit_after_writes(), events.append("exit")))
    stopper.start()
    stopper.join(timeout=0.2)
    assert stopper.is_alive() and events == []  # waiting for the write
    release.set()
    writer.join()
    stopper.join()
    assert events == ["written", "exit"] and exits == [0]
    with pytest.raises(irtps.IrtpsError, match="stopping"), tasks.writing():
        pass


def test_images_left_out_per_data_set_and_a_resume_that_asks_for_others(cluster, three_sets, tmp_path, capsys):
    cap, ball, _ = three_sets
    out = tmp_path / "out"
    argv = ["batch", str(cap), str(ball), "--out", str(out), "--scheduler", cluster.scheduler.address, "--quiet"]
    assert (
        main([*argv, "--exclude-images", "ball=8-9", "--exclude-images", "096.png"]) == 2
    )  # cap has no 096.png: it fails alone
    summary = json.loads((out / "batch.json").read_text())
    assert [(s["name"], s["status"]) for s in summary["datasets"]] == [("cap", "failed"), ("ball", "ok")]
    assert summary["datasets"][0]["error"].startswith(f"exclude_images: {cap} has no image named '096.png'")
    assert json.loads((out / "ball" / "run.json").read_text())["excluded_images"] == ["008.png", "009.png", "096.png"]
    direct = reconstruct(load_dataset(ball, exclude_images="8-9,96"))
    np.testing.assert_array_equal(load_reconstruction(out / "ball")[0], direct.normals)
    capsys.readouterr()
    # Resumed with the same lists, ball's folder is kept; asked for other images, it is redone.
    assert main([*argv, "--resume", "--exclude-images", "ball=8-9,96"]) == 0
    assert [s["status"] for s in json.loads((out / "batch.json").read_text())["datasets"]] == ["ok", "reused"]
    assert main([*argv, "--resume"]) == 0
    assert [s["status"] for s in json.loads((out / "batch.json").read_text())["datasets"]] == ["reused", "ok"]
    assert json.loads((out / "ball" / "run.json").read_text())["excluded_images"] == []


def test_a_list_for_no_data_set_is_refused_before_anything_runs(three_sets, tmp_path, capsys):
    argv = ["batch", str(three_sets[0]), "--out", str(tmp_path / "out"), "--exclude-images", "ball=1"]
    assert main(argv) == 2
    assert "irtps: error: --exclude-images: 'ball=1' names no data set (the data sets: cap)" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
    with pytest.raises(irtps.ArgumentError, match="'bear' is none of the data sets"):
        reconstruct_many([three_sets[0]], tmp_path / "out", exclude_images={"bear": "1-20"})


def test_resume_redoes_a_folder_with_another_normal_map_or_without_its_glb(cluster, three_sets, tmp_path, capsys):
    cap, ball, _ = three_sets
    out = tmp_path / "out"
    argv = ["batch", str(cap), str(ball), "--out", str(out), "--scheduler", cluster.scheduler.address, "--quiet"]
    assert main([*argv, "--normal-map", "directx"]) == 0
    (out / "ball" / "mesh.glb").unlink()
    assert main([*argv, "--normal-map", "directx", "--resume"]) == 0
    summary = json.loads((out / "batch.json").read_text())
    assert [(s["name"], s["status"]) for s in summary["datasets"]] == [("cap", "reused"), ("ball", "ok")]
    assert main([*argv, "--resume"]) == 0  # OpenGL now: both redone
    summary = json.loads((out / "batch.json").read_text())
    assert [s["status"] for s in summary["datasets"]] == ["ok", "ok"]
    record = json.loads((out / "cap" / "run.json").read_text())
    assert record["exports"]["normal.png"]["convention"] == "opengl"
    assert main([*argv, "--resume", "--encoding", "linear"]) == 0  # decoded otherwise: both redone
    summary = json.loads((out / "batch.json").read_text())
    assert [s["status"] for s in summary["datasets"]] == ["ok", "ok"]
    assert json.loads((out / "cap" / "run.json").read_text())["encoding"] == "linear"
