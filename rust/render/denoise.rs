//! A cross-bilateral filter for the inter-reflection estimate on the object's pixels.
//!
//! The light that reaches a surface point after bounces (its irradiance) changes slowly along
//! a smooth surface; the Monte-Carlo estimate of it is noisy pixel by pixel. The filter
//! estimates each pixel's irradiance from its 3×3 neighbours on the same surface, as the
//! weighted sum of their light over the weighted sum of their albedo, and multiplies the
//! pixel's albedo back. A neighbour
//! counts by a Gaussian of its distance (σ one pixel), by how far its normal turns from the
//! pixel's (cos⁶⁴: 0.5 at 8.4°) and by a Gaussian of its distance from the pixel's tangent
//! plane (σ one pixel): across a crease or a step, the surface's irradiance changes and the
//! neighbour barely counts. Texture does not blur: it is divided out before the average.

use glam::Vec3A;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::memory::{try_collect, try_vec, try_with_capacity};
use crate::scene::Rgb;

/// Exponent of the cosine between two normals in a neighbour's weight.
const NORMAL_EXPONENT: i32 = 64;
/// Albedo of a channel, relative to the pixel's own weight, below which its neighbours' weighted
/// albedo tells nothing about the irradiance there: the pixel keeps its estimate.
const DARK_ALBEDO: f32 = 1e-3;
/// Neighbours of a pixel: the 3×3 window.
const WINDOW: usize = 9;

/// The surface the filter follows, at the object's pixels.
pub struct Surface<'a> {
    /// Image width and height, pixels.
    pub size: (usize, usize),
    /// Flat (row-major) indices of the object's pixels, ascending.
    pub pixels: &'a [usize],
    /// Height of each listed pixel, in pixels (world height over the pixel size).
    pub height_px: &'a [f32],
    /// Albedo of each listed pixel.
    pub albedo: &'a [Rgb],
}

/// An estimate after the filter.
#[derive(Debug, Clone, PartialEq)]
pub struct Denoised {
    /// The filtered inter-reflected light, (K, N, 3).
    pub indirect: Vec<f32>,
    /// Each pixel's Monte-Carlo noise energy after the filter: Σ f² e of its neighbours'
    /// energies e by the factors f their light gets (their paths are independent).
    pub noise_energy: Vec<f64>,
}

/// Filters `indirect` (K, N, 3) at the N pixels of `surface`, and its per-pixel noise energy
/// `noise_energy` (N,).
///
/// Errors name the argument whose length does not match, `pixels` when the indices are not
/// ascending within the image, and the argument holding a NaN or an infinity.
pub fn denoise(surface: &Surface<'_>, indirect: &[f32], noise_energy: &[f64]) -> Result<Denoised> {
    let n = surface.pixels.len();
    let (width, height) = surface.size;
    if surface.height_px.len() != n || surface.albedo.len() != n || noise_energy.len() != n {
        return Err(Error::input(
            "surface",
            format!(
                "{n} pixels but {} heights, {} albedos and {} noise energies",
                surface.height_px.len(),
                surface.albedo.len(),
                noise_energy.len()
            ),
        ));
    }
    if n > 0
        && (surface.pixels.windows(2).any(|w| w[0] >= w[1])
            || surface.pixels[n - 1] >= width * height)
    {
        return Err(Error::input(
            "pixels",
            format!("expected ascending indices below {}", width * height),
        ));
    }
    if n == 0 || !indirect.len().is_multiple_of(3 * n) {
        return if indirect.is_empty() {
            Ok(Denoised {
                indirect: Vec::new(),
                noise_energy: noise_energy.to_vec(),
            })
        } else {
            Err(Error::input(
                "indirect",
                format!("{} values are not (K, {n}, 3)", indirect.len()),
            ))
        };
    }
    check_finite(surface, indirect, noise_energy)?;
    let position = |index: usize| (index / width, index % width);
    let listed = |row: usize, col: usize| surface.pixels.binary_search(&(row * width + col)).ok();
    let mut normals = try_with_capacity(&format!("the filter's normals of {n} pixels"), n)?;
    normals.par_extend(surface_normals(surface, &listed));
    // Per pixel and window slot: the neighbour and, per channel, the factor its estimate gets.
    let mut weights: Vec<([usize; WINDOW], [Rgb; WINDOW], f64)> =
        try_with_capacity(&format!("the filter's weights of {n} pixels"), n)?;
    weights.par_extend((0..n).into_par_iter().map(|p| {
        let (row, col) = position(surface.pixels[p]);
        let (normal, height_p, albedo_p) = (normals[p], surface.height_px[p], surface.albedo[p]);
        let mut neighbour = [p; WINDOW];
        let mut raw = [0f32; WINDOW];
        for (slot, (dr, dc)) in (-1isize..=1)
            .flat_map(|dr| (-1isize..=1).map(move |dc| (dr, dc)))
            .enumerate()
        {
            let (r, c) = (row as isize + dr, col as isize + dc);
            if r < 0 || c < 0 || r >= height as isize || c >= width as isize {
                continue;
            }
            let Some(q) = listed(r as usize, c as usize) else {
                continue;
            };
            // x grows with the column, y against the row (contract §1), heights in pixels.
            let offset = Vec3A::new(dc as f32, -dr as f32, surface.height_px[q] - height_p);
            let plane = offset.dot(normal);
            let turn = normal.dot(normals[q]).max(0.0).powi(NORMAL_EXPONENT);
            neighbour[slot] = q;
            raw[slot] =
                (-0.5 * (dr * dr + dc * dc) as f32).exp() * turn * (-0.5 * plane * plane).exp();
        }
        // The albedo-weighted mean of the neighbours' irradiance is Σ w·light / Σ w·albedo:
        // a dark neighbour, whose irradiance the division would blow up, barely counts.
        let mut factor = [[0f32; 3]; WINDOW];
        for c in 0..3 {
            let total: f32 = (0..WINDOW)
                .map(|slot| raw[slot] * surface.albedo[neighbour[slot]][c])
                .sum();
            if total > DARK_ALBEDO * raw[WINDOW / 2] {
                for slot in 0..WINDOW {
                    factor[slot][c] = raw[slot] * albedo_p[c] / total;
                }
            } else {
                // Nothing to average with: the pixel keeps its own estimate (slot 4 is itself).
                factor[WINDOW / 2][c] = 1.0;
            }
        }
        let energy = (0..WINDOW)
            .map(|slot| {
                f64::from(factor[slot].iter().sum::<f32>() / 3.0).powi(2)
                    * noise_energy[neighbour[slot]]
            })
            .sum();
        (neighbour, factor, energy)
    }));
    let mut filtered = try_vec(
        &format!("the filtered estimate of {n} pixels"),
        indirect.len(),
        0f32,
    )?;
    filtered
        .par_chunks_mut(3 * n)
        .zip(indirect.par_chunks(3 * n))
        .for_each(|(out, plane)| {
            for (p, (neighbour, factor, _)) in weights.iter().enumerate() {
                for c in 0..3 {
                    out[3 * p + c] = neighbour
                        .iter()
                        .zip(factor)
                        .map(|(&q, f)| f[c] * plane[3 * q + c])
                        .sum();
                }
            }
        });
    let noise_energy = try_collect(
        &format!("the filtered noise energy of {n} pixels"),
        n,
        weights.iter().map(|w| w.2),
    )?;
    Ok(Denoised {
        indirect: filtered,
        noise_energy,
    })
}

