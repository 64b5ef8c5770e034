//! Tests of the tracer.

use super::*;
use crate::trace::mesh::SurfaceKind;
use glam::vec3a;

fn one_triangle() -> Mesh {
    Mesh {
        positions: vec![
            vec3a(0.0, 0.0, 0.0),
            vec3a(2.0, 0.0, 0.0),
            vec3a(0.0, 2.0, 0.0),
        ],
        albedo: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        triangles: vec![[0, 1, 2]],
        normals: vec![Vec3A::Z],
        kinds: vec![SurfaceKind::Object],
        panel_of: vec![crate::trace::mesh::NO_PANEL],
        ..Mesh::default()
    }
}

#[test]
fn barycentrics_weight_the_right_vertices() {
    let mesh = one_triangle();
    let tracer = Tracer::new(&mesh);
    let origin = vec3a(0.5, 0.25, 3.0);
    let hit = tracer
        .closest_hit(origin, -Vec3A::Z, f32::INFINITY)
        .expect("hit");
    assert!((hit.t - 3.0).abs() < 1e-6);
    let [a, b, c] = mesh.corners(0);
    let p = a * (1.0 - hit.u - hit.v) + b * hit.u + c * hit.v;
    assert!((p - vec3a(0.5, 0.25, 0.0)).length() < 1e-6, "{p:?}");
    let albedo = mesh.albedo_at(0, hit.u, hit.v);
    assert!((albedo[1] - 0.25).abs() < 1e-6 && (albedo[2] - 0.125).abs() < 1e-6);
}

#[test]
fn the_bounds_guard_is_never_hit() {
    let tracer = Tracer::new(&one_triangle());
    // The guard lies just beyond the maximum corner (2, 2, 0) of the triangle's bounds.
    let origin = vec3a(-1.0, -1.0, -1.0);
    let toward_guard = (vec3a(2.03, 2.03, 0.01) - origin).normalize();
    assert!(tracer
        .closest_hit(origin, toward_guard, f32::INFINITY)
        .is_none());
    assert!(!tracer.occluded(origin, toward_guard, f32::INFINITY));
}

#[test]
fn the_avx2_traversal_agrees_with_the_portable_one() {
    let scene = crate::scene::Scene {
        camera: crate::scene::Camera {
            width: 24,
            height: 24,
            pixel_size: 1.0,
            pinhole: None,
        },
        surface: crate::scene::HeightField {
            height: (0..576)
                .map(|p| ((p % 24) as f32 * 0.7).sin() * 3.0 + 5.0)
                .collect(),
            mask: vec![true; 576],
            albedo: vec![[0.5; 3]; 576],
        },
        floor: Some(crate::scene::Floor {
            height: 0.0,
            albedo: [0.5; 3],
        }),
        cornell_box: None,
        zero_height: 0.0,
    };
    // Through the height-field grid, and with the grid dropped, through the BVH.
    let mesh = Mesh::from_scene(&scene);
    let without_grid = Mesh {
        grid: None,
        ..mesh.clone()
    };
    for tracer in [Tracer::new(&mesh), Tracer::new(&without_grid)] {
        let mut rng = crate::sampler::Rng::new(9);
        for _ in 0..2000 {
            let origin = vec3a(
                rng.next_f32() * 24.0 - 12.0,
                rng.next_f32() * 24.0 - 12.0,
                9.0,
            );
            let direction =
                vec3a(rng.next_f32() - 0.5, rng.next_f32() - 0.5, -rng.next_f32()).normalize();
            assert_eq!(
                tracer.closest_hit(origin, direction, f32::INFINITY),
                tracer.closest_hit_portable(origin, direction, f32::INFINITY)
            );
            assert_eq!(
                tracer.occluded(origin, direction, f32::INFINITY),
                tracer.occluded_with::<false, true>(origin, direction, f32::INFINITY)
            );
        }
    }
}

