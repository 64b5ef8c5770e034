//! The pyo3 bindings (`irtps._core`): conversions only. Heavy work runs with the GIL
//! released, and every core error becomes, here and only here, the Python exception that
//! irtps raises for it: `irtps.errors.ArgumentError` for an argument, `DatasetError` for a
//! file, `MemoryError` for a buffer that could not be allocated. Their types for Python
//! are in python/irtps/_core.pyi.

use std::borrow::Cow;
use std::path::PathBuf;

use glam::vec3a;
use numpy::ndarray::{Array, Array2, IxDyn};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayDyn, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyReadonlyArray4, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyMemoryError, PyValueError};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::error::Error;
use crate::integrate::sparse_cholesky::SparseCholesky as CoreSparseCholesky;
use crate::io::{self, Image};
use crate::memory::{try_collect, try_vec};
use crate::ps::{
    check_lights as core_check_lights, photometric_stereo as core_ps,
    tukey_with_lobe_check as core_tukey_with_lobe_check, PsOutput, PsSettings, Robust,
};
use crate::render::denoise::{denoise as core_denoise, Surface};
use crate::render::residual::{compare as core_compare, Observed, RenderedPlanes};
use crate::render::{RenderSettings, Renderer as CoreRenderer};
use crate::scene::{Camera, CornellBox, Floor, HeightField, Light, Rgb, Scene};

/// Rays a parallel task of `Renderer.intersect` traces as one batch.
const RAYS_PER_TASK: usize = 4096;

pyo3::import_exception!(irtps.errors, ArgumentError);
pyo3::import_exception!(irtps.errors, DatasetError);

/// `irtps.errors.ArgumentError(argument, problem)`: the message starts with the argument.
fn argument_error(argument: &str, problem: impl Into<String>) -> PyErr {
    ArgumentError::new_err((argument.to_string(), problem.into()))
}

fn to_py(err: Error) -> PyErr {
    match err {
        Error::Input { field, message } => argument_error(&field, message),
        Error::Io { .. } | Error::Format { .. } => DatasetError::new_err(err.to_string()),
        Error::Memory { .. } => PyMemoryError::new_err(err.to_string()),
    }
}

