//! Ray queries over a [`Mesh`]: one compressed wide BVH (obvhs CWBVH) over all triangles.

use std::time::Duration;

use glam::Vec3A;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::rt_triangle::RtTriangle;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

use crate::geometry::Mesh;

/// The closest intersection of a ray with the mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Index of the triangle in the mesh.
    pub triangle: usize,
    /// Distance along the (unit) ray direction.
    pub t: f32,
    /// Barycentric weights of the triangle's vertices 1 and 2 (vertex 0 has 1 − u − v).
    pub u: f32,
    pub v: f32,
}

/// A BVH over a mesh's triangles, answering closest-hit and occlusion queries.
pub struct Tracer {
    bvh: CwBvh,
    /// Triangles in BVH order, laid out for fast intersection.
    triangles: Vec<RtTriangle>,
    /// Mesh index of each triangle in BVH order.
    mesh_index: Vec<u32>,
}

impl Tracer {
    /// Builds the BVH (in parallel on rayon's pool).
    pub fn new(mesh: &Mesh) -> Tracer {
        let tris: Vec<Triangle> = (0..mesh.triangles.len())
            .map(|t| {
                let [v0, v1, v2] = mesh.corners(t);
                Triangle { v0, v1, v2 }
            })
            .collect();
        if tris.is_empty() {
            return Tracer { bvh: CwBvh::default(), triangles: Vec::new(), mesh_index: Vec::new() };
        }
        let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default());
        let mesh_index = bvh.primitive_indices.clone();
        let triangles = mesh_index.iter().map(|&i| RtTriangle::from(&tris[i as usize])).collect();
        Tracer { bvh, triangles, mesh_index }
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Whether there is nothing to hit.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The closest hit along `origin + t·direction` for `t` in (0, `t_max`).
    #[inline]
    pub fn closest_hit(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        if self.triangles.is_empty() {
            return None;
        }
        let ray = make_ray(origin, direction, t_max);
        let mut hit = RayHit::none();
        if !self.bvh.ray_traverse(ray, &mut hit, |r, id| self.triangles[id].intersect(r)) {
            return None;
        }
        let id = hit.primitive_id as usize;
        let uv = self.triangles[id].compute_barycentric(&ray);
        Some(Hit { triangle: self.mesh_index[id] as usize, t: hit.t, u: uv.x, v: uv.y })
    }

    /// Whether anything lies along `origin + t·direction` for `t` in (0, `t_max`).
    #[inline]
    pub fn occluded(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> bool {
        if self.triangles.is_empty() {
            return false;
        }
        let ray = make_ray(origin, direction, t_max);
        !self.bvh.ray_traverse_miss(ray, |r, id| self.triangles[id].intersect(r))
    }
}

/// A ray for obvhs. Signed zeros in the direction are made positive: obvhs picks the
/// traversal octant from `d < 0` but the slab inverse from the sign bit, and the two disagree
/// on −0.0, which loses hits of axis-aligned rays.
#[inline]
fn make_ray(origin: Vec3A, direction: Vec3A, t_max: f32) -> Ray {
    Ray::new(origin, direction + Vec3A::ZERO, 0.0, t_max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::SurfaceKind;
    use glam::vec3a;

    fn one_triangle() -> Mesh {
        let mut mesh = Mesh::default();
        mesh.positions = vec![vec3a(0.0, 0.0, 0.0), vec3a(2.0, 0.0, 0.0), vec3a(0.0, 2.0, 0.0)];
        mesh.albedo = vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        mesh.triangles = vec![[0, 1, 2]];
        mesh.normals = vec![Vec3A::Z];
        mesh.kinds = vec![SurfaceKind::Object];
        mesh.traced_shadows = vec![false];
        mesh
    }

    #[test]
    fn barycentrics_weight_the_right_vertices() {
        let mesh = one_triangle();
        let tracer = Tracer::new(&mesh);
        let origin = vec3a(0.5, 0.25, 3.0);
        let hit = tracer.closest_hit(origin, -Vec3A::Z, f32::INFINITY).expect("hit");
        assert!((hit.t - 3.0).abs() < 1e-6);
        let [a, b, c] = mesh.corners(0);
        let p = a * (1.0 - hit.u - hit.v) + b * hit.u + c * hit.v;
        assert!((p - vec3a(0.5, 0.25, 0.0)).length() < 1e-6, "{p:?}");
        let albedo = mesh.albedo_at(0, hit.u, hit.v);
        assert!((albedo[1] - 0.25).abs() < 1e-6 && (albedo[2] - 0.125).abs() < 1e-6);
    }

    #[test]
    fn occlusion_respects_the_distance_limit() {
        let tracer = Tracer::new(&one_triangle());
        let origin = vec3a(0.5, 0.5, 1.0);
        assert!(tracer.occluded(origin, -Vec3A::Z, 2.0));
        assert!(!tracer.occluded(origin, -Vec3A::Z, 0.5));
        assert!(!tracer.occluded(origin, Vec3A::Z, f32::INFINITY));
        assert!(tracer.closest_hit(vec3a(3.0, 3.0, 1.0), -Vec3A::Z, f32::INFINITY).is_none());
    }
}
