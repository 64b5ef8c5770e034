"""Photometric stereo against ground truth: DiLiGenT, Mitsuba direct-only renders, synthetic."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import irtps
from irtps.cli.main import main
from irtps.errors import IrtpsError
from irtps.model.metrics import angular_error_deg
from irtps.irt.interreflection import remove_interreflections
from irtps import _core
from irtps.ps.fit import (
    DARK,
    FLAGS,
    LOBE_CHECK_ROUNDS,
    LOBE_FIRST,
    LOBE,
    MASKED_OUT,
    OK,
    PsResult,
    choose_robust,
    lobe_share,
    photometric_stereo,
)

DATA = Path(__file__).parent / "data"
SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason="needs the shared data sets (../shared)")


def _mean_error(data: irtps.Dataset, images: np.ndarray, robust: str) -> float:
    fit = photometric_stereo(
        images,
        data.scene.light_directions,
        data.scene.light_irradiance,
        data.mask,
        robust=robust,
        saturation=data.saturation,
    )
    return float(np.nanmean(angular_error_deg(fit.normals, data.gt.normal, data.mask)))


@pytest.mark.parametrize(
    "name, plain_deg, tukey_deg",
    # Measured on the tests/data copies (8 and 24 lights, 4x smaller): least squares 4.10 and
    # 17.09, threshold 3.07 and 17.66, trim 8.48 and 11.09, Tukey 2.21 and 10.67.
    [("diligent_ball_small", 4.2, 2.4), ("diligent_reading_small", 17.2, 11.0)],
)
def test_small_diligent_copies_tukey_sets_highlights_and_shadows_aside(name, plain_deg, tukey_deg):
    data = irtps.load_dataset(DATA / name)
    plain, threshold, tukey = (_mean_error(data, data.images, mode) for mode in ("none", "threshold", "tukey"))
    assert plain <= plain_deg
    assert tukey <= tukey_deg
    assert tukey < threshold


@needs_shared
@pytest.mark.parametrize(
    "name, published_deg, tukey_deg",
    # DiLiGenT's published least-squares baselines; Tukey as the issue asks (measured 1.96, 11.58).
    [("ballPNG", 4.10, 2.0), ("readingPNG", 19.80, 12.0)],
)
def test_diligent_objects_least_squares_as_published_and_tukey_far_below(name, published_deg, tukey_deg):
    data = irtps.load_dataset(SHARED / "diligent" / name)
    assert _mean_error(data, data.images, "none") <= published_deg + 0.2
    assert _mean_error(data, data.images, "tukey") <= tukey_deg


@needs_shared
@pytest.mark.parametrize("scene, floor_deg", [("cap_cornell", 1.2), ("grooves_dark", 1.3)])
def test_mitsuba_direct_images_reach_the_floor(scene, floor_deg):
    data = irtps.load_dataset(SHARED / "mitsuba" / scene)
    assert _mean_error(data, data.gt.direct, "threshold") <= floor_deg
    assert _mean_error(data, data.gt.direct, "tukey") <= floor_deg


@needs_shared
@pytest.mark.parametrize("scene, classic_deg", [("cap_cornell", 7.4), ("grooves_dark", 14.8)])
def test_inter_reflections_bend_classic_ps_as_documented(scene, classic_deg):
    data = irtps.load_dataset(SHARED / "mitsuba" / scene)
    assert _mean_error(data, data.images, "threshold") == pytest.approx(classic_deg, abs=0.1)


@pytest.mark.parametrize("robust", ["threshold", "tukey"])
def test_robust_modes_handle_cast_and_attached_shadows(robust):
    data, _ = irtps.synthesize("cavity", size=48, lights=12, bounces=0, environment="none", seed=1)
    plain, fitted = _mean_error(data, data.images, "none"), _mean_error(data, data.images, robust)
    assert fitted < 0.7 * plain
    assert fitted < 1.3


def test_albedo_is_recovered_per_channel():
    data, _ = irtps.synthesize("relief", size=40, lights=8, bounces=0, environment="none", albedo="textured", seed=2)
    fit = photometric_stereo(data.images, data.scene.light_directions, data.scene.light_irradiance, data.mask)
    error = np.abs(fit.albedo - data.gt.albedo)[data.mask]
    assert np.median(error) < 0.01


def test_saturated_observations_are_dropped():
    lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8], [0, -0.6, 0.8]])
    normal = np.array([0.1, 0.05, 1.0]) / np.linalg.norm([0.1, 0.05, 1.0])
    images = (0.9 * np.clip(lights @ normal, 0, None))[:, None, None, None] * np.ones((5, 1, 1, 3))
    assert images[0].max() > 0.8 > images[1:].max()
    images[0] = np.minimum(images[0], 0.8)  # clipped by the sensor
    irradiance = np.full((5, 3), np.pi)
    for robust in ("threshold", "tukey", "trim", "lobe"):
        clipped = photometric_stereo(images, lights, irradiance, robust=robust, saturation=0.8)
        # Trim would keep 2 of the 5: too few, so it falls back to the 4 unsaturated ones.
        assert clipped.used[0, 0] == 4
        np.testing.assert_allclose(clipped.normals[0, 0], normal, atol=1e-5)
    fooled = photometric_stereo(images, lights, irradiance, robust="none")
    assert np.degrees(np.arccos(np.clip(fooled.normals[0, 0] @ normal, -1, 1))) > 0.1


@pytest.mark.parametrize(
    "directions, message",
    [
        ([[0, 0, 1], [0.6, 0, 0.8]], "at least 3"),
        ([[0, 0, 1], [0.6, 0, 0.8], [-0.6, 0, 0.8]], "coplanar"),
    ],
)
def test_unusable_lights_are_clear_errors(directions, message):
    k = len(directions)
    with pytest.raises(IrtpsError, match=message):
        photometric_stereo(np.ones((k, 2, 2, 3)), np.array(directions, float), np.ones((k, 3)))


def test_shape_mismatch_names_images():
    with pytest.raises(IrtpsError, match="images"):
        photometric_stereo(np.ones((3, 2, 2)), np.eye(3), np.ones((3, 3)))


def _microfacet_plastic(
    normals: np.ndarray, lights: np.ndarray, alpha: float, diffuse: float = 0.5, fresnel_0: float = 0.04
) -> np.ndarray:
    """(K, P, 1, 3) images of a Lambertian albedo `diffuse` under a GGX lobe (Cook-Torrance:
    Smith-Schlick shadowing, Schlick's Fresnel from `fresnel_0`) for unit irradiance π,
    camera along -z."""
    n_l = normals @ lights.T
    half = lights + [0.0, 0.0, 1.0]
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    n_h, n_v = normals @ half.T, normals[:, 2:3]
    distribution = alpha**2 / (np.pi * ((alpha**2 - 1) * n_h**2 + 1) ** 2)
    shadowing = n_v * n_l / ((n_v * (1 - alpha / 2) + alpha / 2) * (n_l * (1 - alpha / 2) + alpha / 2))
    fresnel = fresnel_0 + (1 - fresnel_0) * (1 - half[:, 2]) ** 5
    lobe_times_n_l = distribution * shadowing * fresnel / (4 * n_v)
    radiance = np.where(n_l > 0, diffuse / np.pi * n_l + lobe_times_n_l, 0.0)
    return np.repeat(np.pi * radiance.T[:, :, None, None], 3, axis=3).astype(np.float32)


def _microfacet_errors(modes: tuple[str, ...], **material: float) -> dict[str, float]:
    """Mean angular error of each robust mode on 400 random normals under 24 lights."""
    rng = np.random.default_rng(3)
    azimuth, zenith = rng.uniform(0, 2 * np.pi, 400), np.radians(rng.uniform(0, 60, 400))
    normals = np.stack([np.sin(zenith) * np.cos(azimuth), np.sin(zenith) * np.sin(azimuth), np.cos(zenith)], axis=1)
    k = np.arange(24)
    light_zenith = np.radians(10 + 40 * k / 23)
    lights = np.stack(
        [np.sin(light_zenith) * np.cos(2.4 * k), np.sin(light_zenith) * np.sin(2.4 * k), np.cos(light_zenith)], axis=1
    )
    images = _microfacet_plastic(normals, lights, **material)
    errors = {}
    for mode in modes:
        fit = photometric_stereo(images, lights, np.full((24, 3), np.pi), robust=mode)
        errors[mode] = float(angular_error_deg(fit.normals, normals[:, None], np.ones((400, 1), bool)).mean())
    return errors


def test_tukey_sets_a_microfacet_highlight_aside():
    errors = _microfacet_errors(("none", "threshold", "tukey"), alpha=0.2)
    # Measured: least squares 3.78°, threshold 3.50°, Tukey 1.15° (24 lights, not 96).
    assert errors["none"] > 3.0  # the highlight bends plain least squares
    assert errors["tukey"] < 1.5
    assert errors["tukey"] < 0.5 * errors["threshold"]


def test_lobe_mode_fits_a_broad_metallic_highlight():
    # A metal-like GGX lobe (α 0.3, Fresnel 0.9) over a dim diffuse base: the highlight is no
    # outlier but most of the light. Blinn-Phong is not GGX, so the lobe fit is not exact.
    errors = _microfacet_errors(("tukey", "lobe"), alpha=0.3, diffuse=0.05, fresnel_0=0.9)
    # Measured: Tukey 21.28°, lobe 4.25°.
    assert errors["tukey"] > 5.0
    assert errors["lobe"] < 0.5 * errors["tukey"]


def test_lobe_mode_keeps_the_tukey_fit_of_lambertian_pixels():
    # Direct light only on a Lambertian cavity: cast and attached shadows, no highlight.
    data, _ = irtps.synthesize("cavity", size=48, lights=24, bounces=0, environment="none", seed=1)
    fit = photometric_stereo(
        data.images, data.scene.light_directions, data.scene.light_irradiance, data.mask, robust="lobe"
    )
    # Measured: Tukey 0.783°, lobe 0.783°, 0.55 % of the pixels fitted with a lobe.
    assert (fit.flags[data.mask] == 4).mean() < 0.02
    assert _mean_error(data, data.images, "lobe") == pytest.approx(_mean_error(data, data.images, "tukey"), abs=0.02)


def _metal_cap() -> irtps.Dataset:
    """A synthesized cap, direct light only, re-shaded as a metal-like GGX surface (α 0.3,
    Fresnel 0.9, dim diffuse base) from its true normals."""
    data, _ = irtps.synthesize("cap", size=40, lights=24, bounces=0, environment="none", seed=2)
    shading = _microfacet_plastic(
        data.gt.normal[data.mask].astype(np.float64),
        data.scene.light_directions.astype(np.float64),
        alpha=0.3,
        diffuse=0.05,
        fresnel_0=0.9,
    )
    images = data.images.copy()
    images[:, data.mask] = shading[:, :, 0] * (data.scene.light_irradiance[:, None, :] / np.pi)
    return dataclasses.replace(data, images=images)


def test_reconstruct_picks_the_lobe_mode_for_a_metallic_object(tmp_path, capsys):
    irtps.save_dataset(_metal_cap(), tmp_path / "metal")
    errors, advice, runs = {}, {}, {}
    for mode in ("tukey", "lobe", "auto"):
        out = tmp_path / mode
        chosen = [] if mode == "auto" else ["--robust", mode]  # auto: the default
        assert main(["reconstruct", str(tmp_path / "metal"), "--out", str(out), *chosen, "--quiet"]) == 0
        advice[mode] = "--robust lobe" in capsys.readouterr().err
        assert main(["evaluate", str(out), "--gt", str(tmp_path / "metal"), "--json"]) == 0
        errors[mode] = json.loads(capsys.readouterr().out)["normal_mean_angular_deg"]
        runs[mode] = json.loads((out / "run.json").read_text())
    # Measured: Tukey 17.96°, lobe 5.29°; 579 of 688 pixels fitted with a lobe.
    assert errors["lobe"] < 0.5 * errors["tukey"]
    assert runs["lobe"]["flags"]["fitted with a specular lobe"] > runs["lobe"]["flags"]["fitted"]
    # The default saw the lobe and fitted it; a Tukey run said so; the lobe run had nothing
    # to check.
    assert runs["auto"]["robust_used"] == "lobe" and errors["auto"] == errors["lobe"]
    assert runs["tukey"]["lobe_share"] > 0.5 and runs["auto"]["lobe_share"] == runs["tukey"]["lobe_share"]
    assert advice == {"tukey": True, "lobe": False, "auto": False}
    assert runs["lobe"]["lobe_share"] is None
    for mode, said in (
        ("tukey", "robust mode &#x27;lobe&#x27; (--robust lobe) is advised"),
        ("auto", "fitted with robust mode &#x27;lobe&#x27;"),
    ):
        assert main(["report", str(tmp_path / mode), "--quiet"]) == 0
        assert said in (tmp_path / mode / "report" / "index.html").read_text()


@pytest.mark.parametrize(
    "make, chosen",
    [
        (lambda: irtps.synthesize("cap", size=40, lights=24, bounces=0, environment="none", seed=2)[0], "tukey"),
        (_metal_cap, "lobe"),
    ],
)
def test_the_auto_mode_is_the_fit_of_the_mode_the_share_picks(make, chosen):
    data = make()
    args = (data.images, data.scene.light_directions, data.scene.light_irradiance, data.mask)
    auto = photometric_stereo(*args)  # "auto" is the default
    alone = photometric_stereo(*args, robust=chosen)
    # The check beside the Tukey fit counts what `lobe_share` counts, and picks by it.
    assert auto.robust_used == chosen == choose_robust(auto.lobe_share)
    assert auto.lobe_share == lobe_share(*args)
    for name in ("normals", "albedo", "flags", "used"):
        np.testing.assert_array_equal(getattr(auto, name), getattr(alone, name))
    assert alone.robust_used is None and alone.lobe_share is None


def test_the_auto_mode_of_a_share_near_the_line_looks_further_as_lobe_share_does(monkeypatch):
    data = _half_metal_cap()
    args = (data.images, data.scene.light_directions, data.scene.light_irradiance, data.mask)
    calls = _pixels_fitted(monkeypatch)
    auto = photometric_stereo(*args, robust="auto")
    # The first pixels beside the Tukey fit; the next ones, as the share is not yet decided,
    # in calls of their own; then the lobe fit of the whole object if the lobe is chosen.
    made = list(calls)
    assert made[:4] == [LOBE_FIRST, 2 * LOBE_FIRST, 4 * LOBE_FIRST, int(data.mask.sum()) - 8 * LOBE_FIRST]
    assert made[4:] == ([data.mask.size] if auto.robust_used == "lobe" else [])
    assert auto.lobe_share == lobe_share(*args)


def test_the_auto_mode_of_an_empty_mask_fits_nothing():
    data = _metal_cap()
    fit = photometric_stereo(
        data.images,
        data.scene.light_directions,
        data.scene.light_irradiance,
        np.zeros(data.mask.shape, bool),
        robust="auto",
    )
    assert fit.robust_used == "tukey" and fit.lobe_share == 0.0 and (fit.flags == MASKED_OUT).all()


@pytest.mark.parametrize("mode", ["tukey", "lobe", "threshold", "trim", "none", "auto"])
def test_a_fit_with_a_progress_bar_is_the_same_fit(mode):
    metal = _metal_cap()
    args = (metal.images, metal.scene.light_directions, metal.scene.light_irradiance, metal.mask)
    whole = photometric_stereo(*args, robust=mode)
    banded = photometric_stereo(*args, robust=mode, progress=True)  # 40 rows: bands of one row
    for name in ("normals", "albedo", "flags", "used"):
        np.testing.assert_array_equal(getattr(banded, name), getattr(whole, name))


def test_irtps_fits_every_pass_with_the_mode_auto_picked():
    metal = _metal_cap()
    result = irtps.reconstruct(metal, "irtps", iterations=1, samples=4)
    # Every pass is fitted in lobe mode: the returned fit has lobe pixels whichever it is.
    assert result.robust_used == "lobe" and result.lobe_share > 0.5
    assert (result.flags[metal.mask] == LOBE).mean() > 0.5
    # The loop called alone picks the same way.
    loop = remove_interreflections(metal, iterations=0)
    assert (loop.fit.flags[metal.mask] == LOBE).mean() > 0.5


@pytest.mark.parametrize("name, most", [("diligent_ball_small", 0.05), ("diligent_reading_small", 0.3)])
def test_no_lobe_on_the_small_diligent_copies(tmp_path, capsys, name, most):
    # Measured: 1.6 % of ball's first 64 pixels take a lobe (0.9 % of all its 930), 14.1 % of
    # reading's first 64 (13.5 % of 1 000); 8 and 24 lights.
    assert main(["reconstruct", str(DATA / name), "--out", str(tmp_path / name), "--quiet"]) == 0
    assert "--robust lobe" not in capsys.readouterr().err
    run = json.loads((tmp_path / name / "run.json").read_text())
    assert run["lobe_share"] < most and run["robust_used"] == "tukey"


def _half_metal_cap() -> irtps.Dataset:
    """`_metal_cap` on the left 404 of the object's 688 pixels, its matte original on the
    right: about half of the pixels take a lobe (84 % of the metal's do)."""
    matte, _ = irtps.synthesize("cap", size=40, lights=24, bounces=0, environment="none", seed=2)
    metal = _metal_cap()
    images = metal.images.copy()
    images[:, :, 22:] = matte.images[:, :, 22:]
    return dataclasses.replace(metal, images=images)


def _pixels_fitted(monkeypatch) -> list[int]:
    """The number of pixels of each call of the core's photometric stereo from here on."""
    calls: list[int] = []
    fit = irtps._core.photometric_stereo

    def counted(images, *args, **kwargs):
        calls.append(images.shape[1] * images.shape[2])
        return fit(images, *args, **kwargs)

    monkeypatch.setattr(irtps._core, "photometric_stereo", counted)
    return calls


@pytest.mark.parametrize(
    "make, lobe_pixels",
    [
        (lambda: irtps.synthesize("cap", size=40, lights=24, bounces=0, environment="none", seed=2)[0], False),
        (_metal_cap, True),
    ],
)
def test_lobe_share_tells_matte_from_metal_on_its_first_pixels(monkeypatch, make, lobe_pixels):
    data = make()
    args = (data.images, data.scene.light_directions, data.scene.light_irradiance, data.mask)
    calls = _pixels_fitted(monkeypatch)
    share = lobe_share(*args)
    # Measured: the matte cap is decided on its first 64 pixels (0 %), the metal on 128 (66 %;
    # 74 % of all 688 in the check's fit, 84 % in the lobe mode's).
    assert calls == ([LOBE_FIRST, LOBE_FIRST] if lobe_pixels else [LOBE_FIRST])
    assert (share > 0.6) if lobe_pixels else (share == 0)
    assert choose_robust(share) == choose_robust(lobe_share(*args, stop_early=False))


def test_lobe_share_near_the_line_is_measured_on_every_pixel_as_one_fit(monkeypatch):
    data = _half_metal_cap()
    args = (data.images, data.scene.light_directions, data.scene.light_irradiance, data.mask)
    calls = _pixels_fitted(monkeypatch)
    share = lobe_share(*args)
    # Doubled from the first pixels until all were fitted, the share never clear of the line.
    assert calls == [LOBE_FIRST, LOBE_FIRST, 2 * LOBE_FIRST, 4 * LOBE_FIRST, int(data.mask.sum()) - 8 * LOBE_FIRST]
    whole = _check_fit(data)
    assert share == pytest.approx((whole.flags[data.mask] == LOBE).mean(), abs=1e-12)
    assert 0.3 < share < 0.7


def _check_fit(data: irtps.Dataset) -> PsResult:
    """The lobe fit of every pixel of `data` as `lobe_share` fits them (`LOBE_CHECK_ROUNDS`)."""
    settings = (data.scene.light_directions.astype(np.float32), data.scene.light_irradiance.astype(np.float32), "lobe")
    return PsResult(
        *irtps._core.photometric_stereo(
            data.images.astype(np.float32), data.mask, *settings, lobe_rounds=LOBE_CHECK_ROUNDS
        )
    )


@pytest.mark.parametrize(
    "make",
    [
        _metal_cap,
        _half_metal_cap,
        lambda: irtps.load_dataset(DATA / "diligent_reading_small"),
        lambda: irtps.load_dataset(DATA / "diligent_ball_small"),
    ],
)
def test_the_check_takes_objects_to_the_side_of_the_line_the_full_lobe_fit_does(make):
    data = make()
    args = (data.images, data.scene.light_directions, data.scene.light_irradiance, data.mask)
    full = (photometric_stereo(*args, robust="lobe").flags[data.mask] == LOBE).mean()
    share = lobe_share(*args, stop_early=False)
    assert choose_robust(share) == choose_robust(full)
    # Measured (lobe mode, check): metal cap 84 / 74 %, half of it 50 / 44 %, reading 17.1 /
    # 13.5 %, ball 1.0 / 0.9 %: a few pixels take a lobe only after more rounds.
    assert full - 0.15 <= share <= full + 0.01


def test_a_share_is_decided_only_clear_of_the_line():
    from irtps.ps.fit import share_is_decided

    # One half is never clear of the line, however many pixels say so.
    assert not any(share_is_decided(fitted // 2, fitted) for fitted in range(2, 1001, 2))
    # 64 pixels decide 0 and 64 lobes, and 13 (20 %), but not 20 (31 %) nor 44 (69 %).
    assert [share_is_decided(lobes, 64) for lobes in (0, 13, 20, 44, 51, 64)] == [True, True, False, False, True, True]
    # 1 000 pixels tell 45 % from one half (Wilson half-width 4.7 points at 3 sigma), not 46 %.
    assert share_is_decided(450, 1000) and share_is_decided(550, 1000)
    assert not share_is_decided(460, 1000) and not share_is_decided(540, 1000)


def test_flag_values_are_those_the_core_writes():
    """`irtps.ps.fit`'s flags name the constants of rust/ps/kernel.rs `mod flag`, which the binding
    does not export: a masked-out, a fitted and a dark (no light) pixel, straight from the core."""
    lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8]], np.float32)
    images = np.zeros((4, 1, 3, 3), np.float32)
    images[:, 0, 1] = 0.5 * lights[:, 2:3]  # a flat grey pixel, lit by every light
    mask = np.array([[False, True, True]])  # pixel 2: on the object, black in every image
    _, _, flags, _ = _core.photometric_stereo(images, mask, lights, np.ones((4, 3), np.float32), "none")
    assert flags.tolist() == [[MASKED_OUT, OK, DARK]]
    assert FLAGS[MASKED_OUT] == "outside the mask" and FLAGS[OK] == "fitted" and FLAGS[DARK] == "no light"
