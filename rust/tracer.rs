//! Ray queries over a [`Mesh`]: one compressed wide BVH (obvhs CWBVH) over all triangles.

use std::time::Duration;

use glam::{UVec2, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;
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
    /// Whether this CPU runs the AVX2 build of the traversal.
    avx2: bool,
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
        let mut tris: Vec<Triangle> = in_bvh
            .iter()
            .map(|&t| {
                let [v0, v1, v2] = mesh.corners(t as usize);
                Triangle { v0, v1, v2 }
            })
            .collect();
        let triangle_count = mesh.triangles.len();
        if tris.is_empty() {
            return Tracer { bvh: CwBvh::default(), triangles: Vec::new(), mesh_index: Vec::new(), planes, triangle_count, bounds_guard: usize::MAX, avx2: false };
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
        tris.push(Triangle { v0: guard, v1: guard, v2: guard });
        let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::very_fast_build(), &mut Duration::default());
        let bounds_guard = bvh.primitive_indices.iter().position(|&i| i == guard_index).expect("the guard is in the BVH");
        let mesh_index = bvh.primitive_indices.iter().map(|&i| in_bvh.get(i as usize).copied().unwrap_or(u32::MAX)).collect();
        let triangles = bvh.primitive_indices.iter().map(|&i| RtTriangle::from(&tris[i as usize])).collect();
        Tracer { bvh, triangles, mesh_index, planes, triangle_count, bounds_guard, avx2: avx2_available() }
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
            if let Some((id, t)) = self.closest_in_bvh(ray) {
                let uv = self.triangles[id].compute_barycentric(&ray);
                best = Some(Hit { triangle: self.mesh_index[id] as usize, t, u: uv.x, v: uv.y });
                t_limit = t;
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
        self.any_in_bvh(make_ray(origin, direction, t_max))
    }

    /// The closest BVH primitive along `ray`: (BVH position, distance).
    #[inline]
    fn closest_in_bvh(&self, ray: Ray) -> Option<(usize, f32)> {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only when the CPU has every feature enabled below.
            return unsafe { self.closest_avx2(ray) };
        }
        self.closest_portable(ray)
    }

    /// Whether any BVH primitive lies along `ray`.
    #[inline]
    fn any_in_bvh(&self, ray: Ray) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: as in `closest_in_bvh`.
            return unsafe { self.any_avx2(ray) };
        }
        self.any_portable(ray)
    }

    #[inline(always)]
    fn closest_portable(&self, ray: Ray) -> Option<(usize, f32)> {
        let mut traverse_ray = ray;
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        let mut best = None;
        obvhs::traverse!(self.bvh, node, state, node.intersect_ray(&traverse_ray, state.oct_inv4), {
            let id = state.primitive_id as usize;
            let t = self.intersect(&traverse_ray, id);
            if t < traverse_ray.tmax {
                best = Some(id);
                traverse_ray.tmax = t;
            }
        });
        best.map(|id| (id, traverse_ray.tmax))
    }

    #[inline(always)]
    fn any_portable(&self, ray: Ray) -> bool {
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        let mut hit = false;
        'search: {
            obvhs::traverse!(self.bvh, node, state, node.intersect_ray(&ray, state.oct_inv4), {
                if self.intersect(&ray, state.primitive_id as usize) < ray.tmax {
                    hit = true;
                    break 'search;
                }
            });
        }
        hit
    }

    /// The same traversal compiled for AVX2 (chosen at run time; the results are identical).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn closest_avx2(&self, ray: Ray) -> Option<(usize, f32)> {
        self.closest_portable(ray)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn any_avx2(&self, ray: Ray) -> bool {
        self.any_portable(ray)
    }
}

/// Whether the CPU has the features of the AVX2 traversal.
fn avx2_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("fma")
            && is_x86_feature_detected!("bmi1")
            && is_x86_feature_detected!("bmi2")
            && is_x86_feature_detected!("lzcnt")
            && is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
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
        Mesh {
            positions: vec![vec3a(0.0, 0.0, 0.0), vec3a(2.0, 0.0, 0.0), vec3a(0.0, 2.0, 0.0)],
            albedo: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            triangles: vec![[0, 1, 2]],
            normals: vec![Vec3A::Z],
            kinds: vec![SurfaceKind::Object],
            panel_of: vec![crate::geometry::NO_PANEL],
            ..Mesh::default()
        }
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
    fn the_avx2_traversal_agrees_with_the_portable_one() {
        let scene = crate::scene::Scene {
            camera: crate::scene::Camera { width: 24, height: 24, pixel_size: 1.0 },
            surface: crate::scene::HeightField {
                height: (0..576).map(|p| ((p % 24) as f32 * 0.7).sin() * 3.0 + 5.0).collect(),
                mask: vec![true; 576],
                albedo: vec![[0.5; 3]; 576],
            },
            floor: Some(crate::scene::Floor { height: 0.0, albedo: [0.5; 3] }),
            cornell_box: None,
        };
        let tracer = Tracer::new(&Mesh::from_scene(&scene));
        let mut rng = crate::sampler::Rng::new(9);
        for _ in 0..2000 {
            let origin = vec3a(rng.next_f32() * 24.0 - 12.0, rng.next_f32() * 24.0 - 12.0, 9.0);
            let direction = vec3a(rng.next_f32() - 0.5, rng.next_f32() - 0.5, -rng.next_f32()).normalize();
            let ray = make_ray(origin, direction, f32::INFINITY);
            assert_eq!(tracer.closest_in_bvh(ray), tracer.closest_portable(ray));
            assert_eq!(tracer.any_in_bvh(ray), tracer.any_portable(ray));
        }
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
