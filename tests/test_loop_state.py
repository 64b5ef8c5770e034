"""The IRT-PS loop's state between passes and its update strategy, on hand-made figures."""

import numpy as np

from irtps.irt.loop_state import PATIENCE, SIGNIFICANCE, LoopState
from irtps.irt.update import corrected
from irtps.render.residual import Residual


def _state() -> LoopState:
    observed = np.ones((2, 3, 3), np.float32)
    return LoopState(observed=observed, saturated=None, images=observed, step=1.0)


def test_the_best_pass_is_the_lowest_residual_and_noise_level_gains_stall_the_loop():
    state, noise = _state(), 0.01
    residuals = [0.30, 0.20, 0.20 - SIGNIFICANCE * noise / 2, 0.25]
    stalled = []
    for index, value in enumerate(residuals):
        state.subtracted = None if index == 0 else np.full((2, 3, 3), index, np.float32)
        state.judge(index, f"pass {index}", Residual(value, None, noise))  # type: ignore[arg-type]
        stalled.append(state.stalled)
    # Pass 2 is lower than pass 1 (so the best), but within twice the noise: no improvement.
    assert state.best is not None and state.best.index == 2 and state.best.reconstruction == "pass 2"
    assert state.best.subtracted is not None and state.best.subtracted[0, 0, 0] == 2
    assert stalled == [0, 0, 1, 2] and state.stalled_out and PATIENCE == 2


def test_a_significant_gain_resets_the_stall_count():
    state = _state()
    for index, value in enumerate([0.3, 0.3, 0.1]):
        state.judge(index, index, Residual(value, None, 0.001))  # type: ignore[arg-type]
    assert state.stalled == 0 and not state.stalled_out and state.best is not None and state.best.index == 2


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
