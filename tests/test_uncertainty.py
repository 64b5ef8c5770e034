"""The standard error of least-squares normals against the spread of normals fitted from
noisy images (Monte Carlo)."""

import numpy as np

from irtps.ps.uncertainty import normal_standard_error


def _lights(count: int, rng) -> np.ndarray:
    tilt = rng.uniform(0.2, 0.8, count)
    azimuth = rng.uniform(0, 2 * np.pi, count)
    return np.stack([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)], axis=1)


def test_the_standard_error_matches_the_spread_of_normals_fitted_from_noisy_images():
    rng = np.random.default_rng(5)
    lights = _lights(24, rng)
    normal = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    side = 60
    brightness = np.clip(lights @ normal, 0, None)  # every light is in front here
    assert (brightness > 0).all()
    noise = 0.02
    images = brightness[:, None, None, None] / 3 + noise * rng.standard_normal((24, side, side, 3))
    mask = np.ones((side, side), bool)
    predicted = normal_standard_error(images, lights, np.ones((24, 3)), mask)
    # The fitted normals themselves, by plain least squares per pixel.
    summed = images.sum(axis=3).reshape(24, -1)
    g = np.linalg.lstsq(lights, summed, rcond=None)[0].T
    fitted = g / np.linalg.norm(g, axis=1, keepdims=True)
    angles = np.degrees(np.arccos(np.clip(fitted @ normal, -1, 1)))
    rms_angle = np.sqrt(np.mean(angles**2))
    assert 0.2 < rms_angle < 5  # a spread worth measuring
    assert abs(np.sqrt(np.mean(predicted**2)) - rms_angle) < 0.1 * rms_angle


def test_exact_images_fix_the_normal_and_undetermined_pixels_are_nan():
    rng = np.random.default_rng(1)
    lights = _lights(6, rng)
    normal = np.array([0.0, 0.0, 1.0])
    images = np.repeat((lights @ normal)[:, None, None, None], 3, axis=3) * np.ones((6, 2, 3, 3)) / 3
    mask = np.array([[True, True, False], [True, True, True]])
    usable = np.ones((6, 2, 3, 1), bool)
    usable[3:, 0, 1] = False  # three observations left: no degree of freedom for the residual
    error = normal_standard_error(images, lights, np.ones((6, 3)), mask, usable)
    assert np.isnan(error[0, 1]) and np.isnan(error[0, 2])
    assert np.allclose(error[mask & ~np.isnan(error)], 0.0, atol=1e-4)
    assert np.isfinite(error[1]).all()
