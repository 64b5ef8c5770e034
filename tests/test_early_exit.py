"""IRT-PS stops at its first correction, keeping classic photometric stereo's result, where
that correction turns the normals by less than the images fix them (a real object alone),
goes on where it does not (an object in a box), and says why it stopped in run.json, the
summary and the report."""

import json
from pathlib import Path

import pytest

import irtps
from irtps.cli.main import main
from irtps.irt.early_exit import CorrectionSize
from irtps.irt.loop_state import STOP_REASONS, LoopState
from irtps.report.build import build_report
from irtps.report.page import report_html
from irtps.render.residual import Residual

DATA = Path(__file__).parent / "data"
BALL = DATA / "diligent_ball_small"
CAP_IN_A_BOX = DATA / "mitsuba_small" / "cap_cornell"


@pytest.fixture(scope="module")
def ball_run(tmp_path_factory):
    """IRT-PS on the downsampled DiLiGenT ball (a real convex object alone: its bounces carry
    nothing its sensor noise and gloss do not swamp)."""
    out = tmp_path_factory.mktemp("runs") / "ball"
    assert main(["reconstruct", str(BALL), "--out", str(out), "--method", "irtps", "--samples", "16", "--quiet"]) == 0
    return out


def test_a_real_object_alone_stops_at_its_first_correction_and_says_why(ball_run):
    run = json.loads((ball_run / "run.json").read_text())
    stop = run["stop"]
    assert stop["reason"] == "below_noise" and stop["after_pass"] == 0
    assert [step["index"] for step in run["history"]] == [0] and run["chosen_pass"] == 0
    correction = stop["correction"]
    assert 0 <= correction["change_deg"] < 0.5 * correction["noise_deg"] and correction["pixels"] > 100
    assert stop["message"].endswith("the result is classic photometric stereo's")
    assert not (ball_run / "indirect").exists()  # nothing was removed from the images


def test_that_result_is_classic_photometric_stereo_s():
    data = irtps.load_dataset(BALL)
    classic, corrected = irtps.reconstruct(data), irtps.reconstruct(data, "irtps", samples=16)
    assert corrected.stop is not None and corrected.stop.reason == "below_noise"
    assert (corrected.normals == classic.normals).all()


def test_the_summary_and_the_report_say_where_and_why_the_loop_stopped(ball_run, capsys, tmp_path):
    report = build_report(ball_run)
    page = report_html(report)
    assert "The loop stopped after pass 0: the first correction turned the normals by" in page
    convergence = next(figure for figure in report.figures if figure.name == "convergence")
    assert "The loop stopped after pass 0" in convergence.caption
    out = tmp_path / "again"
    assert main(["reconstruct", str(BALL), "--out", str(out), "--method", "irtps", "--samples", "16"]) == 0
    assert "stopped after pass 0: the first correction turned the normals by" in capsys.readouterr().out


def test_an_object_in_a_box_goes_on_past_its_first_correction():
    data, _ = irtps.synthesize("cavity", size=32, lights=12, environment="cornell", bounces=4, samples=64, seed=2)
    result = irtps.reconstruct(data, "irtps", samples=16, iterations=3)
    assert result.stop is not None and result.stop.reason in ("stalled", "iterations")
    assert len(result.history) > 2
    correction = result.stop.correction
    assert correction is not None and correction.change_deg > 2 * correction.noise_deg


def test_three_lights_leave_the_noise_unknown_and_the_loop_goes_on():
    # Three images fix a normal exactly and leave no residual to judge a correction by.
    result = irtps.reconstruct(irtps.load_dataset(CAP_IN_A_BOX), "irtps", samples=8, iterations=2)
    assert [step.index for step in result.history] == [0, 1, 2]
    assert result.stop is not None and result.stop.correction is None


def test_without_early_stop_every_correction_asked_for_is_made():
    data = irtps.load_dataset(BALL)
    result = irtps.reconstruct(data, "irtps", samples=8, iterations=2, early_stop=False)
    assert [step.index for step in result.history] == [0, 1, 2]
    assert result.stop is not None and result.stop.reason == "iterations" and result.stop.correction is None
    assert result.stop.message == "the 2 corrections asked for were made"


def _state(residuals) -> LoopState:
    state = LoopState(observed=None, saturated=None, images=None, step=1.0)  # type: ignore[arg-type]
    for index, value in enumerate(residuals):
        state.judge(index, index, Residual(value, None, 1e-4))  # type: ignore[arg-type]
    return state


@pytest.mark.parametrize("change, expected", [(0.3, "below_noise"), (0.7, None), (3.0, None)])
def test_the_first_correction_stops_the_loop_only_below_the_noise(change, expected):
    state = _state([0.3])
    assert state.correction_stop() is None  # not measured yet
    state.correction = CorrectionSize(change_deg=change, noise_deg=1.0, pixels=100)
    stop = state.correction_stop()
    assert (None if stop is None else stop.reason) == expected
    assert stop is None or (stop.reason in STOP_REASONS and stop.after_pass == 0 and stop.correction is not None)


@pytest.mark.parametrize(
    "index, early_stop, expected", [(1, True, None), (4, True, "iterations"), (4, False, "iterations")]
)
def test_the_largest_number_of_corrections_stops_the_loop(index, early_stop, expected):
    state = _state([0.3, 0.2, 0.15, 0.1, 0.05][: index + 1])
    stop = state.stop(index, 4, early_stop)
    assert (None if stop is None else stop.reason) == expected


def test_a_stalled_residual_stops_the_loop_with_its_reason():
    state = _state([0.3, 0.2, 0.2, 0.2])
    stop = state.stop(3, 8, True)
    assert stop is not None and stop.reason == "stalled" and "Monte-Carlo noise" in stop.message
    assert _state([0.3]).stop(0, 0, True).message == "no correction was asked for"
