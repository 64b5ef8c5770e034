//! Tests of the renderer.

use super::*;
use crate::scene::{Emitter, HeightField, Pinhole, PointLight};
use crate::trace::environment::EnvironmentAccel;
use glam::vec3a;
use std::f32::consts::PI;

fn tilted_plate(size: usize, albedo: Rgb) -> Scene {
    let height = (0..size * size)
        .map(|p| 0.25 * (p % size) as f32 + 3.0)
        .collect();
    object_alone(
        Camera {
            width: size,
            height: size,
            pixel_size: 1.0,
            pinhole: None,
        },
        height,
        albedo,
    )
}

/// The object of heights `height` and a uniform `albedo`, every pixel masked, alone.
fn object_alone(camera: Camera, height: Vec<f32>, albedo: Rgb) -> Scene {
    let pixels = camera.pixel_count();
    Scene {
        camera,
        surface: HeightField {
            height,
            mask: vec![true; pixels],
            albedo: vec![albedo; pixels],
        },
        floor: None,
        cornell_box: None,
        zero_height: 0.0,
    }
}

#[test]
fn direct_light_on_an_unshadowed_plane_is_lamberts_law() {
    let albedo = [0.8, 0.5, 0.25];
    let light = Light {
        direction: vec3a(-0.3, 0.2, 0.9).normalize(),
        irradiance: [PI, 2.0, 1.0],
    };
    let renderer = Renderer::new(&tilted_plate(8, albedo), &[light]).unwrap();
    let settings = RenderSettings {
        bounces: 0,
        samples: 0,
        direct_samples: 9,
        seed: 0,
        split_bounces: true,
        cached_direct: false,
    };
    let image = renderer.render_rows(0..8, &settings).unwrap();
    let cosine = vec3a(-0.25, 0.0, 1.0).normalize().dot(light.direction);
    for (row, col) in [(1, 1), (4, 5), (6, 2)] {
        for c in 0..3 {
            let expected = albedo[c] * light.irradiance[c] * cosine / PI;
            let got = image[(row * 8 + col) * 3 + c];
            assert!(
                (got - expected).abs() <= 1e-6 * expected,
                "{got} vs {expected}"
            );
        }
    }
}

#[test]
fn direct_light_from_the_cache_with_traced_shadow_edges_matches_the_traced_one() {
    let mut scene = tilted_plate(8, [0.6, 0.5, 0.4]);
    scene.surface.height[27] += 6.0; // a spike that shadows the plate's lower side
    let light = Light {
        direction: vec3a(0.6, 0.0, 0.8),
        irradiance: [PI; 3],
    };
    let renderer = Renderer::new(&scene, &[light]).unwrap();
    let traced = RenderSettings {
        bounces: 0,
        samples: 0,
        direct_samples: 16,
        seed: 1,
        split_bounces: true,
        cached_direct: false,
    };
    let cached = RenderSettings {
        cached_direct: true,
        ..traced
    };
    let (exact, interpolated) = (
        renderer.render_rows(0..8, &traced).unwrap(),
        renderer.render_rows(0..8, &cached).unwrap(),
    );
    for (i, (e, c)) in exact.iter().zip(&interpolated).enumerate() {
        assert!(
            (e - c).abs() <= 1e-5 * e.max(1e-3),
            "pixel {}: {e} vs {c}",
            i / 3
        );
    }
    // The spike at (3, 3) shadows (3, 1) on its side away from the light.
    assert!(exact[(3 * 8 + 1) * 3] < 0.5 * exact[(3 * 8 + 6) * 3]);
}

