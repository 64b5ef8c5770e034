//! BVH build time and ray-query throughput of `irtps::Tracer` on a 512×512 height field in a
//! Cornell box with a floor (about 0.65 M triangles).
//!
//! Run with `cargo bench --bench bvh`. Ray queries run on one thread, so the reported
//! throughput is rays per second per thread; the build uses rayon's pool (all cores). Rays
//! leave random pixels (incoherent), and in `closest_hit_pixel_order` the same rays are
//! sorted by origin pixel, as a render traces them.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, SamplingMode, Throughput};
use glam::Vec3A;
use irtps::sampler::{cosine_hemisphere, hash, Rng};
use irtps::{Camera, CornellBox, Floor, HeightField, Mesh, Scene, Tracer};

/// Side of the height field in pixels (pixel size 1).
const SIZE: usize = 512;
/// Rays per benchmark iteration.
const RAYS: usize = 100_000;
/// Offset of ray origins along the surface normal.
const OFFSET: f32 = 1e-3;

/// Height of pixel (`i`, `j`) of an `n`×`n` field: a base level, a few sinusoids and a
/// spherical cap in the middle (the same relief as `embree_compare.py`).
fn relief(i: usize, j: usize, n: usize) -> f32 {
    let scale = n as f32 / 512.0;
    let (u, v) = (j as f32 / n as f32, i as f32 / n as f32);
    let tau = std::f32::consts::TAU;
    let waves = 6.0 * (tau * 3.0 * u).sin() * (tau * 2.0 * v).cos()
        + 4.0 * (tau * (5.0 * u + 4.0 * v)).sin()
        + 3.0 * (tau * 7.0 * v).cos();
    let (dx, dy) = (
        j as f32 + 0.5 - n as f32 / 2.0,
        i as f32 + 0.5 - n as f32 / 2.0,
    );
    let r2 = dx * dx + dy * dy;
    let (sphere, cap) = (200.0 * scale, 150.0 * scale);
    let bump = if r2 < cap * cap {
        (sphere * sphere - r2).sqrt() - (sphere * sphere - cap * cap).sqrt()
    } else {
        0.0
    };
    (40.0 + waves) * scale + bump
}

/// The benchmark scene: an all-masked `n`×`n` height field on a floor at z = 0 inside an
/// open-topped Cornell box reaching an eighth of the field beyond it on each side.
fn scene(n: usize) -> Scene {
    let height: Vec<f32> = (0..n * n).map(|p| relief(p / n, p % n, n)).collect();
    let albedo = (0..n * n)
        .map(|p| {
            [
                0.5 + 0.3 * (p % n) as f32 / n as f32,
                0.6,
                0.7 - 0.3 * (p / n) as f32 / n as f32,
            ]
        })
        .collect();
    let half = 0.5 * n as f32 + 0.125 * n as f32;
    Scene {
        camera: Camera {
            width: n,
            height: n,
            pixel_size: 1.0,
            pinhole: None,
        },
        surface: HeightField {
            height,
            mask: vec![true; n * n],
            albedo,
        },
        floor: Some(Floor {
            height: 0.0,
            albedo: [0.8, 0.8, 0.8],
        }),
        cornell_box: Some(CornellBox {
            x: [-half, half],
            y: [-half, half],
            z_top: 0.5 * n as f32,
            left: [0.8, 0.1, 0.1],
            right: [0.1, 0.8, 0.1],
            back: [0.7, 0.7, 0.7],
            front: [0.7, 0.7, 0.7],
        }),
        zero_height: 0.0,
    }
}

/// `count` cosine-distributed rays leaving random pixel vertices of the height field, offset
/// along their vertex normals.
fn rays(mesh: &Mesh, count: usize, seed: u64) -> Vec<(Vec3A, Vec3A)> {
    let pixels = mesh.pixel_vertex.len() as u64;
    (0..count as u64)
        .map(|k| {
            let mut rng = Rng::new(hash(&[seed, k]));
            let vertex = mesh.pixel_vertex[(hash(&[seed, k, 1]) % pixels) as usize] as usize;
            let n = mesh.vertex_normals[vertex];
            let origin = mesh.positions[vertex] + n * OFFSET;
            (origin, cosine_hemisphere(rng.next_f32(), rng.next_f32(), n))
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let scene = scene(SIZE);
    let mesh = Mesh::from_scene(&scene);
    let tracer = Tracer::new(&mesh);
    let batch = rays(&mesh, RAYS, 7);
    let hits = batch
        .iter()
        .filter(|(o, d)| tracer.closest_hit(*o, *d, f32::INFINITY).is_some())
        .count();
    eprintln!(
        "scene: {SIZE}x{SIZE} height field in a Cornell box, {} triangles; {RAYS} rays per iteration, {:.1}% hit",
        mesh.triangles.len(),
        100.0 * hits as f64 / RAYS as f64
    );

    let mut build = c.benchmark_group("bvh_build");
    build
        .sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(8));
    build.throughput(Throughput::Elements(mesh.triangles.len() as u64));
    build.bench_function("tracer_new", |b| b.iter(|| Tracer::new(black_box(&mesh))));
    build.finish();

    // The same rays sorted by origin pixel (row-major), as a render traces them.
    let mut sorted = batch.clone();
    sorted.sort_by(|a, b| (-a.0.y, a.0.x).partial_cmp(&(-b.0.y, b.0.x)).unwrap());

    let mut trace = c.benchmark_group("trace_1_thread");
    trace
        .sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5));
    trace.throughput(Throughput::Elements(RAYS as u64));
    for (name, rays) in [
        ("closest_hit", &batch),
        ("closest_hit_pixel_order", &sorted),
    ] {
        trace.bench_function(name, |b| {
            b.iter(|| {
                let mut hits = 0usize;
                for &(o, d) in rays {
                    hits += tracer
                        .closest_hit(black_box(o), black_box(d), f32::INFINITY)
                        .is_some() as usize;
                }
                hits
            })
        });
    }
    trace.bench_function("occluded", |b| {
        b.iter(|| {
            let mut blocked = 0usize;
            for &(o, d) in &batch {
                blocked += tracer.occluded(black_box(o), black_box(d), f32::INFINITY) as usize;
            }
            blocked
        })
    });
    trace.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