fn image_to_array(py: Python<'_>, image: Image) -> PyResult<Bound<'_, PyArrayDyn<f32>>> {
    let shape = if image.channels == 1 {
        vec![image.height, image.width]
    } else {
        vec![image.height, image.width, image.channels]
    };
    let array = Array::from_shape_vec(IxDyn(&shape), image.data)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(array.into_pyarray(py))
}

/// The (H, W) or (H, W, C) array `array` as an image, refused by `name` unless it has a
/// pixel.
fn array_to_image(array: &PyReadonlyArrayDyn<'_, f32>, name: &str) -> PyResult<Image> {
    let shape = array.shape();
    let (height, width, channels) = match *shape {
        [h, w] => (h, w, 1),
        [h, w, c] => (h, w, c),
        _ => {
            return Err(argument_error(
                name,
                format!("expected an (H, W) or (H, W, C) array, got shape {shape:?}"),
            ))
        }
    };
    if height == 0 || width == 0 {
        return Err(argument_error(
            name,
            format!("shape {shape:?} has no pixel"),
        ));
    }
    let data = flat(array, name)?.into_owned();
    Ok(Image {
        width,
        height,
        channels,
        data,
    })
}

/// `err` with the core's input `field` renamed `argument`, the binding's name for it.
fn renamed(err: Error, field: &str, argument: &str) -> Error {
    match err {
        Error::Input { field: f, message } if f == field => Error::input(argument, message),
        other => other,
    }
}

/// Reads an OpenEXR file: float32 (H, W, 3) for R, G, B or (H, W) for a single Y channel.
#[pyfunction]
fn read_exr(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArrayDyn<f32>>> {
    let image = py
        .detach(|| io::exr_image::read_exr(&path))
        .map_err(to_py)?;
    image_to_array(py, image)
}

/// Writes a float32 (H, W) array as a Y channel or (H, W, 3) as R, G, B to OpenEXR.
#[pyfunction]
fn write_exr(py: Python<'_>, path: PathBuf, array: PyReadonlyArrayDyn<'_, f32>) -> PyResult<()> {
    let image = array_to_image(&array, "array")?;
    py.detach(|| io::exr_image::write_exr(&path, &image))
        .map_err(|e| to_py(renamed(e, "image", "array")))
}

/// Reads an 8- or 16-bit PNG: (values / (2^bits − 1) as float32, (H, W) or (H, W, 3); bits).
#[pyfunction]
fn read_png(py: Python<'_>, path: PathBuf) -> PyResult<(Bound<'_, PyArrayDyn<f32>>, u8)> {
    let (image, bits) = py
        .detach(|| io::png_image::read_png(&path))
        .map_err(to_py)?;
    Ok((image_to_array(py, image)?, bits))
}

/// Writes float32 values in [0, 1], (H, W) gray or (H, W, 3) RGB, as an 8- or 16-bit PNG.
#[pyfunction]
fn write_png(
    py: Python<'_>,
    path: PathBuf,
    array: PyReadonlyArrayDyn<'_, f32>,
    bit_depth: u8,
) -> PyResult<()> {
    let image = array_to_image(&array, "array")?;
    py.detach(|| io::png_image::write_png(&path, &image, bit_depth))
        .map_err(|e| to_py(renamed(e, "image", "array")))
}

/// Reads EXR/PNG images in parallel into one float32 (K, H, W, 3) array.
#[pyfunction]
fn read_images(py: Python<'_>, paths: Vec<PathBuf>) -> PyResult<Bound<'_, PyArrayDyn<f32>>> {
    let (width, height, data) = py
        .detach(|| io::stack::read_image_stack(&paths))
        .map_err(to_py)?;
    let array = Array::from_shape_vec(IxDyn(&[paths.len(), height, width, 3]), data)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(array.into_pyarray(py))
}

fn rows_of_3(array: &PyReadonlyArray2<'_, f32>, name: &str) -> PyResult<Vec<[f32; 3]>> {
    let a = array.as_array();
    if a.ncols() != 3 {
        return Err(argument_error(
            name,
            format!("expected shape (N, 3), got {:?}", a.shape()),
        ));
    }
    Ok(a.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// The rows of an (N, 3) array of finite values as one flat slice: borrowed when the array
/// is C-contiguous, copied otherwise.
fn flat_rows_of_3<'a>(
    array: &'a PyReadonlyArray2<'_, f32>,
    name: &str,
) -> PyResult<Cow<'a, [f32]>> {
    if array.shape()[1] != 3 {
        return Err(argument_error(
            name,
            format!("expected shape (N, 3), got {:?}", array.shape()),
        ));
    }
    let values = flat(array, name)?;
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(argument_error(
            name,
            format!("non-finite value {} in row {}", values[index], index / 3),
        ));
    }
    Ok(values)
}

/// An array's values in C order: borrowed when the array is C-contiguous, copied otherwise
/// (a `MemoryError` naming `name` when the copy cannot be allocated).
fn flat<'a, T: numpy::Element + Copy, D: numpy::ndarray::Dimension>(
    array: &'a numpy::PyReadonlyArray<'_, T, D>,
    name: &str,
) -> PyResult<Cow<'a, [T]>> {
    // numpy's own `as_slice` also lends Fortran-ordered data: ndarray's `to_slice` only C order.
    let view = array.as_array();
    match view.to_slice() {
        Some(values) => Ok(Cow::Borrowed(values)),
        None => Ok(Cow::Owned(
            try_collect(
                &format!("a C-ordered copy of {name}"),
                view.len(),
                view.iter().copied(),
            )
            .map_err(to_py)?,
        )),
    }
}

/// Distances (inf on a miss) and triangle indices (−1 on a miss) of a batch of rays.
type HitArrays<'py> = (Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<i64>>);

/// Positions, triangles, vertex albedo and triangle normals of a scene's mesh.
type MeshArrays<'py> = (
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray2<u32>>,
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray2<f32>>,
);

/// The floor as Python gives it: `irtps.scene.Floor` (or any object with these attributes).
#[derive(FromPyObject)]
struct FloorArgs {
    #[pyo3(attribute)]
    height: f32,
    #[pyo3(attribute)]
    albedo: Rgb,
}

/// The Cornell box as Python gives it: `irtps.scene.CornellBox` (or any object with these
/// attributes).
#[derive(FromPyObject)]
struct BoxArgs {
    #[pyo3(attribute)]
    x: (f32, f32),
    #[pyo3(attribute)]
    y: (f32, f32),
    #[pyo3(attribute)]
    z_top: f32,
    #[pyo3(attribute)]
    albedo_left: Rgb,
    #[pyo3(attribute)]
    albedo_right: Rgb,
    #[pyo3(attribute)]
    albedo_back: Rgb,
    #[pyo3(attribute)]
    albedo_front: Rgb,
}

/// A scene made ready for rendering and ray queries: height-field object, optional floor
/// and Cornell box, distant lights.
///
/// Parameters: `height` (H, W) float32, `mask` (H, W) bool, `albedo` (H, W, 3) float32,
/// `pixel_size`, `light_directions` (K, 3), `light_irradiance` (K, 3), `floor` an
/// `irtps.scene.Floor` or None, `cornell_box` an `irtps.scene.CornellBox` or None.
#[pyclass(frozen, module = "irtps._core")]
struct Renderer {
    inner: CoreRenderer,
}

