//! Tests of photometric stereo through its entry points, mode by mode.

use std::f32::consts::PI;

use glam::{vec3a, Vec3};

use super::*;

fn lights(dirs: &[[f32; 3]]) -> Vec<Light> {
    dirs.iter()
        .map(|d| Light {
            direction: vec3a(d[0], d[1], d[2]).normalize(),
            irradiance: [2.0, 3.0, 4.0],
        })
        .collect()
}

fn render(normal: Vec3, albedo: [f32; 3], lights: &[Light]) -> Vec<f32> {
    lights
        .iter()
        .flat_map(|l| {
            let cosine = normal.dot(l.direction.into()).max(0.0);
            [0, 1, 2].map(|c| albedo[c] * l.irradiance[c] * cosine / PI)
        })
        .collect()
}

/// The fit of one pixel's `images` under `ls` in the robust mode `robust`, a distant camera.
fn fit_one(images: &[f32], ls: &[Light], robust: Robust) -> PsOutput {
    let settings = PsSettings {
        robust,
        ..Default::default()
    };
    photometric_stereo(images, &[true], ls, &settings, None).unwrap()
}

#[test]
fn recovers_normal_and_albedo_exactly_without_shadows() {
    let ls = lights(&[
        [0.0, 0.0, 1.0],
        [0.5, 0.1, 0.8],
        [-0.3, 0.4, 0.8],
        [0.1, -0.5, 0.8],
    ]);
    let normal = Vec3::new(0.1, -0.2, 1.0).normalize();
    let images = render(normal, [0.9, 0.5, 0.2], &ls);
    for robust in [
        Robust::None,
        Robust::Threshold,
        Robust::Trim,
        Robust::Tukey,
        Robust::Lobe,
    ] {
        let out = fit_one(&images, &ls, robust);
        assert!(
            (Vec3::from(out.normals[0]) - normal).length() < 1e-5,
            "{robust:?} {:?}",
            out.normals[0]
        );
        for (got, want) in out.albedo[0].iter().zip([0.9, 0.5, 0.2]) {
            assert!((got - want).abs() < 1e-5);
        }
    }
}

#[test]
fn robust_mode_ignores_attached_shadows() {
    let ls = lights(&[
        [0.0, 0.0, 1.0],
        [0.7, 0.0, 0.7],
        [-0.7, 0.0, 0.7],
        [0.0, 0.7, 0.7],
        [0.0, -0.7, 0.7],
        [-0.9, -0.3, 0.3],
    ]);
    let normal = Vec3::new(0.6, 0.2, 0.8).normalize(); // the last light is behind it
    let images = render(normal, [0.5; 3], &ls);
    let plain = fit_one(&images, &ls, Robust::None);
    assert!((Vec3::from(plain.normals[0]) - normal).length() > 1e-2);
    for robust in [Robust::Threshold, Robust::Tukey] {
        let out = fit_one(&images, &ls, robust);
        assert!((Vec3::from(out.normals[0]) - normal).length() < 1e-5);
        assert_eq!(out.used[0], 5);
    }
}

/// 24 lights around the pole; a normal lit by all of them.
fn ring() -> Vec<Light> {
    let dirs: Vec<[f32; 3]> = (0..24)
        .map(|k| {
            let (azimuth, elevation) = (k as f32 * 0.9, 0.5 + 0.04 * k as f32);
            [
                elevation.cos() * azimuth.cos(),
                elevation.cos() * azimuth.sin(),
                elevation.sin(),
            ]
        })
        .collect();
    lights(&dirs)
}

#[test]
fn tukey_mode_sets_aside_soft_shadows_and_highlights_that_the_threshold_keeps() {
    let ls = ring();
    let normal = Vec3::new(0.1, 0.05, 1.0).normalize();
    let mut images = render(normal, [0.6; 3], &ls);
    for k in [2, 7, 11] {
        images[k * 3..k * 3 + 3].iter_mut().for_each(|v| *v *= 0.3); // partial cast shadows
    }
    for k in [4, 15] {
        images[k * 3..k * 3 + 3].iter_mut().for_each(|v| *v += 0.8); // highlights
    }
    let error = |robust| {
        let out = fit_one(&images, &ls, robust);
        (
            (Vec3::from(out.normals[0]).dot(normal))
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees(),
            out.used[0],
        )
    };
    let (threshold, _) = error(Robust::Threshold);
    let (tukey, used) = error(Robust::Tukey);
    assert!(threshold > 2.0, "threshold fit {threshold}");
    assert!(tukey < 0.1, "Tukey fit {tukey}");
    assert_eq!(used, 19);
}

