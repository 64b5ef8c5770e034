//! The forward renderer: for every light, the direct image and the image of each
//! inter-reflection bounce, averaged over each pixel's footprint.
//!
//! Every camera path is traced once and serves all K lights: the direct light at each path
//! vertex comes from the [`LightCache`]. Bounce b of a path (b = 1 … B) carries the product of
//! the albedos met so far (cosine-weighted sampling cancels the Lambert cosine and 1/π) times
//! the direct radiance leaving its (b+1)-th vertex.
//!
//! This module is the [`Renderer`]; beside it: [`light_cache`], the direct light of every
//! light at once; [`intersect`], the closest hits of batches of rays in world units;
//! [`residual`], a rendering compared with the images; [`denoise`], the filter of an
//! inter-reflection estimate along the surface.

use std::ops::Range;
use std::sync::Arc;

use glam::Vec3A;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::memory::{check_available, try_collect, try_vec};
use crate::render::light_cache::{offset_at, LightCache};
use crate::sampler::{cosine_hemisphere, hash, low_discrepancy_4d, unit_float, Rng};
use crate::scene::{
    check_albedo, validate_emitters, validate_lights, Camera, Emitter, Frame, Light, Rgb, Scene,
};
use crate::trace::environment::EnvironmentAccel;
use crate::trace::mesh::{Mesh, PlacedEnvironment};
use crate::trace::Tracer;

pub mod denoise;
pub mod intersect;
pub mod light_cache;
pub mod residual;

/// Bytes per camera pixel that building a scene takes at its peak, with room to spare: the
/// mesh (a vertex and two triangles a pixel, their normals and albedo), the height-field
/// grid, the BVH of the surroundings and their build's temporaries. [`Renderer::new`]
/// reserves them up front, as the BVH (obvhs) allocates without a way to fail.
const SCENE_BYTES_PER_PIXEL: usize = 512;
/// Bytes per camera pixel and light of the light cache: the visibility of each light at the
/// object's vertices and at the panels' grid points, about a pixel apart.
const LIGHT_CACHE_BYTES_PER_PIXEL: usize = 2;

/// How much to render.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// Number of inter-reflection bounces B (0 renders the direct image only).
    pub bounces: usize,
    /// Camera paths per pixel for the indirect images.
    pub samples: usize,
    /// Footprint samples per pixel for the direct image (0 skips it); at most `samples`
    /// when there are bounces.
    pub direct_samples: usize,
    /// Seed of every random choice.
    pub seed: u64,
    /// One image per bounce (true), or all the bounces summed into one (false).
    pub split_bounces: bool,
    /// Shade the points the camera sees with the light cache's visibility where the cache
    /// points around them agree, and a shadow ray only where a shadow's edge passes (true),
    /// or with one shadow ray per light and footprint sample (false). Both are exact but
    /// for occluders thinner than the cache's spacing; true traces far fewer rays.
    pub cached_direct: bool,
}

impl RenderSettings {
    /// Number of image planes per light: the direct image when it is rendered, then each
    /// bounce or their sum.
    pub fn planes(&self) -> usize {
        usize::from(self.direct_samples > 0)
            + if self.split_bounces {
                self.bounces
            } else {
                self.bounces.min(1)
            }
    }

    /// Plane of bounce `b` (1-based) in the output.
    #[inline]
    fn bounce_plane(&self, b: usize) -> usize {
        usize::from(self.direct_samples > 0) + if self.split_bounces { b - 1 } else { 0 }
    }
}

/// A scene made ready for rendering: geometry, BVH and light cache, built in the scene's
/// working [`Frame`] (one unit a pixel), so that renderings do not depend on its scale.
pub struct Renderer {
    /// The camera in the working frame (a pixel size of 1).
    camera: Camera,
    frame: Frame,
    mesh: Mesh,
    /// Geometry only: shared by the renderers made with [`Renderer::with_reflectance`].
    tracer: Arc<Tracer>,
    cache: LightCache,
    ray_offset: f32,
    camera_z: f32,
    /// Whether this processor runs [`Renderer::render_pixel`]'s AVX2 build.
    avx2: bool,
}

impl Renderer {
    /// Builds the geometry, its BVH and the per-vertex light visibility, in the scene's
    /// working frame; refuses, naming the field, geometry that float32 cannot resolve there
    /// (see [`Frame::local_scene`]).
    pub fn new(scene: &Scene, lights: &[Light]) -> Result<Renderer> {
        let emitters: Vec<Emitter> = lights.iter().copied().map(Emitter::Distant).collect();
        Self::with_emitters(scene, &emitters)
    }