#[test]
fn a_convex_object_alone_has_no_inter_reflection() {
    let light = Light {
        direction: Vec3A::Z,
        irradiance: [PI; 3],
    };
    let renderer = Renderer::new(&tilted_plate(8, [0.9; 3]), &[light]).unwrap();
    let settings = RenderSettings {
        bounces: 2,
        samples: 16,
        direct_samples: 1,
        seed: 0,
        split_bounces: true,
        cached_direct: false,
    };
    let image = renderer.render_rows(0..8, &settings).unwrap();
    let plane = 8 * 8 * 3;
    assert!(image[..plane].iter().any(|&v| v > 0.0));
    assert!(image[plane..].iter().all(|&v| v == 0.0));
}

#[test]
fn summed_bounces_equal_the_split_ones_added() {
    let mut scene = tilted_plate(8, [0.7; 3]);
    scene.floor = Some(crate::scene::Floor {
        height: 0.0,
        albedo: [0.5; 3],
    });
    let light = Light {
        direction: vec3a(0.3, 0.1, 0.9).normalize(),
        irradiance: [PI; 3],
    };
    let renderer = Renderer::new(&scene, &[light]).unwrap();
    let split = RenderSettings {
        bounces: 3,
        samples: 8,
        direct_samples: 0,
        seed: 2,
        split_bounces: true,
        cached_direct: false,
    };
    let summed = RenderSettings {
        split_bounces: false,
        ..split
    };
    assert_eq!((split.planes(), summed.planes()), (3, 1));
    let per_bounce = renderer.render_rows(0..8, &split).unwrap();
    let total = renderer.render_rows(0..8, &summed).unwrap();
    let plane = total.len();
    for (i, &t) in total.iter().enumerate() {
        let expected: f32 = (0..3).map(|b| per_bounce[b * plane + i]).sum();
        assert!(
            (t - expected).abs() <= 1e-6 * expected.max(1e-3),
            "{t} vs {expected}"
        );
    }
    assert!(total.iter().any(|&v| v > 0.0));
}

#[test]
fn new_reflectance_renders_as_a_renderer_built_with_it() {
    // A plate with a spike (skirt walls, shadows) on a floor: bounces and cached direct light.
    let mut scene = tilted_plate(8, [0.3; 3]);
    scene.surface.height[27] += 6.0;
    scene.floor = Some(crate::scene::Floor {
        height: -2.0,
        albedo: [0.5; 3],
    });
    let lights = [vec3a(0.6, 0.0, 0.8), vec3a(0.0, -0.6, 0.8)].map(|direction| Light {
        direction,
        irradiance: [PI; 3],
    });
    let albedo: Vec<Rgb> = (0..64).map(|p| [0.1 + 0.01 * p as f32, 0.9, 0.4]).collect();
    let irradiance = [[1.0, 2.0, 3.0], [0.5, 0.5, 0.5]];
    let renderer = Renderer::new(&scene, &lights)
        .unwrap()
        .with_reflectance(&albedo, &irradiance)
        .unwrap();
    scene.surface.albedo = albedo.clone();
    let built = Renderer::new(
        &scene,
        &lights.map(|l| Light {
            irradiance: if l.direction.x > 0.0 {
                irradiance[0]
            } else {
                irradiance[1]
            },
            ..l
        }),
    )
    .unwrap();
    let settings = RenderSettings {
        bounces: 2,
        samples: 4,
        direct_samples: 4,
        seed: 3,
        split_bounces: false,
        cached_direct: true,
    };
    let pixels: Vec<usize> = (0..64).collect();
    assert_eq!(
        renderer.render_pixels(&pixels, &settings).unwrap(),
        built.render_pixels(&pixels, &settings).unwrap()
    );
    let too_bright = vec![[1.5; 3]; 64];
    let error = |result: Result<Renderer>| result.err().map(|e| e.to_string()).unwrap_or_default();
    assert!(
        error(renderer.with_reflectance(&too_bright, &irradiance)).starts_with("albedo at pixel")
    );
    assert!(error(renderer.with_reflectance(&albedo, &irradiance[..1])).starts_with("irradiance"));
}