#[test]
fn trim_mode_keeps_the_middle_of_each_pixels_observations() {
    let ls = ring();
    let normal = Vec3::new(0.0, 0.1, 1.0).normalize();
    let mut images = render(normal, [0.5; 3], &ls);
    // The 5 brightest get highlights: exactly the 20 % the trim drops.
    let mut order: Vec<usize> = (0..24).collect();
    order.sort_by(|&a, &b| images[a * 3].total_cmp(&images[b * 3]));
    for &k in &order[19..] {
        images[k * 3..k * 3 + 3].iter_mut().for_each(|v| *v += 1.0);
    }
    let out = fit_one(&images, &ls, Robust::Trim);
    assert!((Vec3::from(out.normals[0]) - normal).length() < 1e-5);
    assert_eq!(out.used[0], 24 - 10 - 5);
}

#[test]
fn every_mode_fits_a_pixel_alike_whichever_other_pixels_the_mask_holds() {
    // 1500 pixels: several chunks and tiles of every mode; some shadowed or highlighted
    // observations; a mask with runs and gaps of every length. Each pixel fitted alone,
    // with every pixel and with some must come out the same.
    let (ls, pixels) = (ring(), 1500);
    let mut images = vec![0.0; ls.len() * pixels * 3];
    for p in 0..pixels {
        let (u, v) = ((p % 50) as f32 / 50.0 - 0.5, (p / 50) as f32 / 30.0 - 0.5);
        let observed = render(
            Vec3::new(u, v, 1.0).normalize(),
            [0.3 + 0.4 * u.abs(), 0.5, 0.7 - 0.3 * v.abs()],
            &ls,
        );
        for (k, rgb) in observed.chunks_exact(3).enumerate() {
            let factor = match (p * 7 + k * 13) % 17 {
                0 => 0.3,
                1 => 2.0,
                _ => 1.0,
            };
            for (c, value) in rgb.iter().enumerate() {
                images[(k * pixels + p) * 3 + c] = value * factor;
            }
        }
    }
    let every = vec![true; pixels];
    let some: Vec<bool> = (0..pixels)
        .map(|p| (p * p / 7 + p / 11) % 3 != 0 && !(600..700).contains(&p))
        .collect();
    for robust in [
        Robust::None,
        Robust::Threshold,
        Robust::Trim,
        Robust::Tukey,
        Robust::Lobe,
    ] {
        let settings = PsSettings {
            robust,
            ..Default::default()
        };
        let (all, part) = (
            photometric_stereo(&images, &every, &ls, &settings, None).unwrap(),
            photometric_stereo(&images, &some, &ls, &settings, None).unwrap(),
        );
        assert!(
            all.flags.iter().all(|&f| f != flag::MASKED_OUT),
            "{robust:?}"
        );
        for p in (0..pixels).step_by(97) {
            let alone: Vec<f32> = (0..ls.len())
                .flat_map(|k| images[(k * pixels + p) * 3..][..3].to_vec())
                .collect();
            let one = photometric_stereo(&alone, &[true], &ls, &settings, None).unwrap();
            assert_eq!(
                (one.normals[0], one.albedo[0], one.used[0]),
                (all.normals[p], all.albedo[p], all.used[p]),
                "{robust:?} pixel {p} alone"
            );
        }
        for (p, &kept) in some.iter().enumerate() {
            if kept {
                let bits = |out: &PsOutput| {
                    (
                        out.normals[p].map(f32::to_bits),
                        out.albedo[p].map(f32::to_bits),
                        out.flags[p],
                        out.used[p],
                    )
                };
                assert_eq!(bits(&part), bits(&all), "{robust:?} pixel {p}");
            } else {
                assert_eq!(
                    (part.normals[p], part.flags[p]),
                    ([0.0; 3], flag::MASKED_OUT),
                    "{robust:?} pixel {p}"
                );
            }
        }
    }
}