    /// [`Renderer::new`] under lights that may be points near the object (contract §4b):
    /// each point light's direction and inverse-square falloff vary over the scene, and its
    /// shadow rays stop at it.
    pub fn with_emitters(scene: &Scene, lights: &[Emitter]) -> Result<Renderer> {
        Self::with_environment(scene, lights, None)
    }

    /// [`Renderer::with_emitters`] in surroundings given as a mesh (contract §3b), built for
    /// ray queries once ([`EnvironmentAccel`]) and shared, not copied, with the shadows it
    /// casts on itself, traced once for these lights: renderers of the same scene with other
    /// objects (IRT-PS's passes) build only the object's structures. Refuses, naming it, a
    /// mesh that float32 cannot resolve in the scene's working frame.
    pub fn with_environment(
        scene: &Scene,
        lights: &[Emitter],
        environment: Option<Arc<EnvironmentAccel>>,
    ) -> Result<Renderer> {
        scene.validate()?;
        if lights.is_empty() {
            return Err(Error::input("lights", "no lights given"));
        }
        validate_emitters(lights)?;
        let (pixels, k) = (scene.camera.pixel_count(), lights.len());
        let estimate = pixels.saturating_mul(
            SCENE_BYTES_PER_PIXEL.saturating_add(LIGHT_CACHE_BYTES_PER_PIXEL.saturating_mul(k)),
        );
        check_available(
            &format!(
                "the mesh, BVH and light cache of a {}x{} scene under {k} lights",
                scene.camera.width, scene.camera.height
            ),
            estimate,
        )?;
        let frame = Frame::of(scene);
        let scene = &frame.local_scene(scene)?;
        let mut mesh = Mesh::from_scene(scene);
        // The top of the environment mesh, which an orthographic camera's rays start above.
        let mut environment_top = f32::NEG_INFINITY;
        let mut environment_visibility = None;
        if let Some(accel) = environment {
            let (lo, hi) = accel.bounds();
            for corner in [lo, hi] {
                let local = frame.local_point("environment.vertices", corner, || {
                    "at a corner of the box around them".to_string()
                })?;
                environment_top = environment_top.max(local.z);
            }
            environment_visibility = Some(accel.visibility(lights)?);
            mesh.environment = Some(PlacedEnvironment {
                accel,
                scale: frame.scale as f32,
                z_origin: frame.z_origin as f32,
            });
        }
        let tracer = Arc::new(Tracer::new(&mesh));
        let (lo, hi) = mesh.near_bounds();
        let view = scene.camera.width.max(scene.camera.height) as f32;
        let extent = if lo.x.is_finite() {
            (hi - lo).max_element().max(view)
        } else {
            view
        };
        let ray_offset = 1e-4 * extent;
        let top = hi.z.max(environment_top);
        let camera_z = if top.is_finite() {
            top + extent
        } else {
            extent
        };
        let local: Vec<Emitter> = lights.iter().map(|l| frame.local_emitter(l)).collect();
        let cache = LightCache::new(&mesh, &tracer, &local, ray_offset, environment_visibility);
        #[cfg(target_arch = "x86_64")]
        let avx2 = std::is_x86_feature_detected!("avx2");
        #[cfg(not(target_arch = "x86_64"))]
        let avx2 = false;
        Ok(Renderer {
            camera: scene.camera,
            frame,
            mesh,
            tracer,
            cache,
            ray_offset,
            camera_z,
            avx2,
        })
    }

    /// The same scene with the object's albedo `albedo` (one per pixel, row-major; read at
    /// the object's pixels) and each light's irradiance `irradiance`: the geometry, its BVH
    /// and the light visibility are kept, not built or traced again.
    pub fn with_reflectance(&self, albedo: &[Rgb], irradiance: &[Rgb]) -> Result<Renderer> {
        let pixels = self.camera.width * self.camera.height;
        if albedo.len() != pixels {
            return Err(Error::input(
                "albedo",
                format!("{} values for {pixels} pixels", albedo.len()),
            ));
        }
        if irradiance.len() != self.light_count() {
            return Err(Error::input(
                "irradiance",
                format!(
                    "{} values for {} lights",
                    irradiance.len(),
                    self.light_count()
                ),
            ));
        }
        for &pixel in self
            .mesh
            .albedo_pixel
            .iter()
            .filter(|&&p| (p as usize) < pixels)
        {
            let p = pixel as usize;
            check_albedo(
                &format!(
                    "albedo at pixel (row {}, column {})",
                    p / self.camera.width,
                    p % self.camera.width
                ),
                &albedo[p],
            )?;
        }
        let lights: Vec<Light> = irradiance
            .iter()
            .map(|e| Light {
                direction: Vec3A::Z,
                irradiance: *e,
            })
            .collect();
        validate_lights(&lights)?;
        let mut mesh = self.mesh.clone();
        mesh.set_object_albedo(albedo);
        Ok(Renderer {
            mesh,
            tracer: Arc::clone(&self.tracer),
            cache: self
                .cache
                .with_irradiance(irradiance, self.frame.scale * self.frame.scale),
            ..*self
        })
    }