/// Refuses a NaN or an infinity in the surface's heights or albedo, the estimate or its noise
/// energy, naming the argument and the listed pixel.
fn check_finite(surface: &Surface<'_>, indirect: &[f32], noise_energy: &[f64]) -> Result<()> {
    let n = surface.pixels.len();
    let first_bad = |values: &[f32]| values.iter().position(|v| !v.is_finite());
    let checks: [(&str, usize, Option<usize>); 4] = [
        ("height_px", 1, first_bad(surface.height_px)),
        ("albedo", 3, first_bad(surface.albedo.as_flattened())),
        ("indirect", 3, first_bad(indirect)),
        (
            "noise_energy",
            1,
            noise_energy.iter().position(|v| !v.is_finite()),
        ),
    ];
    match checks
        .into_iter()
        .find_map(|(name, per_pixel, bad)| bad.map(|index| (name, index / per_pixel % n)))
    {
        Some((name, p)) => Err(Error::input(
            name,
            format!(
                "non-finite value at listed pixel {p} (row {}, column {})",
                surface.pixels[p] / surface.size.0,
                surface.pixels[p] % surface.size.0
            ),
        )),
        None => Ok(()),
    }
}

/// Unit normals of the height field at the listed pixels, from central differences where
/// both neighbours are on the object, one-sided where one is, flat where none is.
fn surface_normals<'a>(
    surface: &'a Surface<'_>,
    listed: &'a (impl Fn(usize, usize) -> Option<usize> + Sync),
) -> impl IndexedParallelIterator<Item = Vec3A> + 'a {
    let (width, height) = surface.size;
    surface
        .pixels
        .par_iter()
        .enumerate()
        .map(move |(p, &index)| {
            let (row, col) = (index / width, index % width);
            let h = surface.height_px[p];
            let at = |r: isize, c: isize| -> Option<f32> {
                (r >= 0 && c >= 0 && (r as usize) < height && (c as usize) < width)
                    .then(|| listed(r as usize, c as usize))
                    .flatten()
                    .map(|q| surface.height_px[q])
            };
            let slope = |before: Option<f32>, after: Option<f32>| match (before, after) {
                (Some(b), Some(a)) => 0.5 * (a - b),
                (Some(b), None) => h - b,
                (None, Some(a)) => a - h,
                (None, None) => 0.0,
            };
            let (r, c) = (row as isize, col as isize);
            let along_col = slope(at(r, c - 1), at(r, c + 1));
            let along_row = slope(at(r - 1, c), at(r + 1, c));
            // dh/dx = along_col, dh/dy = −along_row.
            Vec3A::new(-along_col, along_row, 1.0).normalize()
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane_surface(size: usize, slope: f32) -> (Vec<usize>, Vec<f32>) {
        let pixels: Vec<usize> = (0..size * size).collect();
        let heights = pixels.iter().map(|&i| slope * (i % size) as f32).collect();
        (pixels, heights)
    }

    #[test]
    fn noise_on_a_plane_shrinks_and_a_linear_estimate_stays() {
        let size = 16;
        let (pixels, height_px) = plane_surface(size, 0.5);
        let albedo = vec![[0.5, 0.25, 0.8]; pixels.len()];
        let surface = Surface {
            size: (size, size),
            pixels: &pixels,
            height_px: &height_px,
            albedo: &albedo,
        };
        // A linear irradiance times the albedo: the symmetric window keeps it inside.
        let linear: Vec<f32> = pixels
            .iter()
            .flat_map(|&i| albedo[i].map(|a| a * (1.0 + 0.1 * (i / size) as f32)))
            .collect();
        let energy = vec![1.0; pixels.len()];
        let out = denoise(&surface, &linear, &energy).unwrap();
        for row in 1..size - 1 {
            for col in 1..size - 1 {
                for c in 0..3 {
                    let i = 3 * (row * size + col) + c;
                    assert!(
                        (out.indirect[i] - linear[i]).abs() < 1e-5 * linear[i],
                        "{row} {col}"
                    );
                }
            }
        }
        // Nine equal-ish neighbours: the noise energy of an inner pixel falls several times.
        let inner = out.noise_energy[5 * size + 5];
        assert!(inner < 0.25 && inner > 1.0 / 9.0, "{inner}");
    }

    #[test]
    fn a_crease_keeps_its_sides_apart() {
        // A right-angled V (slopes ±1): each side's estimate stays its own.
        let size = 12;
        let pixels: Vec<usize> = (0..size * size).collect();
        let height_px: Vec<f32> = pixels
            .iter()
            .map(|&i| ((i % size) as f32 - 5.5).abs())
            .collect();
        let albedo = vec![[1.0; 3]; pixels.len()];
        let surface = Surface {
            size: (size, size),
            pixels: &pixels,
            height_px: &height_px,
            albedo: &albedo,
        };
        let estimate: Vec<f32> = pixels
            .iter()
            .flat_map(|&i| [if i % size < 6 { 1.0 } else { 0.0 }; 3])
            .collect();
        let out = denoise(&surface, &estimate, &vec![0.0; pixels.len()]).unwrap();
        let (left, right) = (
            out.indirect[3 * (6 * size + 5)],
            out.indirect[3 * (6 * size + 6)],
        );
        assert!(left > 0.99 && right < 0.01, "{left} {right}");
    }

    #[test]
    fn texture_is_divided_out_and_back() {
        // Uniform irradiance on a checkerboard of grey and black: the filter gives back the same
        // light (black pixels, with no irradiance to tell, neither blow up nor spread).
        let size = 8;
        let (pixels, height_px) = plane_surface(size, 0.0);
        let albedo: Vec<Rgb> = pixels
            .iter()
            .map(|&i| {
                if (i / size + i % size) % 2 == 0 {
                    [0.9; 3]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        let surface = Surface {
            size: (size, size),
            pixels: &pixels,
            height_px: &height_px,
            albedo: &albedo,
        };
        let estimate: Vec<f32> = albedo.iter().flat_map(|a| a.map(|v| 2.0 * v)).collect();
        let out = denoise(&surface, &estimate, &vec![0.0; pixels.len()]).unwrap();
        for (got, want) in out.indirect.iter().zip(&estimate) {
            assert!((got - want).abs() < 1e-5, "{got} {want}");
        }
    }

    #[test]
    fn mismatched_inputs_name_the_argument() {
        let (pixels, height_px) = plane_surface(2, 0.0);
        let albedo = vec![[0.5; 3]; 4];
        let surface = Surface {
            size: (2, 2),
            pixels: &pixels,
            height_px: &height_px,
            albedo: &albedo,
        };
        assert!(denoise(&surface, &[0.0; 5], &[0.0; 4])
            .unwrap_err()
            .to_string()
            .contains("indirect"));
        assert!(denoise(&surface, &[0.0; 12], &[0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("surface"));
        let unordered = [1, 0, 2, 3];
        let surface = Surface {
            size: (2, 2),
            pixels: &unordered,
            height_px: &height_px,
            albedo: &albedo,
        };
        assert!(denoise(&surface, &[0.0; 12], &[0.0; 4])
            .unwrap_err()
            .to_string()
            .contains("pixels"));
    }
}
