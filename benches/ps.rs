//! Photometric stereo throughput of each robust mode on a glossy sphere under 96 lights
//! (DiLiGenT's size of light set): attached shadows, soft cast shadows on a quarter of the
//! observations and a Blinn-Phong highlight, 128×128 pixels, every pixel on the object.
//!
//! Run with `cargo bench --bench ps`. The fits use rayon's pool (all cores).

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::{vec3a, Vec3};
use irtps::ps::{photometric_stereo, PsSettings, Robust};
use irtps::sampler::{hash, Rng};
use irtps::Light;

/// Side of the image in pixels.
const SIZE: usize = 128;
/// Number of lights.
const LIGHTS: usize = 96;

fn lights() -> Vec<Light> {
    (0..LIGHTS)
        .map(|k| {
            let (azimuth, elevation) = (
                k as f32 * 2.4,
                0.35 + 1.1 * (k as f32 + 0.5) / LIGHTS as f32,
            );
            let direction = vec3a(
                elevation.cos() * azimuth.cos(),
                elevation.cos() * azimuth.sin(),
                elevation.sin(),
            );
            Light {
                direction,
                irradiance: [1.0, 0.9, 0.8],
            }
        })
        .collect()
}

/// Images (K, pixels, 3) of a sphere seen from above, every pixel on it.
fn images(lights: &[Light]) -> Vec<f32> {
    let mut rng = Rng::new(hash(&[7]));
    let view = Vec3::Z;
    let mut out = vec![0.0; LIGHTS * SIZE * SIZE * 3];
    for p in 0..SIZE * SIZE {
        let (x, y) = (
            ((p % SIZE) as f32 + 0.5) / SIZE as f32 * 1.6 - 0.8,
            ((p / SIZE) as f32 + 0.5) / SIZE as f32 * 1.6 - 0.8,
        );
        let normal = Vec3::new(x, y, (1.0 - x * x - y * y).max(0.05).sqrt()).normalize();
        for (k, light) in lights.iter().enumerate() {
            let l = Vec3::from(light.direction);
            let cosine = normal.dot(l).max(0.0);
            let highlight = if cosine > 0.0 {
                0.5 * normal.dot((l + view).normalize()).max(0.0).powi(60)
            } else {
                0.0
            };
            let shadow = if rng.next_f32() < 0.25 {
                0.2 * rng.next_f32()
            } else {
                1.0
            };
            for c in 0..3 {
                out[(k * SIZE * SIZE + p) * 3 + c] =
                    shadow * (0.6 * cosine + highlight) * light.irradiance[c]
                        / std::f32::consts::PI;
            }
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    let lights = lights();
    let images = images(&lights);
    let mask = vec![true; SIZE * SIZE];
    let mut group = c.benchmark_group("photometric_stereo");
    group.throughput(Throughput::Elements((SIZE * SIZE) as u64));
    for (name, robust) in [
        ("none", Robust::None),
        ("threshold", Robust::Threshold),
        ("trim", Robust::Trim),
        ("tukey", Robust::Tukey),
    ] {
        let settings = PsSettings {
            robust,
            ..Default::default()
        };
        group.bench_function(name, |b| {
            b.iter(|| {
                black_box(photometric_stereo(&images, &mask, &lights, &settings, None).unwrap())
            })
        });
    }
    group.finish();
    // The lobe mode fits 16 candidate lobes per pixel: seconds per run, so fewer samples.
    let mut group = c.benchmark_group("photometric_stereo_lobe");
    group
        .throughput(Throughput::Elements((SIZE * SIZE) as u64))
        .sample_size(10);
    let settings = PsSettings {
        robust: Robust::Lobe,
        ..Default::default()
    };
    group.bench_function("lobe", |b| {
        b.iter(|| black_box(photometric_stereo(&images, &mask, &lights, &settings, None).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
