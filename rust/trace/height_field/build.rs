//! Building the walk's pyramid: each block's flags, the bands of the pyramid's cells, the
//! escape cones and the skirt's quads.

use glam::Vec3A;
use rayon::prelude::*;

use crate::trace::mesh::{HeightFieldGrid, Mesh, NO_TRIANGLE};

use super::escape_cone::{escape_cones, escape_slopes};
use super::{
    Band, HeightFieldAccel, LevelInfo, Range, SkirtQuad, EMPTY, MAX_BAND_SLOPE, MAX_LEVELS,
    NOTHING, SKIRT, SURFACE,
};

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
}
