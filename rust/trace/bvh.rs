//! A compressed wide BVH (obvhs CWBVH) over a set of triangles: closest-hit and any-hit
//! queries, each hit named by the caller's index of its triangle.

use std::time::Duration;

use glam::{UVec2, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;
use obvhs::rt_triangle::RtTriangle;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

use crate::error::Result;
use crate::memory::{advise_huge_pages, on_huge_pages};

/// A triangle laid out for intersection (64 bytes), on a cache line of its own: a test reads
/// one line, not the two it would straddle where the allocator's alignment (16 bytes) puts it.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct LeafTriangle(RtTriangle);

/// Triangles in a CWBVH, laid out for fast intersection.
#[derive(Default)]
pub struct TriangleBvh {
    bvh: CwBvh,
    /// Triangles in BVH order.
    triangles: Vec<LeafTriangle>,
    /// The caller's index of each triangle, in BVH order (empty when the triangles are
    /// numbered in BVH order: see [`TriangleBvh::in_bvh_order`]).
    ids: Vec<u32>,
    /// BVH position of the point placed beyond the bounds (see [`TriangleBvh::new`]).
    bounds_guard: usize,
}

impl TriangleBvh {
    /// Builds the BVH of `tris` (in parallel on rayon's pool); `ids[i]` names `tris[i]` in
    /// the hits.
    pub fn new(mut tris: Vec<Triangle>, ids: Vec<u32>) -> TriangleBvh {
        if tris.is_empty() {
            return TriangleBvh {
                bounds_guard: usize::MAX,
                ..TriangleBvh::default()
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
        let order_ids = bvh
            .primitive_indices
            .iter()
            .map(|&i| ids.get(i as usize).copied().unwrap_or(u32::MAX))
            .collect();
        // A large mesh's traversals read them at random places: on huge pages.
        let mut triangles = Vec::with_capacity(bvh.primitive_indices.len());
        advise_huge_pages(&triangles);
        triangles.extend(
            bvh.primitive_indices
                .iter()
                .map(|&i| LeafTriangle(RtTriangle::from(&tris[i as usize]))),
        );
        TriangleBvh {
            bvh,
            triangles,
            ids: order_ids,
            bounds_guard,
        }
    }

    /// Builds the BVH of `tris` with the triangles numbered in the order it lays them out:
    /// the hits name triangle `order[i]` of `tris` as `i`, and data the caller keeps per
    /// triangle in that order lies together in memory where hits do in space (a large
    /// mesh's shading data is then read from a few cache lines, not from scattered ones).
    /// Returns the BVH and `order`.
    pub fn in_bvh_order(tris: Vec<Triangle>) -> (TriangleBvh, Vec<u32>) {
        let count = tris.len() as u32;
        let mut bvh = TriangleBvh::new(tris, (0..count).collect());
        let order = bvh.ids.iter().copied().filter(|&i| i != u32::MAX).collect();
        bvh.ids = Vec::new();
        (bvh, order)
    }

    /// Moves its nodes (which obvhs allocates) onto memory backed by huge pages when they
    /// are large ([`on_huge_pages`]), as its triangles are: a large mesh's traversals read
    /// them at random places.
    pub fn onto_huge_pages(&mut self) -> Result<()> {
        self.bvh.nodes = on_huge_pages("a BVH's nodes", std::mem::take(&mut self.bvh.nodes))?;
        Ok(())
    }

    /// The caller's index of the triangle at BVH position `slot` (not the bounds guard's).
    #[inline(always)]
    fn id(&self, slot: usize) -> u32 {
        if self.ids.is_empty() {
            (slot - usize::from(slot > self.bounds_guard)) as u32
        } else {
            self.ids[slot]
        }
    }

    /// Whether it holds no triangle.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Distance to BVH primitive `slot` along `ray` (infinite for the bounds guard).
    #[inline(always)]
    fn intersect(&self, ray: &Ray, slot: usize) -> f32 {
        if slot == self.bounds_guard {
            f32::INFINITY
        } else {
            self.triangles[slot].0.intersect(ray)
        }
    }

    /// The nearest triangle along `ray` before its `tmax`: the caller's index, the distance
    /// and the barycentric weights of its vertices 1 and 2.
    #[inline(always)]
    pub fn closest(&self, ray: Ray) -> Option<(u32, f32, f32, f32)> {
        self.closest_hinted(ray, |_| ())
    }

    /// [`TriangleBvh::closest`], calling `candidate` with the caller's index of each triangle
    /// that becomes the nearest so far (to ask for what the caller reads of the hit, while
    /// the search goes on).
    #[inline(always)]
    pub fn closest_hinted(
        &self,
        ray: Ray,
        candidate: impl Fn(u32),
    ) -> Option<(u32, f32, f32, f32)> {
        if self.is_empty() {
            return None;
        }
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
                let slot = state.primitive_id as usize;
                let t = self.intersect(&traverse_ray, slot);
                if t < traverse_ray.tmax {
                    best = Some(slot);
                    traverse_ray.tmax = t;
                    candidate(self.id(slot));
                }
            }
        );
        best.map(|slot| {
            let uv = self.triangles[slot].0.compute_barycentric(&traverse_ray);
            (self.id(slot), traverse_ray.tmax, uv.x, uv.y)
        })
    }

    /// Whether any triangle lies along `ray` before its `tmax`.
    #[inline(always)]
    pub fn any(&self, ray: Ray) -> bool {
        if self.is_empty() {
            return false;
        }
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
