//! Surroundings given as a mesh (contract §3b), made ready for ray queries once, in world
//! coordinates, and shared by every renderer of the scene: the object changes from pass to
//! pass, the environment does not, so its BVH is built once a run.

use glam::Vec3A;
use obvhs::triangle::Triangle;

use crate::error::Result;
use crate::scene::{EnvironmentMesh, Rgb};
use crate::trace::bvh::TriangleBvh;
use crate::trace::make_ray;

/// An environment mesh with its triangles' normals and BVH, in world coordinates.
pub struct EnvironmentAccel {
    mesh: EnvironmentMesh,
    /// Unit geometric normal of each triangle as wound (zero for a degenerate one, which is
    /// left out of the BVH).
    normals: Vec<Vec3A>,
    bvh: TriangleBvh,
    /// The corners of the box around its vertices.
    bounds: (Vec3A, Vec3A),
}

impl EnvironmentAccel {
    /// Checks `mesh` (naming the first bad vertex or triangle) and builds its BVH.
    pub fn new(mesh: EnvironmentMesh) -> Result<EnvironmentAccel> {
        mesh.validate()?;
        let corners = |tri: &[u32; 3]| tri.map(|i| mesh.positions[i as usize]);
        let normals: Vec<Vec3A> = mesh
            .triangles
            .iter()
            .map(|tri| {
                let [a, b, c] = corners(tri);
                (b - a).cross(c - a).normalize_or_zero()
            })
            .collect();
        let kept: Vec<u32> = (0..mesh.triangles.len() as u32)
            .filter(|&t| normals[t as usize] != Vec3A::ZERO)
            .collect();
        let tris = kept
            .iter()
            .map(|&t| {
                let [v0, v1, v2] = corners(&mesh.triangles[t as usize]);
                Triangle { v0, v1, v2 }
            })
            .collect();
        let bounds = mesh
            .positions
            .iter()
            .fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), &p| {
                (lo.min(p), hi.max(p))
            });
        Ok(EnvironmentAccel {
            bvh: TriangleBvh::new(tris, kept),
            mesh,
            normals,
            bounds,
        })
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.mesh.triangles.len()
    }

    /// Whether it has no triangle.
    pub fn is_empty(&self) -> bool {
        self.mesh.triangles.is_empty()
    }

    /// The corners of the box around its vertices (world units).
    pub fn bounds(&self) -> (Vec3A, Vec3A) {
        self.bounds
    }

    /// Unit normal of triangle `t` as wound (both of its sides reflect).
    #[inline(always)]
    pub fn normal(&self, t: usize) -> Vec3A {
        self.normals[t]
    }

    /// Albedo at barycentrics (`u`, `v`) of triangle `t`.
    #[inline(always)]
    pub fn albedo_at(&self, t: usize, u: f32, v: f32) -> Rgb {
        let [a, b, c] = self.mesh.triangles[t].map(|i| self.mesh.albedo[i as usize]);
        let w = 1.0 - u - v;
        [0, 1, 2].map(|ch| w * a[ch] + u * b[ch] + v * c[ch])
    }

    /// Corner positions of triangle `t` (world units).
    pub fn corners(&self, t: usize) -> [Vec3A; 3] {
        self.mesh.triangles[t].map(|i| self.mesh.positions[i as usize])
    }

    /// The nearest triangle along `origin + t·direction`, t in (0, `t_max`), world units:
    /// its index, distance and barycentrics.
    #[inline(always)]
    pub fn closest(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> Option<(u32, f32, f32, f32)> {
        self.bvh.closest(make_ray(origin, direction, t_max))
    }

    /// Whether a triangle lies along `origin + t·direction`, t in (0, `t_max`), world units.
    #[inline(always)]
    pub fn occluded(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> bool {
        self.bvh.any(make_ray(origin, direction, t_max))
    }
}
