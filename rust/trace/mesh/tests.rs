//! Tests of the scene's triangles.

use super::*;
use crate::scene::{Camera, CornellBox, Floor, HeightField, Scene};
use glam::vec3a;
use std::sync::Arc;

pub(crate) fn flat_scene(w: usize, h: usize, z: f32, mask: impl Fn(usize, usize) -> bool) -> Scene {
    let n = w * h;
    Scene {
        camera: Camera {
            width: w,
            height: h,
            pixel_size: 1.0,
            pinhole: None,
        },
        surface: HeightField {
            height: vec![z; n],
            mask: (0..n).map(|p| mask(p / w, p % w)).collect(),
            albedo: vec![[0.5, 0.5, 0.5]; n],
        },
        floor: None,
        cornell_box: None,
        zero_height: 0.0,
    }
}

#[test]
fn height_field_follows_the_contract_triangulation() {
    let mut scene = flat_scene(3, 2, 0.0, |_, _| true);
    scene.surface.height = vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
    let mesh = Mesh::from_scene(&scene);
    let object: Vec<_> = (0..mesh.triangles.len())
        .filter(|&t| mesh.kinds[t] == SurfaceKind::Object)
        .collect();
    assert_eq!(object.len(), 4);
    // First triangle of block (0,0): pixels (0,0), (1,0), (0,1), normal facing +z.
    let corners = mesh.corners(object[0]);
    let expect: Vec<Vec3A> = [(0, 0), (1, 0), (0, 1)]
        .iter()
        .map(|&(i, j)| {
            scene
                .camera
                .surface_point(i, j, scene.surface.height[i * 3 + j])
        })
        .collect();
    for c in expect {
        assert!(corners.contains(&c));
    }
    // z = j + 3 i  →  dz/dx = 1, dz/dy = −3 (rows grow downward): n ∝ (−1, 3, 1).
    let n = mesh.normals[object[0]];
    assert!(
        (n - vec3a(-1.0, 3.0, 1.0).normalize()).length() < 1e-6,
        "{n:?}"
    );
}

#[test]
fn skirt_closes_the_object_and_faces_outward() {
    let scene = flat_scene(4, 4, 2.0, |i, j| (1..3).contains(&i) && (1..3).contains(&j));
    let mesh = Mesh::from_scene(&scene);
    let skirt: Vec<_> = (0..mesh.triangles.len())
        .filter(|&t| mesh.kinds[t] == SurfaceKind::Skirt)
        .collect();
    // One block, four boundary edges, two skirt rows of two triangles each.
    assert_eq!(skirt.len(), 4 * 2 * 2);
    for &t in &skirt {
        let centroid = mesh.corners(t).iter().sum::<Vec3A>() / 3.0;
        let outward = vec3a(centroid.x, centroid.y, 0.0);
        assert!(mesh.normals[t].dot(outward) > 0.0);
        assert!(mesh.normals[t].z.abs() < 1e-6);
    }
}

#[test]
fn box_walls_face_inside_and_floor_faces_up() {
    let mut scene = flat_scene(4, 4, 1.0, |_, _| false);
    scene.floor = Some(Floor {
        height: 0.0,
        albedo: [0.8; 3],
    });
    scene.cornell_box = Some(CornellBox {
        x: [-3.0, 3.0],
        y: [-3.0, 3.0],
        z_top: 2.0,
        left: [1.0, 0.0, 0.0],
        right: [0.0, 1.0, 0.0],
        back: [0.5; 3],
        front: [0.5; 3],
    });
    let mesh = Mesh::from_scene(&scene);
    for t in 0..mesh.triangles.len() {
        let centroid = mesh.corners(t).iter().sum::<Vec3A>() / 3.0;
        let inside = vec3a(0.0, 0.0, 1.0) - centroid;
        assert!(
            mesh.normals[t].dot(inside) > 0.0,
            "triangle {t} faces outward"
        );
    }
    assert_eq!(mesh.panels.len(), 5);
    for panel in &mesh.panels {
        let centre = panel.origin + (panel.edge_u + panel.edge_v) * 0.5;
        assert!(panel.normal.dot(vec3a(0.0, 0.0, 1.0) - centre) > 0.0);
        assert_eq!(
            panel.grid_coords(centre),
            Some((panel.cells.0 as f32 / 2.0, panel.cells.1 as f32 / 2.0))
        );
    }
}

#[test]
fn without_a_floor_the_skirt_reaches_world_height_zero_in_the_working_frame() {
    let scene = flat_scene(6, 6, 5.0, |i, j| (1..5).contains(&i) && (1..5).contains(&j));
    let frame = crate::scene::Frame::of(&scene);
    let mesh = Mesh::from_scene(&frame.local_scene(&scene).unwrap());
    let lowest = (0..mesh.triangles.len())
        .filter(|&t| mesh.kinds[t] == SurfaceKind::Skirt)
        .flat_map(|t| mesh.corners(t))
        .map(|p| frame.to_world(p).z)
        .fold(f32::INFINITY, f32::min);
    assert_eq!(lowest, 0.0);
}

#[test]
fn an_environment_mesh_keeps_its_winding_and_albedo_and_follows_the_meshs_triangles() {
    let mut mesh = Mesh::from_scene(&flat_scene(4, 4, 1.0, |_, _| true));
    let accel = crate::trace::environment::EnvironmentAccel::new(crate::scene::EnvironmentMesh {
        positions: vec![
            vec3a(0.0, 0.0, 0.0),
            vec3a(1.0, 0.0, 0.0),
            vec3a(0.0, 1.0, 0.0),
            vec3a(5.0, 5.0, 5.0),
        ],
        albedo: vec![[0.1, 0.2, 0.3], [0.4, 0.5, 0.6], [0.7, 0.8, 0.9], [1.0; 3]],
        // Wound clockwise seen from +z, then a degenerate one.
        triangles: vec![[0, 2, 1], [3, 3, 3]],
    })
    .unwrap();
    assert_eq!(accel.normal(0), -Vec3A::Z);
    assert_eq!(accel.normal(1), Vec3A::ZERO);
    mesh.environment = Some(PlacedEnvironment {
        accel: Arc::new(accel),
        scale: 1.0,
        z_origin: 0.0,
    });
    let first = mesh.triangles.len();
    assert!(mesh.is_environment(first) && !mesh.is_environment(first - 1));
    assert_eq!(mesh.albedo_at(first, 1.0, 0.0), [0.7, 0.8, 0.9]);
    // Seen from above, its facing normal is turned toward the ray; the object's back is black.
    assert_eq!(mesh.seen_normal(first, -Vec3A::Z), Some(Vec3A::Z));
    assert_eq!(mesh.seen_normal(first, Vec3A::Z), Some(-Vec3A::Z));
    assert_eq!(mesh.seen_normal(0, Vec3A::Z), None);
}