#[test]
fn a_batch_gets_the_same_hits_as_one_ray_at_a_time() {
    let scene = crate::scene::Scene {
        camera: crate::scene::Camera {
            width: 20,
            height: 16,
            pixel_size: 0.5,
            pinhole: None,
        },
        surface: crate::scene::HeightField {
            height: (0..320)
                .map(|p| ((p % 20) as f32 * 0.5).cos() * 2.0 + (p / 20) as f32 * 0.2)
                .collect(),
            mask: (0..320).map(|p| p % 7 != 3).collect(),
            albedo: vec![[0.5; 3]; 320],
        },
        floor: Some(crate::scene::Floor {
            height: -1.0,
            albedo: [0.5; 3],
        }),
        cornell_box: Some(crate::scene::CornellBox {
            x: [-8.0, 8.0],
            y: [-7.0, 7.0],
            z_top: 9.0,
            left: [0.5; 3],
            right: [0.5; 3],
            back: [0.5; 3],
            front: [0.5; 3],
        }),
        zero_height: 0.0,
    };
    let tracer = Tracer::new(&Mesh::from_scene(&scene));
    let mut rng = crate::sampler::Rng::new(3);
    let rays: Vec<(Vec3A, Vec3A)> = (0..3000)
        .map(|_| {
            (
                vec3a(
                    rng.next_f32() * 12.0 - 6.0,
                    rng.next_f32() * 10.0 - 5.0,
                    rng.next_f32() * 8.0 - 1.0,
                ),
                vec3a(
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                )
                .normalize(),
            )
        })
        .collect();
    let mut batch = Vec::new();
    tracer.closest_hits(rays.iter().copied(), 20.0, |hit| batch.push(hit));
    let one_by_one: Vec<Option<Hit>> = rays
        .iter()
        .map(|&(o, d)| tracer.closest_hit(o, d, 20.0))
        .collect();
    assert_eq!(batch, one_by_one);
    assert!(
        batch.iter().filter(|h| h.is_some()).count() > 1500 && batch.iter().any(|h| h.is_none())
    );
}

#[test]
fn occlusion_respects_the_distance_limit() {
    let tracer = Tracer::new(&one_triangle());
    let origin = vec3a(0.5, 0.5, 1.0);
    assert!(tracer.occluded(origin, -Vec3A::Z, 2.0));
    assert!(!tracer.occluded(origin, -Vec3A::Z, 0.5));
    assert!(!tracer.occluded(origin, Vec3A::Z, f32::INFINITY));
    assert!(tracer
        .closest_hit(vec3a(3.0, 3.0, 1.0), -Vec3A::Z, f32::INFINITY)
        .is_none());
}

#[test]
fn an_environment_mesh_knows_which_of_its_vertices_its_own_shadow_covers() {
    use crate::scene::{Emitter, EnvironmentMesh, PointLight};
    use crate::trace::environment::{lit, EnvironmentAccel};
    // A floor triangle with a vertex under a square card; the light above the card.
    let mesh = EnvironmentMesh {
        positions: vec![
            vec3a(0.0, 0.0, 0.0),
            vec3a(10.0, 0.0, 0.0),
            vec3a(0.0, 10.0, 0.0),
            vec3a(-1.0, -1.5, 2.0),
            vec3a(1.5, -1.5, 2.0),
            vec3a(1.5, 1.0, 2.0),
            vec3a(-1.0, 1.0, 2.0),
        ],
        albedo: vec![[0.5; 3]; 7],
        triangles: vec![[0, 1, 2], [3, 4, 5], [3, 5, 6]],
    };
    let accel = EnvironmentAccel::new(mesh).unwrap();
    let light = |x: f32| {
        Emitter::Point(PointLight {
            position: vec3a(x, 0.0, 6.0),
            intensity: [1.0; 3],
        })
    };
    let above = accel.visibility(&[light(0.0), light(30.0)]).unwrap();
    // The vertex at the origin lies in the card's shadow of the light above it, not of the
    // one far aside; the floor's other corners and the card's own see both.
    for v in 0..7 {
        let expected = if accel.position(v) == Vec3A::ZERO {
            [0, 1]
        } else {
            [1, 1]
        };
        let seen = [0, 1].map(|k| lit(above.at_vertex(v), k));
        assert_eq!(seen, expected, "vertex {v}");
    }
    // Kept for the same lights, whatever their intensities; traced again for others.
    let brighter = Emitter::Point(PointLight {
        position: vec3a(0.0, 0.0, 6.0),
        intensity: [9.0; 3],
    });
    let again = accel.visibility(&[brighter, light(30.0)]).unwrap();
    assert!(std::sync::Arc::ptr_eq(&above, &again));
    let other = accel.visibility(&[light(30.0)]).unwrap();
    assert!((0..7).all(|v| lit(other.at_vertex(v), 0) == 1));
    // Only triangles no longer than the spacing (the card's two) read their corners.
    let read = (0..3).filter(|&t| accel.corner_visibility(&other, t, 4.0).is_some());
    assert_eq!(read.count(), 2);
}
