//! The walk along a ray over the pyramid: where it starts, the steps over cells and blocks,
//! and the blocks it visits.

use glam::Vec4;

use super::ray::min;
use super::{
    BlockHit, GridRay, HeightFieldAccel, WalkState, MAX_LEVELS, X_ENTRY, X_EXIT, Y_ENTRY, Y_EXIT,
};

impl HeightFieldAccel {
    /// Visits, in order along the ray, the blocks it may meet before `t_limit`, keeping in
    /// `best` the nearest hit (with `ANY`, the first hit found, which ends the walk).
    #[inline(always)]
    pub(super) fn walk<const ANY: bool, const F: bool>(
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
}
