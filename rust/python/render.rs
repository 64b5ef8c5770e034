//! The renderer: a scene made ready for rendering and ray queries.

use std::borrow::Cow;

use glam::Vec3A;

use numpy::ndarray::{Array, Array2, IxDyn};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayDyn, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::render::{RenderSettings, Renderer as CoreRenderer};
use std::sync::Arc;

use crate::scene::{
    Camera, CornellBox, Emitter, EnvironmentMesh, Floor, HeightField, Light, Pinhole, PointLight,
    Rgb, Scene,
};
use crate::trace::environment::EnvironmentAccel;

use super::convert::{flat, lights_from, rows_of_3};
use super::errors::{argument_error, renamed, to_py};

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

/// A scene made ready for rendering and ray queries: height-field object, optional floor,
/// Cornell box and environment mesh, distant or point lights.
///
/// Parameters: `height` (H, W) float32, `mask` (H, W) bool, `albedo` (H, W, 3) float32,
/// `pixel_size`, `light_directions` (K, 3), `light_irradiance` (K, 3), `floor` an
/// `irtps.scene.Floor` or None, `cornell_box` an `irtps.scene.CornellBox` or None, `pinhole`
/// None (orthographic) or `(fx, fy, cx, cy, zc)` of a pinhole camera at `(0, 0, zc)`, whose
/// `pixel_size` is then a pixel's world size at the depth of the object's base;
/// `light_positions` as [`emitters_from`] reads them; `environment_mesh` None or an
/// [`Environment`].
#[pyclass(frozen, module = "irtps._core")]
pub(super) struct Renderer {
    inner: CoreRenderer,
}

/// Light k as a point at row k of `positions` where that row is finite, its irradiance row
/// then its intensity; else the distant light `lights[k]`.
fn emitters_from(
    lights: Vec<Light>,
    positions: Option<&PyReadonlyArray2<'_, f32>>,
) -> PyResult<Vec<Emitter>> {
    let Some(positions) = positions else {
        return Ok(lights.into_iter().map(Emitter::Distant).collect());
    };
    let rows = rows_of_3(positions, "light_positions")?;
    if rows.len() != lights.len() {
        return Err(argument_error(
            "light_positions",
            format!("{} rows for {} lights", rows.len(), lights.len()),
        ));
    }
    Ok(lights
        .into_iter()
        .zip(rows)
        .map(|(light, row)| {
            if row.iter().all(|v| v.is_nan()) {
                Emitter::Distant(light)
            } else {
                Emitter::Point(PointLight {
                    position: Vec3A::from(row),
                    intensity: light.irradiance,
                })
            }
        })
        .collect())
}

/// Surroundings given as a mesh (contract §3b), made ready for ray queries once and shared
/// by every renderer built with it: `vertices` (V, 3) float32 in world units, `triangles`
/// (F, 3) uint32, `albedo` (V, 3) float32 in [0, 1].
#[pyclass(frozen, module = "irtps._core")]
pub(super) struct Environment {
    inner: Arc<EnvironmentAccel>,
}

#[pymethods]
impl Environment {
    #[new]
    fn new(
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f32>,
        triangles: PyReadonlyArray2<'_, u32>,
        albedo: PyReadonlyArray2<'_, f32>,
    ) -> PyResult<Environment> {
        let positions = rows_of_3(&vertices, "vertices")?;
        let albedo = rows_of_3(&albedo, "albedo")?;
        let indices = triangles.as_array();
        if indices.ncols() != 3 {
            return Err(argument_error(
                "triangles",
                format!("expected shape (F, 3), got {:?}", indices.shape()),
            ));
        }
        let mesh = EnvironmentMesh {
            positions: positions.into_iter().map(Vec3A::from).collect(),
            albedo,
            triangles: indices
                .rows()
                .into_iter()
                .map(|r| [r[0], r[1], r[2]])
                .collect(),
        };
        let inner = py.detach(|| EnvironmentAccel::new(mesh)).map_err(to_py)?;
        Ok(Environment {
            inner: Arc::new(inner),
        })
    }

    /// Number of triangles.
    #[getter]
    fn triangle_count(&self) -> usize {
        self.inner.len()
    }

    /// Distance from `origin` along the unit `direction` (world units) to the nearest
    /// triangle, either side, within (0, `t_max`); None if there is none.
    fn first_hit(&self, origin: [f32; 3], direction: [f32; 3], t_max: f32) -> Option<f32> {
        self.inner
            .closest(Vec3A::from(origin), Vec3A::from(direction), t_max)
            .map(|(_, t, _, _)| t)
    }
}

#[pymethods]
impl Renderer {
    #[new]
    #[pyo3(signature = (height, mask, albedo, pixel_size, light_directions, light_irradiance, floor=None, cornell_box=None, pinhole=None, light_positions=None, environment_mesh=None))]
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
        pinhole: Option<(f32, f32, f32, f32, f32)>,
        light_positions: Option<PyReadonlyArray2<'_, f32>>,
        environment_mesh: Option<PyRef<'_, Environment>>,
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
        let lights = emitters_from(
            lights_from(&light_directions, &light_irradiance)?,
            light_positions.as_ref(),
        )?;
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
                pinhole: pinhole.map(|(fx, fy, cx, cy, center_z)| Pinhole {
                    fx,
                    fy,
                    cx,
                    cy,
                    center_z,
                }),
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
            zero_height: 0.0,
        };
        let environment = environment_mesh.map(|e| Arc::clone(&e.inner));
        let inner = py
            .detach(|| CoreRenderer::with_environment(&scene, &lights, environment))
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
        let hits = py
            .detach(|| self.inner.intersect(&o, &d, threads))
            .map_err(to_py)?;
        Ok((
            PyArray1::from_vec(py, hits.distances),
            PyArray1::from_vec(py, hits.triangles),
        ))
    }
}
