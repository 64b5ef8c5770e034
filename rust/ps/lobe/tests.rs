//! Tests of the lobe fit.

use super::weights::select_near;
use super::*;
use crate::ps::{photometric_stereo, PsSettings, Robust};
use crate::scene::Light;
use glam::Vec3A;

/// 48 lights on rings 15°–60° from the camera's axis.
fn ring_lights() -> Vec<Vec3> {
    let mut out = Vec::new();
    for (ring, polar) in [15.0f32, 30.0, 45.0, 60.0].iter().enumerate() {
        for i in 0..12 {
            let azimuth = (i as f32 + 0.5 * ring as f32) * std::f32::consts::TAU / 12.0;
            let (sp, cp) = polar.to_radians().sin_cos();
            out.push(Vec3::new(sp * azimuth.cos(), sp * azimuth.sin(), cp));
        }
    }
    out
}

fn angle_deg(a: [f32; 3], b: Vec3) -> f32 {
    Vec3::from(a).dot(b).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Pixels rendered with a Lambertian base (albedo `rho` per channel) and a Blinn-Phong
/// lobe of exponent `exponent` and height `height`, fitted in `mode`.
fn fit_glossy(
    normals: &[Vec3],
    rho: [f32; 3],
    height: f32,
    exponent: i32,
    mode: Robust,
) -> crate::ps::PsOutput {
    fit_glossy_with(
        normals,
        rho,
        height,
        exponent,
        PsSettings {
            robust: mode,
            ..PsSettings::default()
        },
    )
    .unwrap()
}

/// [`fit_glossy`] with `settings`.
fn fit_glossy_with(
    normals: &[Vec3],
    rho: [f32; 3],
    height: f32,
    exponent: i32,
    settings: PsSettings,
) -> crate::error::Result<crate::ps::PsOutput> {
    let (images, lights) = glossy_images(normals, rho, height, exponent, None);
    photometric_stereo(
        &images,
        &vec![true; normals.len()],
        &lights,
        &settings,
        None,
    )
}

/// The images of [`fit_glossy`]'s pixels and their lights, pixel p seen from `views[p]`,
/// or from a distant camera along +z.
fn glossy_images(
    normals: &[Vec3],
    rho: [f32; 3],
    height: f32,
    exponent: i32,
    views: Option<&[[f32; 3]]>,
) -> (Vec<f32>, Vec<Light>) {
    let directions = ring_lights();
    let lights: Vec<Light> = directions
        .iter()
        .map(|&d| Light {
            direction: Vec3A::from(d),
            irradiance: [std::f32::consts::PI; 3],
        })
        .collect();
    let mut images = Vec::new();
    for &l in &directions {
        for (p, &n) in normals.iter().enumerate() {
            let toward = views.map_or(Vec3::Z, |views| Vec3::from(views[p]));
            let h = (l + toward).normalize();
            let nl = n.dot(l).max(0.0);
            let lobe = height * n.dot(h).max(0.0).powi(exponent);
            images.extend(rho.map(|r| nl * (r + lobe)));
        }
    }
    (images, lights)
}

/// The directions toward a pinhole 64° across (fx = 8, principal point (5, 2)) from the
/// pixels of an image 10 wide: up to 32° from the axis.
fn pinhole_views(count: usize) -> Vec<[f32; 3]> {
    (0..count)
        .map(|p| {
            let (i, j) = ((p / 10) as f32, (p % 10) as f32);
            Vec3::new(-(j + 0.5 - 5.0) / 8.0, (i + 0.5 - 2.0) / 8.0, 1.0)
                .normalize()
                .to_array()
        })
        .collect()
}

#[test]
fn pixels_seen_through_a_pinhole_take_the_half_vectors_of_their_own_views() {
    let (normals, views) = (tilted(40), pinhole_views(40));
    let (images, lights) = glossy_images(&normals, [0.2, 0.3, 0.4], 4.0, 32, Some(&views));
    let settings = PsSettings {
        robust: Robust::Lobe,
        ..PsSettings::default()
    };
    let fit = |views| {
        let out = photometric_stereo(&images, &[true; 40], &lights, &settings, views).unwrap();
        let errors = normals.iter().zip(&out.normals);
        errors.map(|(&n, &m)| angle_deg(m, n)).sum::<f32>() / 40.0
    };
    let (own, distant) = (fit(Some(&views)), fit(None));
    assert!(own < 0.05, "mean error {own}° with each pixel's view");
    assert!(
        distant > 10.0 * own,
        "{distant}° from afar: the test shows nothing"
    );
}

#[test]
fn views_that_are_not_one_unit_vector_per_pixel_are_refused() {
    let normals = tilted(40);
    let (images, lights) = glossy_images(&normals, [0.2; 3], 4.0, 32, None);
    let settings = PsSettings {
        robust: Robust::Lobe,
        ..PsSettings::default()
    };
    let mut bad = pinhole_views(40);
    bad[7] = [0.0, 0.0, -1.0];
    for (views, problem) in [
        (pinhole_views(39), "39 directions for 40 pixels"),
        (bad, "at pixel 7 is not a unit vector toward the camera"),
    ] {
        let refused = photometric_stereo(&images, &[true; 40], &lights, &settings, Some(&views));
        assert!(refused.unwrap_err().to_string().contains(problem));
    }
}

fn tilted(count: usize) -> Vec<Vec3> {
    (0..count)
        .map(|i| {
            Vec3::new(
                0.5 * (i as f32 * 0.7).sin(),
                0.5 * (i as f32 * 1.3).cos(),
                1.0,
            )
            .normalize()
        })
        .collect()
}

#[test]
fn lobe_mode_recovers_normals_and_diffuse_albedo_of_glossy_pixels() {
    let normals = tilted(40);
    let lobe = fit_glossy(&normals, [0.2, 0.3, 0.4], 4.0, 32, Robust::Lobe);
    let tukey = fit_glossy(&normals, [0.2, 0.3, 0.4], 4.0, 32, Robust::Tukey);
    let mean = |out: &crate::ps::PsOutput| {
        normals
            .iter()
            .zip(&out.normals)
            .map(|(&n, &m)| angle_deg(m, n))
            .sum::<f32>()
            / normals.len() as f32
    };
    assert!(
        mean(&lobe) < 0.05,
        "lobe mode's mean error {}°",
        mean(&lobe)
    );
    assert!(
        mean(&tukey) > 5.0 * mean(&lobe),
        "the Tukey fit is already right ({}°): the test shows nothing",
        mean(&tukey)
    );
    for albedo in &lobe.albedo {
        for (value, truth) in albedo.iter().zip([0.2, 0.3, 0.4]) {
            assert!(
                (value - truth).abs() < 0.01,
                "diffuse albedo {albedo:?}, truth [0.2, 0.3, 0.4]"
            );
        }
    }
}

#[test]
fn a_fit_of_few_rounds_tells_glossy_pixels_from_matte_ones() {
    let normals = tilted(40);
    let shortened = |height, lobe_rounds| {
        fit_glossy_with(
            &normals,
            [0.2, 0.3, 0.4],
            height,
            32,
            PsSettings {
                robust: Robust::Lobe,
                lobe_rounds,
                ..PsSettings::default()
            },
        )
        .unwrap()
    };
    for rounds in [1, 5] {
        assert!(
            shortened(4.0, rounds)
                .flags
                .iter()
                .all(|&f| f == flag::LOBE),
            "{rounds} rounds: a glossy pixel without a lobe"
        );
        assert!(
            shortened(0.0, rounds).flags.iter().all(|&f| f == flag::OK),
            "{rounds} rounds: a matte pixel with a lobe"
        );
    }
    // Five rounds leave the normals less settled than the full fit's (what that does to the
    // lobe share: docs/benchmarks.md, Photometric stereo on rendered materials).
    let worst = |out: &crate::ps::PsOutput| {
        normals
            .iter()
            .zip(&out.normals)
            .map(|(&n, &m)| angle_deg(m, n))
            .fold(0.0f32, f32::max)
    };
    assert!(
        worst(&shortened(4.0, 5)) > 3.0 * worst(&shortened(4.0, LOBE_ROUNDS)),
        "5 rounds fit as well as {LOBE_ROUNDS}: the rounds are not used"
    );
    let refused = fit_glossy_with(
        &normals,
        [0.2, 0.3, 0.4],
        4.0,
        32,
        PsSettings {
            robust: Robust::Lobe,
            lobe_rounds: 0,
            ..PsSettings::default()
        },
    );
    assert!(refused.unwrap_err().to_string().contains("lobe_rounds"));
}

#[test]
fn the_auto_modes_check_beside_the_tukey_fit_is_each_fit_alone() {
    // Half the pixels glossy, half matte: the check's pixels pick from both.
    let directions = ring_lights();
    let lights: Vec<Light> = directions
        .iter()
        .map(|&d| Light {
            direction: Vec3A::from(d),
            irradiance: [std::f32::consts::PI; 3],
        })
        .collect();
    let normals = tilted(60);
    let mut images = Vec::new();
    for &l in &directions {
        let h = (l + Vec3::Z).normalize();
        for (p, &n) in normals.iter().enumerate() {
            let height = if p % 2 == 0 { 4.0 } else { 0.0 };
            images.extend(
                [0.2f32, 0.3, 0.4]
                    .map(|r| n.dot(l).max(0.0) * (r + height * n.dot(h).max(0.0).powi(32))),
            );
        }
    }
    let mask: Vec<bool> = (0..normals.len()).map(|p| p != 7).collect();
    let check = [3, 10, 11, 40, 59, 2];
    let settings = PsSettings::default();
    let (fit, flags) =
        crate::ps::tukey_with_lobe_check(&images, &mask, &check, &lights, &settings, 5, None)
            .unwrap();
    assert_eq!(
        fit,
        photometric_stereo(
            &images,
            &mask,
            &lights,
            &PsSettings {
                robust: Robust::Tukey,
                ..settings
            },
            None
        )
        .unwrap()
    );
    let observed: Vec<f32> = images
        .chunks_exact(3 * normals.len())
        .flat_map(|image| {
            check
                .iter()
                .flat_map(move |&p| image[3 * p..3 * p + 3].to_vec())
        })
        .collect();
    let alone = photometric_stereo(
        &observed,
        &[true; 6],
        &lights,
        &PsSettings {
            robust: Robust::Lobe,
            lobe_rounds: 5,
            ..settings
        },
        None,
    )
    .unwrap();
    assert_eq!(flags, alone.flags);
    assert_eq!(
        flags.iter().map(|&f| f == flag::LOBE).collect::<Vec<_>>(),
        check.map(|p| p % 2 == 0),
        "the glossy pixels take a lobe, the matte ones none"
    );
    let outside =
        crate::ps::tukey_with_lobe_check(&images, &mask, &[60], &lights, &settings, 5, None)
            .unwrap_err()
            .to_string();
    assert!(
        outside.starts_with("check: pixel 60 is outside"),
        "{outside}"
    );
}

#[test]
fn lobe_mode_keeps_lambertian_pixels() {
    let normals = tilted(40);
    let out = fit_glossy(&normals, [0.5, 0.5, 0.5], 0.0, 1, Robust::Lobe);
    for (&n, (m, albedo)) in normals.iter().zip(out.normals.iter().zip(&out.albedo)) {
        assert!(
            angle_deg(*m, n) < 0.05,
            "normal off by {}°",
            angle_deg(*m, n)
        );
        assert!(
            albedo.iter().all(|&a| (a - 0.5).abs() < 2e-3),
            "albedo {albedo:?}"
        );
    }
}

#[test]
fn pixels_with_few_lit_observations_keep_the_tukey_fit() {
    // Five lights: a lobe's five unknowns would fit any such pixel's observations.
    let directions: Vec<Vec3> = ring_lights().into_iter().step_by(10).collect();
    let lights: Vec<Light> = directions
        .iter()
        .map(|&d| Light {
            direction: Vec3A::from(d),
            irradiance: [1.0; 3],
        })
        .collect();
    let normals = tilted(20);
    let mut images = Vec::new();
    for &l in &directions {
        let h = (l + Vec3::Z).normalize();
        for &n in &normals {
            images.extend([n.dot(l).max(0.0) * (0.3 + 2.0 * n.dot(h).max(0.0).powi(16)); 3]);
        }
    }
    let mask = vec![true; normals.len()];
    let fit = |robust| {
        photometric_stereo(
            &images,
            &mask,
            &lights,
            &PsSettings {
                robust,
                ..PsSettings::default()
            },
            None,
        )
        .unwrap()
    };
    assert_eq!(fit(Robust::Lobe), fit(Robust::Tukey));
}

/// The lobe fits of glossy pixels with soft shadows, noise and saturated observations
/// under `count` lights, in the portable registers and in each wider set this CPU has.
fn fits_in_every_instruction_set(count: usize) -> Vec<Vec<(usize, PixelFit)>> {
    let mut rng = crate::sampler::Rng::new(7);
    let mut uniform = || rng.next_f32();
    let directions: Vec<Vec3> = ring_lights()
        .into_iter()
        .cycle()
        .take(count)
        .enumerate()
        .map(|(k, l)| (l + Vec3::new(0.0, 0.0, 0.01 * k as f32)).normalize())
        .collect();
    let gram = directions
        .iter()
        .fold(glam::Mat3::ZERO, |m, &l| m + crate::ps::kernel::outer(l));
    let lights = Lights::new(
        &directions,
        &vec![[1.0; 3]; count],
        &vec![[2.0; 3]; count],
        gram,
    );
    let normals = tilted(200);
    let mut images = vec![0.0f32; count * normals.len() * 3];
    for (k, &l) in directions.iter().enumerate() {
        let h = (l + Vec3::Z).normalize();
        for (p, &n) in normals.iter().enumerate() {
            let shade = if uniform() < 0.1 {
                0.3 * uniform()
            } else {
                1.0 + 0.01 * (uniform() - 0.5)
            };
            let value = shade
                * n.dot(l).max(0.0)
                * (0.3 + (p % 3) as f32 * n.dot(h).max(0.0).powi(1 << (p % 7)));
            images[(k * normals.len() + p) * 3..][..3].copy_from_slice(&[
                value,
                0.9 * value,
                0.8 * value,
            ]);
        }
    }
    let n = normals.len();
    let mut out = PsOutput {
        normals: vec![[0.0; 3]; n],
        albedo: vec![[0.0; 3]; n],
        flags: vec![flag::MASKED_OUT; n],
        used: vec![0; n],
    };
    crate::ps::tukey::fit_pixels(&images, &vec![true; n], &lights, 0.05, &mut out).unwrap();
    let job = Job::new(&images, &lights, LOBE_ROUNDS, None, &out);
    let pixels: Vec<usize> = (0..n).collect();
    let mut state = (Scratch::default(), Work::default(), HalfVectors::default());
    let mut portable = Vec::new();
    job.fit_tile(Portable, &mut state, &pixels, &mut portable);
    let mut all = vec![portable];
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = crate::ps::lanes::Avx2::detect() {
        let mut fits = Vec::new();
        // SAFETY: `detect` found AVX2 and FMA.
        unsafe { job.fit_tile_avx2(avx2, &mut state, &pixels, &mut fits) };
        all.push(fits);
    }
    all
}

#[test]
fn every_instruction_set_fits_the_same_bits() {
    // 37: lights that fill no whole group of lanes.
    for count in [48, 37] {
        let all = fits_in_every_instruction_set(count);
        let lobes = all[0]
            .iter()
            .filter(|(_, fit)| fit.flag == flag::LOBE)
            .count();
        assert!(
            lobes > 50,
            "{count} lights: {lobes} of 200 pixels take a lobe, the test shows little"
        );
        for fits in &all[1..] {
            assert_eq!(fits, &all[0], "{count} lights");
        }
    }
}

#[test]
fn select_near_finds_the_rank_of_a_sort_for_any_guess() {
    let mut rng = crate::sampler::Rng::new(3);
    for trial in 0..500 {
        let count = 1 + trial % 97;
        // Keys of residuals 0.001-10, a tenth of them tied.
        let keys: Vec<u32> = (0..count)
            .map(|_| {
                if rng.next_f32() < 0.1 {
                    0.5f32.to_bits()
                } else {
                    (0.001 * 10_000f32.powf(rng.next_f32())).to_bits()
                }
            })
            .collect();
        let mut sorted = keys.clone();
        sorted.sort_unstable();
        let rank = (trial * 7) % count;
        let truth = sorted[rank];
        // The guess: the value itself, near it on either side, far off, and the ends.
        for guess in [
            truth,
            truth + 3,
            truth - truth.min(5_000),
            truth.saturating_add(1 << 24),
            truth.saturating_sub(1 << 24),
            0,
            u32::MAX,
        ] {
            assert_eq!(
                select_near(&mut keys.clone(), rank, guess),
                truth,
                "rank {rank} of {count}, guess {guess}"
            );
        }
    }
}

#[test]
fn bound_solutions_are_non_negative() {
    assert_eq!(diffuse_and_lobe(1.0, 0.0, 1.0, -1.0, 2.0), (0.0, 2.0));
    assert_eq!(diffuse_and_lobe(1.0, 0.0, 1.0, 3.0, -1.0), (3.0, 0.0));
    let (a, c) = diffuse_and_lobe(2.0, 1.0, 2.0, 3.0, 3.0);
    assert!((a - 1.0).abs() < 1e-6 && (c - 1.0).abs() < 1e-6);
}
