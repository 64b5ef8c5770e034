//! Ray queries over a height field and its skirt, exploiting the pixel grid: an implicit
//! min/max quadtree over the grid's blocks.
//!
//! A node of level L covers 2^L × 2^L blocks; its box spans their x and y (known from the
//! node's position, nothing stored) and the minimum and maximum height of their triangles
//! and skirts (stored). Each node stores the height ranges of its four children side by side,
//! so one 32-byte load tests all four. Leaves are the blocks: their two triangles are built on
//! the fly from the height grid, and their skirt triangles are tested only when the ray meets
//! the skirt's trapezoid. The structure costs 8 bytes a block and no pointer chasing, which is
//! what makes it faster than a general BVH over the same triangles.

use std::mem::MaybeUninit;
use std::sync::Arc;

use glam::{Vec3A, Vec4};

use crate::geometry::{BlockSide, HeightFieldGrid, Mesh, NO_TRIANGLE};
use crate::tracer::Hit;

/// Height ranges of a node's four children, in the order (row, column) = (0,0), (0,1), (1,0),
/// (1,1). An empty child has `min > max`.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(32))]
struct ChildRanges {
    min: [f32; 4],
    max: [f32; 4],
}

const EMPTY: ChildRanges = ChildRanges { min: [f32::INFINITY; 4], max: [f32::NEG_INFINITY; 4] };

/// One level of the quadtree: `cols` × `rows` nodes, row-major.
#[derive(Debug, Clone)]
struct Level {
    cols: usize,
    children: Vec<ChildRanges>,
}

/// A skirt edge ready for intersection.
#[derive(Debug, Clone)]
struct SkirtQuad {
    block: u32,
    side: BlockSide,
    /// Top of the skirt (the higher of its two top corners).
    top: f32,
    /// Mesh index of the first triangle, and the triangles' corners.
    first_triangle: u32,
    corners: Vec<[Vec3A; 3]>,
}

/// A triangle met inside a block: one of its two surface triangles, or a skirt triangle (by
/// mesh index). The surface triangle's mesh index is looked up only for the final hit.
#[derive(Debug, Clone, Copy)]
enum Triangle {
    Surface { block: usize, second: bool },
    Skirt(u32),
}

/// A hit found inside a block.
#[derive(Debug, Clone, Copy)]
struct BlockHit {
    triangle: Triangle,
    t: f32,
    u: f32,
    v: f32,
}

/// A node waiting on the traversal stack, with the distance at which the ray enters it and
/// its lowest height.
#[derive(Debug, Clone, Copy)]
struct Pending {
    level: u32,
    row: u32,
    col: u32,
    t_enter: f32,
    z_min: f32,
}

/// A ray with its precomputed reciprocal direction and, for the grid's slabs, the distance
/// to the boundary of block column (row) k as `k·step + start`, with the slack subtracted
/// (`_lo`) or added (`_hi`) to the boundary.
#[derive(Debug, Clone, Copy)]
struct GridRay {
    origin: Vec3A,
    direction: Vec3A,
    inv: Vec3A,
    x_step: f32,
    x_start_lo: f32,
    x_start_hi: f32,
    y_step: f32,
    y_start_lo: f32,
    y_start_hi: f32,
}

/// Closest-hit and occlusion queries over the triangles of a [`HeightFieldGrid`].
#[derive(Debug, Clone)]
pub struct HeightFieldAccel {
    grid: Arc<HeightFieldGrid>,
    /// Blocks per row.
    block_cols: usize,
    /// Level L + 1 of the quadtree is `levels[L]` (level 0 are the blocks themselves).
    levels: Vec<Level>,
    /// Height range of the root node.
    root: (f32, f32),
    /// Index into `skirt` of each block's first skirt edge, or `u32::MAX`.
    first_skirt: Vec<u32>,
    skirt: Vec<SkirtQuad>,
    /// Slack added to each box's x and y extent, so that rays along block boundaries are
    /// tested against both neighbours and rounding never loses a box.
    slack: f32,
    /// Spacing of the vertex columns along x and of the rows along y (negative).
    step: (f32, f32),
}

