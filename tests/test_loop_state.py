"""The IRT-PS loop's state between passes and its update strategy, on hand-made figures."""

import numpy as np

from irtps.irt.loop_state import SIGNIFICANCE, TREND, LoopState, within_noise
from irtps.irt.update import corrected
from irtps.render.residual import Residual


def _state() -> LoopState:
    observed = np.ones((2, 3, 3), np.float32)
    return LoopState(observed=observed, saturated=None, images=observed, step=1.0)


def test_the_best_pass_is_the_lowest_residual_and_a_fall_within_noise_over_two_passes_stops():
    state, noise = _state(), 0.01
    residuals = [0.30, 0.20, 0.20 - SIGNIFICANCE * noise / 2, 0.25]
    stalled = []
    for index, value in enumerate(residuals):
        state.subtracted = None if index == 0 else np.full((2, 3, 3), index, np.float32)
        state.judge(index, f"pass {index}", Residual(value, None, noise))  # type: ignore[arg-type]
        stalled.append(state.stalled_out)
    # Pass 2 is the lowest, so the best; from pass 1 to pass 3 the residual rose: it stops.
    assert state.best is not None and state.best.index == 2 and state.best.reconstruction == "pass 2"
    assert state.best.subtracted is not None and state.best.subtracted[0, 0, 0] == 2
    assert stalled == [False, False, False, True] and TREND == 2


def test_one_noisy_pass_does_not_stop_a_falling_residual():
    # Pass 2 rises well above pass 1 (an over-relaxed step, or a noisy rendering), yet from
    # pass 1 to pass 3 the residual falls beyond its noise: the loop goes on.
    state = _state()
    for index, value in enumerate([0.3, 0.2, 0.26, 0.15]):
        state.judge(index, index, Residual(value, None, 0.005))  # type: ignore[arg-type]
        assert not state.stalled_out
    assert state.best is not None and state.best.index == 3


def test_noise_decides_whether_a_fall_counts():
    falling = [0.3, 0.2, 0.2, 0.18]
    for noise, stops in ((0.001, False), (0.01, True)):  # a fall of 0.02 over two passes
        state = _state()
        for index, value in enumerate(falling):
            state.judge(index, index, Residual(value, None, noise))  # type: ignore[arg-type]
        assert state.stalled_out == stops
    assert within_noise(Residual(0.21, None, 0.005), Residual(0.2, None, 0.0))
    assert not within_noise(Residual(0.211, None, 0.005), Residual(0.2, None, 0.0))


def test_corrected_images_are_clipped_at_zero_and_keep_saturated_observations():
    images = np.array([[[0.5, 0.2, 1.0]]], np.float32)
    estimate = np.array([[[0.1, 0.4, 0.3]]], np.float32)
    saturated = np.array([[[False, False, True]]])
    original = images.copy()
    result = corrected(images, estimate, original, saturated[..., 2:])
    # The pixel's observation saturated in a channel is put back whole, as observed.
    assert np.array_equal(result, original)
    result = corrected(images, estimate, original, None)
    assert np.allclose(result, [[[0.4, 0.0, 0.7]]]) and result.min() >= 0
