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
//!
//! This module holds the accelerator's types and its queries; beside it: `build`, the
//! pyramid and the escape cones (`escape_cone`); `walk`, the walk over the pyramid; `block`,
//! the triangles of a block; `ray`, a ray's steps across the grid and its tests against
//! slabs.

use std::sync::Arc;

use glam::{Vec3A, Vec4};

use crate::trace::mesh::{BlockSide, HeightFieldGrid};
use crate::trace::Hit;

mod block;
mod build;
mod escape_cone;
mod ray;
mod walk;

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
    /// [`escape_cones`](escape_cone::escape_cones) of each block, four quadrants a block (which rays from it meet
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
}

#[cfg(test)]
mod tests;
