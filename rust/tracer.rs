//! Ray queries over a [`Mesh`]: one compressed wide BVH (obvhs CWBVH) over all triangles.

use std::time::Duration;

use glam::Vec3A;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::rt_triangle::RtTriangle;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

use crate::geometry::{Mesh, NO_PANEL};

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

/// A BVH over a mesh's triangles, answering closest-hit and occlusion queries. Unbounded
/// panels (an infinite floor) are intersected analytically, outside the BVH, so that their
/// size does not spoil the BVH's spatial ordering.
pub struct Tracer {
    bvh: CwBvh,
    /// Triangles in BVH order, laid out for fast intersection.
    triangles: Vec<RtTriangle>,
    /// Mesh index of each triangle in BVH order.
    mesh_index: Vec<u32>,
    /// Infinite planes: a point on the plane, its normal, and the mesh triangle reported.
    planes: Vec<(Vec3A, Vec3A, usize)>,
    /// Number of mesh triangles.
    triangle_count: usize,
    /// BVH position of the point placed beyond the bounds (see [`Tracer::new`]).
    bounds_guard: usize,
}

impl Tracer {
    /// Builds the BVH (in parallel on rayon's pool).
    pub fn new(mesh: &Mesh) -> Tracer {
        let on_plane = |t: usize| mesh.panel_of[t] != NO_PANEL && mesh.panels[mesh.panel_of[t] as usize].unbounded;
        let mut planes: Vec<(Vec3A, Vec3A, usize)> = Vec::new();
        let mut in_bvh: Vec<u32> = Vec::new();
        for t in 0..mesh.triangles.len() {
            if !on_plane(t) {
                in_bvh.push(t as u32);
            } else if !planes.iter().any(|p| mesh.panel_of[p.2] == mesh.panel_of[t]) {
                let panel = &mesh.panels[mesh.panel_of[t] as usize];
                planes.push((panel.origin, panel.normal, t));
            }
        }
        let tris: Vec<Triangle> = in_bvh
            .iter()
            .map(|&t| {
                let [v0, v1, v2] = mesh.corners(t as usize);
                Triangle { v0, v1, v2 }
            })
            .collect();
        let triangle_count = mesh.triangles.len();
        if tris.is_empty() {
            return Tracer { bvh: CwBvh::default(), triangles: Vec::new(), mesh_index: Vec::new(), planes, triangle_count, bounds_guard: usize::MAX };
        }
        // obvhs's Morton code wraps a coordinate lying exactly on the build bounds' maximum
        // to 0 (e.g. the skirt on the +x and +y sides), which spoils the BVH (2x the nodes
        // visited). A degenerate point beyond the maximum keeps every real triangle inside;
        // traversal skips it.
        let (lo, hi) = tris.iter().fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(t.v0).min(t.v1).min(t.v2), hi.max(t.v0).max(t.v1).max(t.v2))
        });
        let guard = hi + (hi - lo).max(Vec3A::ONE) * 0.01;
        let guard_index = tris.len() as u32;
        let mut build = tris.clone();
        build.push(Triangle { v0: guard, v1: guard, v2: guard });
        let bvh = build_cwbvh_from_tris(&build, BvhBuildParams::very_fast_build(), &mut Duration::default());
        let bounds_guard = bvh.primitive_indices.iter().position(|&i| i == guard_index).expect("the guard is in the BVH");
        let mesh_index = bvh.primitive_indices.iter().map(|&i| in_bvh.get(i as usize).copied().unwrap_or(u32::MAX)).collect();
        let triangles = bvh.primitive_indices.iter().map(|&i| RtTriangle::from(&build[i as usize])).collect();
        Tracer { bvh, triangles, mesh_index, planes, triangle_count, bounds_guard }
    }

    /// Distance to BVH primitive `id` along `ray` (infinite for the bounds guard).
    #[inline(always)]
    fn intersect(&self, ray: &Ray, id: usize) -> f32 {
        if id == self.bounds_guard {
            f32::INFINITY
        } else {
            self.triangles[id].intersect(ray)
        }
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangle_count
    }

    /// Whether there is nothing to hit.
    pub fn is_empty(&self) -> bool {
        self.triangle_count == 0
    }

    /// The nearest infinite-plane hit in (0, `t_max`), as (t, triangle).
    #[inline]
    fn plane_hit(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<(f32, usize)> {
        let mut best: Option<(f32, usize)> = None;
        for &(point, normal, triangle) in &self.planes {
            let t = (point - origin).dot(normal) / direction.dot(normal);
            if t > 0.0 && t < best.map_or(t_max, |b| b.0) {
                best = Some((t, triangle));
            }
        }
        best
    }

    /// The closest hit along `origin + t·direction` for `t` in (0, `t_max`).
    #[inline]
    pub fn closest_hit(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        let mut best = None;
        let mut t_limit = t_max;
        if !self.triangles.is_empty() {
            let ray = make_ray(origin, direction, t_max);
            let mut hit = RayHit::none();
            if self.bvh.ray_traverse(ray, &mut hit, |r, id| self.intersect(r, id)) {
                let id = hit.primitive_id as usize;
                let uv = self.triangles[id].compute_barycentric(&ray);
                best = Some(Hit { triangle: self.mesh_index[id] as usize, t: hit.t, u: uv.x, v: uv.y });
                t_limit = hit.t;
            }
        }
        // A plane's albedo is uniform, so its barycentrics do not matter.
        match self.plane_hit(origin, direction, t_limit) {
            Some((t, triangle)) => Some(Hit { triangle, t, u: 0.0, v: 0.0 }),
            None => best,
        }
    }

    /// Whether anything lies along `origin + t·direction` for `t` in (0, `t_max`).
    #[inline]
    pub fn occluded(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> bool {
        if self.plane_hit(origin, direction, t_max).is_some() {
            return true;
        }
        if self.triangles.is_empty() {
            return false;
        }
        let ray = make_ray(origin, direction, t_max);
        !self.bvh.ray_traverse_miss(ray, |r, id| self.intersect(r, id))
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
        mesh.panel_of = vec![crate::geometry::NO_PANEL];
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
    fn the_bounds_guard_is_never_hit() {
        let tracer = Tracer::new(&one_triangle());
        // The guard lies just beyond the maximum corner (2, 2, 0) of the triangle's bounds.
        let origin = vec3a(-1.0, -1.0, -1.0);
        let toward_guard = (vec3a(2.03, 2.03, 0.01) - origin).normalize();
        assert!(tracer.closest_hit(origin, toward_guard, f32::INFINITY).is_none());
        assert!(!tracer.occluded(origin, toward_guard, f32::INFINITY));
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
