//! Ray queries over a height field and its skirt, exploiting the pixel grid: a walk along
//! the ray over a min/max pyramid of the grid's blocks.
//!
//! Level L of the pyramid splits the grid into cells of 2^L × 2^L blocks and stores, per
//! cell, the lowest and highest point of the triangles (surface and skirt) of its blocks
//! *and of the ring of blocks around it*. The walk visits the cells the ray passes through in
//! order, like a line-drawing DDA: a cell the ray passes wholly above or below is stepped
//! over, going up as many levels as the step crossed parent boundaries; a cell the ray may
//! meet is entered a level down. A ray that starts inside the field starts at its own block.
//! At level 0 the block's two triangles are built from the height grid and tested (after its
//! own height range), its skirt when it has one, and any neighbouring block whose side the
//! ray runs along within rounding distance. The ring in each range is what makes stepping
//! over a cell safe for a ray that grazes its border. The walk needs no stack, follows no
//! pointer and stores 8 bytes a cell (a third of the blocks' count in all): on fields larger
//! than the caches it beats a quadtree over the same grid (see benches/README.md).

use std::sync::Arc;

use glam::Vec3A;

use crate::geometry::{BlockSide, HeightFieldGrid, Mesh, NO_TRIANGLE};
use crate::tracer::Hit;

/// Height range of a pyramid cell and the ring of blocks around it. A cell with nothing in
/// reach is stored as `min = max = +∞`, which every ray passes below.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(8))]
struct Range {
    min: f32,
    max: f32,
}

const NOTHING: Range = Range { min: f32::INFINITY, max: f32::INFINITY };

/// One level of the pyramid while it is built, with a ring of cells outside the field: cell
/// (`row`, `col`) for `row` in −1..`rows` − 1 (and likewise columns) sits at
/// `(row + 1)·cols + col + 1`.
#[derive(Debug, Clone)]
struct Level {
    cols: i32,
    rows: i32,
    ranges: Vec<Range>,
}