/// Enough for 3 pending children a level over 20 levels (a million pixels a side).
const STACK_SIZE: usize = 64;

impl HeightFieldAccel {
    /// Builds the quadtree over `mesh`'s grid, or None when the mesh has none.
    pub fn new(mesh: &Mesh) -> Option<HeightFieldAccel> {
        let grid = mesh.grid.clone()?;
        let (block_cols, block_rows) = (grid.width - 1, grid.height - 1);
        let skirt: Vec<SkirtQuad> = grid
            .skirt
            .iter()
            .map(|edge| {
                let corners: Vec<[Vec3A; 3]> = edge.triangles.clone().map(|t| mesh.corners(t as usize)).collect();
                let top = corners.iter().flatten().map(|p| p.z).fold(f32::NEG_INFINITY, f32::max);
                SkirtQuad { block: edge.block, side: edge.side, top, first_triangle: edge.triangles.start, corners }
            })
            .collect();
        let mut first_skirt = vec![u32::MAX; block_cols * block_rows];
        for (k, quad) in skirt.iter().enumerate().rev() {
            first_skirt[quad.block as usize] = k as u32;
        }
        // Height range of every block: its four vertices, down to the base under a skirt.
        let mut ranges: Vec<(f32, f32)> = (0..block_cols * block_rows)
            .map(|b| {
                if grid.block_triangles[b] == NO_TRIANGLE {
                    return (f32::INFINITY, f32::NEG_INFINITY);
                }
                let (i, j) = (b / block_cols, b % block_cols);
                let w = grid.width;
                let z = [grid.z[i * w + j], grid.z[i * w + j + 1], grid.z[(i + 1) * w + j], grid.z[(i + 1) * w + j + 1]];
                (z.iter().copied().fold(f32::INFINITY, f32::min), z.iter().copied().fold(f32::NEG_INFINITY, f32::max))
            })
            .collect();
        for quad in &skirt {
            let r = &mut ranges[quad.block as usize];
            let low = quad.corners.iter().flatten().map(|p| p.z).fold(f32::INFINITY, f32::min);
            *r = (r.0.min(low), r.1.max(quad.top));
        }
        let (mut cols, mut rows) = (block_cols, block_rows);
        let mut levels = Vec::new();
        while cols > 1 || rows > 1 {
            let (up_cols, up_rows) = (cols.div_ceil(2), rows.div_ceil(2));
            let mut children = vec![EMPTY; up_cols * up_rows];
            let mut up_ranges = vec![(f32::INFINITY, f32::NEG_INFINITY); up_cols * up_rows];
            for r in 0..rows {
                for c in 0..cols {
                    let node = (r / 2) * up_cols + c / 2;
                    let k = (r % 2) * 2 + c % 2;
                    let (lo, hi) = ranges[r * cols + c];
                    children[node].min[k] = lo;
                    children[node].max[k] = hi;
                    up_ranges[node] = (up_ranges[node].0.min(lo), up_ranges[node].1.max(hi));
                }
            }
            levels.push(Level { cols: up_cols, children });
            (cols, rows, ranges) = (up_cols, up_rows, up_ranges);
        }
        let step = ((grid.xs[grid.width - 1] - grid.xs[0]) / block_cols as f32, (grid.ys[grid.height - 1] - grid.ys[0]) / block_rows as f32);
        // Box boundaries are computed as k·step + start: allow for its rounding.
        let extent = grid.xs[0].abs().max(grid.xs[block_cols].abs()).max(grid.ys[0].abs()).max(grid.ys[block_rows].abs());
        let slack = step.0.abs() * 1e-4 + extent * 4.0 * f32::EPSILON;
        Some(HeightFieldAccel { slack, step, root: ranges[0], grid, block_cols, levels, first_skirt, skirt })
    }

