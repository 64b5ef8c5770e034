"""irtps renders against independent Mitsuba 3 renders of the same scenes.

Uses the small copy in tests/data/mitsuba_small (3 lights per scene); when the full shared
data sets are present, every light of every scene there is checked too.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from irtps import height_to_normals, load_dataset, load_scene_object, render

SMALL = Path(__file__).parent / "data" / "mitsuba_small"
SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mitsuba"


def _scene(folder: Path):
    return pytest.param(folder, id=f"{folder.parent.name}/{folder.name}")


SCENES = [SMALL / "cap_cornell", SMALL / "grooves_dark", SMALL / "cap_rig"]
if SHARED.is_dir():
    SCENES += sorted(p for p in SHARED.iterdir() if (p / "scene.json").is_file())
PARAMS = [_scene(folder) for folder in SCENES]
#: The scenes whose normals are those of their height field (contract §2): a perspective
#: scene's are its depth map's (contract §1b), checked by tests/test_perspective_camera.py.
HEIGHT_FIELD_PARAMS = [
    _scene(folder)
    for folder in SCENES
    if json.loads((folder / "scene.json").read_text())["camera"]["projection"] == "orthographic"
]


@pytest.fixture(scope="module", params=PARAMS)
def rendered(request):
    folder = request.param
    scene, height, albedo, mask = load_scene_object(folder)
    # The depth of the reference renders: 4 indirect bounces.
    rendering = render(scene, height, albedo, mask, bounces=4, samples=256, seed=11)
    return load_dataset(folder), rendering


def test_direct_light_matches_within_two_percent(rendered):
    reference, ours = rendered
    inner = ndimage.binary_erosion(reference.mask, iterations=2)
    expected = reference.gt.direct[:, inner]
    error = np.abs(ours.direct[:, inner] - expected).mean() / expected.mean()
    assert error <= 0.02


def test_indirect_light_object_mean_matches_within_five_percent(rendered):
    reference, ours = rendered
    mask = reference.mask
    expected = (reference.images - reference.gt.direct)[:, mask].mean(axis=1)  # (K, 3)
    got = ours.indirect[:, mask].mean(axis=1)
    assert expected.min() > 0.01  # the scenes really have inter-reflections
    np.testing.assert_allclose(got, expected, rtol=0.05)


@pytest.mark.parametrize("folder", HEIGHT_FIELD_PARAMS)
def test_normals_from_heights_match_the_reference_normals(folder):
    scene, height, _, mask = load_scene_object(folder)
    reference = load_dataset(folder).gt.normal
    ours = height_to_normals(height, mask, scene.camera.pixel_size)
    cosine = np.clip((ours * reference).sum(-1)[mask], -1, 1)
    assert np.degrees(np.arccos(cosine)).max() < 0.1, folder