#[pymethods]
impl Renderer {
    #[new]
    #[pyo3(signature = (height, mask, albedo, pixel_size, light_directions, light_irradiance, floor=None, cornell_box=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        height: PyReadonlyArray2<'_, f32>,
        mask: PyReadonlyArray2<'_, bool>,
        albedo: PyReadonlyArray3<'_, f32>,
        pixel_size: f32,
        light_directions: PyReadonlyArray2<'_, f32>,
        light_irradiance: PyReadonlyArray2<'_, f32>,
        floor: Option<FloorArgs>,
        cornell_box: Option<BoxArgs>,
    ) -> PyResult<Renderer> {
        let (h, w) = (height.shape()[0], height.shape()[1]);
        if mask.shape() != [h, w] {
            return Err(argument_error(
                "mask",
                format!("shape {:?} differs from height {:?}", mask.shape(), [h, w]),
            ));
        }
        if albedo.shape() != [h, w, 3] {
            return Err(argument_error(
                "albedo",
                format!("shape {:?}, expected {:?}", albedo.shape(), [h, w, 3]),
            ));
        }
        let directions = rows_of_3(&light_directions, "light_directions")?;
        let irradiance = rows_of_3(&light_irradiance, "light_irradiance")?;
        if directions.len() != irradiance.len() {
            return Err(argument_error(
                "light_irradiance",
                "needs one row per light direction",
            ));
        }
        let albedo_values = flat(&albedo, "albedo")?;
        let surface = HeightField {
            height: flat(&height, "height")?.into_owned(),
            mask: flat(&mask, "mask")?.into_owned(),
            albedo: albedo_values
                .chunks_exact(3)
                .map(|p| [p[0], p[1], p[2]])
                .collect(),
        };
        let scene = Scene {
            camera: Camera {
                width: w,
                height: h,
                pixel_size,
            },
            surface,
            floor: floor.map(|floor| Floor {
                height: floor.height,
                albedo: floor.albedo,
            }),
            cornell_box: cornell_box.map(|walls| CornellBox {
                x: [walls.x.0, walls.x.1],
                y: [walls.y.0, walls.y.1],
                z_top: walls.z_top,
                left: walls.albedo_left,
                right: walls.albedo_right,
                back: walls.albedo_back,
                front: walls.albedo_front,
            }),
        };
        let lights: Vec<Light> = directions
            .iter()
            .zip(&irradiance)
            .map(|(d, e)| Light {
                direction: vec3a(d[0], d[1], d[2]),
                irradiance: *e,
            })
            .collect();
        let inner = py
            .detach(|| CoreRenderer::new(&scene, &lights))
            .map_err(|e| {
                to_py(renamed(
                    renamed(e, "camera", "height"),
                    "camera.pixel_size",
                    "pixel_size",
                ))
            })?;
        Ok(Renderer { inner })
    }

    /// The same scene with the object's albedo `albedo` (H, W, 3) and each light's
    /// irradiance `light_irradiance` (K, 3): the geometry, its BVH and the light visibility
    /// are kept, not built or traced again.
    fn with_reflectance(
        &self,
        py: Python<'_>,
        albedo: PyReadonlyArray3<'_, f32>,
        light_irradiance: PyReadonlyArray2<'_, f32>,
    ) -> PyResult<Renderer> {
        let camera = self.inner.camera();
        if albedo.shape() != [camera.height, camera.width, 3] {
            return Err(argument_error(
                "albedo",
                format!(
                    "shape {:?}, expected {:?}",
                    albedo.shape(),
                    [camera.height, camera.width, 3]
                ),
            ));
        }
        let values = flat(&albedo, "albedo")?;
        let albedo: Vec<Rgb> = values.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
        let irradiance = rows_of_3(&light_irradiance, "light_irradiance")?;
        let inner = py
            .detach(|| self.inner.with_reflectance(&albedo, &irradiance))
            .map_err(|e| to_py(renamed(e, "irradiance", "light_irradiance")))?;
        Ok(Renderer { inner })
    }

    /// Number of triangles in the scene.
    #[getter]
    fn triangle_count(&self) -> usize {
        self.inner.tracer().len()
    }

    /// Number of lights.
    #[getter]
    fn light_count(&self) -> usize {
        self.inner.light_count()
    }

    /// Renders rows `row_start..row_end`: float32 (P, K, rows, W, 3) whose planes are the
    /// direct image (when `direct_samples` > 0), then each inter-reflection bounce
    /// (`split_bounces`) or their sum.
    #[pyo3(signature = (row_start, row_end, bounces, samples, direct_samples, seed, split_bounces=true))]
    #[allow(clippy::too_many_arguments)]
    fn render_rows<'py>(
        &self,
        py: Python<'py>,
        row_start: usize,
        row_end: usize,
        bounces: usize,
        samples: usize,
        direct_samples: usize,
        seed: u64,
        split_bounces: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let settings = RenderSettings {
            bounces,
            samples,
            direct_samples,
            seed,
            split_bounces,
            cached_direct: false,
        };
        let data = py
            .detach(|| self.inner.render_rows(row_start..row_end, &settings))
            .map_err(to_py)?;
        let shape = [
            settings.planes(),
            self.inner.light_count(),
            row_end - row_start,
            self.inner.camera().width,
            3,
        ];
        let array = Array::from_shape_vec(IxDyn(&shape), data)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(array.into_pyarray(py))
    }

    /// Renders the listed pixels (row-major indices): float32 (P, K, N, 3), planes as in
    /// `render_rows`; `cached_direct` shades the direct image from the light cache (no
    /// shadow rays) instead of exactly.
    #[pyo3(signature = (pixels, bounces, samples, direct_samples, seed, split_bounces=true, cached_direct=false))]
    #[allow(clippy::too_many_arguments)]
    fn render_pixels<'py>(
        &self,
        py: Python<'py>,
        pixels: Vec<usize>,
        bounces: usize,
        samples: usize,
        direct_samples: usize,
        seed: u64,
        split_bounces: bool,
        cached_direct: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let settings = RenderSettings {
            bounces,
            samples,
            direct_samples,
            seed,
            split_bounces,
            cached_direct,
        };
        let data = py
            .detach(|| self.inner.render_pixels(&pixels, &settings))
            .map_err(to_py)?;
        let shape = [settings.planes(), self.inner.light_count(), pixels.len(), 3];
        let array = Array::from_shape_vec(IxDyn(&shape), data)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(array.into_pyarray(py))
    }

    /// The scene's triangles: (positions (V, 3) float32 in world units, triangles (T, 3) uint32, vertex
    /// albedo (V, 3) float32, facing unit normals (T, 3) float32).
    fn mesh_arrays<'py>(&self, py: Python<'py>) -> MeshArrays<'py> {
        let (mesh, frame) = (self.inner.mesh(), self.inner.frame());
        let positions = Array2::from_shape_fn((mesh.positions.len(), 3), |(i, c)| {
            frame.to_world(mesh.positions[i])[c]
        });
        let triangles =
            Array2::from_shape_fn((mesh.triangles.len(), 3), |(t, c)| mesh.triangles[t][c]);
        let albedo = Array2::from_shape_fn((mesh.albedo.len(), 3), |(i, c)| mesh.albedo[i][c]);
        let normals = Array2::from_shape_fn((mesh.normals.len(), 3), |(t, c)| mesh.normals[t][c]);
        (
            positions.into_pyarray(py),
            triangles.into_pyarray(py),
            albedo.into_pyarray(py),
            normals.into_pyarray(py),
        )
    }

    /// Closest hits of a batch of rays, traced on `threads` threads (all cores if None) in
    /// tasks of [`RAYS_PER_TASK`] rays:
    /// (distance (N,) float32, inf on a miss; triangle (N,) int64, −1 on a miss).
    #[pyo3(signature = (origins, directions, threads=None))]
    fn intersect<'py>(
        &self,
        py: Python<'py>,
        origins: PyReadonlyArray2<'_, f32>,
        directions: PyReadonlyArray2<'_, f32>,
        threads: Option<usize>,
    ) -> PyResult<HitArrays<'py>> {
        let o = flat_rows_of_3(&origins, "origins")?;
        let d = flat_rows_of_3(&directions, "directions")?;
        if o.len() != d.len() {
            return Err(argument_error("directions", "needs one row per origin"));
        }
        if let Some(row) = d.chunks_exact(3).position(|d| d == [0.0; 3]) {
            return Err(argument_error(
                "directions",
                format!("row {row} is the zero vector"),
            ));
        }
        if threads == Some(0) {
            return Err(argument_error(
                "threads",
                "must be at least 1 (None: all cores)",
            ));
        }
        let (tracer, frame) = (self.inner.tracer(), self.inner.frame());
        let rays = o.len() / 3;
        let mut t = try_vec(
            &format!("the distances of {rays} rays"),
            rays,
            f32::INFINITY,
        )
        .map_err(to_py)?;
        let mut id =
            try_vec(&format!("the triangles of {rays} rays"), rays, -1i64).map_err(to_py)?;
        // A batch of rays (flat xyz rows) into its outputs.
        let batch = |t: &mut [f32], id: &mut [i64], o: &[f32], d: &[f32]| {
            let mut out = t.iter_mut().zip(id.iter_mut());
            let rays = o.chunks_exact(3).zip(d.chunks_exact(3)).map(|(o, d)| {
                (
                    frame.to_local(vec3a(o[0], o[1], o[2])),
                    vec3a(d[0], d[1], d[2]),
                )
            });
            tracer.closest_hits(rays, f32::INFINITY, |hit| {
                if let (Some((t, id)), Some(hit)) = (out.next(), hit) {
                    (*t, *id) = (frame.to_world_length(hit.t), hit.triangle as i64);
                }
            });
        };
        let parallel = |t: &mut [f32], id: &mut [i64]| {
            t.par_chunks_mut(RAYS_PER_TASK)
                .zip(id.par_chunks_mut(RAYS_PER_TASK))
                .zip(
                    o.par_chunks(3 * RAYS_PER_TASK)
                        .zip(d.par_chunks(3 * RAYS_PER_TASK)),
                )
                .for_each(|((t, id), (o, d))| batch(t, id, o, d))
        };
        py.detach(|| -> PyResult<()> {
            match threads {
                None => parallel(&mut t, &mut id),
                // One thread: one batch, without a pool or work splitting.
                Some(1) => batch(&mut t, &mut id, &o, &d),
                Some(n) => {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(n)
                        .build()
                        .map_err(|e| argument_error("threads", format!("{e}")))?;
                    pool.install(|| parallel(&mut t, &mut id));
                }
            }
            Ok(())
        })?;
        Ok((PyArray1::from_vec(py, t), PyArray1::from_vec(py, id)))
    }
}

