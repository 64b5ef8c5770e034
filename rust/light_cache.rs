//! Direct light for every light at once.
//!
//! Each mesh vertex stores whether each light is visible from it (one shadow ray per vertex
//! and light, traced once). The direct radiance leaving any point of a triangle then costs K
//! multiply-adds and no rays: the Lambert term uses the triangle's own normal and the
//! visibility is interpolated from its corners. Triangles flagged `traced_shadows` (the far
//! floor) and the points the camera sees directly are shaded with real shadow rays instead.

use std::f32::consts::PI;

use glam::Vec3A;
use rayon::prelude::*;

use crate::geometry::Mesh;
use crate::scene::{Light, Rgb};
use crate::tracer::Tracer;

/// Per-vertex light visibility plus the light parameters needed to shade with it.
pub struct LightCache {
    directions: Vec<Vec3A>,
    /// Irradiance of each light divided by π (Lambertian BRDF without the albedo).
    radiance_scale: Vec<Rgb>,
    /// `visibility[vertex · K + k]` is 1 when light k is unoccluded from the vertex.
    visibility: Vec<u8>,
    ray_offset: f32,
}

impl LightCache {
    /// Traces one shadow ray per vertex and light (in parallel); `ray_offset` is the distance
    /// by which shadow rays start off the surface.
    pub fn new(mesh: &Mesh, tracer: &Tracer, lights: &[Light], ray_offset: f32) -> LightCache {
        let k = lights.len();
        let directions: Vec<Vec3A> = lights.iter().map(|l| l.direction.normalize()).collect();
        let radiance_scale = lights.iter().map(|l| l.irradiance.map(|e| e / PI)).collect();
        let mut cached = vec![false; mesh.positions.len()];
        for (tri, &traced) in mesh.triangles.iter().zip(&mesh.traced_shadows) {
            if !traced {
                tri.iter().for_each(|&v| cached[v as usize] = true);
            }
        }
        let mut visibility = vec![0u8; mesh.positions.len() * k];
        if k > 0 {
            visibility.par_chunks_mut(k).enumerate().for_each(|(v, row)| {
                if !cached[v] {
                    return;
                }
                let origin = mesh.positions[v] + mesh.vertex_normals[v] * ray_offset;
                for (slot, dir) in row.iter_mut().zip(&directions) {
                    *slot = u8::from(!tracer.occluded(origin, *dir, f32::INFINITY));
                }
            });
        }
        LightCache { directions, radiance_scale, visibility, ray_offset }
    }

    /// Number of lights.
    pub fn light_count(&self) -> usize {
        self.directions.len()
    }

    /// Radiance leaving a point of triangle `t` (barycentrics `u`, `v`, albedo `albedo`,
    /// position `point`) under each light alone, written to `out[k]`.
    #[inline]
    pub fn direct_radiance(&self, mesh: &Mesh, tracer: &Tracer, t: usize, (u, v): (f32, f32), point: Vec3A, albedo: Rgb, out: &mut [Rgb]) {
        let n = mesh.normals[t];
        if mesh.traced_shadows[t] {
            self.traced_direct_radiance(tracer, point, n, albedo, out);
            return;
        }
        let k_count = self.directions.len();
        let [a, b, c] = mesh.triangles[t].map(|i| &self.visibility[i as usize * k_count..][..k_count]);
        let w = 1.0 - u - v;
        for k in 0..k_count {
            let cosine = n.dot(self.directions[k]);
            let visible = w * a[k] as f32 + u * b[k] as f32 + v * c[k] as f32;
            let factor = cosine.max(0.0) * visible;
            let s = self.radiance_scale[k];
            out[k] = [albedo[0] * s[0] * factor, albedo[1] * s[1] * factor, albedo[2] * s[2] * factor];
        }
    }

    /// Like [`Self::direct_radiance`], but with one real shadow ray per light.
    #[inline]
    pub fn traced_direct_radiance(&self, tracer: &Tracer, point: Vec3A, n: Vec3A, albedo: Rgb, out: &mut [Rgb]) {
        let origin = point + n * self.ray_offset;
        for (k, dir) in self.directions.iter().enumerate() {
            let cosine = n.dot(*dir);
            out[k] = if cosine > 0.0 && !tracer.occluded(origin, *dir, f32::INFINITY) {
                let s = self.radiance_scale[k];
                [albedo[0] * s[0] * cosine, albedo[1] * s[1] * cosine, albedo[2] * s[2] * cosine]
            } else {
                [0.0; 3]
            };
        }
    }
}