/// `scene` at `scale` times its size, its heights raised by `lift` pixel sizes.
fn scaled(scene: &Scene, scale: f32, lift: f32) -> Scene {
    let s = scene.camera.pixel_size * scale;
    let z = |h: f32| h * scale + lift * s;
    let mut out = scene.clone();
    out.camera.pixel_size = s;
    out.surface.height = scene.surface.height.iter().map(|&h| z(h)).collect();
    out.floor = scene.floor.map(|f| crate::scene::Floor {
        height: z(f.height),
        ..f
    });
    out.cornell_box = scene.cornell_box.map(|b| crate::scene::CornellBox {
        x: b.x.map(|v| v * scale),
        y: b.y.map(|v| v * scale),
        z_top: z(b.z_top),
        ..b
    });
    out
}

#[test]
fn direct_light_does_not_depend_on_the_scenes_scale_or_height() {
    // A shadowing spike on a plate, in a Cornell box: object, skirt, floor and walls.
    let mut scene = tilted_plate(8, [0.6, 0.5, 0.4]);
    scene.surface.height[27] += 6.0;
    scene.floor = Some(crate::scene::Floor {
        height: 1.0,
        albedo: [0.5; 3],
    });
    scene.cornell_box = Some(crate::scene::CornellBox {
        x: [-30.0, 30.0],
        y: [-30.0, 30.0],
        z_top: 12.0,
        left: [0.8, 0.2, 0.2],
        right: [0.2, 0.8, 0.2],
        back: [0.6; 3],
        front: [0.6; 3],
    });
    let light = Light {
        direction: vec3a(0.6, 0.0, 0.8),
        irradiance: [PI; 3],
    };
    let traced = RenderSettings {
        bounces: 0,
        samples: 0,
        direct_samples: 4,
        seed: 5,
        split_bounces: true,
        cached_direct: false,
    };
    let render = |scene: &Scene, settings: &RenderSettings| {
        Renderer::new(scene, &[light])
            .unwrap()
            .render_rows(0..8, settings)
            .unwrap()
    };
    for settings in [
        traced,
        RenderSettings {
            cached_direct: true,
            ..traced
        },
    ] {
        let truth = render(&scene, &settings);
        assert!(truth.iter().filter(|&&v| v > 0.0).count() > truth.len() / 2);
        // Heights 10^6 pixel sizes up are exact in float32 at power-of-two scales only
        // (elsewhere rounded to 1/16 pixel size): a lift of 10^3 for the others.
        for (scale, lift) in [
            (1e-9, 0.0),
            (1e-3, 0.0),
            (1e3, 0.0),
            (1e7, 0.0),
            (1e9, 0.0),
            (1e-9, 1e3),
            (1e9, -1e3),
            (1.0, 1e6),
            (2f32.powi(30), -1e6),
        ] {
            let image = render(&scaled(&scene, scale, lift), &settings);
            let worst = image
                .iter()
                .zip(&truth)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(worst <= 1e-4, "scale {scale:e}, lift {lift:e}: {worst}");
        }
    }
}

#[test]
fn geometry_float32_cannot_resolve_is_refused_by_name() {
    let light = Light {
        direction: Vec3A::Z,
        irradiance: [PI; 3],
    };
    let mut scene = tilted_plate(4, [0.5; 3]);
    scene.floor = Some(crate::scene::Floor {
        height: -2e7,
        albedo: [0.5; 3],
    });
    let error = Renderer::new(&scene, &[light])
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(error.starts_with("floor.height"), "{error}");
    scene.floor = None;
    scene.surface.height[5] = 3e7;
    let error = Renderer::new(&scene, &[light])
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        error.starts_with("height") && error.contains("at pixel (row"),
        "{error}"
    );
}

#[test]
fn rows_out_of_range_are_an_error_naming_rows() {
    let light = Light {
        direction: Vec3A::Z,
        irradiance: [PI; 3],
    };
    let renderer = Renderer::new(&tilted_plate(4, [0.5; 3]), &[light]).unwrap();
    let settings = RenderSettings {
        bounces: 1,
        samples: 1,
        direct_samples: 1,
        seed: 0,
        split_bounces: true,
        cached_direct: false,
    };
    assert!(renderer
        .render_rows(2..9, &settings)
        .unwrap_err()
        .to_string()
        .starts_with("rows"));
}