fn lights_from(
    directions: &PyReadonlyArray2<'_, f32>,
    irradiance: &PyReadonlyArray2<'_, f32>,
) -> PyResult<Vec<Light>> {
    let directions = rows_of_3(directions, "light_directions")?;
    let irradiance = rows_of_3(irradiance, "light_irradiance")?;
    if directions.len() != irradiance.len() {
        return Err(argument_error(
            "light_irradiance",
            "needs one row per light direction",
        ));
    }
    Ok(directions
        .iter()
        .zip(&irradiance)
        .map(|(d, e)| Light {
            direction: vec3a(d[0], d[1], d[2]),
            irradiance: *e,
        })
        .collect())
}

/// Checks lights for photometric stereo: at least 3, not (nearly) coplanar, irradiance
/// positive in every channel. Raises ValueError naming the field otherwise.
#[pyfunction]
fn check_lights(
    light_directions: PyReadonlyArray2<'_, f32>,
    light_irradiance: PyReadonlyArray2<'_, f32>,
) -> PyResult<()> {
    let lights = lights_from(&light_directions, &light_irradiance)?;
    core_check_lights(&lights).map(|_| ()).map_err(to_py)
}

type PsArrays<'py> = (
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<u8>>,
    Bound<'py, PyArrayDyn<u16>>,
);

