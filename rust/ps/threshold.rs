//! The plain fit (every observation, [`Robust::None`](super::Robust::None)) and the
//! threshold fit (observations in shadow or saturated left out,
//! [`Robust::Threshold`](super::Robust::Threshold)) of photometric stereo: per pixel, an
//! observation is in shadow when its summed `b` is below `shadow_fraction` of that pixel's
//! brightest, and the pixel is re-solved from the rest when at least 3 non-coplanar lights
//! remain; otherwise it keeps the full fit and is flagged.
//!
//! The fits run over tiles of pixels, streaming through each image's rows of the tile
//! (twice in threshold mode: once for each pixel's brightest, once to accumulate); only the
//! tile's masked pixels are de-interleaved and summed, their sums kept in structure-of-arrays
//! form so that the loops run over contiguous values.

use glam::{Mat3, Vec3};

use crate::ps::kernel::{
    eigen_range, finish, flag, for_each_with, PerLight, PsOutput, COPLANAR_RATIO,
};

/// Pixels per tile.
const TILE: usize = 256;

/// The plain fit (`shadow_fraction` `None`) or the threshold fit of the pixels where `mask`
/// is true, from `images` laid out `(K, pixels, 3)`, into `out` (`gram`: Σ l lᵀ over every
/// light).
pub(crate) fn fit_pixels(
    images: &[f32],
    mask: &[bool],
    lights: &PerLight,
    gram: Mat3,
    shadow_fraction: Option<f32>,
    out: PsOutput,
) -> PsOutput {
    let fit = Fit {
        lights,
        gram,
        shadow_fraction,
    };
    fit.streamed(images, mask, out)
}

impl Fit<'_> {
    /// The plain or threshold fit, streamed over tiles of the images.
    fn streamed(&self, images: &[f32], mask: &[bool], mut out: PsOutput) -> PsOutput {
        let k_count = self.lights.directions.len();
        let n = mask.len();
        let tiles = out
            .normals
            .chunks_mut(TILE)
            .zip(out.albedo.chunks_mut(TILE))
            .zip(out.flags.chunks_mut(TILE))
            .zip(out.used.chunks_mut(TILE))
            .enumerate();
        for_each_with(
            tiles,
            || Box::new(Sums::default()),
            |sums, (tile, (((normals, albedo), flags), used))| {
                let start = tile * TILE;
                let pixels = normals.len();
                let kept = sums.keep(&mask[start..start + pixels]);
                if kept == 0 {
                    return;
                }
                let src = |k: usize| &images[(k * n + start) * 3..][..pixels * 3];
                self.accumulate_tile(src, sums, kept, kept == pixels);
                for (i, &p) in sums.at[..kept].iter().enumerate() {
                    let (normal, rho, f, count) = self.solve(sums, i, || {
                        (0..k_count).map(|k| self.observation(src(k), k, p))
                    });
                    normals[p] = normal;
                    albedo[p] = rho;
                    flags[p] = f;
                    used[p] = count;
                }
            },
        );
        out
    }
}

/// Per-pixel sums of the masked pixels of a tile, structure of arrays so that loops run over
/// contiguous values.
struct Sums {
    /// The tile's masked pixels (offsets in the tile), whose sums these are in order.
    at: [usize; TILE],
    /// Σ w l_j b_c, index `j·3 + c`.
    rhs: [[f32; TILE]; 9],
    /// Σ w l lᵀ: xx, xy, xz, yy, yz, zz.
    gram: [[f32; TILE]; 6],
    /// Σ w.
    count: [f32; TILE],
    /// Largest channel-summed `b` of each pixel.
    brightest: [f32; TILE],
    /// One light's `b` per channel, de-interleaved.
    b: [[f32; TILE]; 3],
}

impl Default for Sums {
    fn default() -> Self {
        Sums {
            at: [0; TILE],
            rhs: [[0.0; TILE]; 9],
            gram: [[0.0; TILE]; 6],
            count: [0.0; TILE],
            brightest: [0.0; TILE],
            b: [[0.0; TILE]; 3],
        }
    }
}

impl Sums {
    /// Takes the pixels of a tile where `tile_mask` is true; returns how many.
    fn keep(&mut self, tile_mask: &[bool]) -> usize {
        let mut kept = 0;
        for (p, &on) in tile_mask.iter().enumerate() {
            self.at[kept] = p;
            kept += usize::from(on);
        }
        kept
    }
}

/// A plain or threshold fit: the lights and what is kept of each pixel's observations.
struct Fit<'a> {
    lights: &'a PerLight,
    /// Σ l lᵀ over every light.
    gram: Mat3,
    /// In the threshold fit, the fraction of a pixel's brightest channel-summed `b` below
    /// which an observation is in shadow; `None` in the plain fit.
    shadow_fraction: Option<f32>,
}