    /// The camera, in the working frame (a pixel size of 1).
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The working frame: [`Renderer::mesh`] and [`Renderer::tracer`] are in it.
    pub fn frame(&self) -> &Frame {
        &self.frame
    }

    /// The scene's triangles, in the working frame.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The ray-query structure, in the working frame.
    pub fn tracer(&self) -> &Tracer {
        &self.tracer
    }

    /// Number of lights.
    pub fn light_count(&self) -> usize {
        self.cache.light_count()
    }

    /// Renders image rows `rows`. The result is laid out `(P, K, rows, W, 3)` with the P
    /// planes of [`RenderSettings::planes`]: the direct image first when it is rendered, then
    /// bounce 1 … B (or their sum when the bounces are not split).
    pub fn render_rows(&self, rows: Range<usize>, settings: &RenderSettings) -> Result<Vec<f32>> {
        if rows.start >= rows.end || rows.end > self.camera.height {
            return Err(Error::input(
                "rows",
                format!("{rows:?} is not inside 0..{}", self.camera.height),
            ));
        }
        let w = self.camera.width;
        let pixels = try_collect(
            &format!("the indices of rows {rows:?} of {w} pixels"),
            (rows.end - rows.start) * w,
            rows.start * w..rows.end * w,
        )?;
        self.render_pixels(&pixels, settings)
    }

    /// Renders the listed pixels (row-major indices), laid out `(P, K, pixels, 3)`.
    pub fn render_pixels(&self, pixels: &[usize], settings: &RenderSettings) -> Result<Vec<f32>> {
        self.check(settings)?;
        let (w, k_count) = (self.camera.width, self.light_count());
        if let Some(&bad) = pixels.iter().find(|&&p| p >= self.camera.pixel_count()) {
            return Err(Error::input(
                "pixels",
                format!(
                    "index {bad} is outside the {}x{} image",
                    w, self.camera.height
                ),
            ));
        }
        let stride = settings.planes() * k_count * 3;
        let what = format!(
            "the rendering of {} pixels under {k_count} lights ({} planes)",
            pixels.len(),
            settings.planes()
        );
        let mut per_pixel = try_vec(&what, pixels.len().saturating_mul(stride), 0.0f32)?;
        per_pixel
            .par_chunks_mut(stride)
            .zip(pixels)
            .for_each(|(acc, &p)| self.render_pixel(p / w, p % w, settings, acc));
        // Transpose pixel-major (pixel, plane, c, k) to image-major (plane, k, pixel, c).
        let planes = settings.planes() * k_count;
        let plane_len = pixels.len() * 3;
        let mut out = try_vec(&what, planes * plane_len, 0.0f32)?;
        out.par_chunks_mut(plane_len.max(1))
            .enumerate()
            .for_each(|(image, dst)| {
                let (plane, k) = (image / k_count, image % k_count);
                for (p, px) in dst.chunks_exact_mut(3).enumerate() {
                    let sums = &per_pixel[p * stride + plane * 3 * k_count..];
                    for (c, value) in px.iter_mut().enumerate() {
                        *value = sums[c * k_count + k];
                    }
                }
            });
        Ok(out)
    }

    fn check(&self, s: &RenderSettings) -> Result<()> {
        if s.bounces > 0 && s.samples == 0 {
            return Err(Error::input(
                "samples",
                "must be at least 1 when bounces are rendered",
            ));
        }
        if s.bounces == 0 && s.direct_samples == 0 {
            return Err(Error::input(
                "direct_samples",
                "must be at least 1 when no bounces are rendered",
            ));
        }
        Ok(())
    }

