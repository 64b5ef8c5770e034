use super::*;

/// Row-major unit normals (height × width × 3) of a surface given by its heights in pixel
/// units (orthographic, y up), by central differences inside and one-sided at the border.
fn normals_of_heights(heights: &[f64], height: usize, width: usize) -> Vec<f32> {
    let at = |r: usize, c: usize| heights[r * width + c];
    let mut normals = Vec::with_capacity(height * width * 3);
    for r in 0..height {
        for c in 0..width {
            let (c0, c1) = (c.saturating_sub(1), (c + 1).min(width - 1));
            let (r0, r1) = (r.saturating_sub(1), (r + 1).min(height - 1));
            let dz_dx = (at(r, c1) - at(r, c0)) / (c1 - c0) as f64;
            // y grows against the rows.
            let dz_dy = -(at(r1, c) - at(r0, c)) / (r1 - r0) as f64;
            let norm = (dz_dx * dz_dx + dz_dy * dz_dy + 1.0).sqrt();
            normals.extend([
                (-dz_dx / norm) as f32,
                (-dz_dy / norm) as f32,
                (1.0 / norm) as f32,
            ]);
        }
    }
    normals
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    sum / n as f64
}

#[test]
fn an_orthographic_plane_comes_back_exactly_up_to_its_offset() {
    let (height, width) = (12, 17);
    let truth: Vec<f64> = (0..height * width)
        .map(|p| 0.3 * (p % width) as f64 - 0.7 * (p / width) as f64)
        .collect();
    let normals = normals_of_heights(&truth, height, width);
    let mask = vec![true; height * width];
    let surface = integrate_bilateral(
        &normals,
        &mask,
        height,
        width,
        Projection::Orthographic,
        BilateralSettings::default(),
    )
    .unwrap();
    let offset = mean(surface.values.iter().zip(&truth).map(|(v, t)| v - t));
    for (value, want) in surface.values.iter().zip(&truth) {
        assert!((value - offset - want).abs() < 1e-5, "{value} vs {want}");
    }
    assert!(surface.cuts.iter().all(|&c| c == 0));
    assert!(surface.converged);
}

#[test]
fn a_tilted_plane_seen_through_a_pinhole_comes_back_up_to_scale() {
    // The plane n·P = 1 in the camera frame (x right, y down, z forward), seen by a
    // 60°-wide camera: depth d = 1 / (n·r) along each pixel's centre ray r.
    let (height, width) = (40, 48);
    let (fx, fy, cx, cy) = (42.0, 40.0, 23.0, 21.5);
    let plane = [0.25_f64, -0.2, 0.9];
    let norm = plane.iter().map(|v| v * v).sum::<f64>().sqrt();
    // The contract's frame is (x, −y, −z) of the camera's, and the normal faces the camera.
    let world_normal = [-plane[0] / norm, plane[1] / norm, plane[2] / norm];
    let normals: Vec<f32> = (0..height * width)
        .flat_map(|_| world_normal.map(|v| v as f32))
        .collect();
    let mask = vec![true; height * width];
    let projection = Projection::Perspective { fx, fy, cx, cy };
    let surface = integrate_bilateral(
        &normals,
        &mask,
        height,
        width,
        projection,
        BilateralSettings::default(),
    )
    .unwrap();
    let log_depth: Vec<f64> = (0..height * width)
        .map(|p| {
            let (u, v) = ((p % width) as f64 + 0.5, (p / width) as f64 + 0.5);
            let ray = [(u - cx) / fx, (v - cy) / fy, 1.0];
            -(plane[0] * ray[0] + plane[1] * ray[1] + plane[2] * ray[2]).ln()
        })
        .collect();
    let offset = mean(surface.values.iter().zip(&log_depth).map(|(v, t)| v - t));
    let worst = surface
        .values
        .iter()
        .zip(&log_depth)
        .map(|(v, t)| (v - offset - t).abs())
        .fold(0.0, f64::max);
    // One-sided slopes of a curved ln d: second-order small on a 60° field.
    assert!(worst < 2e-4, "largest log-depth error {worst}");
}

#[test]
fn pixels_outside_the_mask_are_nan_and_parts_keep_their_own_offset() {
    let (height, width) = (6, 9);
    let mut mask = vec![true; height * width];
    for r in 0..height {
        mask[r * width + 4] = false;
    }
    let normals: Vec<f32> = (0..height * width)
        .flat_map(|_| [0.0f32, 0.0, 1.0])
        .collect();
    let surface = integrate_bilateral(
        &normals,
        &mask,
        height,
        width,
        Projection::Orthographic,
        BilateralSettings::default(),
    )
    .unwrap();
    for (p, value) in surface.values.iter().enumerate() {
        assert_eq!(value.is_nan(), !mask[p]);
        assert!(value.is_nan() || value.abs() < 1e-9);
    }
}

#[test]
fn bad_inputs_are_errors_naming_them() {
    let normals = vec![0.0f32, 0.0, 1.0, f32::NAN, 0.0, 1.0];
    let mask = vec![true, true];
    let settings = BilateralSettings::default();
    let message = |r: Result<BilateralSurface>| r.unwrap_err().to_string();
    assert_eq!(
        message(integrate_bilateral(
            &normals,
            &mask,
            1,
            2,
            Projection::Orthographic,
            settings
        )),
        "normals: non-finite normal at row 0, column 1"
    );
    assert!(message(integrate_bilateral(
        &normals,
        &mask[..1],
        1,
        2,
        Projection::Orthographic,
        settings
    ))
    .starts_with("mask:"));
    let flat = vec![0.0f32, 0.0, 1.0, 0.0, 0.0, 1.0];
    let bad_focal = Projection::Perspective {
        fx: 0.0,
        fy: 1.0,
        cx: 0.0,
        cy: 0.0,
    };
    assert!(
        message(integrate_bilateral(&flat, &mask, 1, 2, bad_focal, settings))
            .starts_with("intrinsics: focal lengths")
    );
    let blunt = BilateralSettings {
        sharpness: -1.0,
        ..settings
    };
    assert!(message(integrate_bilateral(
        &flat,
        &mask,
        1,
        2,
        Projection::Orthographic,
        blunt
    ))
    .starts_with("sharpness:"));
}