impl Level {
    /// The range of cell (`row`, `col`); nothing outside the ring.
    #[inline(always)]
    fn range(&self, row: i32, col: i32) -> Range {
        let (r, c) = (row + 1, col + 1);
        if (0..self.rows).contains(&r) && (0..self.cols).contains(&c) {
            self.ranges[(r * self.cols + c) as usize]
        } else {
            NOTHING
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

/// Sides of a block, as bits (see [`HeightFieldAccel::visit_neighbours`]).
const LEFT: u8 = 1;
const RIGHT: u8 = 2;
const TOP: u8 = 4;
const BOTTOM: u8 = 8;

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
/// boundary, the ray is within the slack of it.
#[derive(Debug, Clone, Copy)]
struct GridRay {
    origin: Vec3A,
    direction: Vec3A,
    inv: Vec3A,
    x_step: f32,
    x_start: f32,
    y_step: f32,
    y_start: f32,
    margin: f32,
    /// origin.z · inv.z: height z is reached at `z·inv.z − z_offset`.
    z_offset: f32,
    /// Distance the ray takes to cross a block column (row), and to move twice the slack
    /// along x (y).
    x_width: f32,
    y_width: f32,
    x_graze: f32,
    y_graze: f32,
    forward_x: bool,
    forward_y: bool,
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
    /// Ranges of the pyramid's levels 1 to `top`, each with its ring and one more cell of
    /// nothing on every side, so that the walk's indices need no bounds check; cell (0, 0) of
    /// level `top` covers the whole field.
    pyramid: Vec<Range>,
    level_info: [LevelInfo; MAX_LEVELS],
    top: usize,
    /// Height range of the whole field.
    field: Range,
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
                let corners: Vec<[Vec3A; 3]> = edge.triangles.clone().map(|t| mesh.corners(t as usize)).collect();
                let top = corners.iter().flatten().map(|p| p.z).fold(f32::NEG_INFINITY, f32::max);
                SkirtQuad { block: edge.block, side: edge.side, top, first_triangle: edge.triangles.start, corners }
            })
            .collect();
        let mut first_skirt = vec![u32::MAX; cols * rows];
        let mut block_flags: Vec<u8> = grid.block_triangles.iter().map(|&t| if t == NO_TRIANGLE { 0 } else { SURFACE }).collect();
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
                let z = [grid.z[i * w + j], grid.z[i * w + j + 1], grid.z[(i + 1) * w + j], grid.z[(i + 1) * w + j + 1]];
                let (mut lo, hi) = (z.iter().copied().fold(f32::INFINITY, f32::min), z.iter().copied().fold(f32::NEG_INFINITY, f32::max));
                if block_flags[b] & SKIRT != 0 {
                    lo = lo.min(grid.base);
                }
                Range { min: lo, max: hi }
            })
            .collect();
        // Each block's range widened to its 3 × 3 neighbourhood, for the blocks of the field
        // and a ring of one block around it: the range of a cell and its ring is the union of
        // its blocks' neighbourhoods.
        let union = |a: Range, b: Range| -> Range {
            match (a == NOTHING, b == NOTHING) {
                (true, _) => b,
                (_, true) => a,
                _ => Range { min: a.min.min(b.min), max: a.max.max(b.max) },
            }
        };
        let field = own.iter().fold(NOTHING, |a, &b| union(a, b));
        let (ci, ri) = (cols as i32, rows as i32);
        let mut below = Level { cols: ci + 2, rows: ri + 2, ranges: Vec::with_capacity((cols + 2) * (rows + 2)) };
        for r in -1..=ri {
            for c in -1..=ci {
                let mut range = NOTHING;
                for rr in (r - 1).max(0)..(r + 2).min(ri) {
                    for cc in (c - 1).max(0)..(c + 2).min(ci) {
                        range = union(range, own[(rr * ci + cc) as usize]);
                    }
                }
                below.ranges.push(range);
            }
        }
        let mut levels = Vec::new();
        let mut level = 0;
        while (ci - 1) >> level > 0 || (ri - 1) >> level > 0 {
            level += 1;
            // Cells −1..=(blocks >> level) of this level.
            let (up_cols, up_rows) = ((ci >> level) + 2, (ri >> level) + 2);
            let mut up = Level { cols: up_cols, rows: up_rows, ranges: vec![NOTHING; (up_cols * up_rows) as usize] };
            for r in -1..up_rows - 1 {
                for c in -1..up_cols - 1 {
                    let mut range = NOTHING;
                    for (rr, cc) in [(2 * r, 2 * c), (2 * r, 2 * c + 1), (2 * r + 1, 2 * c), (2 * r + 1, 2 * c + 1)] {
                        range = union(range, below.range(rr, cc));
                    }
                    up.ranges[((r + 1) * up_cols + c + 1) as usize] = range;
                }
            }
            levels.push(up.clone());
            below = up;
        }
        assert!(levels.len() < MAX_LEVELS, "height field too large for the pyramid");
        let mut pyramid = Vec::new();
        let mut level_info = [LevelInfo::default(); MAX_LEVELS];
        level_info[0] = LevelInfo { origin: 0, stride: 0, last_col: ci as u32 + 1, last_row: ri as u32 + 1 };
        for (k, level) in levels.iter().enumerate() {
            let stride = level.cols as isize + 2;
            let start = pyramid.len() as isize;
            for r in -2..level.rows {
                for c in -2..level.cols {
                    pyramid.push(level.range(r, c));
                }
            }
            level_info[k + 1] = LevelInfo { origin: start + 2 * stride + 2, stride, last_col: level.cols as u32 - 1, last_row: level.rows as u32 - 1 };
        }
        let step = ((grid.xs[cols] - grid.xs[0]) / cols as f32, (grid.ys[rows] - grid.ys[0]) / rows as f32);
        // Block boundaries are computed as k·step + start: allow for its rounding.
        let extent = grid.xs[0].abs().max(grid.xs[cols].abs()).max(grid.ys[0].abs()).max(grid.ys[rows].abs());
        let slack = step.0.abs() * 1e-4 + extent * 4.0 * f32::EPSILON;
        let mut packed_flags = vec![0u8; block_flags.len().div_ceil(4)];
        for (b, &f) in block_flags.iter().enumerate() {
            packed_flags[b / 4] |= f << (2 * (b % 4));
        }
        Some(HeightFieldAccel { block_cols: ci, block_rows: ri, packed_flags, pyramid, level_info, top: levels.len(), field, first_skirt, skirt, slack, step, inv_step: (1.0 / step.0, 1.0 / step.1), grid })
    }

    /// Corners of the box holding every triangle of the field and its skirt.
    pub fn bounds(&self) -> (Vec3A, Vec3A) {
        let g = &self.grid;
        (Vec3A::new(g.xs[0], g.ys[g.height - 1], self.field.min), Vec3A::new(g.xs[g.width - 1], g.ys[0], self.field.max))
    }

    /// The closest hit along `origin + t·direction` for `t` in [0, `t_max`].
    #[inline(always)]
    pub fn closest_hit(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<Hit> {
        let ray = GridRay::new(self, origin, direction);
        let mut best: Option<BlockHit> = None;
        let mut t_best = t_max;
        self.walk(&ray, &mut t_best, |accel, row, col, span, t_limit| {
            let hit = accel.block_hit(&ray, row, col, span, t_limit, false);
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
        self.walk(&ray, &mut t_limit, |accel, row, col, span, t_limit| {
            found = accel.block_hit(&ray, row, col, span, t_limit, true).is_some();
            // A hit at distance −1 ends the walk at once.
            found.then_some(-1.0)
        });
        found
    }

    /// Visits, in order along the ray, the blocks it may meet before `t_limit`, calling
    /// `visit(self, row, col, span, t_limit)`: `span` is the stretch of the ray within the
    /// slack of the block. A returned distance lowers the limit (below 0 ends the walk).
    #[inline(always)]
    fn walk(&self, ray: &GridRay, t_limit: &mut f32, mut visit: impl FnMut(&Self, i32, i32, (f32, f32), f32) -> Option<f32>) {
        let Some(mut state) = self.start(ray, *t_limit) else { return };
        loop {
            let alive = if state.level > 0 { self.cell_step(ray, &mut state, *t_limit) } else { self.block_step(ray, &mut state, t_limit, &mut visit) };
            if !alive {
                return;
            }
        }
    }

    /// Where the walk of `ray` starts, or None if the ray misses the field's box before
    /// `t_limit`. A ray starting inside the box starts at its block; any other at the top
    /// cell.
    #[inline(always)]
    fn start(&self, ray: &GridRay, t_limit: f32) -> Option<WalkState> {
        let g = &self.grid;
        let e = self.slack;
        let x = (g.xs[0] - e, g.xs[g.width - 1] + e);
        let y = (g.ys[g.height - 1] - e, g.ys[0] + e);
        let t_in = ray.box_entry(x, y, (self.field.min, self.field.max), t_limit)?;
        if t_in != 0.0 {
            return Some(WalkState { level: self.top, row: 0, col: 0, entry: 0, t_in });
        }
        let (row, col) = (Self::block_of(ray.origin.y, &g.ys, self.inv_step.1, self.block_rows), Self::block_of(ray.origin.x, &g.xs, self.inv_step.0, self.block_cols));
        // Going away from a side of the block its origin lies strictly inside, the ray
        // cannot meet the block behind that side: treat it as the side the ray came in
        // through. (An origin on a side may lie on that block's skirt.)
        let (x0, x1, y0, y1) = (g.xs[col as usize], g.xs[col as usize + 1], g.ys[row as usize], g.ys[row as usize + 1]);
        let (ox, oy) = (ray.origin.x, ray.origin.y);
        let (x_entry, _, y_entry, _) = ray.sides();
        let entry = if x0 < ox && ox < x1 && y1 < oy && oy < y0 { x_entry | y_entry } else { 0 };
        self.prefetch_around(row, col);
        Some(WalkState { level: 0, row, col, entry, t_in })
    }

    /// One step of the walk in a cell above the blocks: down into the child the ray is in
    /// when the ray may meet the cell's range, else on to the next cell. False when the walk
    /// is over.
    #[inline(always)]
    fn cell_step(&self, ray: &GridRay, state: &mut WalkState, t_limit: f32) -> bool {
        let WalkState { level, row, col, t_in, .. } = *state;
        let (tx, ty, t_out) = ray.exits(level, row, col, t_in);
        let info = self.level_info[level % MAX_LEVELS];
        let cell = info.origin + row as isize * info.stride + col as isize;
        debug_assert!((0..self.pyramid.len() as isize).contains(&cell), "cell ({row}, {col}) of level {level}");
        // SAFETY: the walk keeps to the ring's cells and their children, which lie within
        // the padding of one cell around the ring.
        let range = unsafe { *self.pyramid.get_unchecked(cell as usize) };
        if ray.meets(range, (t_in - ray.margin, t_out + ray.margin)) {
            // Down to the child the ray is in at t_in.
            let level = level - 1;
            let mx = ((2 * col + 1) << level) as f32 * ray.x_step + ray.x_start;
            let my = ((2 * row + 1) << level) as f32 * ray.y_step + ray.y_start;
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
    fn block_step(&self, ray: &GridRay, state: &mut WalkState, t_limit: &mut f32, visit: &mut impl FnMut(&Self, i32, i32, (f32, f32), f32) -> Option<f32>) -> bool {
        let WalkState { row, col, t_in, entry, .. } = *state;
        let (tx, ty, t_out) = ray.exits(0, row, col, t_in);
        let along_x = tx < ty;
        let span = (t_in - ray.margin, t_out + ray.margin);
        let info = self.level_info[0];
        if (col + 1) as u32 <= info.last_col && (row + 1) as u32 <= info.last_row {
            // A block of the field, or of the ring around it (which has no triangles but
            // may run along the field's side).
            if (col as u32) < self.block_cols as u32 && (row as u32) < self.block_rows as u32 {
                if let Some(t) = visit(self, row, col, span, *t_limit) {
                    if t < 0.0 {
                        return false;
                    }
                    *t_limit = t;
                }
            }
            let (x_entry, x_exit, y_entry, y_exit) = ray.sides();
            let exit = if along_x { x_exit } else { y_exit };
            // Sides the ray runs within twice the slack of: before it passes the entry
            // side's line plus the slack, or after the exit side's line minus it.
            let mut sides = 0;
            if t_in < tx - ray.x_width + ray.x_graze {
                sides |= x_entry;
            }
            if t_out > tx - ray.x_graze {
                sides |= x_exit;
            }
            if t_in < ty - ray.y_width + ray.y_graze {
                sides |= y_entry;
            }
            if t_out > ty - ray.y_graze {
                sides |= y_exit;
            }
            let sides = sides & !(entry | exit);
            if sides != 0 && self.visit_neighbours(row, col, sides, (span.0 - ray.margin, span.1 + ray.margin), t_limit, visit) {
                return false;
            }
        }
        t_out - ray.margin <= *t_limit && self.advance(ray, state, along_x, t_out)
    }

    /// Steps to the next cell of the state's level (along x or y), then up as many levels
    /// as the step crossed parent boundaries. False past the ring.
    #[inline(always)]
    fn advance(&self, ray: &GridRay, state: &mut WalkState, along_x: bool, t_out: f32) -> bool {
        let info = self.level_info[state.level % MAX_LEVELS];
        let (fx, fy) = (i32::from(ray.forward_x), i32::from(ray.forward_y));
        let (x_entry, _, y_entry, _) = ray.sides();
        let up = if along_x {
            state.col += 2 * fx - 1;
            state.entry = x_entry;
            if (state.col + 1) as u32 > info.last_col {
                return false;
            }
            (state.col + 1 - fx) as u32
        } else {
            state.row += 2 * fy - 1;
            state.entry = y_entry;
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

    /// Asks for the memory the walk from block (`row`, `col`) reads first (its heights and
    /// flags, the pyramid cell above it), so that the cache misses of an incoherent ray
    /// overlap instead of following one another.
    #[inline(always)]
    fn prefetch_around(&self, row: i32, col: i32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let g = &self.grid;
            let (i, j) = (row as usize, col as usize);
            let vertex = i * g.width + j;
            // SAFETY: prefetching is a hint; the addresses are within the arrays.
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>(g.z.as_ptr().add(vertex).cast());
                _mm_prefetch::<_MM_HINT_T0>(g.z.as_ptr().add(vertex + g.width).cast());
                _mm_prefetch::<_MM_HINT_T0>(self.packed_flags.as_ptr().add((i * self.block_cols as usize + j) / 4).cast());
                if self.top > 0 {
                    let info = self.level_info[1];
                    _mm_prefetch::<_MM_HINT_T0>(self.pyramid.as_ptr().offset(info.origin + (row >> 1) as isize * info.stride + (col >> 1) as isize).cast());
                }
            }
        }
    }

    /// The block column (row) whose vertex columns `vertices` (increasing or decreasing)
    /// enclose coordinate `v`, clamped to the `blocks` of the field.
    #[inline(always)]
    fn block_of(v: f32, vertices: &[f32], inv_step: f32, blocks: i32) -> i32 {
        let mut k = (((v - vertices[0]) * inv_step) as i32).clamp(0, blocks - 1);
        // Rounding can put v one block off; the vertex coordinates decide.
        let ahead = |bound: f32| if inv_step > 0.0 { v >= bound } else { v <= bound };
        if k + 1 < blocks && ahead(vertices[k as usize + 1]) {
            k += 1;
        } else if k > 0 && !ahead(vertices[k as usize]) {
            k -= 1;
        }
        k
    }

    /// Visits the neighbours of block (`row`, `col`) across `sides` that exist; true if a
    /// visit ended the walk.
    #[cold]
    fn visit_neighbours(&self, row: i32, col: i32, sides: u8, span: (f32, f32), t_limit: &mut f32, visit: &mut impl FnMut(&Self, i32, i32, (f32, f32), f32) -> Option<f32>) -> bool {
        for (side, (dr, dc)) in [(LEFT, (0, -1)), (RIGHT, (0, 1)), (TOP, (-1, 0)), (BOTTOM, (1, 0))] {
            let (r, c) = (row + dr, col + dc);
            if sides & side != 0 && (0..self.block_rows).contains(&r) && (0..self.block_cols).contains(&c) {
                if let Some(t) = visit(self, r, c, span, *t_limit) {
                    if t < 0.0 {
                        return true;
                    }
                    *t_limit = t;
                }
            }
        }
        false
    }

    /// The nearest hit of `ray` within block (`row`, `col`) before `t_limit` (any hit if
    /// `any`). With a `span`, the block is skipped when the ray passes above or below it
    /// over that stretch.
    #[inline(always)]
    fn block_hit(&self, ray: &GridRay, row: i32, col: i32, span: (f32, f32), t_limit: f32, any: bool) -> Option<BlockHit> {
        let g = &self.grid;
        let (i, j) = (row as usize, col as usize);
        let block = i * self.block_cols as usize + j;
        let w = g.width;
        debug_assert!(row < self.block_rows && col < self.block_cols);
        // SAFETY: (row, col) is a block of the field: its flags and four vertices exist.
        let flags = unsafe { *self.packed_flags.get_unchecked(block / 4) } >> (2 * (block % 4)) & 3;
        if flags == 0 {
            return None;
        }
        let z = |k: usize| unsafe { *g.z.get_unchecked(k) };
        let (z00, z01, z10, z11) = (z(i * w + j), z(i * w + j + 1), z((i + 1) * w + j), z((i + 1) * w + j + 1));
        let mut lo = min(min(z00, z01), min(z10, z11));
        if flags & SKIRT != 0 {
            lo = min(lo, g.base);
        }
        let hi = max(max(z00, z01), max(z10, z11));
        if !ray.meets(Range { min: lo, max: hi }, span) {
            return None;
        }
        // SAFETY: as above.
        let (x0, x1, y0, y1) = unsafe { (*g.xs.get_unchecked(j), *g.xs.get_unchecked(j + 1), *g.ys.get_unchecked(i), *g.ys.get_unchecked(i + 1)) };
        let (p00, p10, p01, p11) = (Vec3A::new(x0, y0, z00), Vec3A::new(x0, y1, z10), Vec3A::new(x1, y0, z01), Vec3A::new(x1, y1, z11));
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
            x_start: (g.xs[0] - origin.x) * inv.x,
            y_step: accel.step.1 * inv.y,
            y_start: (g.ys[0] - origin.y) * inv.y,
            margin: e * inv.x.abs().max(inv.y.abs()),
            z_offset: origin.z * inv.z,
            x_width: (accel.step.0 * inv.x).abs(),
            y_width: (accel.step.1 * inv.y).abs(),
            x_graze: 2.0 * e * inv.x.abs(),
            y_graze: 2.0 * e * inv.y.abs(),
            forward_x: accel.step.0 * inv.x > 0.0,
            forward_y: accel.step.1 * inv.y > 0.0,
        }
    }

    /// Distances at which the ray leaves cell (`row`, `col`) of `level` through its x side
    /// and its y side, and the distance it leaves the cell (not before `t_in`).
    #[inline(always)]
    fn exits(&self, level: usize, row: i32, col: i32, t_in: f32) -> (f32, f32, f32) {
        let tx = ((col + i32::from(self.forward_x)) << level) as f32 * self.x_step + self.x_start;
        let ty = ((row + i32::from(self.forward_y)) << level) as f32 * self.y_step + self.y_start;
        (tx, ty, max(min(tx, ty), t_in))
    }

    /// The block sides through which the ray enters and leaves a block: (entry along x,
    /// exit along x, entry along y, exit along y).
    #[inline(always)]
    fn sides(&self) -> (u8, u8, u8, u8) {
        let (x_entry, x_exit) = if self.forward_x { (LEFT, RIGHT) } else { (RIGHT, LEFT) };
        let (y_entry, y_exit) = if self.forward_y { (TOP, BOTTOM) } else { (BOTTOM, TOP) };
        (x_entry, x_exit, y_entry, y_exit)
    }

    /// Whether the ray's stretch [`t_in`, `t_out`] may meet heights in `range`.
    #[inline(always)]
    fn meets(&self, range: Range, (t_in, t_out): (f32, f32)) -> bool {
        let ta = range.min * self.inv.z - self.z_offset;
        let tb = range.max * self.inv.z - self.z_offset;
        let near = max(t_in, min(ta, tb));
        let far = min(t_out, max(ta, tb));
        near <= far * (1.0 + 4.0 * f32::EPSILON)
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

    /// Rays as a renderer casts them: from points on the surface (inside triangles and at
    /// vertices, where four blocks meet), just off it, in every direction of the upper
    /// hemisphere and some below it.
    #[test]
    fn rays_leaving_the_surface_agree_with_testing_every_triangle() {
        for (w, h, seed) in [(24, 19, 11), (40, 40, 12)] {
            let scene = ragged_scene(w, h, seed);
            let mesh = Mesh::from_scene(&scene);
            let accel = HeightFieldAccel::new(&mesh).expect("a height-field mesh has a grid");
            let object: Vec<usize> = (0..mesh.triangles.len()).filter(|&t| mesh.kinds[t] == crate::geometry::SurfaceKind::Object).collect();
            let mut rng = Rng::new(seed);
            let mut hits = 0;
            for k in 0..6000 {
                let t = object[(rng.next_f32() * object.len() as f32) as usize % object.len()];
                let [a, b, c] = mesh.corners(t);
                let (u, v) = (rng.next_f32(), rng.next_f32());
                let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
                // Every third ray starts at a vertex of the grid.
                let on_surface = if k % 3 == 0 { a } else { a + (b - a) * u + (c - a) * v };
                let origin = on_surface + mesh.normals[t] * 1e-3;
                let direction = vec3a(rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 1.6 - 0.3).normalize();
                let ray = GridRay::new(&accel, origin, direction);
                let expected = brute_force(&mesh, &ray);
                let got = accel.closest_hit(origin, direction, f32::INFINITY);
                assert_eq!(got.map(|g| (g.triangle, g.t)), expected, "ray {origin:?} {direction:?} in {w}x{h}");
                assert_eq!(accel.occluded(origin, direction, f32::INFINITY), expected.is_some());
                hits += usize::from(expected.is_some());
            }
            assert!(hits > 1000, "{w}x{h}: only {hits} hits");
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
