//! Escape cones of a height field's blocks: for each block and each quadrant of directions,
//! how steeply a ray must rise from it to clear every triangle beyond the block's ring of
//! 3×3 blocks (see [`crate::trace::height_field`]).

use rayon::prelude::*;

use crate::trace::mesh::HeightFieldGrid;

/// Escape slopes (squared) that [`escape_cones`] rounds up to: 0, then a geometric series
/// from 1e-6 to 1e6 (slopes 1e-3 to 1e3, 5.6 % apart), then +∞ (no escape).
pub(crate) fn escape_slopes() -> [f32; 256] {
    let ratio = 1e12f64.powf(1.0 / 253.0);
    std::array::from_fn(|c| match c {
        0 => 0.0,
        255 => f32::INFINITY,
        c => ((1e-6 * ratio.powi(c as i32 - 1)) as f32).next_up(),
    })
}

/// For each block and each quadrant of directions (toward higher block columns or not, plus
/// twice toward higher block rows or not), the index in `slopes` (see [`escape_slopes`]) of a
/// `k²` such that a ray in that quadrant that starts in the block's column (or within `slack`
/// of it) no lower than its lowest vertex and rises at least `k` in height for every unit it
/// moves across (`dz > 0`, `dz² ≥ k²·(dx² + dy²)`) passes above every triangle outside the
/// ring of 3×3 blocks around it (255: no such ray; blocks that are not `meshed`). `block_top`
/// holds each block's highest point (−∞ where there is nothing), `step` the vertex spacing.
///
/// The bound `k` is the steepest slope from the block's lowest vertex up to the highest
/// point of a pyramid cell, over a set of cells that covers the field outside the ring: at
/// each level the cells within the 3×3 parents around the block's own parent that are not
/// within the 3×3 cells around its own cell (at most 27), each at its least distance from
/// the block; a quadrant's rays only pass over the cells that reach the block's column
/// (row), or the one before it, or beyond, on the side they go.
pub(crate) fn escape_cones(
    grid: &HeightFieldGrid,
    block_top: Vec<f32>,
    meshed: impl Fn(usize) -> bool + Sync,
    top: usize,
    step: (f32, f32),
    slack: f32,
    slopes: &[f32; 256],
) -> Vec<u8> {
    let (cols, rows) = (grid.width - 1, grid.height - 1);
    let dims = |level: usize| (((cols - 1) >> level) + 1, ((rows - 1) >> level) + 1);
    // Highest point of every cell of every level (−∞ where there is nothing).
    let mut maxima: Vec<Vec<f32>> = vec![block_top];
    for level in 1..=top {
        let ((w, h), (child_w, child_h)) = (dims(level), dims(level - 1));
        let child = &maxima[level - 1];
        let cells = (0..w * h)
            .map(|c| {
                let (r, q) = (c / w, c % w);
                let mut z = f32::NEG_INFINITY;
                for (cr, cq) in [
                    (2 * r, 2 * q),
                    (2 * r, 2 * q + 1),
                    (2 * r + 1, 2 * q),
                    (2 * r + 1, 2 * q + 1),
                ] {
                    if cr < child_h && cq < child_w {
                        z = z.max(child[cr * child_w + cq]);
                    }
                }
                z
            })
            .collect();
        maxima.push(cells);
    }
    let (sx, sy) = (step.0.abs() as f64, step.1.abs() as f64);
    let highest = maxima[top][0] as f64;
    let w = grid.width;
    (0..cols * rows)
        .into_par_iter()
        .flat_map_iter(|b| {
            if !meshed(b) {
                return [255; 4];
            }
            let (i, j) = (b / cols, b % cols);
            let z_ref = [
                grid.z[i * w + j],
                grid.z[i * w + j + 1],
                grid.z[(i + 1) * w + j],
                grid.z[(i + 1) * w + j + 1],
            ]
            .into_iter()
            .fold(f32::INFINITY, f32::min);
            let headroom = highest - z_ref as f64;
            let (i, j) = (i as i64, j as i64);
            let mut k2 = [0.0f64; 4];
            for (level, cells) in maxima.iter().enumerate().take(top) {
                let least = k2.iter().copied().fold(f64::INFINITY, f64::min);
                // The cells of this level and above lie at least a cell away and no higher
                // than the field's top: once that cannot raise the slope, none can.
                let nearest = ((1u64 << level) as f64 * sx.min(sy) - 2.0 * slack as f64).max(0.0);
                if headroom * headroom <= least * nearest * nearest {
                    break;
                }
                let (level_w, level_h) = dims(level);
                let (own_r, own_c) = (i >> level, j >> level);
                // The gap between the block (column or row `own`) and `cell`'s blocks, in
                // world units, less the origin's allowance off the block.
                let gap = |own: i64, cell: i64, spacing: f64| {
                    (((cell << level) - own - 1)
                        .max(own - ((cell + 1) << level))
                        .max(0) as f64
                        * spacing
                        - 2.0 * slack as f64)
                        .max(0.0)
                };
                let (parent_r, parent_c) = (own_r >> 1, own_c >> 1);
                // Nor can this level's cells if none of the 3×3 parents holding them can.
                let (parent_w, parent_h) = dims(level + 1);
                let parents = &maxima[level + 1];
                let mut region = f32::NEG_INFINITY;
                for r in (parent_r - 1).max(0)..(parent_r + 2).min(parent_h as i64) {
                    for c in (parent_c - 1).max(0)..(parent_c + 2).min(parent_w as i64) {
                        region = region.max(parents[r as usize * parent_w + c as usize]);
                    }
                }
                let rise = region as f64 - z_ref as f64;
                if rise <= 0.0 || rise * rise <= least * nearest * nearest {
                    continue;
                }
                for r in (2 * parent_r - 2).max(0)..(2 * parent_r + 4).min(level_h as i64) {
                    for c in (2 * parent_c - 2).max(0)..(2 * parent_c + 4).min(level_w as i64) {
                        let rise = cells[r as usize * level_w + c as usize] as f64 - z_ref as f64;
                        if ((r - own_r).abs() <= 1 && (c - own_c).abs() <= 1) || rise <= 0.0 {
                            continue;
                        }
                        let (gx, gy) = (gap(j, c, sx), gap(i, r, sy));
                        let d2 = gx * gx + gy * gy;
                        // Which quadrants' rays can pass over the cell: it reaches the block's
                        // column (row) or beyond on their side, or the column (row) next to it,
                        // where an origin up to `slack` off the block lies.
                        let (first_r, last_r, first_c, last_c) = (
                            r << level,
                            ((r + 1) << level) - 1,
                            c << level,
                            ((c + 1) << level) - 1,
                        );
                        for (q, slope2) in k2.iter_mut().enumerate() {
                            let along_c = if q & 1 != 0 {
                                last_c >= j - 1
                            } else {
                                first_c <= j + 1
                            };
                            let along_r = if q & 2 != 0 {
                                last_r >= i - 1
                            } else {
                                first_r <= i + 1
                            };
                            if along_c && along_r && rise * rise > *slope2 * d2 {
                                *slope2 = rise * rise / d2;
                            }
                        }
                    }
                }
            }
            // Far more than the rounding of the ray's test, and of its heights.
            k2.map(|k2| {
                slopes
                    .partition_point(|&s| (s as f64) < k2 * (1.0 + 1e-4))
                    .min(255) as u8
            })
        })
        .collect()
}