/// Calibrated Lambertian photometric stereo on C-contiguous float32 images (K, H, W, 3):
/// (normals (H, W, 3), albedo (H, W, 3), flags (H, W) uint8, observations used (H, W) uint16).
/// `robust` is "none", "threshold", "trim", "tukey" or "lobe"; `lobe_rounds` the lobe mode's
/// most rounds per exponent and start (at least 1; its 15 by default).
#[pyfunction]
#[pyo3(signature = (images, mask, light_directions, light_irradiance, robust="tukey", shadow_fraction=0.05, saturation=None, lobe_rounds=None))]
#[allow(clippy::too_many_arguments)]
fn photometric_stereo<'py>(
    py: Python<'py>,
    images: PyReadonlyArray4<'_, f32>,
    mask: PyReadonlyArray2<'_, bool>,
    light_directions: PyReadonlyArray2<'_, f32>,
    light_irradiance: PyReadonlyArray2<'_, f32>,
    robust: &str,
    shadow_fraction: f32,
    saturation: Option<f32>,
    lobe_rounds: Option<usize>,
) -> PyResult<PsArrays<'py>> {
    let robust = match robust {
        "none" => Robust::None,
        "threshold" => Robust::Threshold,
        "trim" => Robust::Trim,
        "tukey" => Robust::Tukey,
        "lobe" => Robust::Lobe,
        other => {
            return Err(argument_error(
                "robust",
                format!("unknown mode {other:?}; expected none, threshold, trim, tukey or lobe"),
            ))
        }
    };
    let PsInputs {
        shape,
        lights,
        data,
        mask: mask_data,
    } = ps_inputs(&images, &mask, &light_directions, &light_irradiance)?;
    let settings = PsSettings {
        robust,
        shadow_fraction,
        saturation,
        lobe_rounds: lobe_rounds.unwrap_or(crate::ps::lobe::LOBE_ROUNDS),
    };
    let out = py
        .detach(|| core_ps(data, mask_data, &lights, &settings))
        .map_err(to_py)?;
    ps_arrays(py, out, shape[1], shape[2])
}

/// The inputs of a photometric-stereo call, checked against each other.
struct PsInputs<'a> {
    /// The images' (K, H, W, 3).
    shape: Vec<usize>,
    lights: Vec<Light>,
    /// The images' values, row-major.
    data: &'a [f32],
    /// The mask's values, row-major.
    mask: &'a [bool],
}

