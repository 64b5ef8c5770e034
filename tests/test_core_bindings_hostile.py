"""Hostile inputs to every binding of the compiled core (`irtps._core`, rust/python/).

Empty arrays, zero-sized dimensions, NaN and infinities where values must be finite,
out-of-range indices and wrong dtypes must each end in a clean Python exception naming the
argument: never a Rust panic, which pyo3 raises as ``pyo3_runtime.PanicException``, a
`BaseException` that ``except Exception`` does not catch. The core's own errors about an
argument arrive as `irtps.ArgumentError`, whose message starts with the argument; a value
that pyo3 cannot convert (a float64 array for a float32 one, a negative count) as its
`TypeError` or `OverflowError`, which names the argument in a note ("while processing
'images'"). Batches of rays or pixels may be empty: the result is then empty too.
"""

import numpy as np
import pytest

import irtps
from irtps import ArgumentError, _core
from irtps.model.scene import Floor

F32 = np.float32
LIGHTS = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8]], F32)
IRRADIANCE = np.ones((4, 3), F32)
H, W = 3, 4
IMAGES = np.full((4, H, W, 3), 0.5, F32)
MASK = np.ones((H, W), bool)
HEIGHT = np.zeros((H, W), F32)
ALBEDO = np.full((H, W, 3), 0.5, F32)


def _nan(shape, dtype=F32):
    return np.full(shape, np.nan, dtype)


def _renderer():
    return _core.Renderer(HEIGHT, MASK, ALBEDO, 1.0, LIGHTS, IRRADIANCE)


def _bilateral(normals=None, mask=MASK, intrinsics=None, sharpness=2.0, max_iterations=10, tolerance=1e-4):
    normals = np.broadcast_to(np.array([0, 0, 1], F32), (H, W, 3)).copy() if normals is None else normals
    return lambda: _core.integrate_bilateral(normals, mask, intrinsics, sharpness, max_iterations, tolerance)


def _cholesky():
    return _core.SparseCholesky(np.array([0, 1], np.int64), np.array([0], np.int64), np.array([2.0]))


def _ps(images=IMAGES, mask=MASK, directions=LIGHTS, irradiance=IRRADIANCE, **settings):
    return lambda: _core.photometric_stereo(images, mask, directions, irradiance, **settings)


def _check(images=IMAGES, mask=MASK, check=(0,), rounds=5, shadow_fraction=0.05, saturation=None):
    return lambda: _core.tukey_with_lobe_check(
        images, mask, list(check), LIGHTS, IRRADIANCE, shadow_fraction, saturation, rounds
    )


def _compare(direct=None, halves=None, counts=(1,), observed=None, keep=None, first=0):
    direct = np.zeros((4, 2, 3), F32) if direct is None else direct
    halves = [np.zeros((4, 2, 3), F32)] if halves is None else halves
    observed = np.zeros((4, 5, 3), F32) if observed is None else observed
    return lambda: _core.compare_rendering(direct, halves, list(counts), observed, keep, first)


def _denoise(indirect=None, noise_energy=None, mask=MASK, height_px=HEIGHT, albedo=ALBEDO):
    n = int(mask.sum())
    indirect = np.zeros((2, n, 3), F32) if indirect is None else indirect
    noise_energy = np.zeros(n) if noise_energy is None else noise_energy
    return lambda: _core.denoise_indirect(indirect, noise_energy, mask, height_px, albedo)


def _renderer_with(
    height=HEIGHT, mask=MASK, albedo=ALBEDO, pixel_size=1.0, directions=LIGHTS, irradiance=IRRADIANCE, floor=None
):
    return lambda: _core.Renderer(height, mask, albedo, pixel_size, directions, irradiance, floor)


def _sparse(indptr=(0, 1), indices=(0,), data=(2.0,), dtypes=(np.int64, np.int64, np.float64)):
    arrays = [np.asarray(values, dtype) for values, dtype in zip((indptr, indices, data), dtypes)]
    return lambda: _core.SparseCholesky(*arrays)


