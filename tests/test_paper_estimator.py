"""The paper's own estimator: the product of the albedos met along one random path per pixel."""

import numpy as np
import pytest

import irtps
from irtps.errors import IrtpsError
from irtps.irt.interreflection import remove_interreflections
from irtps.irt.paper_estimator import PAPER_SCALE, paper_environment_colour, paper_indirect
from irtps.model.scene import Camera, CornellBox, Floor, Light, Scene


def _closed_uniform_box(albedo: float) -> tuple[Scene, np.ndarray, np.ndarray, np.ndarray]:
    size, half = 16, 8.5
    walls = (albedo,) * 3
    lights = tuple(
        Light(direction=np.array(d) / np.linalg.norm(d), irradiance=(np.pi,) * 3)
        for d in ([0, 0, 1], [0.5, 0, 0.8], [0, 0.5, 0.8])
    )
    # Walls far higher than wide: almost no ray escapes through the open top.
    scene = Scene(
        Camera(size, size, 1.0),
        lights,
        Floor(0.0, walls),
        CornellBox((-half, half), (-half, half), 400.0, walls, walls, walls, walls),
    )
    rows, cols = np.mgrid[0:size, 0:size]
    height = 2.0 + 0.5 * np.sin(cols / 3.0)
    return scene, height, np.full((size, size, 3), albedo), np.ones((size, size), bool)


@pytest.mark.parametrize("reflections", [1, 2, 3])
def test_environment_colour_is_the_product_of_the_albedos_met(reflections):
    scene, height, albedo, mask = _closed_uniform_box(0.6)
    colour = paper_environment_colour(scene, height, albedo, mask, reflections=reflections, seed=1)
    np.testing.assert_allclose(colour[mask], 0.6**reflections, rtol=1e-4)


def test_rays_that_all_escape_leave_no_environment_colour():
    data, _ = irtps.synthesize("cap", size=16, lights=3, environment="none", bounces=0)
    colour = paper_environment_colour(data.scene, data.gt.height, data.gt.albedo, data.mask, reflections=1)
    assert (colour == 0).all()
    estimate = paper_indirect(data.scene, data.gt.height, data.gt.albedo, data.mask, reflections=1)
    assert estimate.shape == data.images.shape and (estimate == 0).all()


def test_paper_estimate_is_the_scaled_colour_for_every_light():
    scene, height, albedo, mask = _closed_uniform_box(0.5)
    estimate = paper_indirect(scene, height, albedo, mask, reflections=2, seed=2)
    np.testing.assert_allclose(estimate, PAPER_SCALE[2] * 0.25, rtol=1e-4)


def test_the_loop_runs_the_paper_estimator_and_rejects_bad_depths():
    data, _ = irtps.synthesize("cap", size=24, lights=6, environment="cornell", bounces=2, samples=16, seed=5)
    result = remove_interreflections(
        data, bounces=2, iterations=2, estimator="paper", update="previous", early_stop=False
    )
    assert len(result.history) == 3 and result.indirect.shape == (len(data.images), data.mask.sum(), 3)
    with pytest.raises(IrtpsError, match="bounces"):
        remove_interreflections(data, bounces=4, estimator="paper")
    with pytest.raises(IrtpsError, match="estimator"):
        remove_interreflections(data, estimator="guess")
