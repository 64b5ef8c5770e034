//! The triangles of one block met by a ray: its two surface triangles, built from the height
//! grid, and its skirt's.

use glam::Vec3A;

use crate::trace::mesh::BlockSide;

use super::ray::{max, min, prefetch};
use super::{BlockHit, GridRay, HeightFieldAccel, Range, SkirtQuad, Triangle, SKIRT};

impl HeightFieldAccel {
    /// Heights of block (`i`, `j`)'s vertices: (i, j), (i, j + 1), (i + 1, j), (i + 1, j + 1).
    #[inline(always)]
    fn corner_heights(&self, i: usize, j: usize) -> (f32, f32, f32, f32) {
        let (g, w) = (&self.grid, self.grid.width);
        debug_assert!(i + 1 < g.height && j + 1 < w);
        // SAFETY: (i, j) is a block of the field: its four vertices exist.
        let z = |k: usize| unsafe { *g.z.get_unchecked(k) };
        (
            z(i * w + j),
            z(i * w + j + 1),
            z((i + 1) * w + j),
            z((i + 1) * w + j + 1),
        )
    }

    /// The height of the lowest of block (`i`, `j`)'s four vertices.
    #[inline(always)]
    pub(super) fn lowest_vertex(&self, i: usize, j: usize) -> f32 {
        let (z00, z01, z10, z11) = self.corner_heights(i, j);
        min(min(z00, z01), min(z10, z11))
    }

    /// The nearest hit of `ray` within block (`row`, `col`) before `t_limit` (any hit if
    /// `any`). With a `span`, the block is skipped when the ray passes above or below it
    /// over that stretch.
    #[inline(always)]
    pub(super) fn block_hit<const F: bool>(
        &self,
        ray: &GridRay<F>,
        row: i32,
        col: i32,
        span: (f32, f32),
        t_limit: f32,
        any: bool,
    ) -> Option<BlockHit> {
        let g = &self.grid;
        let (i, j) = (row as usize, col as usize);
        let block = i * self.block_cols as usize + j;
        debug_assert!(row < self.block_rows && col < self.block_cols);
        // SAFETY: (row, col) is a block of the field: its flags exist.
        let flags = unsafe { *self.packed_flags.get_unchecked(block / 4) } >> (2 * (block % 4)) & 3;
        if flags == 0 {
            return None;
        }
        let (z00, z01, z10, z11) = self.corner_heights(i, j);
        let mut lo = min(min(z00, z01), min(z10, z11));
        if flags & SKIRT != 0 {
            lo = min(lo, g.base);
        }
        let hi = max(max(z00, z01), max(z10, z11));
        if !ray.meets(Range { min: lo, max: hi }, span) {
            return None;
        }
        // SAFETY: as above.
        let (x0, x1, y0, y1) = unsafe {
            (
                *g.xs.get_unchecked(j),
                *g.xs.get_unchecked(j + 1),
                *g.ys.get_unchecked(i),
                *g.ys.get_unchecked(i + 1),
            )
        };
        let (p00, p10, p01, p11) = (
            Vec3A::new(x0, y0, z00),
            Vec3A::new(x0, y1, z10),
            Vec3A::new(x1, y0, z01),
            Vec3A::new(x1, y1, z11),
        );
        let mut best: Option<BlockHit> = None;
        let mut limit = t_limit;
        for (second, corners) in [(false, [p00, p10, p01]), (true, [p01, p10, p11])] {
            if let Some((t, u, v)) = intersect_triangle(ray, &corners, limit) {
                // The hit's mesh index is looked up when the walk ends: load it meanwhile.
                prefetch(&g.block_triangles[block]);
                best = Some(BlockHit {
                    triangle: Triangle::Surface { block, second },
                    t,
                    u,
                    v,
                });
                limit = t;
                if any {
                    return best;
                }
            }
        }
        if flags & SKIRT == 0 {
            return best;
        }
        let mut k = self.first_skirt[block] as usize;
        while k < self.skirt.len() && self.skirt[k].block as usize == block {
            if let Some(hit) = self.skirt_hit(ray, &self.skirt[k], (i, j), limit) {
                limit = hit.t;
                best = Some(hit);
                if any {
                    return best;
                }
            }
            k += 1;
        }
        best
    }

    /// The nearest hit of `ray` on a skirt edge of block (`i`, `j`) before `t_limit`.
    #[inline(always)]
    fn skirt_hit<const F: bool>(
        &self,
        ray: &GridRay<F>,
        quad: &SkirtQuad,
        (i, j): (usize, usize),
        t_limit: f32,
    ) -> Option<BlockHit> {
        let g = &self.grid;
        // The skirt lies in a vertical plane; test its trapezoid's box before its triangles.
        let (t, along, range) = match quad.side {
            BlockSide::Top | BlockSide::Bottom => {
                let y = if quad.side == BlockSide::Top {
                    g.ys[i]
                } else {
                    g.ys[i + 1]
                };
                let t = (y - ray.origin.y) * ray.inv.y;
                (
                    t,
                    ray.origin.x + t * ray.direction.x,
                    (g.xs[j], g.xs[j + 1]),
                )
            }
            BlockSide::Left | BlockSide::Right => {
                let x = if quad.side == BlockSide::Left {
                    g.xs[j]
                } else {
                    g.xs[j + 1]
                };
                let t = (x - ray.origin.x) * ray.inv.x;
                (
                    t,
                    ray.origin.y + t * ray.direction.y,
                    (g.ys[i + 1], g.ys[i]),
                )
            }
        };
        let e = self.slack;
        let z = ray.origin.z + t * ray.direction.z;
        let near_plane = t.is_finite() && t >= -e && t <= t_limit * (1.0 + 4.0 * f32::EPSILON) + e;
        if !(near_plane
            && along >= range.0 - e
            && along <= range.1 + e
            && z >= g.base - e
            && z <= quad.top + e)
        {
            return None;
        }
        let mut best: Option<BlockHit> = None;
        let mut limit = t_limit;
        for (k, corners) in quad.corners.iter().enumerate() {
            if let Some((t, u, v)) = intersect_triangle(ray, corners, limit) {
                best = Some(BlockHit {
                    triangle: Triangle::Skirt(quad.first_triangle + k as u32),
                    t,
                    u,
                    v,
                });
                limit = t;
            }
        }
        best
    }
}

/// Möller–Trumbore intersection with triangle `corners` for t in [0, `t_limit`]: (t, u, v),
/// with u and v the weights of corners 1 and 2. Points on an edge count as inside.
#[inline(always)]
pub(super) fn intersect_triangle<const F: bool>(
    ray: &GridRay<F>,
    corners: &[Vec3A; 3],
    t_limit: f32,
) -> Option<(f32, f32, f32)> {
    let [v0, v1, v2] = *corners;
    let (e1, e2) = (v1 - v0, v2 - v0);
    let ng = e2.cross(e1);
    let det = ng.dot(ray.direction);
    if det == 0.0 {
        return None;
    }
    let inv_det = 1.0 / det;
    let c = v0 - ray.origin;
    // The distance first: a ray leaving the triangle's plane (the common case for rays
    // leaving the surface) is rejected before the barycentrics are computed.
    let t = ng.dot(c) * inv_det;
    if !(t >= 0.0 && t <= t_limit) {
        return None;
    }
    let r = ray.direction.cross(c);
    let u = r.dot(e2) * inv_det;
    let v = -r.dot(e1) * inv_det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0).then_some((t, u, v))
}
