//! Ray queries over a height field and its skirt, exploiting the pixel grid: a walk along
//! the ray over a pyramid of slabs bounding the grid's blocks.
//!
//! Level L of the pyramid splits the grid into cells of 2^L × 2^L blocks and stores, per
//! cell, a slab between two parallel planes z = a·x + b·y + c (a `Band`) that holds the
//! triangles (surface and skirt) of its blocks *and of the ring of blocks around it*. The
//! planes follow the least-squares slope of the cell, so on a smooth surface the slab is far
//! thinner than the cell's height range and a ray leaving the surface is found to pass above
//! it after a short way. The walk visits the cells the ray passes through in order, like a
//! line-drawing DDA: a cell the ray passes wholly above or below is stepped over, going up as
//! many levels as the step crossed parent boundaries; a cell the ray may meet is entered a
//! level down; the walk ends where the ray leaves the field's box. A ray that starts inside
//! the field starts at its own block. At level 0 the block's two triangles are built from the
//! height grid and tested (after its own height range), its skirt when it has one, and any
//! neighbouring block whose side the ray runs along within rounding distance. The ring in
//! each slab is what makes stepping over a cell safe for a ray that grazes its border, and
//! each slab test allows for the rounding of the ray's points. The walk needs no stack,
//! follows no pointer and stores 16 bytes a cell (a third of the blocks' count in all).
//!
//! Each block also stores, for each quadrant of directions (a byte each), the slope of a
//! cone that clears every triangle beyond its ring of 3×3 blocks: a ray that starts in the
//! block no lower than its lowest vertex and rises more steeply than that walks only across
//! the ring (most rays leaving a smooth surface toward the sky).

use std::sync::Arc;

use glam::{Vec3A, Vec4};
use rayon::prelude::*;

use crate::trace::height_field::escape_cone::{escape_cones, escape_slopes};
use crate::trace::mesh::{BlockSide, HeightFieldGrid, Mesh, NO_TRIANGLE};
use crate::trace::Hit;

mod escape_cone;

/// A height range (of a block, or of the whole field). Nothing is `min = max = +∞`, which
/// every ray passes below.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(8))]
struct Range {
    min: f32,
    max: f32,
}

const NOTHING: Range = Range {
    min: f32::INFINITY,
    max: f32::INFINITY,
};

/// Bounds of the triangles of a pyramid cell and the ring of blocks around it between two
/// parallel planes: every point of them has `c_lo <= z − a·x − b·y <= c_hi`. The planes follow
/// the surface's mean slope over the cell, so on a smooth surface the slab is much thinner than
/// the cell's height range and rays leaving the surface pass above it sooner. A cell with
/// nothing in reach has `c_lo = c_hi = +∞`, which every ray passes below.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(16))]
struct Band {
    a: f32,
    b: f32,
    c_lo: f32,
    c_hi: f32,
}

const EMPTY: Band = Band {
    a: 0.0,
    b: 0.0,
    c_lo: f32::INFINITY,
    c_hi: f32::INFINITY,
};

/// Steepest slope a band's planes may have: it bounds the rounding of `z − a·x − b·y` (see
/// [`GridRay::z_slack`]); a steeper cell gets a thicker band, never a wrong one.
const MAX_BAND_SLOPE: f64 = 8.0;

/// Vertex flag: the vertex is a corner of a meshed block.
const MESHED_VERTEX: u8 = 1;
/// Vertex flag: the vertex is a corner of a block with skirt edges (the skirt under it
/// reaches down to the base).
const SKIRT_VERTEX: u8 = 2;

/// [`MESHED_VERTEX`] and [`SKIRT_VERTEX`] of each vertex of a `width`×`height` grid, from
/// the flags of its (width − 1)×(height − 1) blocks.
fn vertex_flags(block_flags: &[u8], width: usize, height: usize) -> Vec<u8> {
    let cols = width - 1;
    let mut flags = vec![0u8; width * height];
    for (b, &f) in block_flags.iter().enumerate() {
        if f == 0 {
            continue;
        }
        let v = if f & SKIRT != 0 {
            MESHED_VERTEX | SKIRT_VERTEX
        } else {
            MESHED_VERTEX
        };
        let (i, j) = (b / cols, b % cols);
        for k in [
            i * width + j,
            i * width + j + 1,
            (i + 1) * width + j,
            (i + 1) * width + j + 1,
        ] {
            flags[k] |= v;
        }
    }
    flags
}

