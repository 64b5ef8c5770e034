//! Tests of the height-field walk against testing every triangle.

use super::block::intersect_triangle;
use super::*;
use crate::sampler::Rng;
use crate::scene::{Camera, Floor, HeightField, Scene};
use crate::trace::mesh::Mesh;
use glam::vec3a;

/// A `w`×`h` field with a ragged mask (holes and islands), heights that cross the floor,
/// and steep steps, so that skirts of every side and height occur.
fn ragged_scene(w: usize, h: usize, seed: u64) -> Scene {
    let mut rng = Rng::new(seed);
    let n = w * h;
    let height = (0..n)
        .map(|p| {
            (((p % w) as f32 * 0.9).sin() * 4.0
                + ((p / w) as f32 * 0.6).cos() * 3.0
                + rng.next_f32() * 2.0)
                .max(-0.5)
                + 1.0
        })
        .collect();
    let mask = (0..n).map(|_| rng.next_f32() > 0.15).collect();
    Scene {
        camera: Camera {
            width: w,
            height: h,
            pixel_size: 0.7,
            pinhole: None,
        },
        surface: HeightField {
            height,
            mask,
            albedo: vec![[0.5; 3]; n],
        },
        floor: Some(Floor {
            height: 0.5,
            albedo: [0.5; 3],
        }),
        cornell_box: None,
        zero_height: 0.0,
    }
}

/// The nearest hit over every height-field and skirt triangle, one by one.
fn brute_force(mesh: &Mesh, ray: &GridRay<false>) -> Option<(usize, f32)> {
    let mut best: Option<(usize, f32)> = None;
    for t in 0..mesh.triangles.len() {
        if !matches!(
            mesh.kinds[t],
            crate::trace::mesh::SurfaceKind::Object | crate::trace::mesh::SurfaceKind::Skirt
        ) {
            continue;
        }
        if let Some((d, _, _)) =
            intersect_triangle(ray, &mesh.corners(t), best.map_or(f32::INFINITY, |b| b.1))
        {
            best = Some((t, d));
        }
    }
    best
}

/// A ray from a random point of a random object triangle (from its first corner, a
/// grid vertex, when `at_vertex`), `offset` off it along its normal, in a direction of
/// the upper hemisphere or a little below it.
fn ray_off_the_surface(
    mesh: &Mesh,
    object: &[usize],
    rng: &mut Rng,
    at_vertex: bool,
    offset: f32,
) -> (Vec3A, Vec3A) {
    let t = object[(rng.next_f32() * object.len() as f32) as usize % object.len()];
    let [a, b, c] = mesh.corners(t);
    let (u, v) = (rng.next_f32(), rng.next_f32());
    let (u, v) = if u + v > 1.0 {
        (1.0 - u, 1.0 - v)
    } else {
        (u, v)
    };
    let on_surface = if at_vertex {
        a
    } else {
        a + (b - a) * u + (c - a) * v
    };
    let direction = vec3a(
        rng.next_f32() * 2.0 - 1.0,
        rng.next_f32() * 2.0 - 1.0,
        rng.next_f32() * 1.6 - 0.3,
    )
    .normalize();
    (on_surface + mesh.normals[t] * offset, direction)
}

/// Asserts that both queries agree with testing every triangle; whether the ray hits.
fn assert_agrees(
    mesh: &Mesh,
    accel: &HeightFieldAccel,
    origin: Vec3A,
    direction: Vec3A,
    what: &str,
) -> bool {
    let expected = brute_force(mesh, &GridRay::<false>::new(accel, origin, direction));
    let got = accel.closest_hit::<false>(origin, direction, f32::INFINITY);
    assert_eq!(
        got.map(|g| (g.triangle, g.t)),
        expected,
        "ray {origin:?} {direction:?} in {what}"
    );
    assert_eq!(
        accel.closest_hit::<true>(origin, direction, f32::INFINITY),
        got,
        "fused walk, ray {origin:?} {direction:?} in {what}"
    );
    assert_eq!(
        accel.occluded::<false>(origin, direction, f32::INFINITY),
        expected.is_some(),
        "ray {origin:?} {direction:?} in {what}"
    );
    assert_eq!(
        accel.occluded::<true>(origin, direction, f32::INFINITY),
        expected.is_some(),
        "fused walk, ray {origin:?} {direction:?} in {what}"
    );
    expected.is_some()
}