#: (id, call, the argument its error must name).
CASES = [
    # photometric_stereo
    ("ps-height-0", _ps(np.zeros((4, 0, W, 3), F32), np.zeros((0, W), bool)), "images"),
    ("ps-width-0", _ps(np.zeros((4, H, 0, 3), F32), np.zeros((H, 0), bool)), "images"),
    ("ps-no-image", _ps(np.zeros((0, H, W, 3), F32), MASK, np.zeros((0, 3), F32), np.zeros((0, 3), F32)), "lights"),
    ("ps-channels-0", _ps(np.zeros((4, H, W, 0), F32)), "images"),
    ("ps-nan-image", _ps(_nan((4, H, W, 3))), "images"),
    ("ps-inf-image", _ps(np.full((4, H, W, 3), np.inf, F32), robust="lobe"), "images"),
    ("ps-nan-direction", _ps(directions=_nan((4, 3))), "lights[0].direction"),
    ("ps-zero-direction", _ps(directions=np.zeros((4, 3), F32)), "lights[0].direction"),
    ("ps-nan-irradiance", _ps(irradiance=_nan((4, 3))), "lights[0].irradiance"),
    ("ps-directions-(4,0)", _ps(directions=np.zeros((4, 0), F32)), "light_directions"),
    ("ps-nan-shadow", _ps(shadow_fraction=float("nan")), "shadow_fraction"),
    ("ps-shadow-2", _ps(shadow_fraction=2.0), "shadow_fraction"),
    ("ps-nan-saturation", _ps(saturation=float("nan")), "saturation"),
    ("ps-lobe-rounds-0", _ps(robust="lobe", lobe_rounds=0), "lobe_rounds"),
    ("ps-lobe-rounds-negative", _ps(lobe_rounds=-1), "lobe_rounds"),
    ("ps-float64-images", _ps(IMAGES.astype(np.float64)), "images"),
    ("ps-int-mask", _ps(mask=MASK.astype(np.uint8)), "mask"),
    ("ps-3d-images", _ps(IMAGES[0]), "images"),
    ("ps-list-images", _ps(IMAGES.tolist()), "images"),
    ("ps-unknown-robust", _ps(robust="median"), "robust"),
    # tukey_with_lobe_check
    ("check-height-0", _check(np.zeros((4, 0, W, 3), F32), np.zeros((0, W), bool), check=()), "images"),
    ("check-height-0-with-pixels", _check(np.zeros((4, 0, W, 3), F32), np.zeros((0, W), bool)), "check"),
    ("check-pixel-out-of-range", _check(check=(H * W,)), "check"),
    ("check-negative-pixel", _check(check=(-1,)), "check"),
    ("check-rounds-0", _check(rounds=0), "check_rounds"),
    ("check-nan-image", _check(_nan((4, H, W, 3))), "images"),
    ("check-nan-saturation", _check(saturation=float("nan")), "saturation"),
    ("check-float64-images", _check(IMAGES.astype(np.float64)), "images"),
    # check_lights
    ("lights-empty", lambda: _core.check_lights(np.zeros((0, 3), F32), np.zeros((0, 3), F32)), "lights"),
    ("lights-nan", lambda: _core.check_lights(_nan((4, 3)), IRRADIANCE), "lights[0].direction"),
    ("lights-(4,0)", lambda: _core.check_lights(np.zeros((4, 0), F32), IRRADIANCE), "light_directions"),
    ("lights-float64", lambda: _core.check_lights(LIGHTS.astype(np.float64), IRRADIANCE), "light_directions"),
    # Renderer
    (
        "renderer-height-0",
        _renderer_with(np.zeros((0, W), F32), np.ones((0, W), bool), np.zeros((0, W, 3), F32)),
        "height",
    ),
    (
        "renderer-width-0",
        _renderer_with(np.zeros((H, 0), F32), np.ones((H, 0), bool), np.zeros((H, 0, 3), F32)),
        "height",
    ),
    ("renderer-nan-height", _renderer_with(height=_nan((H, W))), "height"),
    ("renderer-nan-albedo", _renderer_with(albedo=_nan((H, W, 3))), "albedo"),
    ("renderer-nan-pixel-size", _renderer_with(pixel_size=float("nan")), "pixel_size"),
    ("renderer-no-light", _renderer_with(directions=np.zeros((0, 3), F32), irradiance=np.zeros((0, 3), F32)), "lights"),
    ("renderer-nan-direction", _renderer_with(directions=_nan((4, 3))), "lights[0].direction"),
    ("renderer-nan-irradiance", _renderer_with(irradiance=_nan((4, 3))), "lights[0].irradiance"),
    ("renderer-nan-floor", _renderer_with(floor=Floor(height=float("nan"), albedo=(0.5, 0.5, 0.5))), "floor.height"),
    ("renderer-mask-shape", _renderer_with(mask=np.ones((H, W + 1), bool)), "mask"),
    ("renderer-float64-height", _renderer_with(height=HEIGHT.astype(np.float64)), "height"),
    ("with-reflectance-nan", lambda: _renderer().with_reflectance(_nan((H, W, 3)), IRRADIANCE), "albedo"),
    ("with-reflectance-empty", lambda: _renderer().with_reflectance(np.zeros((0, 0, 3), F32), IRRADIANCE), "albedo"),
    ("with-reflectance-lights", lambda: _renderer().with_reflectance(ALBEDO, np.ones((2, 3), F32)), "light_irradiance"),
    ("with-reflectance-float64", lambda: _renderer().with_reflectance(ALBEDO.astype(np.float64), IRRADIANCE), "albedo"),
    ("render-rows-empty", lambda: _renderer().render_rows(1, 1, 1, 1, 1, 0), "rows"),
    ("render-rows-outside", lambda: _renderer().render_rows(0, H + 1, 1, 1, 1, 0), "rows"),
    ("render-rows-negative", lambda: _renderer().render_rows(-1, 1, 1, 1, 1, 0), "row_start"),
    ("render-rows-samples-0", lambda: _renderer().render_rows(0, 1, 1, 0, 1, 0), "samples"),
    ("render-pixels-outside", lambda: _renderer().render_pixels([H * W], 1, 1, 1, 0), "pixels"),
    ("render-pixels-negative", lambda: _renderer().render_pixels([-1], 1, 1, 1, 0), "pixels"),
    ("render-pixels-no-sample", lambda: _renderer().render_pixels([0], 0, 1, 0, 0), "direct_samples"),
    ("intersect-nan-origin", lambda: _renderer().intersect(_nan((2, 3)), np.ones((2, 3), F32)), "origins"),
    (
        "intersect-inf-direction",
        lambda: _renderer().intersect(np.ones((2, 3), F32), np.full((2, 3), np.inf, F32)),
        "directions",
    ),
    (
        "intersect-zero-direction",
        lambda: _renderer().intersect(np.ones((2, 3), F32), np.zeros((2, 3), F32)),
        "directions",
    ),
    ("intersect-(2,0)", lambda: _renderer().intersect(np.zeros((2, 0), F32), np.zeros((2, 0), F32)), "origins"),
    ("intersect-threads-0", lambda: _renderer().intersect(np.ones((2, 3), F32), np.ones((2, 3), F32), 0), "threads"),
    ("intersect-float64", lambda: _renderer().intersect(np.ones((2, 3)), np.ones((2, 3), F32)), "origins"),
    # compare_rendering
    ("compare-channels-0", _compare(direct=np.zeros((4, 2, 0), F32)), "direct"),
    ("compare-no-half", _compare(halves=[], counts=()), "counts"),
    ("compare-count-0", _compare(counts=(0,)), "counts"),
    ("compare-nan-direct", _compare(direct=_nan((4, 2, 3))), "direct"),
    ("compare-nan-half", _compare(halves=[_nan((4, 2, 3))]), "halves"),
    ("compare-nan-observed", _compare(observed=_nan((4, 5, 3))), "observed"),
    ("compare-first-outside", _compare(first=4), "observed"),
    ("compare-first-overflows", _compare(first=2**64 - 1), "observed"),
    ("compare-keep-shape", _compare(keep=np.ones((4, 2), bool)), "keep"),
    ("compare-float64", _compare(direct=np.zeros((4, 2, 3))), "direct"),
    # denoise_indirect
    (
        "denoise-height-0",
        _denoise(mask=np.ones((0, W), bool), height_px=np.zeros((0, W), F32), albedo=np.zeros((0, W, 3), F32)),
        "mask",
    ),
    ("denoise-nan-indirect", _denoise(indirect=_nan((2, H * W, 3))), "indirect"),
    ("denoise-nan-energy", _denoise(noise_energy=_nan((H * W,), np.float64)), "noise_energy"),
    ("denoise-nan-height", _denoise(height_px=_nan((H, W))), "height_px"),
    ("denoise-nan-albedo", _denoise(albedo=_nan((H, W, 3))), "albedo"),
    ("denoise-indirect-shape", _denoise(indirect=np.zeros((2, 5, 3), F32)), "indirect"),
    ("denoise-float32-energy", _denoise(noise_energy=np.zeros(H * W, F32)), "noise_energy"),
    # SparseCholesky
    ("cholesky-empty", _sparse((), (), ()), "matrix"),
    ("cholesky-0x0", _sparse((0,), (), ()), "matrix"),
    ("cholesky-nan", _sparse(data=(np.nan,)), "matrix"),
    ("cholesky-row-outside", _sparse(indices=(5,)), "matrix"),
    ("cholesky-indptr-outside", _sparse((0, 5, 1), (0,), (1.0,)), "matrix"),
    ("cholesky-negative-index", _sparse(indices=(-1,)), "matrix"),
    ("cholesky-float32-data", _sparse(dtypes=(np.int64, np.int64, np.float32)), "data"),
    ("solve-empty", lambda: _cholesky().solve(np.zeros(0)), "b"),
    ("solve-nan", lambda: _cholesky().solve(np.array([np.nan])), "b"),
    ("solve-float32", lambda: _cholesky().solve(np.ones(1, F32)), "b"),
    # integrate_bilateral
    ("bilateral-nan-normal", _bilateral(normals=_nan((H, W, 3))), "normals"),
    ("bilateral-normals-shape", _bilateral(normals=np.zeros((H, W + 1, 3), F32)), "normals"),
    ("bilateral-float64", _bilateral(normals=np.zeros((H, W, 3))), "normals"),
    ("bilateral-focal-0", _bilateral(intrinsics=(0.0, 1.0, 1.0, 1.0)), "intrinsics"),
    ("bilateral-nan-centre", _bilateral(intrinsics=(1.0, 1.0, np.nan, 1.0)), "intrinsics"),
    ("bilateral-sharpness-nan", _bilateral(sharpness=np.nan), "sharpness"),
    ("bilateral-tolerance-negative", _bilateral(tolerance=-1.0), "tolerance"),
    ("bilateral-iterations-negative", _bilateral(max_iterations=-1), "max_iterations"),
]