    /// Accumulates one pixel into `acc` (layout `(P, 3, K)`: by plane, channel, light),
    /// already averaged; with AVX2 where the processor has it.
    fn render_pixel(&self, row: usize, col: usize, s: &RenderSettings, acc: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only when the processor supports AVX2.
            return unsafe { self.render_pixel_avx2(row, col, s, acc) };
        }
        self.render_pixel_portable(row, col, s, acc);
    }

    /// [`Renderer::render_pixel_portable`] compiled for AVX2: the sums over the lights run
    /// eight at a time, the same operations in the same order, so the same results.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn render_pixel_avx2(
        &self,
        row: usize,
        col: usize,
        s: &RenderSettings,
        acc: &mut [f32],
    ) {
        self.render_pixel_portable(row, col, s, acc);
    }

    #[inline(always)]
    fn render_pixel_portable(&self, row: usize, col: usize, s: &RenderSettings, acc: &mut [f32]) {
        let k_count = self.light_count();
        let pixel = (row * self.camera.width + col) as u64;
        let key = hash(&[s.seed, pixel]);
        let shift = [0u64, 1, 2, 3].map(|d| unit_float(hash(&[key, d])));
        let path_count = if s.bounces > 0 { s.samples } else { 0 };
        for sample in 0..path_count.max(s.direct_samples) {
            let q = low_discrepancy_4d(sample as u32, shift);
            let (origin, dir) =
                self.camera
                    .ray(row as f32 + q[1], col as f32 + q[0], self.camera_z);
            let Some(hit) = self.tracer.closest_hit(origin, dir, f32::INFINITY) else {
                continue;
            };
            let Some(n) = self.mesh.seen_normal(hit.triangle, dir) else {
                continue;
            };
            let point = origin + dir * hit.t;
            let albedo = self.mesh.albedo_at(hit.triangle, hit.u, hit.v);
            if sample < s.direct_samples {
                let weight = [1.0 / s.direct_samples as f32; 3];
                let direct = &mut acc[..k_count * 3];
                if s.cached_direct {
                    self.cache.add_direct_radiance(
                        &self.mesh,
                        &self.tracer,
                        hit.triangle,
                        (hit.u, hit.v),
                        point,
                        n,
                        albedo,
                        true,
                        weight,
                        direct,
                    );
                } else {
                    self.cache.add_traced_direct_radiance(
                        &self.tracer,
                        point,
                        n,
                        albedo,
                        weight,
                        direct,
                    );
                }
            }
            if sample < path_count {
                let mut rng = Rng::new(hash(&[key, sample as u64, 0x5EED]));
                self.trace_path(point, n, albedo, (q[2], q[3]), &mut rng, s, acc);
            }
        }
    }

    /// Follows one cosine-sampled path from a camera hit, adding bounce b's radiance
    /// (already divided by the sample count) into its plane of `acc`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn trace_path(
        &self,
        mut point: Vec3A,
        mut n: Vec3A,
        albedo: Rgb,
        first: (f32, f32),
        rng: &mut Rng,
        s: &RenderSettings,
        acc: &mut [f32],
    ) {
        let k3 = self.light_count() * 3;
        let inv_samples = 1.0 / s.samples as f32;
        let mut throughput = albedo.map(|a| a * inv_samples);
        for bounce in 1..=s.bounces {
            let (u1, u2) = if bounce == 1 {
                first
            } else {
                (rng.next_f32(), rng.next_f32())
            };
            let dir = cosine_hemisphere(u1, u2, n);
            let origin = point + n * offset_at(self.ray_offset, point);
            let Some(hit) = self.tracer.closest_hit(origin, dir, f32::INFINITY) else {
                return;
            };
            let Some(n_hit) = self.mesh.seen_normal(hit.triangle, dir) else {
                return; // the back of a one-sided surface is black
            };
            let p_hit = origin + dir * hit.t;
            let albedo_hit = self.mesh.albedo_at(hit.triangle, hit.u, hit.v);
            let plane = s.bounce_plane(bounce);
            let sums = &mut acc[plane * k3..(plane + 1) * k3];
            self.cache.add_direct_radiance(
                &self.mesh,
                &self.tracer,
                hit.triangle,
                (hit.u, hit.v),
                p_hit,
                n_hit,
                albedo_hit,
                false,
                throughput,
                sums,
            );
            throughput = [0, 1, 2].map(|c| throughput[c] * albedo_hit[c]);
            if throughput.iter().all(|&t| t == 0.0) {
                return;
            }
            point = p_hit;
            n = n_hit;
        }
    }
}

#[cfg(test)]
mod tests;