#[test]
fn agrees_with_testing_every_triangle() {
    for (w, h, seed) in [(13, 9, 1), (32, 32, 2), (7, 20, 3), (2, 2, 4)] {
        let scene = ragged_scene(w, h, seed);
        let mesh = Mesh::from_scene(&scene);
        let accel = HeightFieldAccel::new(&mesh).expect("a height-field mesh has a grid");
        let mut rng = Rng::new(seed + 100);
        let (sx, sy) = (w as f32 * 0.7, h as f32 * 0.7);
        let (mut hits, mut skirt_hits) = (0, 0);
        for _ in 0..4000 {
            // From anywhere around the field toward a point in its box.
            let origin = vec3a(
                (rng.next_f32() - 0.5) * sx * 2.0,
                (rng.next_f32() - 0.5) * sy * 2.0,
                rng.next_f32() * 12.0 - 1.0,
            );
            let target = vec3a(
                (rng.next_f32() - 0.5) * sx,
                (rng.next_f32() - 0.5) * sy,
                rng.next_f32() * 8.0,
            );
            let direction = (target - origin).normalize();
            let ray = GridRay::<false>::new(&accel, origin, direction);
            let expected = brute_force(&mesh, &ray);
            let got = accel.closest_hit::<false>(origin, direction, f32::INFINITY);
            assert_eq!(
                got.map(|g| (g.triangle, g.t)),
                expected,
                "ray {origin:?} {direction:?} in {w}x{h}"
            );
            assert_eq!(
                accel.closest_hit::<true>(origin, direction, f32::INFINITY),
                got,
                "fused walk, ray {origin:?} {direction:?} in {w}x{h}"
            );
            assert_eq!(
                accel.occluded::<false>(origin, direction, f32::INFINITY),
                expected.is_some()
            );
            assert_eq!(
                accel.occluded::<true>(origin, direction, f32::INFINITY),
                expected.is_some()
            );
            if let Some((t, d)) = expected {
                hits += 1;
                skirt_hits += usize::from(mesh.kinds[t] == crate::trace::mesh::SurfaceKind::Skirt);
                assert!(
                    !accel.occluded::<false>(origin, direction, d * 0.999)
                        && !accel.occluded::<true>(origin, direction, d * 0.999)
                );
            }
        }
        assert!(
            hits > 1500 && skirt_hits > 200,
            "{w}x{h}: {hits} hits, {skirt_hits} on the skirt"
        );
    }
}

/// Rays as a renderer casts them: from points on the surface (inside triangles and at
/// vertices, where four blocks meet), just off it, in every direction of the upper
/// hemisphere and some below it.
#[test]
fn rays_leaving_the_surface_agree_with_testing_every_triangle() {
    for (w, h, seed) in [(24, 19, 11), (40, 40, 12)] {
        let scene = ragged_scene(w, h, seed);
        let mesh = Mesh::from_scene(&scene);
        let accel = HeightFieldAccel::new(&mesh).expect("a height-field mesh has a grid");
        let object: Vec<usize> = (0..mesh.triangles.len())
            .filter(|&t| mesh.kinds[t] == crate::trace::mesh::SurfaceKind::Object)
            .collect();
        let mut rng = Rng::new(seed);
        let mut hits = 0;
        for k in 0..6000 {
            // Every third ray starts at a vertex of the grid.
            let (origin, direction) =
                ray_off_the_surface(&mesh, &object, &mut rng, k % 3 == 0, 1e-3);
            hits += usize::from(assert_agrees(
                &mesh,
                &accel,
                origin,
                direction,
                &format!("{w}x{h}"),
            ));
        }
        assert!(hits > 1000, "{w}x{h}: only {hits} hits");
    }
}