def _message(error: BaseException) -> str:
    return "\n".join([str(error), *getattr(error, "__notes__", [])])


def _assert_clean(call, argument):
    with pytest.raises(BaseException) as caught:
        call()
    error = caught.value
    assert type(error).__name__ != "PanicException", _message(error)
    assert isinstance(error, Exception), repr(error)
    assert argument in _message(error), _message(error)
    if isinstance(error, ArgumentError):
        assert argument in error.argument, str(error)
    return error


@pytest.mark.parametrize("call, argument", [case[1:] for case in CASES], ids=[case[0] for case in CASES])
def test_hostile_input_is_a_clean_exception_naming_the_argument(call, argument):
    _assert_clean(call, argument)


def test_wrong_dtypes_are_type_errors_and_core_refusals_argument_errors():
    assert isinstance(_assert_clean(_ps(IMAGES.astype(np.float64)), "images"), TypeError)
    assert isinstance(_assert_clean(_ps(np.zeros((4, 0, W, 3), F32), np.zeros((0, W), bool)), "images"), ArgumentError)


# Files -------------------------------------------------------------------------------------


def _arrays_to_write():
    return [
        ("empty", np.zeros((0, 0), F32)),
        ("height-0", np.zeros((0, 5, 3), F32)),
        ("width-0", np.zeros((5, 0), F32)),
        ("1-dimensional", np.zeros(5, F32)),
        ("float64", np.zeros((2, 2))),
    ]