/// The band of cell (`row`, `col`) of pyramid `level`: the blocks of rows
/// `row·2^level − 1 ..= (row + 1)·2^level` (and likewise columns), that is the cell's blocks
/// and a ring of one block, bounded between the least-squares plane of their vertices' heights
/// and its parallels (or between horizontal planes when those are closer). Triangles are flat,
/// so bounding their vertices (and the base under skirt vertices) bounds them.
fn cell_band(
    grid: &HeightFieldGrid,
    vertex_flags: &[u8],
    level: usize,
    row: i32,
    col: i32,
) -> Band {
    let size = 1i64 << level;
    let (w, h) = (grid.width as i64, grid.height as i64);
    let rows = ((row as i64 * size - 1).max(0) as usize)
        ..=(((row as i64 + 1) * size + 1).min(h - 1) as usize);
    let (c0, c1) = (
        (col as i64 * size - 1).max(0) as usize,
        ((col as i64 + 1) * size + 1).min(w - 1) as usize,
    );
    let row_of = |i: usize| {
        let k = i * grid.width;
        (&grid.z[k + c0..=k + c1], &vertex_flags[k + c0..=k + c1])
    };
    // Least-squares plane z = a·u + b·v + c in offsets (u, v) from the region's first vertex,
    // from sums over each row (v is constant along a row).
    let (x0, y0) = (grid.xs[c0] as f64, grid.ys[*rows.start()] as f64);
    let xs = &grid.xs[c0..=c1];
    let (mut n, mut su, mut sv, mut sz) = (0.0f64, 0.0, 0.0, 0.0);
    let (mut suu, mut suv, mut svv, mut suz, mut svz) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
    for i in rows.clone() {
        let (zs, flags) = row_of(i);
        let (mut rn, mut ru, mut ruu, mut rz, mut ruz) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for ((&z, &f), &x) in zs.iter().zip(flags).zip(xs) {
            if f != 0 {
                let (u, z) = (x as f64 - x0, z as f64);
                rn += 1.0;
                ru += u;
                ruu += u * u;
                rz += z;
                ruz += u * z;
            }
        }
        let v = grid.ys[i] as f64 - y0;
        n += rn;
        su += ru;
        suu += ruu;
        sz += rz;
        suz += ruz;
        sv += rn * v;
        svv += rn * v * v;
        suv += ru * v;
        svz += rz * v;
    }
    if n == 0.0 {
        return EMPTY;
    }
    let (cuu, cuv, cvv) = (suu - su * su / n, suv - su * sv / n, svv - sv * sv / n);
    let (cuz, cvz) = (suz - su * sz / n, svz - sv * sz / n);
    let det = cuu * cvv - cuv * cuv;
    let (a, b) = if n >= 3.0 && det > 1e-9 * cuu * cvv {
        let a = ((cvv * cuz - cuv * cvz) / det).clamp(-MAX_BAND_SLOPE, MAX_BAND_SLOPE);
        let b = ((cuu * cvz - cuv * cuz) / det).clamp(-MAX_BAND_SLOPE, MAX_BAND_SLOPE);
        (a as f32, b as f32)
    } else {
        (0.0, 0.0)
    };
    // The planes' offsets over every vertex (and the base under skirt vertices), with the
    // stored (f32) slopes, and the horizontal bounds.
    let (a64, b64, base) = (a as f64, b as f64, grid.base as f64);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut z_lo, mut z_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in rows {
        let (zs, flags) = row_of(i);
        let by = b64 * grid.ys[i] as f64;
        for ((&z, &f), &x) in zs.iter().zip(flags).zip(xs) {
            if f != 0 {
                let ax = a64 * x as f64;
                let top = z as f64;
                let bottom = if f & SKIRT_VERTEX != 0 { base } else { top };
                let (low, high) = if bottom < top {
                    (bottom, top)
                } else {
                    (top, bottom)
                };
                let plane = ax + by;
                if low - plane < lo {
                    lo = low - plane;
                }
                if high - plane > hi {
                    hi = high - plane;
                }
                if low < z_lo {
                    z_lo = low;
                }
                if high > z_hi {
                    z_hi = high;
                }
            }
        }
    }
    let outward = |lo: f64, hi: f64| ((lo as f32).next_down(), (hi as f32).next_up());
    if hi - lo < z_hi - z_lo {
        let (c_lo, c_hi) = outward(lo, hi);
        Band { a, b, c_lo, c_hi }
    } else {
        let (c_lo, c_hi) = outward(z_lo, z_hi);
        Band {
            a: 0.0,
            b: 0.0,
            c_lo,
            c_hi,
        }
    }
}

/// Where level L of the pyramid lies in [`HeightFieldAccel::pyramid`] (level 0, the blocks,
/// only has its ring limits).
#[derive(Debug, Clone, Copy, Default)]
struct LevelInfo {
    /// Index of cell (0, 0); cell (`row`, `col`) is at `origin + row·stride + col`.
    origin: isize,
    stride: isize,
    /// The ring's last column (row) + 1: cell `col` is in the field or its ring iff
    /// `(col + 1) as u32 <= last_col`.
    last_col: u32,
    last_row: u32,
}

/// More levels than any grid that fits in memory needs.
const MAX_LEVELS: usize = 32;

/// Block flag: the block holds its two surface triangles.
const SURFACE: u8 = 1;
/// Block flag: the block has skirt edges.
const SKIRT: u8 = 2;

/// Sides of a block as the ray sees them, as bits (see [`HeightFieldAccel::visit_neighbours`]):
/// the x side it enters through, the y side it enters through, the x side it leaves through,
/// the y side it leaves through.
const X_ENTRY: u8 = 1;
const Y_ENTRY: u8 = 2;
const X_EXIT: u8 = 4;
const Y_EXIT: u8 = 8;

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

/// A ray with what the walk needs precomputed: the distance to the boundary of block
/// column (row) k is `k·x_step + x_start` (`k·y_step + y_start`); `forward_*` says whether
/// the ray goes toward higher column (row) indices; within `margin` of distance of a
/// boundary, the ray is within the slack of it. With `FUSED`, the walk's multiply-adds on it
/// are fused (the AVX2+FMA build).
#[derive(Debug, Clone, Copy)]
struct GridRay<const FUSED: bool> {
    origin: Vec3A,
    direction: Vec3A,
    inv: Vec3A,
    x_step: f32,
    x_start: f32,
    y_step: f32,
    y_start: f32,
    margin: f32,
    /// Within a block entered at `t_in` and left along x (y) at `tx` (`ty`), the ray runs
    /// within twice the slack of its entry x (y) side while `t_in + reach.x < tx` (`.y`, `ty`),
    /// and of its exit side while `t_out + reach.z > tx` (`.w`, `ty`): `reach` holds the
    /// distance the ray takes to cross a block column (row) less that to move twice the
    /// slack along x (y), then the latter.
    reach: Vec4,
    forward_x: bool,
    forward_y: bool,
    /// Distances at which the ray enters (0 if it starts inside) and leaves the field's box,
    /// NaN if it misses it: nothing lies beyond `t_far`.
    t_near: f32,
    t_far: f32,
    /// Bound on the rounding of `z − a·x − b·y` at points of the ray up to `t_far`.
    z_slack: f32,
}

/// Where a walk is: cell (`row`, `col`) of pyramid level `level`, entered at distance
/// `t_in`, through the sides in `entry` (a block's neighbours there need no visit).
#[derive(Debug, Clone, Copy)]
struct WalkState {
    level: usize,
    row: i32,
    col: i32,
    entry: u8,
    t_in: f32,
}

/// Closest-hit and occlusion queries over the triangles of a [`HeightFieldGrid`].
#[derive(Debug, Clone)]
pub struct HeightFieldAccel {
    grid: Arc<HeightFieldGrid>,
    /// Blocks per row and block rows.
    block_cols: i32,
    block_rows: i32,
    /// [`SURFACE`] and [`SKIRT`] bits of each block, row-major, four blocks to a byte
    /// (block b in bits 2·(b mod 4) and up).
    packed_flags: Vec<u8>,
    /// Bands of the pyramid's levels 1 to `top`, each with its ring and one more cell of
    /// nothing on every side, so that the walk's indices need no bounds check; cell (0, 0) of
    /// level `top` covers the whole field.
    pyramid: Vec<Band>,
    level_info: [LevelInfo; MAX_LEVELS],
    top: usize,
    /// Height range of the whole field.
    field: Range,
    /// Corners of the field's box, widened by the slack in x and y.
    field_box: (Vec3A, Vec3A),
    /// [`escape_cones`] of each block, four quadrants a block (which rays from it meet
    /// nothing beyond its ring), as indices into `escape_slopes`.
    escape: Vec<u8>,
    escape_slopes: [f32; 256],
    /// Index into `skirt` of each block's first skirt edge, or `u32::MAX`.
    first_skirt: Vec<u32>,
    skirt: Vec<SkirtQuad>,
    /// Rounding allowance in x and y: rays passing this close to a block's side also test
    /// the block across it, and the field's box is widened by it.
    slack: f32,
    /// Spacing of the vertex columns along x and of the rows along y (negative), and its
    /// inverse.
    step: (f32, f32),
    inv_step: (f32, f32),
}