/// Steep ramps (steeper than a band's planes may be), spikes and flat steps, at pixel
/// sizes far from 1 and heights far from 0: the bands' slopes, offsets and rounding
/// allowance must hold at every scale. (Heights of 5 over a field 0.02 wide caught the
/// blocks' height test losing a hit 1.7e-6 away when it compared distances instead of
/// heights.)
#[test]
fn steep_and_scaled_fields_agree_with_testing_every_triangle() {
    for (w, h, pixel_size, lift, seed) in [
        (37, 29, 0.013f32, 0.0f32, 21u64),
        (33, 41, 3.7, 900.0, 22),
        (64, 16, 1.0, -40.0, 23),
        (20, 20, 1e-3, 5.0, 54),
        (30, 25, 250.0, -3e4, 55),
    ] {
        let mut scene = ragged_scene(w, h, seed);
        scene.camera.pixel_size = pixel_size;
        let mut rng = Rng::new(seed);
        for (p, z) in scene.surface.height.iter_mut().enumerate() {
            let (i, j) = ((p / w) as f32, (p % w) as f32);
            let ramp = if j < w as f32 / 2.0 {
                15.0 * j
            } else {
                4.0 * (i * 0.8).sin()
            };
            let spike = if rng.next_f32() < 0.03 { 25.0 } else { 0.0 };
            *z = (ramp + spike + (i * 0.3).floor() * 3.0) * pixel_size + lift;
        }
        if let Some(floor) = scene.floor.as_mut() {
            floor.height = lift;
        }
        let mesh = Mesh::from_scene(&scene);
        let accel = HeightFieldAccel::new(&mesh).expect("a height-field mesh has a grid");
        let object: Vec<usize> = (0..mesh.triangles.len())
            .filter(|&t| mesh.kinds[t] == crate::trace::mesh::SurfaceKind::Object)
            .collect();
        let (lo, hi) = accel.bounds();
        let span = hi - lo;
        let mut hits = 0;
        for k in 0..5000 {
            let (origin, direction) = if k % 2 == 0 {
                ray_off_the_surface(&mesh, &object, &mut rng, k % 6 == 0, 1e-3 * pixel_size)
            } else {
                // From around the field's box toward a point inside it.
                let mut around = |k: usize| lo[k] - span[k] + rng.next_f32() * 3.0 * span[k];
                let origin = vec3a(around(0), around(1), around(2));
                let target = lo + span * vec3a(rng.next_f32(), rng.next_f32(), rng.next_f32());
                (origin, (target - origin).normalize())
            };
            hits += usize::from(assert_agrees(
                &mesh,
                &accel,
                origin,
                direction,
                &format!("{w}x{h} at pixel size {pixel_size}"),
            ));
        }
        assert!(hits > 1500, "{w}x{h}: only {hits} hits");
    }
}

/// Rays rising from a flat field toward a far spike, under and just over its tip:
/// the escape cones must let the ones that clear it skip the walk and none that meet it.
#[test]
fn rays_rising_past_a_far_spike_agree_with_testing_every_triangle() {
    let (w, h) = (40, 40);
    let mut scene = ragged_scene(w, h, 6);
    scene.surface.mask = vec![true; w * h];
    scene.surface.height = (0..w * h)
        .map(|p| {
            if (p / w, p % w) == (30, 31) {
                20.0
            } else {
                1.0
            }
        })
        .collect();
    let mesh = Mesh::from_scene(&scene);
    let accel = HeightFieldAccel::new(&mesh).expect("grid");
    let g = mesh.grid.as_ref().expect("grid");
    let top = vec3a(g.xs[31], g.ys[30], 20.0);
    let mut rng = Rng::new(8);
    let (mut hits, mut misses) = (0, 0);
    for _ in 0..3000 {
        let origin = vec3a(
            g.xs[3] + rng.next_f32() * 6.0 * 0.7,
            g.ys[4] - rng.next_f32() * 6.0 * 0.7,
            1.0 + 1e-3,
        );
        let aim = top
            + vec3a(
                (rng.next_f32() - 0.5) * 0.6,
                (rng.next_f32() - 0.5) * 0.6,
                0.5 - rng.next_f32() * 5.0,
            );
        let hit = assert_agrees(
            &mesh,
            &accel,
            origin,
            (aim - origin).normalize(),
            "the spike field",
        );
        (hits, misses) = if hit {
            (hits + 1, misses)
        } else {
            (hits, misses + 1)
        };
    }
    assert!(hits > 300 && misses > 300, "{hits} hits, {misses} misses");
}

#[test]
fn rays_along_block_boundaries_hit() {
    let scene = ragged_scene(16, 16, 5);
    let mut scene = scene;
    scene.surface.mask = vec![true; 256];
    let mesh = Mesh::from_scene(&scene);
    let accel = HeightFieldAccel::new(&mesh).expect("grid");
    let g = mesh.grid.as_ref().expect("grid");
    // Straight down through every vertex and every edge midpoint: always the surface.
    for i in 0..16 {
        for j in 0..16 {
            for (x, y) in [
                (g.xs[j], g.ys[i]),
                (g.xs[j], g.ys[i] - 0.35),
                (g.xs[j] + 0.35, g.ys[i]),
            ] {
                let hit = accel.closest_hit::<false>(vec3a(x, y, 50.0), -Vec3A::Z, f32::INFINITY);
                // Through a vertex or an edge, the fused walk may meet another of the
                // triangles there first: the same point, to their rounding.
                let fused = accel.closest_hit::<true>(vec3a(x, y, 50.0), -Vec3A::Z, f32::INFINITY);
                assert_eq!(fused.is_some(), hit.is_some(), "({x}, {y})");
                if let (Some(a), Some(b)) = (fused, hit) {
                    assert!((a.t - b.t).abs() <= 1e-5 * b.t, "({x}, {y}): {a:?} {b:?}");
                }
                let inside = x <= g.xs[15] && y >= g.ys[15];
                assert_eq!(hit.is_some(), inside, "({x}, {y})");
            }
        }
    }
}
