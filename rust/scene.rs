//! The scene description of the data-set contract (`irtps.scene/1`): orthographic camera,
//! height-field object, optional floor and Cornell box, distant lights.

use glam::Vec3A;

use crate::error::{Error, Result};

/// Linear RGB triple.
pub type Rgb = [f32; 3];

/// Orthographic camera looking along −z; pixel (i, j) is centred at
/// `x = (j + 0.5 − W/2)·s`, `y = (H/2 − i − 0.5)·s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub width: usize,
    pub height: usize,
    pub pixel_size: f32,
}

impl Camera {
    /// World (x, y) of the continuous image position (`row`, `col`), where pixel (i, j)
    /// covers `[i, i+1) × [j, j+1)`.
    pub fn image_to_world(&self, row: f32, col: f32) -> (f32, f32) {
        let s = self.pixel_size;
        ((col - self.width as f32 / 2.0) * s, (self.height as f32 / 2.0 - row) * s)
    }

    /// World (x, y) of the centre of pixel (`row`, `col`).
    pub fn pixel_center(&self, row: usize, col: usize) -> (f32, f32) {
        self.image_to_world(row as f32 + 0.5, col as f32 + 0.5)
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        self.width * self.height
    }
}

/// A distant light: unit `direction` toward the light, RGB `irradiance` on a facing surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Light {
    pub direction: Vec3A,
    pub irradiance: Rgb,
}

/// The plane `z = height` with a uniform Lambertian albedo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Floor {
    pub height: f32,
    pub albedo: Rgb,
}

/// Four inward-facing Lambertian walls from the floor up to `z_top`, open at the top.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornellBox {
    pub x: [f32; 2],
    pub y: [f32; 2],
    pub z_top: f32,
    pub left: Rgb,
    pub right: Rgb,
    pub back: Rgb,
    pub front: Rgb,
}

/// The object: heights (world units) and RGB albedo at the pixel centres of masked pixels,
/// row-major with the camera's width and height.
#[derive(Debug, Clone, PartialEq)]
pub struct HeightField {
    pub height: Vec<f32>,
    pub mask: Vec<bool>,
    pub albedo: Vec<Rgb>,
}

/// Everything but the lights.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    pub camera: Camera,
    pub surface: HeightField,
    pub floor: Option<Floor>,
    pub cornell_box: Option<CornellBox>,
}

impl Scene {
    /// The height the skirt and walls start from: the floor's, or 0 without a floor.
    pub fn base_height(&self) -> f32 {
        self.floor.map_or(0.0, |f| f.height)
    }

    /// Checks sizes and values; the error names the offending field.
    pub fn validate(&self) -> Result<()> {
        let c = &self.camera;
        if c.width == 0 || c.height == 0 {
            return Err(Error::input("camera", format!("size {}x{} is empty", c.width, c.height)));
        }
        if !(c.pixel_size.is_finite() && c.pixel_size > 0.0) {
            return Err(Error::input("camera.pixel_size", format!("{} is not a positive number", c.pixel_size)));
        }
        let n = c.pixel_count();
        let s = &self.surface;
        for (field, len) in [("height", s.height.len()), ("mask", s.mask.len()), ("albedo", s.albedo.len())] {
            if len != n {
                return Err(Error::input(field, format!("{len} values for a {}x{} camera", c.width, c.height)));
            }
        }
        for (p, (&h, rgb)) in s.height.iter().zip(&s.albedo).enumerate() {
            if !s.mask[p] {
                continue;
            }
            if !h.is_finite() {
                return Err(Error::input("height", format!("non-finite value at pixel {}", describe_pixel(p, c))));
            }
            check_albedo(&format!("albedo at pixel {}", describe_pixel(p, c)), rgb)?;
        }
        if let Some(f) = &self.floor {
            if !f.height.is_finite() {
                return Err(Error::input("floor.height", "is not finite"));
            }
            check_albedo("floor.albedo", &f.albedo)?;
        }
        if let Some(b) = &self.cornell_box {
            let finite = b.x.iter().chain(&b.y).chain([&b.z_top]).all(|v| v.is_finite());
            if !finite || b.x[0] >= b.x[1] || b.y[0] >= b.y[1] {
                return Err(Error::input("environment", "box bounds must be finite with x0 < x1 and y0 < y1"));
            }
            if b.z_top <= self.base_height() {
                return Err(Error::input("environment.z_top", "must lie above the floor"));
            }
            for (name, rgb) in [("left", &b.left), ("right", &b.right), ("back", &b.back), ("front", &b.front)] {
                check_albedo(&format!("environment.albedo.{name}"), rgb)?;
            }
        }
        Ok(())
    }
}

/// Checks that every light has a unit direction pointing up (z > 0) and a finite,
/// non-negative irradiance.
pub fn validate_lights(lights: &[Light]) -> Result<()> {
    for (k, light) in lights.iter().enumerate() {
        let d = light.direction;
        if !d.is_finite() || (d.length() - 1.0).abs() > 1e-3 || d.z <= 0.0 {
            return Err(Error::input(
                &format!("lights[{k}].direction"),
                format!("{d:?} must be a unit vector with z > 0"),
            ));
        }
        if light.irradiance.iter().any(|e| !e.is_finite() || *e < 0.0) {
            return Err(Error::input(&format!("lights[{k}].irradiance"), "must be finite and non-negative"));
        }
    }
    Ok(())
}

/// Refuses an albedo outside [0, 1], naming `field`.
pub fn check_albedo(field: &str, rgb: &Rgb) -> Result<()> {
    if rgb.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)) {
        Ok(())
    } else {
        Err(Error::input(field, format!("{rgb:?} is not in [0, 1]")))
    }
}

fn describe_pixel(p: usize, camera: &Camera) -> String {
    format!("(row {}, column {})", p / camera.width, p % camera.width)
}