/// The images, mask and lights of a photometric-stereo call, checked against each other.
fn ps_inputs<'a>(
    images: &'a PyReadonlyArray4<'_, f32>,
    mask: &'a PyReadonlyArray2<'_, bool>,
    light_directions: &PyReadonlyArray2<'_, f32>,
    light_irradiance: &PyReadonlyArray2<'_, f32>,
) -> PyResult<PsInputs<'a>> {
    let shape = images.shape().to_vec();
    if shape[3] != 3 || mask.shape() != [shape[1], shape[2]] {
        return Err(argument_error(
            "images",
            format!(
                "shape {shape:?} does not match mask {:?} x 3 channels",
                mask.shape()
            ),
        ));
    }
    let lights = lights_from(light_directions, light_irradiance)?;
    if lights.len() != shape[0] {
        return Err(argument_error(
            "images",
            format!("{} images for {} lights", shape[0], lights.len()),
        ));
    }
    let data = images
        .as_array()
        .to_slice()
        .ok_or_else(|| argument_error("images", "must be C-contiguous"))?;
    let mask_data = mask
        .as_array()
        .to_slice()
        .ok_or_else(|| argument_error("mask", "must be C-contiguous"))?;
    Ok(PsInputs {
        shape,
        lights,
        data,
        mask: mask_data,
    })
}

/// `out` as the arrays of [`photometric_stereo`], for images `h` × `w`.
fn ps_arrays(py: Python<'_>, out: PsOutput, h: usize, w: usize) -> PyResult<PsArrays<'_>> {
    let planar = |v: Vec<[f32; 3]>| Array::from_shape_vec(IxDyn(&[h, w, 3]), v.into_flattened());
    let err = |e: numpy::ndarray::ShapeError| PyValueError::new_err(e.to_string());
    Ok((
        planar(out.normals).map_err(err)?.into_pyarray(py),
        planar(out.albedo).map_err(err)?.into_pyarray(py),
        Array::from_shape_vec(IxDyn(&[h, w]), out.flags)
            .map_err(err)?
            .into_pyarray(py),
        Array::from_shape_vec(IxDyn(&[h, w]), out.used)
            .map_err(err)?
            .into_pyarray(py),
    ))
}

/// The auto mode's fits at once: [`photometric_stereo`] of `images` in the Tukey mode and,
/// on the same threads, of the pixels `check` (flat indices into the mask) in the lobe mode
/// with `check_rounds` rounds. Returns the Tukey fit's arrays and the flag of each pixel of
/// `check`.
#[pyfunction]
#[pyo3(signature = (images, mask, check, light_directions, light_irradiance, shadow_fraction, saturation, check_rounds))]
#[allow(clippy::too_many_arguments)]
fn tukey_with_lobe_check<'py>(
    py: Python<'py>,
    images: PyReadonlyArray4<'_, f32>,
    mask: PyReadonlyArray2<'_, bool>,
    check: Vec<usize>,
    light_directions: PyReadonlyArray2<'_, f32>,
    light_irradiance: PyReadonlyArray2<'_, f32>,
    shadow_fraction: f32,
    saturation: Option<f32>,
    check_rounds: usize,
) -> PyResult<(PsArrays<'py>, Bound<'py, PyArray1<u8>>)> {
    let PsInputs {
        shape,
        lights,
        data,
        mask: mask_data,
    } = ps_inputs(&images, &mask, &light_directions, &light_irradiance)?;
    let settings = PsSettings {
        robust: Robust::Tukey,
        shadow_fraction,
        saturation,
        lobe_rounds: crate::ps::lobe::LOBE_ROUNDS,
    };
    let (fit, flags) = py
        .detach(|| {
            core_tukey_with_lobe_check(data, mask_data, &check, &lights, &settings, check_rounds)
        })
        .map_err(to_py)?;
    Ok((
        ps_arrays(py, fit, shape[1], shape[2])?,
        PyArray1::from_vec(py, flags),
    ))
}

/// A rendering's inter-reflection estimate, the noise energy of each pixel's estimate and
/// the residual's sums.
type ComparisonArrays<'py> = (
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray1<f64>>,
    (f64, f64, f64, f64),
);