/// The plane `z = slope · x + 2` seen through a pinhole 40 units above it: each pixel's
/// height is where its centre ray meets the plane, so every vertex lies on it.
fn plane_through_a_pinhole(size: usize, slope: f32, albedo: Rgb) -> Scene {
    let pinhole = Pinhole {
        fx: 30.0,
        fy: 32.0,
        cx: size as f32 / 2.0 + 0.7,
        cy: size as f32 / 2.0 - 0.4,
        center_z: 40.0,
    };
    let height = (0..size * size)
        .map(|p| {
            // z = slope · k (zc − z) + 2 with x = k (zc − z) along the ray.
            let k = ((p % size) as f32 + 0.5 - pinhole.cx) / pinhole.fx;
            (slope * k * pinhole.center_z + 2.0) / (1.0 + slope * k)
        })
        .collect();
    object_alone(
        Camera {
            width: size,
            height: size,
            pixel_size: (pinhole.center_z - 2.0) / pinhole.fx,
            pinhole: Some(pinhole),
        },
        height,
        albedo,
    )
}

#[test]
fn a_pinhole_sees_the_object_where_its_rays_meet_the_surface() {
    let slope = 0.4;
    let scene = plane_through_a_pinhole(9, slope, [0.5; 3]);
    let light = Light {
        direction: Vec3A::Z,
        irradiance: [1.0; 3],
    };
    let renderer = Renderer::new(&scene, &[light]).unwrap();
    let (camera, frame) = (renderer.camera(), renderer.frame());
    for (row, col) in [(1.3, 1.6), (4.5, 5.2), (7.1, 2.9), (6.8, 7.4)] {
        let (origin, dir) = camera.ray(row, col, 0.0);
        let hit = renderer
            .tracer()
            .closest_hit(origin, dir, f32::INFINITY)
            .unwrap();
        let seen = frame.to_world(origin + dir * hit.t);
        // On the plane, and on the ray through (row, col) of the world camera.
        assert!((seen.z - (slope * seen.x + 2.0)).abs() <= 1e-4, "{seen:?}");
        let (x, y) = scene.camera.image_to_world(row, col, seen.z);
        assert!(
            (x - seen.x).abs().max((y - seen.y).abs()) <= 1e-4,
            "{seen:?} vs ({x}, {y})"
        );
    }
}

#[test]
fn direct_light_on_a_tilted_plane_seen_through_a_pinhole_is_lamberts_law() {
    let (slope, albedo) = (0.4, [0.8, 0.5, 0.25]);
    let scene = plane_through_a_pinhole(8, slope, albedo);
    let light = Light {
        direction: vec3a(-0.3, 0.2, 0.9).normalize(),
        irradiance: [PI, 2.0, 1.0],
    };
    let renderer = Renderer::new(&scene, &[light]).unwrap();
    let settings = RenderSettings {
        bounces: 0,
        samples: 0,
        direct_samples: 16,
        seed: 0,
        split_bounces: true,
        cached_direct: false,
    };
    let image = renderer.render_rows(0..8, &settings).unwrap();
    let cosine = vec3a(-slope, 0.0, 1.0).normalize().dot(light.direction);
    // Pixels whose footprint lies inside the mesh (between the outer pixel centres).
    for (row, col) in [(1, 1), (3, 5), (6, 2), (5, 6)] {
        for c in 0..3 {
            let expected = albedo[c] * light.irradiance[c] * cosine / PI;
            let got = image[(row * 8 + col) * 3 + c];
            assert!(
                (got - expected).abs() <= 1e-4 * expected,
                "pixel ({row}, {col}): {got} vs {expected}"
            );
        }
    }
}

