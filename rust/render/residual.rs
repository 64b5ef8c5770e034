//! A rendering compared with the observed images, in one pass over its planes.
//!
//! IRT-PS re-renders its reconstruction after every pass: the direct image and the
//! inter-reflected light of the camera paths, traced in one or two halves. This module turns
//! those planes into the pass's inter-reflection estimate (the halves' weighted mean), the
//! residual's sums over the compared observations, and the Monte-Carlo noise of the estimate
//! at each pixel (from the spread between the halves).

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::memory::try_vec;

/// The planes of a rendering of N pixels under K lights, each laid out (K, N, 3).
pub struct RenderedPlanes<'a> {
    /// The direct image.
    pub direct: &'a [f32],
    /// The inter-reflected light of each half of the camera paths (one or two halves).
    pub halves: &'a [&'a [f32]],
    /// Camera paths per pixel of each half.
    pub counts: &'a [usize],
}

/// The observations a rendering is compared with: those of `total` pixels under K lights, of
/// which the rendering covers `first..first + N`.
pub struct Observed<'a> {
    /// (K, total, 3) the observed values.
    pub values: &'a [f32],
    /// (K, total): the observations compared (all when None).
    pub keep: Option<&'a [bool]>,
    /// Pixels per light in `values` and `keep`.
    pub total: usize,
    /// The rendering's first pixel among them.
    pub first: usize,
}

/// Sums of |rendered − observed| and |observed| over the compared observations.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ResidualSums {
    /// Σ |direct + inter-reflected − observed|.
    pub difference: f64,
    /// Σ |observed|.
    pub observed: f64,
    /// Σ |direct + half h − observed| for each half (0 for a missing second half).
    pub half_difference: [f64; 2],
}

impl ResidualSums {
    fn add(self, other: ResidualSums) -> ResidualSums {
        ResidualSums {
            difference: self.difference + other.difference,
            observed: self.observed + other.observed,
            half_difference: [
                self.half_difference[0] + other.half_difference[0],
                self.half_difference[1] + other.half_difference[1],
            ],
        }
    }
}

/// A rendering compared with the observations.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// The inter-reflected light, (K, N, 3): Σ_h counts\[h\] · half h / Σ counts.
    pub indirect: Vec<f32>,
    /// Per pixel, the Monte-Carlo noise energy of `indirect` summed over lights and channels:
    /// (n₁ n₂ / n²) Σ |half 1 − half 2|² (all 0 with one half).
    pub noise_energy: Vec<f64>,
    /// The residual's sums.
    pub sums: ResidualSums,
}