@pytest.mark.parametrize("name, array", _arrays_to_write(), ids=[case[0] for case in _arrays_to_write()])
@pytest.mark.parametrize("writer", ["exr", "png"])
def test_writing_an_array_without_a_pixel_is_refused(writer, name, array, tmp_path):
    path = tmp_path / f"out.{writer}"
    call = (
        (lambda: _core.write_exr(str(path), array))
        if writer == "exr"
        else (lambda: _core.write_png(str(path), array, 8))
    )
    _assert_clean(call, "array")
    assert not path.exists()


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_a_png_of_a_non_finite_value_is_refused_by_row_and_column(value, tmp_path):
    array = np.zeros((2, 3), F32)
    array[1, 2] = value
    error = _assert_clean(lambda: _core.write_png(str(tmp_path / "out.png"), array, 8), "array")
    shown = {"nan": "NaN", "inf": "inf", "-inf": "-inf"}[str(value)]
    assert str(error) == f"array: non-finite value {shown} at row 1, column 2"
    assert not (tmp_path / "out.png").exists()


def test_a_bit_depth_out_of_range_names_it(tmp_path):
    _assert_clean(lambda: _core.write_png(str(tmp_path / "out.png"), np.zeros((2, 2), F32), 300), "bit_depth")
    _assert_clean(lambda: _core.write_png(str(tmp_path / "out.png"), np.zeros((2, 2), F32), 12), "bit_depth")