/// Compares a rendering of N pixels under K lights with their observations: the direct
/// image `direct` and the inter-reflected light of one or two halves of the camera paths,
/// `halves`, of `counts` paths a pixel each, all (K, N, 3), against pixels `first..first + N`
/// of `observed` (K, T, 3). Returns (the inter-reflected light (K, N, 3), each pixel's
/// Monte-Carlo noise energy (N,) (0 with one half), (Σ|rendered − observed|, Σ|observed|,
/// and Σ|direct + half − observed| for each half)), the sums over the observations whose
/// `keep` (K, T) is true.
#[pyfunction]
#[pyo3(signature = (direct, halves, counts, observed, keep=None, first=0))]
#[allow(clippy::too_many_arguments)]
fn compare_rendering<'py>(
    py: Python<'py>,
    direct: PyReadonlyArray3<'_, f32>,
    halves: Vec<PyReadonlyArray3<'_, f32>>,
    counts: Vec<usize>,
    observed: PyReadonlyArray3<'_, f32>,
    keep: Option<PyReadonlyArray2<'_, bool>>,
    first: usize,
) -> PyResult<ComparisonArrays<'py>> {
    let shape = direct.shape().to_vec();
    if shape[2] != 3 {
        return Err(argument_error(
            "direct",
            format!("expected shape (K, N, 3), got {shape:?}"),
        ));
    }
    let (lights, pixels) = (shape[0], shape[1]);
    for half in &halves {
        if half.shape() != shape.as_slice() {
            return Err(argument_error(
                "halves",
                format!("shape {:?} differs from direct {shape:?}", half.shape()),
            ));
        }
    }
    let total = observed.shape()[1];
    if observed.shape()[0] != lights
        || observed.shape()[2] != 3
        || first.checked_add(pixels).is_none_or(|end| end > total)
    {
        return Err(argument_error(
            "observed",
            format!(
                "shape {:?} does not hold {pixels} pixels from {first} for {lights} lights",
                observed.shape()
            ),
        ));
    }
    if let Some(keep) = &keep {
        if keep.shape() != [lights, total] {
            return Err(argument_error(
                "keep",
                format!("shape {:?}, expected {:?}", keep.shape(), [lights, total]),
            ));
        }
    }
    let (direct, observed) = (flat(&direct, "direct")?, flat(&observed, "observed")?);
    let halves = halves
        .iter()
        .map(|half| flat(half, "halves"))
        .collect::<PyResult<Vec<_>>>()?;
    let keep = keep.as_ref().map(|keep| flat(keep, "keep")).transpose()?;
    let comparison = py
        .detach(|| {
            let half_slices: Vec<&[f32]> = halves.iter().map(|h| h.as_ref()).collect();
            let planes = RenderedPlanes {
                direct: &direct,
                halves: &half_slices,
                counts: &counts,
            };
            core_compare(
                &planes,
                &Observed {
                    values: &observed,
                    keep: keep.as_deref(),
                    total,
                    first,
                },
                lights,
                pixels,
            )
        })
        .map_err(to_py)?;
    let indirect = Array::from_shape_vec((lights, pixels, 3), comparison.indirect)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let sums = comparison.sums;
    Ok((
        indirect.into_pyarray(py),
        PyArray1::from_vec(py, comparison.noise_energy),
        (
            sums.difference,
            sums.observed,
            sums.half_difference[0],
            sums.half_difference[1],
        ),
    ))
}

/// A filtered inter-reflection estimate and each pixel's noise energy after the filter.
type DenoisedArrays<'py> = (Bound<'py, PyArray3<f32>>, Bound<'py, PyArray1<f64>>);

/// Filters the inter-reflection estimate `indirect` (K, N, 3) at the N pixels of `mask`
/// (H, W) in row-major order, and their noise energy `noise_energy` (N,), guided by the
/// surface: heights `height_px` (H, W) in pixels and `albedo` (H, W, 3) (`rust/denoise.rs`).
#[pyfunction]
fn denoise_indirect<'py>(
    py: Python<'py>,
    indirect: PyReadonlyArray3<'_, f32>,
    noise_energy: PyReadonlyArray1<'_, f64>,
    mask: PyReadonlyArray2<'_, bool>,
    height_px: PyReadonlyArray2<'_, f32>,
    albedo: PyReadonlyArray3<'_, f32>,
) -> PyResult<DenoisedArrays<'py>> {
    let (h, w) = (mask.shape()[0], mask.shape()[1]);
    if h == 0 || w == 0 {
        return Err(argument_error(
            "mask",
            format!("shape {:?} has no pixel", mask.shape()),
        ));
    }
    if height_px.shape() != [h, w] {
        return Err(argument_error(
            "height_px",
            format!(
                "shape {:?} differs from mask {:?}",
                height_px.shape(),
                [h, w]
            ),
        ));
    }
    if albedo.shape() != [h, w, 3] {
        return Err(argument_error(
            "albedo",
            format!("shape {:?}, expected {:?}", albedo.shape(), [h, w, 3]),
        ));
    }
    let pixels: Vec<usize> = mask
        .as_array()
        .iter()
        .enumerate()
        .filter_map(|(i, &inside)| inside.then_some(i))
        .collect();
    let shape = indirect.shape().to_vec();
    if shape[1..] != [pixels.len(), 3] {
        return Err(argument_error(
            "indirect",
            format!(
                "shape {shape:?}, expected (K, {}, 3) for the mask's pixels",
                pixels.len()
            ),
        ));
    }
    let (heights, albedo_all) = (flat(&height_px, "height_px")?, flat(&albedo, "albedo")?);
    let height_px: Vec<f32> = pixels.iter().map(|&i| heights[i]).collect();
    let albedo: Vec<Rgb> = pixels
        .iter()
        .map(|&i| {
            [
                albedo_all[3 * i],
                albedo_all[3 * i + 1],
                albedo_all[3 * i + 2],
            ]
        })
        .collect();
    let (indirect, noise_energy) = (
        flat(&indirect, "indirect")?,
        flat(&noise_energy, "noise_energy")?,
    );
    let surface = Surface {
        size: (w, h),
        pixels: &pixels,
        height_px: &height_px,
        albedo: &albedo,
    };
    let denoised = py
        .detach(|| core_denoise(&surface, &indirect, &noise_energy))
        .map_err(to_py)?;
    let filtered = Array::from_shape_vec((shape[0], shape[1], 3), denoised.indirect)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok((
        filtered.into_pyarray(py),
        PyArray1::from_vec(py, denoised.noise_energy),
    ))
}