/// The direct image alone, 256 stratified footprint samples a pixel (within 0.5 % of the
/// footprint's mean of the steep irradiance of a near light), real shadow rays.
fn centre_direct() -> RenderSettings {
    RenderSettings {
        bounces: 0,
        samples: 0,
        direct_samples: 256,
        seed: 0,
        split_bounces: true,
        cached_direct: false,
    }
}

/// An orthographic camera of `size` × `size` pixels.
fn level_camera(size: usize, pixel_size: f32) -> Camera {
    Camera {
        width: size,
        height: size,
        pixel_size,
        pinhole: None,
    }
}

/// ρ I cos θ / (π r²) under a point light, averaged over the footprint of pixel (`row`,
/// `col`) of a level surface at height `z` (a 16 × 16 grid of points).
fn point_radiance(
    albedo: Rgb,
    light: &PointLight,
    camera: &Camera,
    (row, col): (usize, usize),
    z: f32,
    c: usize,
) -> f32 {
    let mut sum = 0.0;
    for i in 0..16 {
        for j in 0..16 {
            let (x, y) = camera.image_to_world(
                row as f32 + (i as f32 + 0.5) / 16.0,
                col as f32 + (j as f32 + 0.5) / 16.0,
                z,
            );
            let offset = light.position - vec3a(x, y, z);
            let r2 = offset.length_squared();
            sum += albedo[c] * light.intensity[c] * offset.z.max(0.0) / r2.sqrt() / (PI * r2);
        }
    }
    sum / 256.0
}

#[test]
fn a_point_light_falls_off_with_the_square_of_the_distance_in_world_units() {
    // A level plate of pixel size 0.5: the working frame's unit is 2 world units, so the
    // intensity must be rescaled for the inverse-square law to hold in world units.
    let (size, camera) = (16, level_camera(16, 0.5));
    let albedo = [0.5, 0.6, 0.7];
    let scene = object_alone(camera, vec![0.0; size * size], albedo);
    let light = PointLight {
        position: vec3a(1.0, -2.0, 6.0),
        intensity: [10.0, 20.0, 30.0],
    };
    let renderer = Renderer::with_emitters(&scene, &[Emitter::Point(light)]).unwrap();
    let image = renderer.render_rows(0..size, &centre_direct()).unwrap();
    let brighter = renderer
        .with_reflectance(&vec![albedo; size * size], &[[20.0, 40.0, 60.0]])
        .unwrap()
        .render_rows(0..size, &centre_direct())
        .unwrap();
    // Interior pixels: the surface runs between pixel centres, so the outer half pixel of
    // the image holds none of it.
    for (row, col) in [(1, 1), (5, 9), (12, 3), (14, 14)] {
        for c in 0..3 {
            let expected = point_radiance(albedo, &light, &camera, (row, col), 0.0, c);
            let got = image[(row * size + col) * 3 + c];
            assert!(
                (got - expected).abs() <= 5e-3 * expected,
                "{got} vs {expected}"
            );
            let doubled = brighter[(row * size + col) * 3 + c];
            assert!(
                (doubled - 2.0 * got).abs() <= 1e-5 * got,
                "{doubled} vs 2 x {got}"
            );
        }
    }
}