@pytest.mark.parametrize("suffix", ["exr", "png"])
def test_reading_an_empty_file_names_it(suffix, tmp_path):
    path = tmp_path / f"empty.{suffix}"
    path.write_bytes(b"")
    reader = _core.read_exr if suffix == "exr" else _core.read_png
    _assert_clean(lambda: reader(str(path)), str(path))
    _assert_clean(lambda: _core.read_images([str(path)]), str(path))


def test_reading_no_image_and_a_wrong_path_type_name_the_argument():
    _assert_clean(lambda: _core.read_images([]), "paths")
    _assert_clean(lambda: _core.read_exr(5), "path")
    _assert_clean(lambda: _core.read_images("a.png"), "paths")


# Empty batches: an empty result, not an error -----------------------------------------------


def test_empty_batches_give_empty_results():
    renderer = _renderer()
    t, triangle = renderer.intersect(np.zeros((0, 3), F32), np.zeros((0, 3), F32))
    assert t.shape == (0,) and triangle.shape == (0,)
    assert renderer.render_pixels([], 1, 1, 1, 0).shape == (2, 4, 0, 3)
    indirect, energy, sums = _compare(np.zeros((4, 0, 3), F32), [np.zeros((4, 0, 3), F32)])()
    assert indirect.shape == (4, 0, 3) and energy.shape == (0,) and sums == (0.0, 0.0, 0.0, 0.0)
    filtered, energy = _denoise(mask=np.zeros((H, W), bool))()
    assert filtered.shape == (2, 0, 3) and energy.shape == (0,)
    (normals, _, flags, _), checked = _check(check=())()
    assert normals.shape == (H, W, 3) and flags.shape == (H, W) and checked.shape == (0,)


# The public API --------------------------------------------------------------------------------


@pytest.mark.parametrize("robust", ["auto", "tukey", "lobe", "none"])
@pytest.mark.parametrize("shape", [(4, 0, W, 3), (4, H, 0, 3), (4, 0, 0, 3)])
def test_photometric_stereo_of_images_without_a_pixel_is_an_argument_error(shape, robust):
    images = np.zeros(shape)
    with pytest.raises(ArgumentError) as error:
        irtps.photometric_stereo(images, LIGHTS, IRRADIANCE, np.ones(shape[1:3], bool), robust=robust)
    assert str(error.value).startswith(f"images: shape {shape} is empty")