/// Compares `planes` (N pixels, K lights) with the observations of the same pixels in
/// `observed`.
///
/// Errors name the argument whose length does not match or that holds a NaN or an infinity,
/// or the counts when there are not one or two halves with a path each.
pub fn compare(
    planes: &RenderedPlanes<'_>,
    observed: &Observed<'_>,
    lights: usize,
    pixels: usize,
) -> Result<Comparison> {
    let size = lights * pixels * 3;
    let check = |name: &str, len: usize, expected: usize| {
        if len == expected {
            Ok(())
        } else {
            Err(Error::input(
                name,
                format!(
                    "{len} values, expected {expected} for {lights} lights and {pixels} pixels"
                ),
            ))
        }
    };
    check("direct", planes.direct.len(), size)?;
    if observed
        .first
        .checked_add(pixels)
        .is_none_or(|end| end > observed.total)
    {
        return Err(Error::input(
            "first",
            format!(
                "pixels {}..{}+{pixels} of {}",
                observed.first, observed.first, observed.total
            ),
        ));
    }
    check(
        "observed",
        observed.values.len(),
        lights * observed.total * 3,
    )?;
    if let Some(keep) = observed.keep {
        check("keep", keep.len(), lights * observed.total)?;
    }
    if !(1..=2).contains(&planes.halves.len())
        || planes.counts.len() != planes.halves.len()
        || planes.counts.contains(&0)
    {
        return Err(Error::input(
            "counts",
            format!(
                "{:?}: expected one or two halves with at least one path each",
                planes.counts
            ),
        ));
    }
    for half in planes.halves {
        check("halves", half.len(), size)?;
    }
    check_finite("direct", planes.direct, pixels, 0)?;
    for half in planes.halves {
        check_finite("halves", half, pixels, 0)?;
    }
    for k in 0..lights {
        let seen = &observed.values[3 * (k * observed.total + observed.first)..][..3 * pixels];
        check_finite("observed", seen, pixels, k * pixels)?;
    }
    let samples = planes.counts.iter().sum::<usize>() as f32;
    let weights: Vec<f32> = planes.counts.iter().map(|&c| c as f32).collect();
    let mut indirect = try_vec(
        &format!("the inter-reflected light of {pixels} pixels under {lights} lights"),
        size,
        0f32,
    )?;
    let row = pixels * 3;
    let sums = if size == 0 {
        ResidualSums::default()
    } else {
        indirect
            .par_chunks_mut(row)
            .enumerate()
            .map(|(k, out)| {
                let span = k * row..(k + 1) * row;
                let direct = &planes.direct[span.clone()];
                let seen_first = k * observed.total + observed.first;
                let seen = &observed.values[3 * seen_first..3 * (seen_first + pixels)];
                let keep = observed
                    .keep
                    .map(|keep| &keep[seen_first..seen_first + pixels]);
                let halves: Vec<&[f32]> = planes.halves.iter().map(|h| &h[span.clone()]).collect();
                let mut sums = ResidualSums::default();
                for (i, value) in out.iter_mut().enumerate() {
                    let weighted = halves
                        .iter()
                        .zip(&weights)
                        .fold(0f32, |acc, (h, w)| acc + w * h[i]);
                    *value = weighted / samples;
                    if keep.is_some_and(|keep| !keep[i / 3]) {
                        continue;
                    }
                    let value_seen = seen[i];
                    sums.difference += f64::from((direct[i] + *value - value_seen).abs());
                    sums.observed += f64::from(value_seen.abs());
                    for (slot, h) in sums.half_difference.iter_mut().zip(&halves) {
                        *slot += f64::from((direct[i] + h[i] - value_seen).abs());
                    }
                }
                sums
            })
            .reduce(ResidualSums::default, ResidualSums::add)
    };
    let mut noise_energy = vec![0f64; pixels];
    if let [first, second] = planes.halves {
        let factor = (planes.counts[0] * planes.counts[1]) as f64 / f64::from(samples).powi(2);
        noise_energy
            .par_iter_mut()
            .enumerate()
            .for_each(|(p, energy)| {
                let spread: f64 = (0..lights)
                    .flat_map(|k| (0..3).map(move |c| (k * pixels + p) * 3 + c))
                    .map(|i| f64::from(first[i] - second[i]).powi(2))
                    .sum();
                *energy = spread * factor;
            });
    }
    Ok(Comparison {
        indirect,
        noise_energy,
        sums,
    })
}