impl HeightFieldAccel {
    /// Builds the pyramid over `mesh`'s grid, or None when the mesh has none.
    pub fn new(mesh: &Mesh) -> Option<HeightFieldAccel> {
        let grid = mesh.grid.clone()?;
        let (cols, rows) = (grid.width - 1, grid.height - 1);
        let skirt: Vec<SkirtQuad> = grid
            .skirt
            .iter()
            .map(|edge| {
                let corners: Vec<[Vec3A; 3]> = edge
                    .triangles
                    .clone()
                    .map(|t| mesh.corners(t as usize))
                    .collect();
                let top = corners
                    .iter()
                    .flatten()
                    .map(|p| p.z)
                    .fold(f32::NEG_INFINITY, f32::max);
                SkirtQuad {
                    block: edge.block,
                    side: edge.side,
                    top,
                    first_triangle: edge.triangles.start,
                    corners,
                }
            })
            .collect();
        let mut first_skirt = vec![u32::MAX; cols * rows];
        let mut block_flags: Vec<u8> = grid
            .block_triangles
            .iter()
            .map(|&t| if t == NO_TRIANGLE { 0 } else { SURFACE })
            .collect();
        for (k, quad) in skirt.iter().enumerate().rev() {
            first_skirt[quad.block as usize] = k as u32;
            block_flags[quad.block as usize] |= SKIRT;
        }
        // Height range of every block: its four vertices, down to the base under a skirt.
        let w = grid.width;
        let own: Vec<Range> = (0..cols * rows)
            .map(|b| {
                if block_flags[b] == 0 {
                    return NOTHING;
                }
                let (i, j) = (b / cols, b % cols);
                let z = [
                    grid.z[i * w + j],
                    grid.z[i * w + j + 1],
                    grid.z[(i + 1) * w + j],
                    grid.z[(i + 1) * w + j + 1],
                ];
                let (mut lo, hi) = (
                    z.iter().copied().fold(f32::INFINITY, f32::min),
                    z.iter().copied().fold(f32::NEG_INFINITY, f32::max),
                );
                if block_flags[b] & SKIRT != 0 {
                    lo = lo.min(grid.base);
                }
                Range { min: lo, max: hi }
            })
            .collect();
        let field = own.iter().fold(NOTHING, |a, &b| {
            if a == NOTHING {
                b
            } else if b == NOTHING {
                a
            } else {
                Range {
                    min: a.min.min(b.min),
                    max: a.max.max(b.max),
                }
            }
        });
        let (ci, ri) = (cols as i32, rows as i32);
        let vertex_flags = vertex_flags(&block_flags, w, grid.height);
        let mut top = 0;
        while (ci - 1) >> top > 0 || (ri - 1) >> top > 0 {
            top += 1;
        }
        assert!(top < MAX_LEVELS, "height field too large for the pyramid");
        let mut pyramid = Vec::new();
        let mut level_info = [LevelInfo::default(); MAX_LEVELS];
        level_info[0] = LevelInfo {
            origin: 0,
            stride: 0,
            last_col: ci as u32 + 1,
            last_row: ri as u32 + 1,
        };
        for (level, info) in level_info.iter_mut().enumerate().take(top + 1).skip(1) {
            // Cells −1..=(blocks >> level) of this level, and one more of nothing each side.
            let (level_cols, level_rows) = ((ci >> level) + 2, (ri >> level) + 2);
            let stride = level_cols as isize + 2;
            let start = pyramid.len() as isize;
            let bands: Vec<Band> = (-2..level_rows)
                .into_par_iter()
                .flat_map_iter(|r| {
                    let (grid, vertex_flags) = (&grid, &vertex_flags);
                    (-2..level_cols).map(move |c| {
                        let in_ring =
                            (-1..level_rows - 1).contains(&r) && (-1..level_cols - 1).contains(&c);
                        if in_ring {
                            cell_band(grid, vertex_flags, level, r, c)
                        } else {
                            EMPTY
                        }
                    })
                })
                .collect();
            pyramid.extend(bands);
            *info = LevelInfo {
                origin: start + 2 * stride + 2,
                stride,
                last_col: level_cols as u32 - 1,
                last_row: level_rows as u32 - 1,
            };
        }
        let step = (
            (grid.xs[cols] - grid.xs[0]) / cols as f32,
            (grid.ys[rows] - grid.ys[0]) / rows as f32,
        );
        // Block boundaries are computed as k·step + start: allow for its rounding.
        let extent = grid.xs[0]
            .abs()
            .max(grid.xs[cols].abs())
            .max(grid.ys[0].abs())
            .max(grid.ys[rows].abs());
        let slack = step.0.abs() * 1e-6 + extent * 4.0 * f32::EPSILON;
        let mut packed_flags = vec![0u8; block_flags.len().div_ceil(4)];
        for (b, &f) in block_flags.iter().enumerate() {
            packed_flags[b / 4] |= f << (2 * (b % 4));
        }
        let field_box = (
            Vec3A::new(grid.xs[0] - slack, grid.ys[rows] - slack, field.min),
            Vec3A::new(grid.xs[cols] + slack, grid.ys[0] + slack, field.max),
        );
        let escape_slopes = escape_slopes();
        let block_top = own
            .iter()
            .map(|r| {
                if r.max.is_finite() {
                    r.max
                } else {
                    f32::NEG_INFINITY
                }
            })
            .collect();
        let escape = escape_cones(
            &grid,
            block_top,
            |b| block_flags[b] & SURFACE != 0,
            top,
            step,
            slack,
            &escape_slopes,
        );
        Some(HeightFieldAccel {
            block_cols: ci,
            block_rows: ri,
            packed_flags,
            pyramid,
            level_info,
            top,
            field,
            field_box,
            escape,
            escape_slopes,
            first_skirt,
            skirt,
            slack,
            step,
            inv_step: (1.0 / step.0, 1.0 / step.1),
            grid,
        })
    }