#[test]
fn too_few_or_coplanar_lights_are_errors() {
    let two = lights(&[[0.0, 0.0, 1.0], [0.5, 0.0, 0.8]]);
    assert!(check_lights(&two)
        .unwrap_err()
        .to_string()
        .contains("at least 3"));
    let coplanar = lights(&[
        [0.0, 0.0, 1.0],
        [0.5, 0.0, 0.8],
        [-0.5, 0.0, 0.8],
        [0.3, 0.0, 0.9],
    ]);
    assert!(check_lights(&coplanar)
        .unwrap_err()
        .to_string()
        .contains("coplanar"));
}

#[test]
fn dark_and_masked_pixels_are_flagged() {
    let ls = lights(&[[0.0, 0.0, 1.0], [0.5, 0.1, 0.8], [-0.3, 0.4, 0.8]]);
    let images = vec![0.0; 3 * 2 * 3];
    let out =
        photometric_stereo(&images, &[true, false], &ls, &PsSettings::default(), None).unwrap();
    assert_eq!(out.flags, vec![flag::DARK, flag::MASKED_OUT]);
}

#[test]
fn per_pixel_lights_fit_each_pixel_with_its_own() {
    // Three pixels, each under the same four lights seen from a different place: pixel p's
    // directions are the shared ones turned about z by p·40°, its irradiance scaled by 1 + p.
    let base = lights(&[
        [0.0, 0.0, 1.0],
        [0.5, 0.1, 0.8],
        [-0.3, 0.4, 0.8],
        [0.1, -0.5, 0.8],
    ]);
    let normals = [
        Vec3::new(0.1, -0.2, 1.0).normalize(),
        Vec3::new(-0.3, 0.1, 1.0).normalize(),
        Vec3::new(0.0, 0.3, 1.0).normalize(),
    ];
    let own: Vec<Vec<Light>> = (0..3)
        .map(|p| {
            let turn = glam::Mat3::from_rotation_z((40.0 * p as f32).to_radians());
            base.iter()
                .map(|l| Light {
                    direction: (turn * Vec3::from(l.direction)).into(),
                    irradiance: l.irradiance.map(|e| e * (1.0 + p as f32)),
                })
                .collect()
        })
        .collect();
    // Images (K, pixels, 3).
    let per_pixel: Vec<Vec<f32>> = (0..3)
        .map(|p| render(normals[p], [0.6, 0.5, 0.4], &own[p]))
        .collect();
    let mut images = vec![0.0; 4 * 3 * 3];
    for (p, values) in per_pixel.iter().enumerate() {
        for k in 0..4 {
            images[(k * 3 + p) * 3..][..3].copy_from_slice(&values[k * 3..][..3]);
        }
    }
    let all: Vec<Light> = own.concat();
    for robust in [Robust::None, Robust::Threshold, Robust::Tukey] {
        let settings = PsSettings {
            robust,
            ..Default::default()
        };
        let out = photometric_stereo_per_pixel(&images, &[true; 3], &all, &settings, None).unwrap();
        for (p, normal) in normals.iter().enumerate() {
            assert!(
                (Vec3::from(out.normals[p]) - *normal).length() < 1e-5,
                "{robust:?} pixel {p}: {:?}",
                out.normals[p]
            );
        }
    }
    // Lights that do not divide among the pixels, or coplanar at one pixel, are named.
    let settings = PsSettings::default();
    let error = photometric_stereo_per_pixel(&images, &[true; 3], &all[..11], &settings, None);
    assert!(error
        .unwrap_err()
        .to_string()
        .starts_with("lights: 11 lights for 3 pixels"));
    let mut flat = all.clone();
    for light in &mut flat[4..8] {
        light.direction = vec3a(1.0, 0.0, 0.0);
    }
    let error = photometric_stereo_per_pixel(&images, &[true; 3], &flat, &settings, None);
    assert!(error
        .unwrap_err()
        .to_string()
        .starts_with("lights at pixel 1: "));
}
