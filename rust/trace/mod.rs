//! Ray queries over a [`Mesh`]: the height field and its skirt through the grid-based
//! [`HeightFieldAccel`], the panels of the surroundings (floor and walls) analytically as
//! rectangles or planes, any other triangle through a compressed wide BVH (obvhs CWBVH,
//! [`bvh`]), and an environment mesh through its own, built once a run ([`environment`]).
//!
//! This module is the [`Tracer`]; [`mesh`] builds the scene's triangles, [`height_field`]
//! walks the height field's grid.

use glam::Vec3A;
use obvhs::ray::Ray;
use obvhs::triangle::Triangle;

use crate::trace::bvh::TriangleBvh;
use crate::trace::height_field::HeightFieldAccel;
use crate::trace::mesh::{Mesh, PlacedEnvironment, SurfaceKind, NO_PANEL};

pub mod bvh;
pub mod environment;
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
    /// Every other triangle of the mesh.
    bvh: TriangleBvh,
    /// Number of mesh triangles.
    triangle_count: usize,
    /// The environment mesh, queried in world units (its triangles follow the mesh's).
    environment: Option<PlacedEnvironment>,
    /// Whether this CPU runs the AVX2 build of the traversal.
    avx2: bool,
    /// The height field's box, when every panel lies outside it: a ray starting inside the
    /// box that hits the field meets no panel before.
    field_box: Option<(Vec3A, Vec3A)>,
}

impl Tracer {
    /// Builds the acceleration structures (the BVH in parallel on rayon's pool); an
    /// environment mesh's is the one it was built with (`Mesh::environment`).
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
        let tris: Vec<Triangle> = in_bvh
            .iter()
            .map(|&t| {
                let [v0, v1, v2] = mesh.corners(t as usize);
                Triangle { v0, v1, v2 }
            })
            .collect();
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
        Tracer {
            field_box: field_box.filter(|_| mesh.environment.is_none()),
            height_field,
            panels,
            axis_ends,
            bvh: TriangleBvh::new(tris, in_bvh),
            triangle_count: mesh.triangles.len(),
            environment: mesh.environment.clone(),
            avx2: avx2_available(),
        }
    }

    /// Number of triangles, the environment mesh's included.
    pub fn len(&self) -> usize {
        self.triangle_count + self.environment.as_ref().map_or(0, |e| e.accel.len())
    }

    /// Whether there is nothing to hit.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
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
        self.occluded_by::<true>(origin, direction, t_max)
    }

    /// Whether anything but the environment mesh lies along `origin + t·direction` for `t`
    /// in (0, `t_max`): the object's part of a shadow whose environment part is known.
    #[inline]
    pub fn occluded_apart_from_environment(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> bool {
        self.occluded_by::<false>(origin, direction, t_max)
    }

    /// [`Tracer::occluded`], the environment mesh included when `ENVIRONMENT`.
    #[inline(always)]
    fn occluded_by<const ENVIRONMENT: bool>(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: as in `closest_hit`.
            return unsafe { self.occluded_avx2::<ENVIRONMENT>(origin, direction, t_max) };
        }
        self.occluded_with::<false, ENVIRONMENT>(origin, direction, t_max)
    }

    /// The closest hit, for a CPU without the AVX2 build's features.
    #[inline(always)]
    fn closest_hit_portable(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        self.closest_hit_with::<false>(origin, direction, t_max)
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
            if self.bvh.is_empty()
                && self
                    .field_box
                    .is_some_and(|(lo, hi)| origin.cmpge(lo).all() && origin.cmple(hi).all())
            {
                return best;
            }
        }
        if let Some((triangle, t, u, v)) = self.bvh.closest(make_ray(origin, direction, t_limit)) {
            best = Some(Hit {
                triangle: triangle as usize,
                t,
                u,
                v,
            });
            t_limit = t;
        }
        if let Some(environment) = &self.environment {
            let scale = environment.scale;
            let found =
                environment
                    .accel
                    .closest(environment.to_world(origin), direction, t_limit * scale);
            if let Some((triangle, t_world, u, v)) = found {
                let t = t_world / scale;
                if t < t_limit {
                    best = Some(Hit {
                        triangle: self.triangle_count + triangle as usize,
                        t,
                        u,
                        v,
                    });
                    t_limit = t;
                }
            }
        }
        self.panel_hit(origin, direction, t_limit).or(best)
    }

    /// Whether anything lies along the ray (`FUSED` as in [`Tracer::closest_hit_with`]; the
    /// environment mesh only when `ENVIRONMENT`).
    #[inline(always)]
    fn occluded_with<const FUSED: bool, const ENVIRONMENT: bool>(
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
        if self.bvh.any(make_ray(origin, direction, t_max)) {
            return true;
        }
        ENVIRONMENT
            && self.environment.as_ref().is_some_and(|environment| {
                environment.accel.occluded(
                    environment.to_world(origin),
                    direction,
                    t_max * environment.scale,
                )
            })
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
    unsafe fn occluded_avx2<const ENVIRONMENT: bool>(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> bool {
        self.occluded_with::<true, ENVIRONMENT>(origin, direction, t_max)
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
pub(crate) fn make_ray(origin: Vec3A, direction: Vec3A, t_max: f32) -> Ray {
    Ray::new(origin, direction + Vec3A::ZERO, 0.0, t_max)
}

#[cfg(test)]
mod tests;