    /// Corners of the box holding every triangle of the field and its skirt.
    pub fn bounds(&self) -> (Vec3A, Vec3A) {
        let g = &self.grid;
        (
            Vec3A::new(g.xs[0], g.ys[g.height - 1], self.field.min),
            Vec3A::new(g.xs[g.width - 1], g.ys[0], self.field.max),
        )
    }

    /// The closest hit along `origin + t·direction` for `t` in [0, `t_max`]. With `FUSED`,
    /// the walk's distances and heights use fused multiply-adds (for a build with FMA
    /// instructions): the same hit, but for which triangle a ray through an edge or vertex
    /// several share gets.
    #[inline(always)]
    pub fn closest_hit<const FUSED: bool>(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> Option<Hit> {
        let ray = GridRay::<FUSED>::new(self, origin, direction);
        let mut best: Option<BlockHit> = None;
        self.walk::<false, FUSED>(&ray, t_max, &mut best);
        best.map(|h| {
            let triangle = match h.triangle {
                Triangle::Surface { block, second } => {
                    self.grid.block_triangles[block] as usize + usize::from(second)
                }
                Triangle::Skirt(t) => t as usize,
            };
            Hit {
                triangle,
                t: h.t,
                u: h.u,
                v: h.v,
            }
        })
    }

    /// Whether anything lies along `origin + t·direction` for `t` in [0, `t_max`] (`FUSED` as
    /// in [`HeightFieldAccel::closest_hit`]).
    #[inline(always)]
    pub fn occluded<const FUSED: bool>(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> bool {
        let ray = GridRay::<FUSED>::new(self, origin, direction);
        let mut found = None;
        self.walk::<true, FUSED>(&ray, t_max, &mut found);
        found.is_some()
    }

    /// Visits, in order along the ray, the blocks it may meet before `t_limit`, keeping in
    /// `best` the nearest hit (with `ANY`, the first hit found, which ends the walk).
    #[inline(always)]
    fn walk<const ANY: bool, const F: bool>(
        &self,
        ray: &GridRay<F>,
        t_limit: f32,
        best: &mut Option<BlockHit>,
    ) {
        let Some((mut state, reach)) = self.start(ray, t_limit) else {
            return;
        };
        // Nothing lies beyond the field's box, nor beyond `reach`.
        let mut t_limit = min(min(t_limit, ray.t_far), reach);
        loop {
            let alive = if state.level > 0 {
                self.cell_step(ray, &mut state, t_limit)
            } else {
                self.block_step::<ANY, F>(ray, &mut state, &mut t_limit, best)
            };
            if !alive {
                return;
            }
        }
    }

    /// Tests block (`row`, `col`) over the ray's stretch `span`: a hit nearer than `t_limit`
    /// goes to `best` and lowers the limit. True when the walk is over (`ANY` and a hit).
    #[inline(always)]
    fn visit<const ANY: bool, const F: bool>(
        &self,
        ray: &GridRay<F>,
        row: i32,
        col: i32,
        span: (f32, f32),
        t_limit: &mut f32,
        best: &mut Option<BlockHit>,
    ) -> bool {
        let Some(hit) = self.block_hit(ray, row, col, span, *t_limit, ANY) else {
            return false;
        };
        *best = Some(hit);
        *t_limit = hit.t;
        ANY
    }

    /// Where the walk of `ray` starts, and how far it needs to go (+∞: to the field box's
    /// exit), or None if the ray misses the field's box before `t_limit`. A ray starting
    /// inside the box starts at its block; any other at the top cell. A ray that rises
    /// out of its block's escape cone meets nothing beyond the block's ring.
    #[inline(always)]
    fn start<const F: bool>(&self, ray: &GridRay<F>, t_limit: f32) -> Option<(WalkState, f32)> {
        let g = &self.grid;
        let t_in = ray.t_near;
        // NaN: the ray misses the box.
        if t_in.is_nan() || t_in > t_limit {
            return None;
        }
        if t_in != 0.0 {
            return Some((
                WalkState {
                    level: self.top,
                    row: 0,
                    col: 0,
                    entry: 0,
                    t_in,
                },
                f32::INFINITY,
            ));
        }
        let (row, col) = (
            Self::block_of::<false>(ray.origin.y, &g.ys, self.inv_step.1, self.block_rows),
            Self::block_of::<true>(ray.origin.x, &g.xs, self.inv_step.0, self.block_cols),
        );
        // Going away from a side of the block its origin lies strictly inside, the ray
        // cannot meet the block behind that side: treat it as the side the ray came in
        // through. (An origin on a side may lie on that block's skirt.)
        // SAFETY: `block_of` gives a block of the field: its vertex column and row and the
        // next exist.
        let (x0, x1, y0, y1) = unsafe {
            (
                *g.xs.get_unchecked(col as usize),
                *g.xs.get_unchecked(col as usize + 1),
                *g.ys.get_unchecked(row as usize),
                *g.ys.get_unchecked(row as usize + 1),
            )
        };
        let (ox, oy) = (ray.origin.x, ray.origin.y);
        let entry = if x0 < ox && ox < x1 && y1 < oy && oy < y0 {
            X_ENTRY | Y_ENTRY
        } else {
            0
        };
        let quadrant = usize::from(ray.forward_x) + 2 * usize::from(ray.forward_y);
        // SAFETY: as above, four codes a block; a code indexes the 256 slopes.
        let k2 = unsafe {
            *self.escape_slopes.get_unchecked(*self.escape.get_unchecked(
                4 * (row as usize * self.block_cols as usize + col as usize) + quadrant,
            ) as usize)
        };
        let d = ray.direction;
        if d.z > 0.0
            && d.z * d.z >= k2 * (d.x * d.x + d.y * d.y)
            && ray.origin.z >= self.lowest_vertex(row as usize, col as usize)
        {
            // To where the ray leaves the ring, and the rounding of its points there.
            let (fx, fy) = (i32::from(ray.forward_x), i32::from(ray.forward_y));
            let (tx, ty) = ray.boundaries(row - 1 + 3 * fy, col - 1 + 3 * fx);
            let t = min(tx, ty);
            return Some((
                WalkState {
                    level: 0,
                    row,
                    col,
                    entry,
                    t_in,
                },
                t + 4.0 * ray.margin + t * 1e-6,
            ));
        }
        Some((
            WalkState {
                level: 0,
                row,
                col,
                entry,
                t_in,
            },
            f32::INFINITY,
        ))
    }

    /// One step of the walk in a cell above the blocks: down into the child the ray is in
    /// when the ray may meet the cell's range, else on to the next cell. False when the walk
    /// is over.
    #[inline(always)]
    fn cell_step<const F: bool>(
        &self,
        ray: &GridRay<F>,
        state: &mut WalkState,
        t_limit: f32,
    ) -> bool {
        let WalkState {
            level,
            row,
            col,
            t_in,
            ..
        } = *state;
        let (tx, ty, t_out) = ray.exits(level, row, col, t_in);
        let info = self.level_info[level % MAX_LEVELS];
        let cell = info.origin + row as isize * info.stride + col as isize;
        debug_assert!(
            (0..self.pyramid.len() as isize).contains(&cell),
            "cell ({row}, {col}) of level {level}"
        );
        // SAFETY: the walk keeps to the ring's cells and their children, which lie within
        // the padding of one cell around the ring.
        let band = unsafe { *self.pyramid.get_unchecked(cell as usize) };
        if ray.meets_band(band, t_in - ray.margin, t_out + ray.margin) {
            // Down to the child the ray is in at t_in.
            let level = level - 1;
            let (mx, my) = ray.boundaries((2 * row + 1) << level, (2 * col + 1) << level);
            state.level = level;
            state.col = 2 * col + i32::from((mx <= t_in) == ray.forward_x);
            state.row = 2 * row + i32::from((my <= t_in) == ray.forward_y);
            return true;
        }
        t_out - ray.margin <= t_limit && self.advance(ray, state, tx < ty, t_out)
    }

    /// One step of the walk in a block: visits it and any neighbour whose side the ray
    /// runs along, then moves on to the next cell. False when the walk is over.
    #[inline(always)]
    fn block_step<const ANY: bool, const F: bool>(
        &self,
        ray: &GridRay<F>,
        state: &mut WalkState,
        t_limit: &mut f32,
        best: &mut Option<BlockHit>,
    ) -> bool {
        let WalkState {
            row,
            col,
            t_in,
            entry,
            ..
        } = *state;
        let (tx, ty, t_out) = ray.exits(0, row, col, t_in);
        let along_x = tx < ty;
        let span = (t_in - ray.margin, t_out + ray.margin);
        let info = self.level_info[0];
        if (col + 1) as u32 <= info.last_col && (row + 1) as u32 <= info.last_row {
            // A block of the field, or of the ring around it (which has no triangles but
            // may run along the field's side).
            if (col as u32) < self.block_cols as u32
                && (row as u32) < self.block_rows as u32
                && self.visit::<ANY, F>(ray, row, col, span, t_limit, best)
            {
                return false;
            }
            let exit = if along_x { X_EXIT } else { Y_EXIT };
            // Sides the ray runs within twice the slack of: before it passes the entry
            // side's line plus the slack, or after the exit side's line minus it (the signs
            // of the four differences, the exits' negated, say it lane by lane).
            let behind =
                Vec4::new(t_in, t_in, t_out, t_out) + ray.reach - Vec4::new(tx, ty, tx, ty);
            let sides = (behind * Vec4::new(1.0, 1.0, -1.0, -1.0)).is_negative_bitmask() as u8
                & !(entry | exit);
            if sides != 0
                && self.visit_neighbours::<ANY, F>(
                    ray,
                    row,
                    col,
                    sides,
                    (span.0 - ray.margin, span.1 + ray.margin),
                    t_limit,
                    best,
                )
            {
                return false;
            }
        }
        t_out - ray.margin <= *t_limit && self.advance(ray, state, along_x, t_out)
    }

    /// Steps to the next cell of the state's level (along x or y), then up as many levels
    /// as the step crossed parent boundaries. False past the ring.
    #[inline(always)]
    fn advance<const F: bool>(
        &self,
        ray: &GridRay<F>,
        state: &mut WalkState,
        along_x: bool,
        t_out: f32,
    ) -> bool {
        let info = self.level_info[state.level % MAX_LEVELS];
        let (fx, fy) = (i32::from(ray.forward_x), i32::from(ray.forward_y));
        let up = if along_x {
            state.col += 2 * fx - 1;
            state.entry = X_ENTRY;
            if (state.col + 1) as u32 > info.last_col {
                return false;
            }
            (state.col + 1 - fx) as u32
        } else {
            state.row += 2 * fy - 1;
            state.entry = Y_ENTRY;
            if (state.row + 1) as u32 > info.last_row {
                return false;
            }
            (state.row + 1 - fy) as u32
        };
        let up = (up.trailing_zeros() as usize).min(self.top - state.level);
        state.level += up;
        state.row >>= up;
        state.col >>= up;
        state.t_in = t_out;
        true
    }

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
    fn lowest_vertex(&self, i: usize, j: usize) -> f32 {
        let (z00, z01, z10, z11) = self.corner_heights(i, j);
        min(min(z00, z01), min(z10, z11))
    }

    /// The block column (row) whose vertex columns `vertices` (`INCREASING` or decreasing)
    /// enclose coordinate `v`, clamped to the `blocks` of the field.
    #[inline(always)]
    fn block_of<const INCREASING: bool>(
        v: f32,
        vertices: &[f32],
        inv_step: f32,
        blocks: i32,
    ) -> i32 {
        let last = (blocks - 1) as f32;
        let k = (v - vertices[0]) * inv_step;
        // Clamped (NaN to 0) in floats, so that the conversion needs no saturation.
        let k = if k > 0.0 { min(k, last) } else { 0.0 };
        // SAFETY: k is finite, in [0, blocks − 1].
        let mut k = unsafe { k.to_int_unchecked::<i32>() };
        // Rounding can put v one block off; the vertex coordinates decide.
        let ahead = |bound: f32| if INCREASING { v >= bound } else { v <= bound };
        // SAFETY: k and k + 1 (when below `blocks`) index vertices of the grid.
        if k + 1 < blocks && ahead(unsafe { *vertices.get_unchecked(k as usize + 1) }) {
            k += 1;
        } else if k > 0 && !ahead(unsafe { *vertices.get_unchecked(k as usize) }) {
            k -= 1;
        }
        k
    }

    /// Visits the neighbours of block (`row`, `col`) across `sides` that exist; true if a
    /// visit ended the walk.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn visit_neighbours<const ANY: bool, const F: bool>(
        &self,
        ray: &GridRay<F>,
        row: i32,
        col: i32,
        sides: u8,
        span: (f32, f32),
        t_limit: &mut f32,
        best: &mut Option<BlockHit>,
    ) -> bool {
        let (dc, dr) = (
            2 * i32::from(ray.forward_x) - 1,
            2 * i32::from(ray.forward_y) - 1,
        );
        for (side, (dr, dc)) in [
            (X_ENTRY, (0, -dc)),
            (Y_ENTRY, (-dr, 0)),
            (X_EXIT, (0, dc)),
            (Y_EXIT, (dr, 0)),
        ] {
            let (r, c) = (row + dr, col + dc);
            if sides & side != 0
                && (0..self.block_rows).contains(&r)
                && (0..self.block_cols).contains(&c)
                && self.visit::<ANY, F>(ray, r, c, span, t_limit, best)
            {
                return true;
            }
        }
        false
    }

    /// The nearest hit of `ray` within block (`row`, `col`) before `t_limit` (any hit if
    /// `any`). With a `span`, the block is skipped when the ray passes above or below it
    /// over that stretch.
    #[inline(always)]
    fn block_hit<const F: bool>(
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

impl<const FUSED: bool> GridRay<FUSED> {
    #[inline(always)]
    fn new(accel: &HeightFieldAccel, origin: Vec3A, direction: Vec3A) -> GridRay<FUSED> {
        // A zero component gets a tiny one instead, so that slab distances stay finite and
        // ordered (a ray along a slab's plane is inside it).
        let tiny = Vec3A::splat(1e-30);
        let inv = Vec3A::select(direction.abs().cmplt(tiny), tiny, direction).recip();
        let (g, e) = (&accel.grid, accel.slack);
        let mut ray = GridRay {
            origin,
            direction,
            inv,
            x_step: accel.step.0 * inv.x,
            x_start: (g.xs[0] - origin.x) * inv.x,
            y_step: accel.step.1 * inv.y,
            y_start: (g.ys[0] - origin.y) * inv.y,
            margin: e * max(inv.x.abs(), inv.y.abs()),
            reach: {
                let (x_width, y_width) =
                    ((accel.step.0 * inv.x).abs(), (accel.step.1 * inv.y).abs());
                let (x_graze, y_graze) = (2.0 * e * inv.x.abs(), 2.0 * e * inv.y.abs());
                Vec4::new(x_width - x_graze, y_width - y_graze, x_graze, y_graze)
            },
            forward_x: accel.step.0 * inv.x > 0.0,
            forward_y: accel.step.1 * inv.y > 0.0,
            t_near: f32::NAN,
            t_far: f32::NAN,
            z_slack: 0.0,
        };
        if let Some((near, far)) = ray.box_span(accel.field_box) {
            ray.t_near = near;
            ray.t_far = far * (1.0 + 8.0 * f32::EPSILON);
            // |z − a·x − b·y| at a point within t_far: the point's rounding (2 ulps of its
            // largest coordinate, times 1 + |a| + |b|) and the expression's own (3 ulps).
            let reach = origin.abs().max_element() + ray.t_far;
            ray.z_slack = (5.0 * (1.0 + 2.0 * MAX_BAND_SLOPE as f32) + 8.0) * f32::EPSILON * reach;
        }
        ray
    }

    /// `a·b + c`, fused with `FUSED`.
    #[inline(always)]
    fn madd(a: f32, b: f32, c: f32) -> f32 {
        if FUSED {
            a.mul_add(b, c)
        } else {
            a * b + c
        }
    }

    /// Distances at which the ray meets the line of vertex column `col` and of vertex row
    /// `row`.
    #[inline(always)]
    fn boundaries(&self, row: i32, col: i32) -> (f32, f32) {
        (
            Self::madd(col as f32, self.x_step, self.x_start),
            Self::madd(row as f32, self.y_step, self.y_start),
        )
    }

    /// Distances at which the ray leaves cell (`row`, `col`) of `level` through its x side
    /// and its y side, and the distance it leaves the cell (not before `t_in`).
    #[inline(always)]
    fn exits(&self, level: usize, row: i32, col: i32, t_in: f32) -> (f32, f32, f32) {
        let (tx, ty) = self.boundaries(
            (row + i32::from(self.forward_y)) << level,
            (col + i32::from(self.forward_x)) << level,
        );
        (tx, ty, max(min(tx, ty), t_in))
    }

    /// Whether the ray's stretch [`t_in`, `t_out`] may meet heights in `range`.
    #[inline(always)]
    fn meets(&self, range: Range, (t_in, t_out): (f32, f32)) -> bool {
        self.meets_linear(
            self.origin.z,
            self.direction.z,
            (t_in, t_out),
            (range.min, range.max),
        )
    }

    /// Distances at which the ray enters (0 if it starts inside) and leaves the box with
    /// corners `lo` and `hi`, if it meets it.
    #[inline(always)]
    fn box_span(&self, (lo, hi): (Vec3A, Vec3A)) -> Option<(f32, f32)> {
        if lo.z > hi.z {
            return None;
        }
        let (lo, hi) = ((lo - self.origin) * self.inv, (hi - self.origin) * self.inv);
        let near = lo.min(hi).max_element().max(0.0);
        let far = lo.max(hi).min_element();
        (near <= far * (1.0 + 4.0 * f32::EPSILON)).then_some((near, far))
    }

    /// Whether the ray's stretch [`t_in`, `t_out`] may meet `band` (it does not when it passes
    /// above or below it at both ends).
    #[inline(always)]
    fn meets_band(&self, band: Band, t_in: f32, t_out: f32) -> bool {
        // z − a·x − b·y along the ray is linear in t.
        let (o, d) = (self.origin, self.direction);
        let h0 = Self::madd(-band.b, o.y, Self::madd(-band.a, o.x, o.z));
        let dh = Self::madd(-band.b, d.y, Self::madd(-band.a, d.x, d.z));
        self.meets_linear(h0, dh, (t_in, t_out), (band.c_lo, band.c_hi))
    }

    /// Whether `h0 + dh·t` may lie in [`lo`, `hi`] for some t of [`t_in`, `t_out`] (cut at
    /// `t_far`), allowing for rounding: it does not when it is above or below at both ends.
    #[inline(always)]
    fn meets_linear(
        &self,
        h0: f32,
        dh: f32,
        (t_in, t_out): (f32, f32),
        (lo, hi): (f32, f32),
    ) -> bool {
        let t_out = min(t_out, self.t_far);
        let (hp, hq) = (Self::madd(dh, t_in, h0), Self::madd(dh, t_out, h0));
        let above = min(hp, hq) - self.z_slack > hi;
        let below = max(hp, hq) + self.z_slack < lo;
        !(above || below)
    }
}

/// Asks for the cache line holding `value` (a hint: no effect on results).
#[inline(always)]
fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: prefetching a valid reference's address has no effect but on the caches.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
            (value as *const T).cast(),
        );
    }
}