/// Non-negative int64 indices as `usize`, or an error naming `name`.
fn indices_of(array: &PyReadonlyArray1<'_, i64>, name: &str) -> PyResult<Vec<usize>> {
    array
        .as_array()
        .iter()
        .map(|&i| {
            usize::try_from(i).map_err(|_| argument_error(name, format!("negative index {i}")))
        })
        .collect()
}

/// The Cholesky factorisation `L Lᵀ` of a sparse symmetric positive definite matrix,
/// factored once (faer), for many solves.
///
/// Parameters: `indptr`, `indices` (int64) and `data` (float64), the CSR (or CSC: the same
/// for a symmetric matrix) arrays of an n×n matrix with sorted indices, of which only the
/// upper triangle is read; `name`, the argument named in errors (an `ArgumentError` when
/// the arrays are malformed or the matrix is not positive definite).
#[pyclass(frozen, module = "irtps._core")]
struct SparseCholesky {
    inner: CoreSparseCholesky,
    name: String,
}

#[pymethods]
impl SparseCholesky {
    #[new]
    #[pyo3(signature = (indptr, indices, data, name="matrix"))]
    fn new(
        py: Python<'_>,
        indptr: PyReadonlyArray1<'_, i64>,
        indices: PyReadonlyArray1<'_, i64>,
        data: PyReadonlyArray1<'_, f64>,
        name: &str,
    ) -> PyResult<SparseCholesky> {
        let indptr = indices_of(&indptr, name)?;
        let indices = indices_of(&indices, name)?;
        let data = data.as_array().to_vec();
        let n = indptr.len().saturating_sub(1);
        let inner = py
            .detach(|| CoreSparseCholesky::factor(name, n, &indptr, &indices, &data))
            .map_err(to_py)?;
        Ok(SparseCholesky {
            inner,
            name: name.to_string(),
        })
    }

    /// The matrix's dimension n.
    #[getter]
    fn dim(&self) -> usize {
        self.inner.dim()
    }

    /// Number of float64 values stored in the factor L.
    #[getter]
    fn factor_len(&self) -> usize {
        self.inner.factor_len()
    }

    /// The solution x of `A x = b` for a float64 (n,) right-hand side `b`.
    fn solve<'py>(
        &self,
        py: Python<'py>,
        b: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let mut x = b.as_array().to_vec();
        if x.len() != self.inner.dim() {
            return Err(argument_error(
                "b",
                format!(
                    "length {} for the {}x{} matrix {}",
                    x.len(),
                    self.inner.dim(),
                    self.inner.dim(),
                    self.name
                ),
            ));
        }
        py.detach(|| self.inner.solve_in_place("b", &mut x, 1))
            .map_err(to_py)?;
        Ok(PyArray1::from_vec(py, x))
    }
}

/// The compiled core of irtps.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // The core's threads are started at import: rayon starts them on first use, and panics
    // there when one cannot be started (its stack is address space, which a limit such as
    // `ulimit -v` may have run out of by then).
    if let Err(err) = rayon::ThreadPoolBuilder::new().build_global() {
        // An I/O error is a thread that could not be started; else the pool was running.
        if std::error::Error::source(&err).is_some() {
            return Err(PyMemoryError::new_err(format!(
                "the core's threads could not be started ({err})"
            )));
        }
    }
    m.add_function(wrap_pyfunction!(read_exr, m)?)?;
    m.add_function(wrap_pyfunction!(write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(read_png, m)?)?;
    m.add_function(wrap_pyfunction!(write_png, m)?)?;
    m.add_function(wrap_pyfunction!(read_images, m)?)?;
    m.add_function(wrap_pyfunction!(photometric_stereo, m)?)?;
    m.add_function(wrap_pyfunction!(tukey_with_lobe_check, m)?)?;
    m.add_function(wrap_pyfunction!(check_lights, m)?)?;
    m.add_function(wrap_pyfunction!(compare_rendering, m)?)?;
    m.add_function(wrap_pyfunction!(denoise_indirect, m)?)?;
    m.add_class::<Renderer>()?;
    m.add_class::<SparseCholesky>()?;
    m.add("MAX_IMAGE_PIXELS", io::MAX_IMAGE_PIXELS)?;
    Ok(())
}