#[test]
fn a_point_light_is_shadowed_only_by_what_stands_between_it_and_the_surface() {
    // A plate with a tall wall on its right (columns 12 on) and a point light left of the
    // wall, below its top: the shadow rays toward the light would hit the wall beyond it,
    // and must stop at the light. A spike between a pixel and the light shadows it.
    let (size, camera) = (16, level_camera(16, 1.0));
    let mut height: Vec<f32> = (0..size * size)
        .map(|p| if p % size >= 12 { 40.0 } else { 0.0 })
        .collect();
    height[4 * size + 5] = 30.0;
    let albedo = [0.8; 3];
    let scene = object_alone(camera, height, albedo);
    let light = PointLight {
        position: camera.surface_point(8, 8, 5.0),
        intensity: [50.0; 3],
    };
    let renderer = Renderer::with_emitters(&scene, &[Emitter::Point(light)]).unwrap();
    let image = renderer.render_rows(0..size, &centre_direct()).unwrap();
    let lit = |row: usize, col: usize| image[(row * size + col) * 3];
    for (row, col) in [(8, 2), (9, 3), (12, 6)] {
        let expected = point_radiance(albedo, &light, &camera, (row, col), 0.0, 0);
        let got = lit(row, col);
        assert!(
            (got - expected).abs() <= 5e-3 * expected,
            "pixel ({row}, {col}): {got} vs {expected}"
        );
    }
    assert_eq!(lit(2, 3), 0.0, "behind the spike");
    assert!(lit(2, 9) > 0.0);
}

#[test]
fn a_point_light_with_a_bad_position_or_intensity_is_named() {
    let scene = tilted_plate(4, [0.5; 3]);
    let bad = |position: Vec3A, intensity: Rgb| {
        let light = Emitter::Point(PointLight {
            position,
            intensity,
        });
        let distant = Emitter::Distant(Light {
            direction: Vec3A::Z,
            irradiance: [1.0; 3],
        });
        Renderer::with_emitters(&scene, &[distant, light])
            .err()
            .map(|e| e.to_string())
            .unwrap()
    };
    assert!(bad(vec3a(0.0, f32::NAN, 9.0), [1.0; 3]).starts_with("lights[1].position: "));
    assert!(bad(vec3a(0.0, 0.0, 9.0), [1.0, -1.0, 1.0]).starts_with("lights[1].intensity: "));
}

/// A square environment mesh at z = 0, 40 pixels a side, wound to face `facing` (±z), of
/// albedo `albedo`.
fn square_mesh(facing: f32, albedo: Rgb) -> crate::scene::EnvironmentMesh {
    let triangles = if facing > 0.0 {
        vec![[0, 1, 2], [0, 2, 3]]
    } else {
        vec![[0, 2, 1], [0, 3, 2]]
    };
    crate::scene::EnvironmentMesh {
        positions: vec![
            vec3a(-20.0, -20.0, 0.0),
            vec3a(20.0, -20.0, 0.0),
            vec3a(20.0, 20.0, 0.0),
            vec3a(-20.0, 20.0, 0.0),
        ],
        albedo: vec![albedo; 4],
        triangles,
    }
}

/// A level plate of `size`² pixels at height 3 (its middle, 3 pixels in from the edges).
fn plate(size: usize) -> Scene {
    let camera = Camera {
        width: size,
        height: size,
        pixel_size: 1.0,
        pinhole: None,
    };
    let mut scene = object_alone(camera, vec![3.0; size * size], [0.5; 3]);
    for p in 0..size * size {
        let (i, j) = (p / size, p % size);
        scene.surface.mask[p] = (3..size - 3).contains(&i) && (3..size - 3).contains(&j);
    }
    scene
}

#[test]
fn an_environment_mesh_reflects_lamberts_law_on_either_side_and_takes_shadows() {
    let albedo = [0.6, 0.4, 0.2];
    let light = Emitter::Distant(Light {
        direction: vec3a(0.0, 0.6, 0.8),
        irradiance: [PI; 3],
    });
    let settings = RenderSettings {
        bounces: 0,
        samples: 0,
        direct_samples: 16,
        seed: 0,
        split_bounces: true,
        cached_direct: true,
    };
    for facing in [1.0, -1.0] {
        let accel = Arc::new(EnvironmentAccel::new(square_mesh(facing, albedo)).unwrap());
        let renderer = Renderer::with_environment(&plate(16), &[light], Some(accel)).unwrap();
        let image = renderer.render_rows(0..16, &settings).unwrap();
        let pixel = |row: usize, col: usize| &image[(row * 16 + col) * 3..][..3];
        // A corner of the mesh, lit: ρ E cos θ / π with E = π.
        for (c, &value) in pixel(0, 0).iter().enumerate() {
            let expected = albedo[c] * 0.8;
            assert!((value - expected).abs() < 1e-5, "{value} vs {expected}");
        }
        // Beside the plate, on the side away from the light (−y, lower rows), its shadow.
        assert_eq!(pixel(13, 8), [0.0; 3], "facing {facing}");
    }
}