impl Fit<'_> {
    /// `b` of light k at tile pixel p, from that light's interleaved tile data.
    #[inline]
    fn observation(&self, src: &[f32], k: usize, p: usize) -> [f32; 3] {
        let s = self.lights.scale[k];
        [
            src[p * 3] * s[0],
            src[p * 3 + 1] * s[1],
            src[p * 3 + 2] * s[2],
        ]
    }

    /// De-interleaves light k's `b` of the kept pixels of a tile (`dense` when they are all
    /// of its pixels) from that light's interleaved tile data.
    fn load(&self, sums: &mut Sums, src: &[f32], k: usize, kept: usize, dense: bool) {
        let s = self.lights.scale[k];
        for c in 0..3 {
            let b = &mut sums.b[c][..kept];
            if dense {
                for (p, d) in b.iter_mut().enumerate() {
                    *d = src[p * 3 + c] * s[c];
                }
            } else {
                for (d, &p) in b.iter_mut().zip(&sums.at[..kept]) {
                    *d = src[p * 3 + c] * s[c];
                }
            }
        }
    }

    /// Fills `sums` for the `kept` pixels of one tile (`dense` when they are all of its
    /// pixels); `src(k)` is light k's interleaved data of the tile.
    fn accumulate_tile<'a>(
        &self,
        src: impl Fn(usize) -> &'a [f32],
        sums: &mut Sums,
        kept: usize,
        dense: bool,
    ) {
        for row in sums.rhs.iter_mut().chain(sums.gram.iter_mut()) {
            row[..kept].fill(0.0);
        }
        sums.count[..kept].fill(0.0);
        sums.brightest[..kept].fill(0.0);
        if let Some(fraction) = self.shadow_fraction {
            for k in 0..self.lights.directions.len() {
                self.load(sums, src(k), k, kept, dense);
                let Sums { b, brightest, .. } = sums;
                for p in 0..kept {
                    brightest[p] = brightest[p].max(b[0][p] + b[1][p] + b[2][p]);
                }
            }
            for v in &mut sums.brightest[..kept] {
                *v *= fraction;
            }
        } else {
            sums.brightest[..kept].fill(f32::NEG_INFINITY);
        }
        for (k, l) in self.lights.directions.iter().enumerate() {
            self.load(sums, src(k), k, kept, dense);
            let sat = self.lights.saturated_b[k];
            let ll = [
                l.x * l.x,
                l.x * l.y,
                l.x * l.z,
                l.y * l.y,
                l.y * l.z,
                l.z * l.z,
            ];
            let lj = [l.x, l.y, l.z];
            let Sums {
                rhs,
                gram,
                count,
                brightest,
                b,
                ..
            } = sums;
            for p in 0..kept {
                let (b0, b1, b2) = (b[0][p], b[1][p], b[2][p]);
                let keep = b0 + b1 + b2 > brightest[p] && b0 < sat[0] && b1 < sat[1] && b2 < sat[2];
                let w = if keep { 1.0 } else { 0.0 };
                count[p] += w;
                for m in 0..6 {
                    gram[m][p] += w * ll[m];
                }
                for j in 0..3 {
                    let wl = w * lj[j];
                    rhs[j * 3][p] += wl * b0;
                    rhs[j * 3 + 1][p] += wl * b1;
                    rhs[j * 3 + 2][p] += wl * b2;
                }
            }
        }
    }

    /// Fits the tile's `p`-th kept pixel from its sums; `all` yields every observation of the
    /// pixel, for the full fit when the robust selection is not enough. Returns (normal,
    /// albedo, flag, observations used).
    fn solve<I: Iterator<Item = [f32; 3]>>(
        &self,
        sums: &Sums,
        p: usize,
        all: impl Fn() -> I,
    ) -> ([f32; 3], [f32; 3], u8, u16) {
        let k_count = self.lights.directions.len();
        let g = |m: usize| sums.gram[m][p];
        let kept_gram = Mat3::from_cols(
            Vec3::new(g(0), g(1), g(2)),
            Vec3::new(g(1), g(3), g(4)),
            Vec3::new(g(2), g(4), g(5)),
        );
        let kept_rhs =
            [0, 1, 2].map(|c| Vec3::new(sums.rhs[c][p], sums.rhs[3 + c][p], sums.rhs[6 + c][p]));
        let count = sums.count[p] as usize;
        let (min, max) = eigen_range(kept_gram);
        let (gram, rhs, used, flag) = if count >= 3 && min >= COPLANAR_RATIO * max {
            (
                kept_gram,
                kept_rhs,
                count,
                if count == k_count || self.shadow_fraction.is_some() {
                    flag::OK
                } else {
                    flag::FULL_FIT
                },
            )
        } else {
            let mut rhs = [Vec3::ZERO; 3];
            for (b, l) in all().zip(&self.lights.directions) {
                for c in 0..3 {
                    rhs[c] += *l * b[c];
                }
            }
            (self.gram, rhs, k_count, flag::FULL_FIT)
        };
        match finish(gram, rhs) {
            Some((normal, albedo)) => (normal, albedo, flag, used as u16),
            None => ([0.0, 0.0, 1.0], [0.0; 3], flag::DARK, used as u16),
        }
    }
}