/// Refuses a NaN or an infinity in `values`, the RGB values of `pixels` pixels for each
/// light from the one that `skipped` pixels precede, naming `name`, the light and the pixel
/// (counted from the first compared).
fn check_finite(name: &str, values: &[f32], pixels: usize, skipped: usize) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => {
            let at = skipped + index / 3;
            Err(Error::input(
                name,
                format!(
                    "non-finite value {} for light {}, pixel {}",
                    values[index],
                    at / pixels,
                    at % pixels
                ),
            ))
        }
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_weigh_the_halves_and_skip_what_is_not_kept() {
        // 2 lights, 1 pixel: direct 1, halves 2 and 4 of 1 and 3 paths → indirect 3.5.
        let direct = [1.0; 6];
        let (first, second) = ([2.0; 6], [4.0; 6]);
        let observed = [4.0, 4.0, 4.0, 9.0, 9.0, 9.0];
        let halves: [&[f32]; 2] = [&first, &second];
        let planes = RenderedPlanes {
            direct: &direct,
            halves: &halves,
            counts: &[1, 3],
        };
        let all = compare(
            &planes,
            &Observed {
                values: &observed,
                keep: None,
                total: 1,
                first: 0,
            },
            2,
            1,
        )
        .unwrap();
        assert_eq!(all.indirect, vec![3.5; 6]);
        assert_eq!(all.sums.difference, 3.0 * 0.5 + 3.0 * 4.5);
        assert_eq!(all.sums.observed, 39.0);
        assert_eq!(
            all.sums.half_difference,
            [3.0 * 1.0 + 3.0 * 6.0, 3.0 * 1.0 + 3.0 * 4.0]
        );
        // 6 values of |2 − 4|² = 4, times n₁n₂/n² = 3/16.
        assert_eq!(all.noise_energy, vec![24.0 * 3.0 / 16.0]);
        let first_light = compare(
            &planes,
            &Observed {
                values: &observed,
                keep: Some(&[true, false]),
                total: 1,
                first: 0,
            },
            2,
            1,
        )
        .unwrap();
        assert_eq!(first_light.sums.difference, 1.5);
        assert_eq!(first_light.sums.observed, 12.0);
        assert_eq!(first_light.indirect, all.indirect);
    }

    #[test]
    fn a_window_of_the_observations_is_compared() {
        // 1 light, observations of 3 pixels; the rendering covers the middle one.
        let halves: [&[f32]; 1] = [&[0.5; 3]];
        let planes = RenderedPlanes {
            direct: &[0.5; 3],
            halves: &halves,
            counts: &[2],
        };
        let values = [9.0, 9.0, 9.0, 1.5, 1.5, 1.5, 9.0, 9.0, 9.0];
        let middle = compare(
            &planes,
            &Observed {
                values: &values,
                keep: Some(&[false, true, false]),
                total: 3,
                first: 1,
            },
            1,
            1,
        )
        .unwrap();
        assert_eq!((middle.sums.difference, middle.sums.observed), (1.5, 4.5));
    }

    #[test]
    fn one_half_has_no_noise_estimate() {
        let (direct, half, observed) = ([0.5; 3], [0.25; 3], [1.0; 3]);
        let halves: [&[f32]; 1] = [&half];
        let planes = RenderedPlanes {
            direct: &direct,
            halves: &halves,
            counts: &[4],
        };
        let only = compare(
            &planes,
            &Observed {
                values: &observed,
                keep: None,
                total: 1,
                first: 0,
            },
            1,
            1,
        )
        .unwrap();
        assert_eq!(only.noise_energy, vec![0.0]);
        assert_eq!(only.sums.half_difference, [0.75, 0.0]);
    }

    #[test]
    fn mismatched_lengths_name_the_argument() {
        let halves: [&[f32]; 1] = [&[0.0; 3]];
        let planes = RenderedPlanes {
            direct: &[0.0; 3],
            halves: &halves,
            counts: &[1],
        };
        let err = compare(
            &planes,
            &Observed {
                values: &[0.0; 3],
                keep: None,
                total: 2,
                first: 0,
            },
            1,
            1,
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("observed"), "{err}");
        let err = compare(
            &planes,
            &Observed {
                values: &[0.0; 6],
                keep: None,
                total: 2,
                first: 2,
            },
            1,
            1,
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("first"), "{err}");
        let planes = RenderedPlanes {
            direct: &[0.0; 3],
            halves: &halves,
            counts: &[0],
        };
        assert!(compare(
            &planes,
            &Observed {
                values: &[0.0; 3],
                keep: None,
                total: 1,
                first: 0
            },
            1,
            1
        )
        .unwrap_err()
        .to_string()
        .contains("counts"));
    }
}