#[test]
fn a_scene_with_an_environment_mesh_renders_alike_at_any_height_and_scale() {
    // The whole scene (plate and mesh) raised by 57 pixel sizes, or drawn at a quarter of the
    // size: the working frame moves, the mesh's BVH stays in world units, the image is the same.
    let settings = RenderSettings {
        bounces: 0,
        samples: 0,
        direct_samples: 4,
        seed: 2,
        split_bounces: true,
        cached_direct: true,
    };
    let light = Emitter::Distant(Light {
        direction: vec3a(0.3, 0.2, 0.9).normalize(),
        irradiance: [PI; 3],
    });
    let render = |scale: f32, lift: f32| {
        let mut scene = plate(12);
        scene.camera.pixel_size = scale;
        scene.zero_height = lift * scale;
        scene
            .surface
            .height
            .iter_mut()
            .for_each(|h| *h = (*h + lift) * scale);
        let mut mesh = square_mesh(1.0, [0.5; 3]);
        mesh.positions
            .iter_mut()
            .for_each(|p| *p = (*p + vec3a(0.0, 0.0, lift)) * scale);
        let accel = Arc::new(EnvironmentAccel::new(mesh).unwrap());
        Renderer::with_environment(&scene, &[light], Some(accel))
            .unwrap()
            .render_rows(0..12, &settings)
            .unwrap()
    };
    let reference = render(1.0, 0.0);
    // The plate's shadow falls on the mesh: a wrong placement of either would move it.
    assert!(reference.contains(&0.0) && reference.iter().any(|&v| v > 0.1));
    for (scale, lift) in [(0.25, 0.0), (1.0, 57.0)] {
        let other = render(scale, lift);
        let worst = reference
            .iter()
            .zip(&other)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(worst <= 1e-4, "{scale} {lift}: off by {worst}");
    }
}

#[test]
fn a_bad_environment_mesh_is_an_error_naming_it() {
    let error = |edit: fn(&mut crate::scene::EnvironmentMesh)| {
        let mut mesh = square_mesh(1.0, [0.5; 3]);
        edit(&mut mesh);
        let light = Emitter::Distant(Light {
            direction: Vec3A::Z,
            irradiance: [1.0; 3],
        });
        EnvironmentAccel::new(mesh)
            .and_then(|accel| {
                Renderer::with_environment(&plate(8), &[light], Some(Arc::new(accel)))
            })
            .err()
            .unwrap()
            .to_string()
    };
    let text = error(|m| m.positions[2].x = f32::NAN);
    assert!(
        text.starts_with("environment.vertices: vertex 2 is not finite"),
        "{text}"
    );
    let text = error(|m| m.triangles[1][2] = 9);
    assert!(
        text.starts_with("environment.triangles: triangle 1 names vertex"),
        "{text}"
    );
    let text = error(|m| m.albedo[3] = [0.5, 1.5, 0.5]);
    assert!(text.starts_with("environment.albedo of vertex 3"), "{text}");
    let text = error(|m| m.positions[0].x = 1e12);
    assert!(
        text.starts_with("environment.vertices: lies at a corner of the box around them"),
        "{text}"
    );
}