/// The smaller of `a` and `b` (`b` when unordered): one instruction, unlike `f32::min`.
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// The larger of `a` and `b` (`b` when unordered).
#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// Möller–Trumbore intersection with triangle `corners` for t in [0, `t_limit`]: (t, u, v),
/// with u and v the weights of corners 1 and 2. Points on an edge count as inside.
#[inline(always)]
fn intersect_triangle<const F: bool>(
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
        let height = (0..n)
            .map(|p| {
                (((p % w) as f32 * 0.9).sin() * 4.0
                    + ((p / w) as f32 * 0.6).cos() * 3.0
                    + rng.next_f32() * 2.0)
                    .max(-0.5)
                    + 1.0
            })
            .collect();
        let mask = (0..n).map(|_| rng.next_f32() > 0.15).collect();
        Scene {
            camera: Camera {
                width: w,
                height: h,
                pixel_size: 0.7,
            },
            surface: HeightField {
                height,
                mask,
                albedo: vec![[0.5; 3]; n],
            },
            floor: Some(Floor {
                height: 0.5,
                albedo: [0.5; 3],
            }),
            cornell_box: None,
        }
    }

    /// The nearest hit over every height-field and skirt triangle, one by one.
    fn brute_force(mesh: &Mesh, ray: &GridRay<false>) -> Option<(usize, f32)> {
        let mut best: Option<(usize, f32)> = None;
        for t in 0..mesh.triangles.len() {
            if !matches!(
                mesh.kinds[t],
                crate::trace::mesh::SurfaceKind::Object | crate::trace::mesh::SurfaceKind::Skirt
            ) {
                continue;
            }
            if let Some((d, _, _)) =
                intersect_triangle(ray, &mesh.corners(t), best.map_or(f32::INFINITY, |b| b.1))
            {
                best = Some((t, d));
            }
        }
        best
    }

    /// A ray from a random point of a random object triangle (from its first corner, a
    /// grid vertex, when `at_vertex`), `offset` off it along its normal, in a direction of
    /// the upper hemisphere or a little below it.
    fn ray_off_the_surface(
        mesh: &Mesh,
        object: &[usize],
        rng: &mut Rng,
        at_vertex: bool,
        offset: f32,
    ) -> (Vec3A, Vec3A) {
        let t = object[(rng.next_f32() * object.len() as f32) as usize % object.len()];
        let [a, b, c] = mesh.corners(t);
        let (u, v) = (rng.next_f32(), rng.next_f32());
        let (u, v) = if u + v > 1.0 {
            (1.0 - u, 1.0 - v)
        } else {
            (u, v)
        };
        let on_surface = if at_vertex {
            a
        } else {
            a + (b - a) * u + (c - a) * v
        };
        let direction = vec3a(
            rng.next_f32() * 2.0 - 1.0,
            rng.next_f32() * 2.0 - 1.0,
            rng.next_f32() * 1.6 - 0.3,
        )
        .normalize();
        (on_surface + mesh.normals[t] * offset, direction)
    }

    /// Asserts that both queries agree with testing every triangle; whether the ray hits.
    fn assert_agrees(
        mesh: &Mesh,
        accel: &HeightFieldAccel,
        origin: Vec3A,
        direction: Vec3A,
        what: &str,
    ) -> bool {
        let expected = brute_force(mesh, &GridRay::<false>::new(accel, origin, direction));
        let got = accel.closest_hit::<false>(origin, direction, f32::INFINITY);
        assert_eq!(
            got.map(|g| (g.triangle, g.t)),
            expected,
            "ray {origin:?} {direction:?} in {what}"
        );
        assert_eq!(
            accel.closest_hit::<true>(origin, direction, f32::INFINITY),
            got,
            "fused walk, ray {origin:?} {direction:?} in {what}"
        );
        assert_eq!(
            accel.occluded::<false>(origin, direction, f32::INFINITY),
            expected.is_some(),
            "ray {origin:?} {direction:?} in {what}"
        );
        assert_eq!(
            accel.occluded::<true>(origin, direction, f32::INFINITY),
            expected.is_some(),
            "fused walk, ray {origin:?} {direction:?} in {what}"
        );
        expected.is_some()
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
                let origin = vec3a(
                    (rng.next_f32() - 0.5) * sx * 2.0,
                    (rng.next_f32() - 0.5) * sy * 2.0,
                    rng.next_f32() * 12.0 - 1.0,
                );
                let target = vec3a(
                    (rng.next_f32() - 0.5) * sx,
                    (rng.next_f32() - 0.5) * sy,
                    rng.next_f32() * 8.0,
                );
                let direction = (target - origin).normalize();
                let ray = GridRay::<false>::new(&accel, origin, direction);
                let expected = brute_force(&mesh, &ray);
                let got = accel.closest_hit::<false>(origin, direction, f32::INFINITY);
                assert_eq!(
                    got.map(|g| (g.triangle, g.t)),
                    expected,
                    "ray {origin:?} {direction:?} in {w}x{h}"
                );
                assert_eq!(
                    accel.closest_hit::<true>(origin, direction, f32::INFINITY),
                    got,
                    "fused walk, ray {origin:?} {direction:?} in {w}x{h}"
                );
                assert_eq!(
                    accel.occluded::<false>(origin, direction, f32::INFINITY),
                    expected.is_some()
                );
                assert_eq!(
                    accel.occluded::<true>(origin, direction, f32::INFINITY),
                    expected.is_some()
                );
                if let Some((t, d)) = expected {
                    hits += 1;
                    skirt_hits +=
                        usize::from(mesh.kinds[t] == crate::trace::mesh::SurfaceKind::Skirt);
                    assert!(
                        !accel.occluded::<false>(origin, direction, d * 0.999)
                            && !accel.occluded::<true>(origin, direction, d * 0.999)
                    );
                }
            }
            assert!(
                hits > 1500 && skirt_hits > 200,
                "{w}x{h}: {hits} hits, {skirt_hits} on the skirt"
            );
        }
    }

    /// Rays as a renderer casts them: from points on the surface (inside triangles and at
    /// vertices, where four blocks meet), just off it, in every direction of the upper
    /// hemisphere and some below it.
    #[test]
    fn rays_leaving_the_surface_agree_with_testing_every_triangle() {
        for (w, h, seed) in [(24, 19, 11), (40, 40, 12)] {
            let scene = ragged_scene(w, h, seed);
            let mesh = Mesh::from_scene(&scene);
            let accel = HeightFieldAccel::new(&mesh).expect("a height-field mesh has a grid");
            let object: Vec<usize> = (0..mesh.triangles.len())
                .filter(|&t| mesh.kinds[t] == crate::trace::mesh::SurfaceKind::Object)
                .collect();
            let mut rng = Rng::new(seed);
            let mut hits = 0;
            for k in 0..6000 {
                // Every third ray starts at a vertex of the grid.
                let (origin, direction) =
                    ray_off_the_surface(&mesh, &object, &mut rng, k % 3 == 0, 1e-3);
                hits += usize::from(assert_agrees(
                    &mesh,
                    &accel,
                    origin,
                    direction,
                    &format!("{w}x{h}"),
                ));
            }
            assert!(hits > 1000, "{w}x{h}: only {hits} hits");
        }
    }

    /// Steep ramps (steeper than a band's planes may be), spikes and flat steps, at pixel
    /// sizes far from 1 and heights far from 0: the bands' slopes, offsets and rounding
    /// allowance must hold at every scale. (Heights of 5 over a field 0.02 wide caught the
    /// blocks' height test losing a hit 1.7e-6 away when it compared distances instead of
    /// heights.)
    #[test]
    fn steep_and_scaled_fields_agree_with_testing_every_triangle() {
        for (w, h, pixel_size, lift, seed) in [
            (37, 29, 0.013f32, 0.0f32, 21u64),
            (33, 41, 3.7, 900.0, 22),
            (64, 16, 1.0, -40.0, 23),
            (20, 20, 1e-3, 5.0, 54),
            (30, 25, 250.0, -3e4, 55),
        ] {
            let mut scene = ragged_scene(w, h, seed);
            scene.camera.pixel_size = pixel_size;
            let mut rng = Rng::new(seed);
            for (p, z) in scene.surface.height.iter_mut().enumerate() {
                let (i, j) = ((p / w) as f32, (p % w) as f32);
                let ramp = if j < w as f32 / 2.0 {
                    15.0 * j
                } else {
                    4.0 * (i * 0.8).sin()
                };
                let spike = if rng.next_f32() < 0.03 { 25.0 } else { 0.0 };
                *z = (ramp + spike + (i * 0.3).floor() * 3.0) * pixel_size + lift;
            }
            if let Some(floor) = scene.floor.as_mut() {
                floor.height = lift;
            }
            let mesh = Mesh::from_scene(&scene);
            let accel = HeightFieldAccel::new(&mesh).expect("a height-field mesh has a grid");
            let object: Vec<usize> = (0..mesh.triangles.len())
                .filter(|&t| mesh.kinds[t] == crate::trace::mesh::SurfaceKind::Object)
                .collect();
            let (lo, hi) = accel.bounds();
            let span = hi - lo;
            let mut hits = 0;
            for k in 0..5000 {
                let (origin, direction) = if k % 2 == 0 {
                    ray_off_the_surface(&mesh, &object, &mut rng, k % 6 == 0, 1e-3 * pixel_size)
                } else {
                    // From around the field's box toward a point inside it.
                    let mut around = |k: usize| lo[k] - span[k] + rng.next_f32() * 3.0 * span[k];
                    let origin = vec3a(around(0), around(1), around(2));
                    let target = lo + span * vec3a(rng.next_f32(), rng.next_f32(), rng.next_f32());
                    (origin, (target - origin).normalize())
                };
                hits += usize::from(assert_agrees(
                    &mesh,
                    &accel,
                    origin,
                    direction,
                    &format!("{w}x{h} at pixel size {pixel_size}"),
                ));
            }
            assert!(hits > 1500, "{w}x{h}: only {hits} hits");
        }
    }

    /// Rays rising from a flat field toward a far spike, under and just over its tip:
    /// the escape cones must let the ones that clear it skip the walk and none that meet it.
    #[test]
    fn rays_rising_past_a_far_spike_agree_with_testing_every_triangle() {
        let (w, h) = (40, 40);
        let mut scene = ragged_scene(w, h, 6);
        scene.surface.mask = vec![true; w * h];
        scene.surface.height = (0..w * h)
            .map(|p| {
                if (p / w, p % w) == (30, 31) {
                    20.0
                } else {
                    1.0
                }
            })
            .collect();
        let mesh = Mesh::from_scene(&scene);
        let accel = HeightFieldAccel::new(&mesh).expect("grid");
        let g = mesh.grid.as_ref().expect("grid");
        let top = vec3a(g.xs[31], g.ys[30], 20.0);
        let mut rng = Rng::new(8);
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..3000 {
            let origin = vec3a(
                g.xs[3] + rng.next_f32() * 6.0 * 0.7,
                g.ys[4] - rng.next_f32() * 6.0 * 0.7,
                1.0 + 1e-3,
            );
            let aim = top
                + vec3a(
                    (rng.next_f32() - 0.5) * 0.6,
                    (rng.next_f32() - 0.5) * 0.6,
                    0.5 - rng.next_f32() * 5.0,
                );
            let hit = assert_agrees(
                &mesh,
                &accel,
                origin,
                (aim - origin).normalize(),
                "the spike field",
            );
            (hits, misses) = if hit {
                (hits + 1, misses)
            } else {
                (hits, misses + 1)
            };
        }
        assert!(hits > 300 && misses > 300, "{hits} hits, {misses} misses");
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
                for (x, y) in [
                    (g.xs[j], g.ys[i]),
                    (g.xs[j], g.ys[i] - 0.35),
                    (g.xs[j] + 0.35, g.ys[i]),
                ] {
                    let hit =
                        accel.closest_hit::<false>(vec3a(x, y, 50.0), -Vec3A::Z, f32::INFINITY);
                    // Through a vertex or an edge, the fused walk may meet another of the
                    // triangles there first: the same point, to their rounding.
                    let fused =
                        accel.closest_hit::<true>(vec3a(x, y, 50.0), -Vec3A::Z, f32::INFINITY);
                    assert_eq!(fused.is_some(), hit.is_some(), "({x}, {y})");
                    if let (Some(a), Some(b)) = (fused, hit) {
                        assert!((a.t - b.t).abs() <= 1e-5 * b.t, "({x}, {y}): {a:?} {b:?}");
                    }
                    let inside = x <= g.xs[15] && y >= g.ys[15];
                    assert_eq!(hit.is_some(), inside, "({x}, {y})");
                }
            }
        }
    }
}