    /// The closest hit along `origin + t·direction` for `t` in [0, `t_max`].
    #[inline(always)]
    pub fn closest_hit(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        let ray = GridRay::new(self, origin, direction);
        let mut best: Option<BlockHit> = None;
        let mut t_best = t_max;
        self.traverse(&ray, &mut t_best, |accel, block, skirt, t_limit| {
            let hit = accel.block_hit(&ray, block, skirt, t_limit, false);
            if hit.is_some() {
                best = hit;
            }
            hit.map(|h| h.t)
        });
        best.map(|h| {
            let triangle = match h.triangle {
                Triangle::Surface { block, second } => self.grid.block_triangles[block] as usize + usize::from(second),
                Triangle::Skirt(t) => t as usize,
            };
            Hit { triangle, t: h.t, u: h.u, v: h.v }
        })
    }

    /// Whether anything lies along `origin + t·direction` for `t` in [0, `t_max`].
    #[inline(always)]
    pub fn occluded(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> bool {
        let ray = GridRay::new(self, origin, direction);
        let mut t_limit = t_max;
        let mut found = false;
        self.traverse(&ray, &mut t_limit, |accel, block, skirt, t_limit| {
            found = accel.block_hit(&ray, block, skirt, t_limit, true).is_some();
            // A hit at distance −1 ends the traversal at once.
            found.then_some(-1.0)
        });
        found
    }

    /// Visits the blocks whose boxes the ray enters, nearest first, calling `visit(self,
    /// block, may_have_skirt, t_limit)`; a returned distance lowers the limit (below 0 stops
    /// the search).
    #[inline(always)]
    fn traverse(&self, ray: &GridRay, t_limit: &mut f32, mut visit: impl FnMut(&Self, usize, bool, f32) -> Option<f32>) {
        let g = &self.grid;
        let x = (g.xs[0] - self.slack, g.xs[g.width - 1] + self.slack);
        let y = (g.ys[g.height - 1] - self.slack, g.ys[0] + self.slack);
        let Some(t_root) = ray.box_entry(x, y, self.root, *t_limit) else { return };
        // Children are pushed farthest first, so that the nearest is visited next: the child
        // nearest along the ray's x and y directions, then the two beside it, then the far one.
        let near_row = u32::from(ray.direction.y > 0.0); // rows grow toward −y
        let near_col = u32::from(ray.direction.x < 0.0);
        let near = near_row * 2 + near_col;
        let push_order = [near ^ 3, near ^ 1, near ^ 2, near];
        let mut stack = [MaybeUninit::<Pending>::uninit(); STACK_SIZE];
        stack[0].write(Pending { level: self.levels.len() as u32, row: 0, col: 0, t_enter: t_root, z_min: self.root.0 });
        let mut top = 1;
        while top > 0 {
            top -= 1;
            // SAFETY: entries below `top` have all been written.
            let Pending { level, row, col, t_enter, z_min } = unsafe { stack[top].assume_init() };
            if t_enter > *t_limit {
                continue;
            }
            if level == 0 {
                // Only a block reaching down to the base can have a skirt.
                let skirt = z_min <= self.grid.base;
                if let Some(t) = visit(self, row as usize * self.block_cols + col as usize, skirt, *t_limit) {
                    if t < 0.0 {
                        return;
                    }
                    *t_limit = t;
                }
                continue;
            }
            let node = &self.levels[level as usize - 1];
            let ranges = &node.children[row as usize * node.cols + col as usize];
            let (entry, hit) = Self::child_entries(ray, level - 1, row * 2, col * 2, ranges, *t_limit);
            for k in push_order {
                if hit & (1 << k) != 0 {
                    let (row, col) = (row * 2 + (k >> 1), col * 2 + (k & 1));
                    stack[top].write(Pending { level: level - 1, row, col, t_enter: entry[k as usize], z_min: ranges.min[k as usize] });
                    top += 1;
                }
            }
        }
    }

    /// Entry distances of the four children (at `level`, first child at `row`, `col`) and a
    /// bit mask of those the ray enters before `t_limit`.
    #[inline(always)]
    fn child_entries(ray: &GridRay, level: u32, row: u32, col: u32, ranges: &ChildRanges, t_limit: f32) -> ([f32; 4], u32) {
        let span = (1u32 << level) as f32;
        let (c, r) = (col as f32 * span, row as f32 * span);
        // First block column (row) of each child, in the order of `ChildRanges`.
        let first_col = Vec4::new(c, c + span, c, c + span);
        let first_row = Vec4::new(r, r, r + span, r + span);
        let tx_a = first_col * ray.x_step + Vec4::splat(ray.x_start_lo);
        let tx_b = (first_col + Vec4::splat(span)) * ray.x_step + Vec4::splat(ray.x_start_hi);
        // Rows grow toward −y: a child's first row is its upper edge.
        let ty_a = first_row * ray.y_step + Vec4::splat(ray.y_start_hi);
        let ty_b = (first_row + Vec4::splat(span)) * ray.y_step + Vec4::splat(ray.y_start_lo);
        let z_min = Vec4::from_array(ranges.min);
        let z_max = Vec4::from_array(ranges.max);
        let tz_a = (z_min - Vec4::splat(ray.origin.z)) * ray.inv.z;
        let tz_b = (z_max - Vec4::splat(ray.origin.z)) * ray.inv.z;
        let near = tx_a.min(tx_b).max(ty_a.min(ty_b)).max(tz_a.min(tz_b)).max(Vec4::ZERO);
        let far = tx_a.max(tx_b).min(ty_a.max(ty_b)).min(tz_a.max(tz_b)) * (1.0 + 4.0 * f32::EPSILON);
        let hit = near.cmple(far) & near.cmple(Vec4::splat(t_limit)) & z_min.cmple(z_max);
        (near.to_array(), hit.bitmask())
    }

    /// The nearest hit of `ray` within block `block` before `t_limit` (any hit if `any`);
    /// the block's skirt is tested only if `skirt`.
    #[inline(always)]
    fn block_hit(&self, ray: &GridRay, block: usize, skirt: bool, t_limit: f32, any: bool) -> Option<BlockHit> {
        let g = &self.grid;
        let (i, j) = (block / self.block_cols, block % self.block_cols);
        let w = g.width;
        let vertex = |r: usize, c: usize| Vec3A::new(g.xs[c], g.ys[r], g.z[r * w + c]);
        let (p00, p10, p01, p11) = (vertex(i, j), vertex(i + 1, j), vertex(i, j + 1), vertex(i + 1, j + 1));
        let mut best: Option<BlockHit> = None;
        let mut limit = t_limit;
        for (second, corners) in [(false, [p00, p10, p01]), (true, [p01, p10, p11])] {
            if let Some((t, u, v)) = intersect_triangle(ray, &corners, limit) {
                best = Some(BlockHit { triangle: Triangle::Surface { block, second }, t, u, v });
                limit = t;
                if any {
                    return best;
                }
            }
        }
        if !skirt {
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
    fn skirt_hit(&self, ray: &GridRay, quad: &SkirtQuad, (i, j): (usize, usize), t_limit: f32) -> Option<BlockHit> {
        let g = &self.grid;
        // The skirt lies in a vertical plane; test its trapezoid's box before its triangles.
        let (t, along, range) = match quad.side {
            BlockSide::Top | BlockSide::Bottom => {
                let y = if quad.side == BlockSide::Top { g.ys[i] } else { g.ys[i + 1] };
                let t = (y - ray.origin.y) * ray.inv.y;
                (t, ray.origin.x + t * ray.direction.x, (g.xs[j], g.xs[j + 1]))
            }
            BlockSide::Left | BlockSide::Right => {
                let x = if quad.side == BlockSide::Left { g.xs[j] } else { g.xs[j + 1] };
                let t = (x - ray.origin.x) * ray.inv.x;
                (t, ray.origin.y + t * ray.direction.y, (g.ys[i + 1], g.ys[i]))
            }
        };
        let e = self.slack;
        let z = ray.origin.z + t * ray.direction.z;
        let near_plane = t.is_finite() && t >= -e && t <= t_limit * (1.0 + 4.0 * f32::EPSILON) + e;
        if !(near_plane && along >= range.0 - e && along <= range.1 + e && z >= g.base - e && z <= quad.top + e) {
            return None;
        }
        let mut best: Option<BlockHit> = None;
        let mut limit = t_limit;
        for (k, corners) in quad.corners.iter().enumerate() {
            if let Some((t, u, v)) = intersect_triangle(ray, corners, limit) {
                best = Some(BlockHit { triangle: Triangle::Skirt(quad.first_triangle + k as u32), t, u, v });
                limit = t;
            }
        }
        best
    }
}

impl GridRay {
    #[inline(always)]
    fn new(accel: &HeightFieldAccel, origin: Vec3A, direction: Vec3A) -> GridRay {
        // A zero component gets a tiny one instead, so that slab distances stay finite and
        // ordered (a ray along a slab's plane is inside it).
        let safe = |d: f32| if d.abs() < 1e-30 { 1e-30 } else { d };
        let inv = Vec3A::new(1.0 / safe(direction.x), 1.0 / safe(direction.y), 1.0 / safe(direction.z));
        let (g, e) = (&accel.grid, accel.slack);
        GridRay {
            origin,
            direction,
            inv,
            x_step: accel.step.0 * inv.x,
            x_start_lo: (g.xs[0] - e - origin.x) * inv.x,
            x_start_hi: (g.xs[0] + e - origin.x) * inv.x,
            y_step: accel.step.1 * inv.y,
            y_start_lo: (g.ys[0] - e - origin.y) * inv.y,
            y_start_hi: (g.ys[0] + e - origin.y) * inv.y,
        }
    }

    /// Distance at which the ray enters the box `x` × `y` × `z` before `t_limit`, if it does.
    #[inline(always)]
    fn box_entry(&self, x: (f32, f32), y: (f32, f32), z: (f32, f32), t_limit: f32) -> Option<f32> {
        if z.0 > z.1 {
            return None;
        }
        let lo = (Vec3A::new(x.0, y.0, z.0) - self.origin) * self.inv;
        let hi = (Vec3A::new(x.1, y.1, z.1) - self.origin) * self.inv;
        let near = lo.min(hi).max_element().max(0.0);
        let far = lo.max(hi).min_element() * (1.0 + 4.0 * f32::EPSILON);
        (near <= far && near <= t_limit).then_some(near)
    }
}

/// Möller–Trumbore intersection with triangle `corners` for t in [0, `t_limit`]: (t, u, v),
/// with u and v the weights of corners 1 and 2. Points on an edge count as inside.
#[inline(always)]
fn intersect_triangle(ray: &GridRay, corners: &[Vec3A; 3], t_limit: f32) -> Option<(f32, f32, f32)> {
    let [v0, v1, v2] = *corners;
    let (e1, e2) = (v1 - v0, v2 - v0);
    let ng = e2.cross(e1);
    let det = ng.dot(ray.direction);
    if det == 0.0 {
        return None;
    }
    let inv_det = 1.0 / det;
    let c = v0 - ray.origin;
    let r = ray.direction.cross(c);
    let u = r.dot(e2) * inv_det;
    let v = -r.dot(e1) * inv_det;
    if !(u >= 0.0 && v >= 0.0 && u + v <= 1.0) {
        return None;
    }
    let t = ng.dot(c) * inv_det;
    (t >= 0.0 && t <= t_limit).then_some((t, u, v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::Rng;
    use crate::scene::{Camera, Floor, HeightField, Scene};
    use glam::vec3a;

    /// A `w`×`h` field with a ragged mask (holes and islands), heights that cross the floor,
    /// and steep steps, so that skirts of every side and height occur.
    fn ragged_scene(w: usize, h: usize, seed: u64) -> Scene {
        let mut rng = Rng::new(seed);
        let n = w * h;
        let height = (0..n).map(|p| (((p % w) as f32 * 0.9).sin() * 4.0 + ((p / w) as f32 * 0.6).cos() * 3.0 + rng.next_f32() * 2.0).max(-0.5) + 1.0).collect();
        let mask = (0..n).map(|_| rng.next_f32() > 0.15).collect();
        Scene {
            camera: Camera { width: w, height: h, pixel_size: 0.7 },
            surface: HeightField { height, mask, albedo: vec![[0.5; 3]; n] },
            floor: Some(Floor { height: 0.5, albedo: [0.5; 3] }),
            cornell_box: None,
        }
    }

    /// The nearest hit over every height-field and skirt triangle, one by one.
    fn brute_force(mesh: &Mesh, ray: &GridRay) -> Option<(usize, f32)> {
        let mut best: Option<(usize, f32)> = None;
        for t in 0..mesh.triangles.len() {
            if !matches!(mesh.kinds[t], crate::geometry::SurfaceKind::Object | crate::geometry::SurfaceKind::Skirt) {
                continue;
            }
            if let Some((d, _, _)) = intersect_triangle(ray, &mesh.corners(t), best.map_or(f32::INFINITY, |b| b.1)) {
                best = Some((t, d));
            }
        }
        best
    }

    #[test]
    fn agrees_with_testing_every_triangle() {
        for (w, h, seed) in [(13, 9, 1), (32, 32, 2), (7, 20, 3), (2, 2, 4)] {
            let scene = ragged_scene(w, h, seed);
            let mesh = Mesh::from_scene(&scene);
            let accel = HeightFieldAccel::new(&mesh).expect("a height-field mesh has a grid");
            let mut rng = Rng::new(seed + 100);
            let (sx, sy) = (w as f32 * 0.7, h as f32 * 0.7);
            let (mut hits, mut skirt_hits) = (0, 0);
            for _ in 0..4000 {
                // From anywhere around the field toward a point in its box.
                let origin = vec3a((rng.next_f32() - 0.5) * sx * 2.0, (rng.next_f32() - 0.5) * sy * 2.0, rng.next_f32() * 12.0 - 1.0);
                let target = vec3a((rng.next_f32() - 0.5) * sx, (rng.next_f32() - 0.5) * sy, rng.next_f32() * 8.0);
                let direction = (target - origin).normalize();
                let ray = GridRay::new(&accel, origin, direction);
                let expected = brute_force(&mesh, &ray);
                let got = accel.closest_hit(origin, direction, f32::INFINITY);
                assert_eq!(got.map(|g| (g.triangle, g.t)), expected, "ray {origin:?} {direction:?} in {w}x{h}");
                assert_eq!(accel.occluded(origin, direction, f32::INFINITY), expected.is_some());
                if let Some((t, d)) = expected {
                    hits += 1;
                    skirt_hits += usize::from(mesh.kinds[t] == crate::geometry::SurfaceKind::Skirt);
                    assert!(!accel.occluded(origin, direction, d * 0.999));
                }
            }
            assert!(hits > 1500 && skirt_hits > 200, "{w}x{h}: {hits} hits, {skirt_hits} on the skirt");
        }
    }

    #[test]
    fn rays_along_block_boundaries_hit() {
        let scene = ragged_scene(16, 16, 5);
        let mut scene = scene;
        scene.surface.mask = vec![true; 256];
        let mesh = Mesh::from_scene(&scene);
        let accel = HeightFieldAccel::new(&mesh).expect("grid");
        let g = mesh.grid.as_ref().expect("grid");
        // Straight down through every vertex and every edge midpoint: always the surface.
        for i in 0..16 {
            for j in 0..16 {
                for (x, y) in [(g.xs[j], g.ys[i]), (g.xs[j], g.ys[i] - 0.35), (g.xs[j] + 0.35, g.ys[i])] {
                    let hit = accel.closest_hit(vec3a(x, y, 50.0), -Vec3A::Z, f32::INFINITY);
                    let inside = x <= g.xs[15] && y >= g.ys[15];
                    assert_eq!(hit.is_some(), inside, "({x}, {y})");
                }
            }
        }
    }
}