/// The corners of each of `corners`' triangles split at their edges' midpoints, `levels`
/// times over (each triangle with its own three vertices).
fn subdivided(corners: Vec<[Vec3A; 3]>, levels: usize) -> crate::scene::EnvironmentMesh {
    let mut corners = corners;
    for _ in 0..levels {
        corners = corners
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = ((a + b) / 2.0, (b + c) / 2.0, (c + a) / 2.0);
                [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
            })
            .collect();
    }
    let count = corners.len() as u32;
    crate::scene::EnvironmentMesh {
        positions: corners.iter().flatten().copied().collect(),
        albedo: vec![[0.6, 0.5, 0.4]; 3 * corners.len()],
        triangles: (0..count).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect(),
    }
}

/// Surroundings of two rectangles: a floor under the whole view and a card standing beside
/// the object, which shadows the floor behind it.
fn floor_and_card() -> Vec<[Vec3A; 3]> {
    let rectangle = |a: Vec3A, b: Vec3A, c: Vec3A, d: Vec3A| [[a, b, c], [a, c, d]];
    let floor = rectangle(
        vec3a(-20.0, -20.0, 0.0),
        vec3a(20.0, -20.0, 0.0),
        vec3a(20.0, 20.0, 0.0),
        vec3a(-20.0, 20.0, 0.0),
    );
    let card = rectangle(
        vec3a(8.0, -10.0, 0.0),
        vec3a(8.0, 10.0, 0.0),
        vec3a(10.0, 10.0, 8.0),
        vec3a(10.0, -10.0, 8.0),
    );
    floor.into_iter().chain(card).collect()
}

#[test]
fn an_environment_mesh_finer_than_a_pixel_renders_as_the_same_mesh_traced() {
    // The same floor and card, as four triangles (larger than the cache's spacing: every
    // shadow traced) and as 8 192 (under a pixel a side: their own shadows read at their
    // corners, the object's traced). The plate's shadow and the card's fall on the floor.
    let size = 32;
    let mut scene = plate(size);
    for p in 0..size * size {
        let (i, j) = (p / size, p % size);
        scene.surface.mask[p] = (11..21).contains(&i) && (11..21).contains(&j);
    }
    let light = Emitter::Point(PointLight {
        position: vec3a(-4.0, 3.0, 14.0),
        intensity: [600.0; 3],
    });
    let render = |levels: usize, settings: &RenderSettings| {
        let accel = Arc::new(EnvironmentAccel::new(subdivided(floor_and_card(), levels)).unwrap());
        let visibility = accel.visibility(&[light]).unwrap();
        let cached = accel.corner_visibility(&visibility, 0, 1.0).is_some();
        assert_eq!(cached, levels > 0, "levels {levels}");
        let renderer = Renderer::with_environment(&scene, &[light], Some(accel)).unwrap();
        renderer.render_rows(0..size, settings).unwrap()
    };
    let direct = |cached_direct| RenderSettings {
        bounces: 0,
        samples: 0,
        direct_samples: 16,
        seed: 5,
        split_bounces: true,
        cached_direct,
    };
    let bounced = RenderSettings {
        bounces: 2,
        samples: 64,
        direct_samples: 0,
        seed: 5,
        split_bounces: false,
        cached_direct: false,
    };
    for (settings, tolerance) in [(direct(false), 1e-3), (direct(true), 1e-3), (bounced, 1e-2)] {
        let (traced, cached) = (render(0, &settings), render(6, &settings));
        let mean = traced.iter().sum::<f32>() / traced.len() as f32;
        let off = traced
            .iter()
            .zip(&cached)
            .map(|(a, b)| (a - b).abs())
            .sum::<f32>()
            / traced.len() as f32;
        assert!(
            off <= tolerance * mean,
            "{settings:?}: off by {off} on average, of {mean}"
        );
        // Both shadows are there: the card's and the plate's leave floor pixels dark.
        if settings.bounces == 0 {
            let pixel = |row: usize, col: usize| cached[(row * size + col) * 3];
            assert!(pixel(16, 30) < 0.01 * pixel(16, 2), "behind the card");
            assert!(pixel(15, 21) < 0.01 * pixel(16, 2), "behind the plate");
        }
    }
}
