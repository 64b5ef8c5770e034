//! Ray queries over a [`Mesh`]: the height field and its skirt through the grid-based
//! [`HeightFieldAccel`], the panels of the surroundings (floor and walls) analytically as
//! rectangles or planes, and any other triangle through a compressed wide BVH (obvhs CWBVH).
//!
//! This module is the [`Tracer`]; [`mesh`] builds the scene's triangles, [`height_field`]
//! walks the height field's grid.

use std::time::Duration;

use glam::{UVec2, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;
use obvhs::rt_triangle::RtTriangle;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

use crate::trace::height_field::HeightFieldAccel;
use crate::trace::mesh::{Mesh, SurfaceKind, NO_PANEL};

pub mod height_field;
pub mod mesh;

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

/// Closest-hit and occlusion queries over a mesh. The height field (when the mesh has its
/// grid) goes to a [`HeightFieldAccel`]; the panels, a handful of rectangles, are tested
/// directly (an unbounded one as its whole plane); the remaining triangles go to a BVH.
pub struct Tracer {
    height_field: Option<HeightFieldAccel>,
    /// The panels, those along x first, then along y, then along z, then any other (each
    /// group in mesh order).
    panels: Vec<PanelShape>,
    /// Where the groups along x, y and z end in `panels`.
    axis_ends: [usize; 3],
    bvh: CwBvh,
    /// Triangles in BVH order, laid out for fast intersection.
    triangles: Vec<RtTriangle>,
    /// Mesh index of each triangle in BVH order.
    mesh_index: Vec<u32>,
    /// Number of mesh triangles.
    triangle_count: usize,
    /// BVH position of the point placed beyond the bounds (see [`Tracer::new`]).
    bounds_guard: usize,
    /// Whether this CPU runs the AVX2 build of the traversal.
    avx2: bool,
    /// The height field's box, when every panel lies outside it: a ray starting inside the
    /// box that hits the field meets no panel before.
    field_box: Option<(Vec3A, Vec3A)>,
}

impl Tracer {
    /// Builds the acceleration structures (the BVH in parallel on rayon's pool).
    pub fn new(mesh: &Mesh) -> Tracer {
        let height_field = HeightFieldAccel::new(mesh);
        let on_grid = |t: usize| {
            height_field.is_some()
                && matches!(mesh.kinds[t], SurfaceKind::Object | SurfaceKind::Skirt)
        };
        let mut panels: Vec<PanelShape> = (0..mesh.panels.len())
            .filter_map(|id| PanelShape::new(mesh, id))
            .collect();
        panels.sort_by_key(|p| p.axis.unwrap_or(3));
        let axis_ends = [0, 1, 2].map(|k| {
            panels
                .iter()
                .filter(|p| p.axis.is_some_and(|a| a <= k))
                .count()
        });
        let on_panel = |t: usize| {
            mesh.panel_of[t] != NO_PANEL && panels.iter().any(|p| p.id == mesh.panel_of[t])
        };
        let in_bvh: Vec<u32> = (0..mesh.triangles.len())
            .filter(|&t| !on_grid(t) && !on_panel(t))
            .map(|t| t as u32)
            .collect();
        let mut tris: Vec<Triangle> = in_bvh
            .iter()
            .map(|&t| {
                let [v0, v1, v2] = mesh.corners(t as usize);
                Triangle { v0, v1, v2 }
            })
            .collect();
        let triangle_count = mesh.triangles.len();
        let field_box = height_field
            .as_ref()
            .map(HeightFieldAccel::bounds)
            .filter(|&(lo, hi)| {
                panels.iter().all(|p| {
                    let (a, b) = p.bounds();
                    // Separated along some axis (touching a face is allowed).
                    (0..3).any(|k| b[k] <= lo[k] || a[k] >= hi[k])
                })
            });
        if tris.is_empty() {
            return Tracer {
                field_box,
                height_field,
                panels,
                axis_ends,
                bvh: CwBvh::default(),
                triangles: Vec::new(),
                mesh_index: Vec::new(),
                triangle_count,
                bounds_guard: usize::MAX,
                avx2: avx2_available(),
            };
        }
        // obvhs's Morton code wraps a coordinate lying exactly on the build bounds' maximum
        // to 0 (e.g. the skirt on the +x and +y sides), which spoils the BVH (many more nodes
        // visited). A degenerate point beyond the maximum keeps every real triangle inside;
        // traversal skips it.
        let (lo, hi) = tris
            .iter()
            .fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), t| {
                (
                    lo.min(t.v0).min(t.v1).min(t.v2),
                    hi.max(t.v0).max(t.v1).max(t.v2),
                )
            });
        let guard = hi + (hi - lo).max(Vec3A::ONE) * 0.01;
        let guard_index = tris.len() as u32;
        tris.push(Triangle {
            v0: guard,
            v1: guard,
            v2: guard,
        });
        let bvh = build_cwbvh_from_tris(
            &tris,
            BvhBuildParams::very_fast_build(),
            &mut Duration::default(),
        );
        let bounds_guard = bvh
            .primitive_indices
            .iter()
            .position(|&i| i == guard_index)
            .expect("the guard is in the BVH");
        let mesh_index = bvh
            .primitive_indices
            .iter()
            .map(|&i| in_bvh.get(i as usize).copied().unwrap_or(u32::MAX))
            .collect();
        let triangles = bvh
            .primitive_indices
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        Tracer {
            field_box,
            height_field,
            panels,
            axis_ends,
            bvh,
            triangles,
            mesh_index,
            triangle_count,
            bounds_guard,
            avx2: avx2_available(),
        }
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

    /// The nearest panel hit in (0, `t_max`) (of equal ones, the first in mesh order).
    #[inline(always)]
    fn panel_hit(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        let inverse = direction.recip();
        let mut best = PanelHit {
            hit: None,
            t: t_max,
            id: 0,
        };
        let [x_end, y_end, z_end] = self.axis_ends;
        // Along an axis, the plane's distance is one product with the direction's inverse.
        for (k, group) in [(0, 0..x_end), (1, x_end..y_end), (2, y_end..z_end)] {
            let (o, i) = (origin[k], inverse[k]);
            for panel in &self.panels[group] {
                panel.consider((panel.plane - o) * i, origin, direction, &mut best);
            }
        }
        for panel in &self.panels[z_end..] {
            panel.consider(
                (panel.origin - origin).dot(panel.normal) / direction.dot(panel.normal),
                origin,
                direction,
                &mut best,
            );
        }
        best.hit
    }

    /// The closest hit along `origin + t·direction` for `t` in (0, `t_max`).
    #[inline]
    pub fn closest_hit(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only when the CPU has every feature the AVX2 build enables.
            return unsafe { self.closest_hit_avx2(origin, direction, t_max) };
        }
        self.closest_hit_portable(origin, direction, t_max)
    }

    /// The closest hits of a batch of rays `(origin, direction)`, each for `t` in (0, `t_max`),
    /// handed to `each` in order. The same hits as [`Tracer::closest_hit`] ray by ray, with
    /// the CPU's features checked once for the batch and the tracer's set-up shared.
    #[inline]
    pub fn closest_hits(
        &self,
        rays: impl Iterator<Item = (Vec3A, Vec3A)>,
        t_max: f32,
        mut each: impl FnMut(Option<Hit>),
    ) {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: as in `closest_hit`.
            return unsafe { self.closest_hits_avx2(rays, t_max, &mut each) };
        }
        for (origin, direction) in rays {
            each(self.closest_hit_portable(origin, direction, t_max));
        }
    }

    /// Whether anything lies along `origin + t·direction` for `t` in (0, `t_max`).
    #[inline]
    pub fn occluded(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: as in `closest_hit`.
            return unsafe { self.occluded_avx2(origin, direction, t_max) };
        }
        self.occluded_portable(origin, direction, t_max)
    }

    /// The closest hit, for a CPU without the AVX2 build's features.
    #[inline(always)]
    fn closest_hit_portable(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        self.closest_hit_with::<false>(origin, direction, t_max)
    }

    /// Whether anything lies along the ray, for a CPU without the AVX2 build's features.
    #[inline(always)]
    fn occluded_portable(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> bool {
        self.occluded_with::<false>(origin, direction, t_max)
    }

    /// The closest hit; with `FUSED`, the height-field walk uses fused multiply-adds.
    #[inline(always)]
    fn closest_hit_with<const FUSED: bool>(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> Option<Hit> {
        let mut best = None;
        let mut t_limit = t_max;
        if let Some(hit) = self
            .height_field
            .as_ref()
            .and_then(|h| h.closest_hit::<FUSED>(origin, direction, t_max))
        {
            t_limit = hit.t;
            best = Some(hit);
            if self.triangles.is_empty()
                && self
                    .field_box
                    .is_some_and(|(lo, hi)| origin.cmpge(lo).all() && origin.cmple(hi).all())
            {
                return best;
            }
        }
        if !self.triangles.is_empty() {
            let ray = make_ray(origin, direction, t_limit);
            if let Some((id, t)) = self.closest_portable(ray) {
                let uv = self.triangles[id].compute_barycentric(&ray);
                best = Some(Hit {
                    triangle: self.mesh_index[id] as usize,
                    t,
                    u: uv.x,
                    v: uv.y,
                });
                t_limit = t;
            }
        }
        self.panel_hit(origin, direction, t_limit).or(best)
    }

    /// Whether anything lies along the ray (`FUSED` as in [`Tracer::closest_hit_with`]).
    #[inline(always)]
    fn occluded_with<const FUSED: bool>(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> bool {
        if self.panel_hit(origin, direction, t_max).is_some() {
            return true;
        }
        if self
            .height_field
            .as_ref()
            .is_some_and(|h| h.occluded::<FUSED>(origin, direction, t_max))
        {
            return true;
        }
        !self.triangles.is_empty() && self.any_portable(make_ray(origin, direction, t_max))
    }

    /// The same queries compiled for AVX2 and FMA (chosen at run time; the same hits, but
    /// for which triangle a ray through an edge or vertex several share gets).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn closest_hit_avx2(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        self.closest_hit_with::<true>(origin, direction, t_max)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn closest_hits_avx2(
        &self,
        rays: impl Iterator<Item = (Vec3A, Vec3A)>,
        t_max: f32,
        each: &mut impl FnMut(Option<Hit>),
    ) {
        for (origin, direction) in rays {
            each(self.closest_hit_with::<true>(origin, direction, t_max));
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn occluded_avx2(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> bool {
        self.occluded_with::<true>(origin, direction, t_max)
    }

    #[inline(always)]
    fn closest_portable(&self, ray: Ray) -> Option<(usize, f32)> {
        let mut traverse_ray = ray;
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        let mut best = None;
        obvhs::traverse!(
            self.bvh,
            node,
            state,
            node.intersect_ray(&traverse_ray, state.oct_inv4),
            {
                let id = state.primitive_id as usize;
                let t = self.intersect(&traverse_ray, id);
                if t < traverse_ray.tmax {
                    best = Some(id);
                    traverse_ray.tmax = t;
                }
            }
        );
        best.map(|id| (id, traverse_ray.tmax))
    }

    #[inline(always)]
    fn any_portable(&self, ray: Ray) -> bool {
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        let mut hit = false;
        'search: {
            obvhs::traverse!(
                self.bvh,
                node,
                state,
                node.intersect_ray(&ray, state.oct_inv4),
                {
                    if self.intersect(&ray, state.primitive_id as usize) < ray.tmax {
                        hit = true;
                        break 'search;
                    }
                }
            );
        }
        hit
    }
}

/// A panel of the mesh ready for intersection: a rectangle `origin + s·edge_u + t·edge_v`
/// (s, t in [0, 1]) meshed as triangles (0,0) (1,0) (1,1) and (0,0) (1,1) (0,1), or, when
/// unbounded, its whole plane.
#[derive(Debug, Clone)]
struct PanelShape {
    id: u32,
    origin: Vec3A,
    normal: Vec3A,
    /// `edge_u / |edge_u|²` and `edge_v / |edge_v|²`: dotted with a point's offset from the
    /// origin they give its (s, t).
    dual_u: Vec3A,
    dual_v: Vec3A,
    edge_u: Vec3A,
    edge_v: Vec3A,
    unbounded: bool,
    /// Mesh index of the first of the panel's two triangles.
    first_triangle: usize,
    /// The axis the normal lies along, if it does (walls and floors), and the plane's
    /// coordinate along it.
    axis: Option<usize>,
    plane: f32,
}

/// The nearest panel hit so far: its distance (the limit while there is none) and panel.
#[derive(Debug, Clone, Copy)]
struct PanelHit {
    hit: Option<Hit>,
    t: f32,
    id: u32,
}

impl PanelShape {
    /// The panel `id` of `mesh`, or None if its two triangles are not where the mesh builder
    /// puts them (consecutive, in the order above) or its edges are not perpendicular.
    fn new(mesh: &Mesh, id: usize) -> Option<PanelShape> {
        let panel = &mesh.panels[id];
        let first_triangle = mesh.panel_of.iter().position(|&p| p == id as u32)?;
        let (u, v, o) = (panel.edge_u, panel.edge_v, panel.origin);
        let expected = [[o, o + u, o + u + v], [o, o + u + v, o + v]];
        let laid_out = (0..2).all(|k| {
            mesh.panel_of.get(first_triangle + k) == Some(&(id as u32))
                && mesh.corners(first_triangle + k) == expected[k]
        });
        let rectangle = u.dot(v).abs() <= 1e-6 * u.length() * v.length();
        let axis = (0..3).find(|&k| panel.normal[k].abs() == 1.0);
        (laid_out && rectangle).then(|| PanelShape {
            id: id as u32,
            origin: o,
            normal: panel.normal,
            dual_u: u / u.length_squared(),
            dual_v: v / v.length_squared(),
            edge_u: u,
            edge_v: v,
            unbounded: panel.unbounded,
            first_triangle,
            axis,
            plane: axis.map_or(0.0, |k| o[k]),
        })
    }

    /// Corners of the panel's box (a whole plane stands for an unbounded panel).
    fn bounds(&self) -> (Vec3A, Vec3A) {
        if self.unbounded {
            let far = Vec3A::splat(f32::INFINITY);
            let flat = self.normal.abs().cmpgt(Vec3A::splat(0.999));
            return (
                Vec3A::select(flat, self.origin, -far),
                Vec3A::select(flat, self.origin, far),
            );
        }
        let corners = [
            self.origin,
            self.origin + self.edge_u,
            self.origin + self.edge_v,
            self.origin + self.edge_u + self.edge_v,
        ];
        (
            corners.iter().fold(Vec3A::INFINITY, |a, &c| a.min(c)),
            corners.iter().fold(Vec3A::NEG_INFINITY, |a, &c| a.max(c)),
        )
    }

    /// Makes the ray's crossing of the panel's plane at distance `t` the `best` hit if it is
    /// positive, nearer (or as near, and the panel earlier in mesh order) and on the panel,
    /// with the barycentrics of the triangle it lies in (zero on an unbounded panel, whose
    /// albedo is uniform).
    #[inline(always)]
    fn consider(&self, t: f32, origin: Vec3A, direction: Vec3A, best: &mut PanelHit) {
        if !(t > 0.0 && (t < best.t || (t == best.t && self.id < best.id))) {
            return;
        }
        let hit = if self.unbounded {
            Hit {
                triangle: self.first_triangle,
                t,
                u: 0.0,
                v: 0.0,
            }
        } else {
            let offset = origin + direction * t - self.origin;
            let (s, r) = (offset.dot(self.dual_u), offset.dot(self.dual_v));
            if !((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&r)) {
                return;
            }
            // Weights of corners 1 and 2 of the triangle holding (s, r).
            if s >= r {
                Hit {
                    triangle: self.first_triangle,
                    t,
                    u: s - r,
                    v: r,
                }
            } else {
                Hit {
                    triangle: self.first_triangle + 1,
                    t,
                    u: s,
                    v: r - s,
                }
            }
        };
        *best = PanelHit {
            hit: Some(hit),
            t,
            id: self.id,
        };
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
mod tests;
