//! The scene description of the data-set contract (`irtps.scene/1`): orthographic or pinhole
//! camera, height-field object, optional floor, Cornell box or environment mesh, distant or
//! point lights.

use glam::Vec3A;

use crate::error::{Error, Result};

/// Linear RGB triple.
pub type Rgb = [f32; 3];

/// The camera, looking along −z: orthographic, or a pinhole (contract §1b).
///
/// Orthographic: pixel (i, j) is centred at `x = (j + 0.5 − W/2)·s`, `y = (H/2 − i − 0.5)·s`
/// with `s` the pixel size. Pinhole: rays leave its optical centre through each pixel's
/// footprint on the image plane; `pixel_size` is then the world size of a pixel at the depth
/// of the object's base, the scale at which the core builds the skirt, caches the panels'
/// light and sets its tolerances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub width: usize,
    pub height: usize,
    pub pixel_size: f32,
    /// The pinhole, or None for an orthographic camera.
    pub pinhole: Option<Pinhole>,
}

/// A pinhole at world `(0, 0, center_z)`: image x along world +x, image rows along world −y;
/// image position (`u`, `v`) = (column, row) looks along `((u − cx)/fx, −(v − cy)/fy, −1)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    /// Focal lengths, pixels.
    pub fx: f32,
    pub fy: f32,
    /// Principal point, pixels.
    pub cx: f32,
    pub cy: f32,
    /// Height of the optical centre, world units.
    pub center_z: f32,
}

impl Camera {
    /// World (x, y) of the continuous image position (`row`, `col`), where pixel (i, j)
    /// covers `[i, i+1) × [j, j+1)`: for a pinhole, on the plane at height `z`.
    pub fn image_to_world(&self, row: f32, col: f32, z: f32) -> (f32, f32) {
        match self.pinhole {
            None => {
                let s = self.pixel_size;
                (
                    (col - self.width as f32 / 2.0) * s,
                    (self.height as f32 / 2.0 - row) * s,
                )
            }
            Some(p) => {
                let depth = p.center_z - z;
                ((col - p.cx) / p.fx * depth, -(row - p.cy) / p.fy * depth)
            }
        }
    }

    /// The point at height `z` that the centre of pixel (`row`, `col`) sees.
    pub fn surface_point(&self, row: usize, col: usize, z: f32) -> Vec3A {
        let (x, y) = self.image_to_world(row as f32 + 0.5, col as f32 + 0.5, z);
        Vec3A::new(x, y, z)
    }

    /// The camera ray through image position (`row`, `col`): its origin (for an orthographic
    /// camera, at height `orthographic_z`) and unit direction.
    pub fn ray(&self, row: f32, col: f32, orthographic_z: f32) -> (Vec3A, Vec3A) {
        match self.pinhole {
            None => {
                let (x, y) = self.image_to_world(row, col, orthographic_z);
                (Vec3A::new(x, y, orthographic_z), -Vec3A::Z)
            }
            Some(p) => (
                Vec3A::new(0.0, 0.0, p.center_z),
                Vec3A::new((col - p.cx) / p.fx, -(row - p.cy) / p.fy, -1.0).normalize(),
            ),
        }
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

/// An isotropic point light (contract §4b): its `position` and RGB radiant `intensity`. A
/// surface point at distance r that faces it receives `intensity / r²`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLight {
    pub position: Vec3A,
    pub intensity: Rgb,
}

/// A light of a scene: distant, or a point near the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Emitter {
    Distant(Light),
    Point(PointLight),
}

impl Emitter {
    /// Its irradiance (distant) or intensity (point), per channel.
    pub fn power(&self) -> Rgb {
        match self {
            Emitter::Distant(light) => light.irradiance,
            Emitter::Point(light) => light.intensity,
        }
    }
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

/// Surroundings given as a triangle mesh (contract §3b): world positions, an RGB albedo per
/// vertex (interpolated across each triangle) and the vertex indices of each triangle. Its
/// surfaces are Lambertian and reflect on both sides.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EnvironmentMesh {
    pub positions: Vec<Vec3A>,
    pub albedo: Vec<Rgb>,
    pub triangles: Vec<[u32; 3]>,
}

impl EnvironmentMesh {
    /// Checks the mesh, naming the first bad vertex or triangle.
    pub fn validate(&self) -> Result<()> {
        if self.albedo.len() != self.positions.len() {
            return Err(Error::input(
                "environment.albedo",
                format!(
                    "{} values for {} vertices",
                    self.albedo.len(),
                    self.positions.len()
                ),
            ));
        }
        if let Some(v) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::input(
                "environment.vertices",
                format!("vertex {v} is not finite: {:?}", self.positions[v]),
            ));
        }
        let count = self.positions.len();
        if let Some(t) = self
            .triangles
            .iter()
            .position(|tri| tri.iter().any(|&i| i as usize >= count))
        {
            return Err(Error::input(
                "environment.triangles",
                format!(
                    "triangle {t} names vertex {:?}, but there are {count} vertices",
                    self.triangles[t]
                ),
            ));
        }
        self.albedo.iter().enumerate().try_for_each(|(v, rgb)| {
            check_albedo(&format!("environment.albedo of vertex {v}"), rgb)
        })
    }
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
    /// The z of world height 0, where the skirt ends when there is no floor: 0 in world
    /// coordinates, moved by [`Frame::local_scene`].
    pub zero_height: f32,
}

impl Scene {
    /// The height the skirt and walls start from: the floor's, or world height 0 without a
    /// floor ([`Scene::zero_height`]).
    pub fn base_height(&self) -> f32 {
        self.floor.map_or(self.zero_height, |f| f.height)
    }

    /// Checks sizes and values; the error names the offending field.
    pub fn validate(&self) -> Result<()> {
        let c = &self.camera;
        if c.width == 0 || c.height == 0 {
            return Err(Error::input(
                "camera",
                format!("size {}x{} is empty", c.width, c.height),
            ));
        }
        if !(c.pixel_size.is_finite() && c.pixel_size > 0.0) {
            return Err(Error::input(
                "camera.pixel_size",
                format!("{} is not a positive number", c.pixel_size),
            ));
        }
        if let Some(p) = &c.pinhole {
            if !(p.fx.is_finite() && p.fx > 0.0 && p.fy.is_finite() && p.fy > 0.0) {
                return Err(Error::input(
                    "camera.fx",
                    format!(
                        "focal lengths {} and {} must be positive numbers",
                        p.fx, p.fy
                    ),
                ));
            }
            if !(p.cx.is_finite() && p.cy.is_finite() && p.center_z.is_finite()) {
                return Err(Error::input(
                    "camera.cx",
                    "the principal point and the optical centre must be finite",
                ));
            }
        }
        let n = c.pixel_count();
        let s = &self.surface;
        for (field, len) in [
            ("height", s.height.len()),
            ("mask", s.mask.len()),
            ("albedo", s.albedo.len()),
        ] {
            if len != n {
                return Err(Error::input(
                    field,
                    format!("{len} values for a {}x{} camera", c.width, c.height),
                ));
            }
        }
        for (p, (&h, rgb)) in s.height.iter().zip(&s.albedo).enumerate() {
            if !s.mask[p] {
                continue;
            }
            if !h.is_finite() {
                return Err(Error::input(
                    "height",
                    format!("non-finite value at pixel {}", describe_pixel(p, c)),
                ));
            }
            if let Some(pinhole) = &c.pinhole {
                if h >= pinhole.center_z {
                    return Err(Error::input(
                        "height",
                        format!(
                            "{h} at pixel {} is not below the optical centre (z = {})",
                            describe_pixel(p, c),
                            pinhole.center_z
                        ),
                    ));
                }
            }
            check_albedo(&format!("albedo at pixel {}", describe_pixel(p, c)), rgb)?;
        }
        if let Some(f) = &self.floor {
            if !f.height.is_finite() {
                return Err(Error::input("floor.height", "is not finite"));
            }
            check_albedo("floor.albedo", &f.albedo)?;
        }
        if let Some(pinhole) = &c.pinhole {
            if self.base_height() >= pinhole.center_z {
                return Err(Error::input(
                    "camera.optical_center",
                    format!(
                        "z = {} is not above the floor (z = {})",
                        pinhole.center_z,
                        self.base_height()
                    ),
                ));
            }
        }
        if let Some(b) = &self.cornell_box {
            let finite =
                b.x.iter()
                    .chain(&b.y)
                    .chain([&b.z_top])
                    .all(|v| v.is_finite());
            if !finite || b.x[0] >= b.x[1] || b.y[0] >= b.y[1] {
                return Err(Error::input(
                    "environment",
                    "box bounds must be finite with x0 < x1 and y0 < y1",
                ));
            }
            if b.z_top <= self.base_height() {
                return Err(Error::input(
                    "environment.z_top",
                    "must lie above the floor",
                ));
            }
            for (name, rgb) in [
                ("left", &b.left),
                ("right", &b.right),
                ("back", &b.back),
                ("front", &b.front),
            ] {
                check_albedo(&format!("environment.albedo.{name}"), rgb)?;
            }
        }
        Ok(())
    }
}

/// Largest distance, in pixel sizes, of any coordinate of the geometry from the working
/// frame's origin (the middle of the object's heights). float32 resolves a sixteenth of a
/// pixel out to 10^6 pixel sizes (the largest base height the contract accepts) and a pixel
/// out to 10^7; the height-field walk's slab distances (a coordinate over a direction
/// component it clamps to 10^-30) stay finite below about 3·10^8.
pub const MAX_FRAME_EXTENT: f64 = 1e7;

/// The similarity the core renders in: one unit a pixel, z measured from the middle of the
/// object's heights. A scene described at any scale or height (float32 world units) lands
/// in the same working frame, where every tolerance of the core is set; so a rendering,
/// which is unitless, does not depend on the scene's scale. The camera's x and y are
/// already centred on 0 and stay so.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// World units per unit of the working frame: the pixel size.
    pub scale: f64,
    /// World z of the working frame's origin.
    pub z_origin: f64,
}

impl Frame {
    /// The working frame of `scene`: z from the middle of the range of the object's heights
    /// (of the base height when no pixel is masked).
    pub fn of(scene: &Scene) -> Frame {
        let s = &scene.surface;
        let heights = s
            .height
            .iter()
            .zip(&s.mask)
            .filter(|(_, &m)| m)
            .map(|(&h, _)| f64::from(h));
        let (lo, hi) = heights.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), h| {
            (lo.min(h), hi.max(h))
        });
        let z_origin = if lo <= hi {
            0.5 * (lo + hi)
        } else {
            f64::from(scene.base_height())
        };
        Frame {
            scale: f64::from(scene.camera.pixel_size),
            z_origin,
        }
    }

    /// Working-frame coordinate of world x or y `v`.
    pub fn local_xy(&self, v: f32) -> f64 {
        f64::from(v) / self.scale
    }

    /// Working-frame coordinate of world z `z`.
    pub fn local_z(&self, z: f32) -> f64 {
        (f64::from(z) - self.z_origin) / self.scale
    }

    /// The world point of working-frame point `p`.
    pub fn to_world(&self, p: Vec3A) -> Vec3A {
        let [x, y, z] = p.to_array().map(|c| f64::from(c) * self.scale);
        Vec3A::new(x as f32, y as f32, (z + self.z_origin) as f32)
    }

    /// The working-frame point of world point `p`.
    pub fn to_local(&self, p: Vec3A) -> Vec3A {
        Vec3A::new(
            self.local_xy(p.x) as f32,
            self.local_xy(p.y) as f32,
            self.local_z(p.z) as f32,
        )
    }

    /// `emitter` in this frame: a point light's position moved and scaled, and its intensity
    /// divided by the scale squared (the inverse-square law in working-frame distances); a
    /// distant light as it is.
    pub fn local_emitter(&self, emitter: &Emitter) -> Emitter {
        match emitter {
            Emitter::Distant(light) => Emitter::Distant(*light),
            Emitter::Point(light) => {
                let area = self.scale * self.scale;
                Emitter::Point(PointLight {
                    position: self.to_local(light.position),
                    intensity: light.intensity.map(|i| (f64::from(i) / area) as f32),
                })
            }
        }
    }

    /// The working-frame point of world point `p`, refused as [`Frame::local_scene`] refuses
    /// a coordinate float32 cannot resolve, naming `field` and `place()`.
    pub fn local_point(&self, field: &str, p: Vec3A, place: impl Fn() -> String) -> Result<Vec3A> {
        Ok(Vec3A::new(
            resolvable(field, self.local_xy(p.x), &place)?,
            resolvable(field, self.local_xy(p.y), &place)?,
            resolvable(field, self.local_z(p.z), &place)?,
        ))
    }

    /// The world length of working-frame length `t`.
    pub fn to_world_length(&self, t: f32) -> f32 {
        (f64::from(t) * self.scale) as f32
    }

    /// `scene` (validated) in this frame: a pixel size of 1 and every coordinate moved and
    /// scaled. Refuses, naming the field, a coordinate farther than [`MAX_FRAME_EXTENT`]
    /// pixel sizes from the frame's origin, which float32 cannot resolve.
    pub fn local_scene(&self, scene: &Scene) -> Result<Scene> {
        let s = &scene.surface;
        let mut height = Vec::with_capacity(s.height.len());
        for (p, (&h, &m)) in s.height.iter().zip(&s.mask).enumerate() {
            let z = if m { self.local_z(h) } else { 0.0 };
            height.push(resolvable("height", z, || {
                format!("at pixel {}", describe_pixel(p, &scene.camera))
            })?);
        }
        let floor = match scene.floor {
            Some(f) => Some(Floor {
                height: resolvable("floor.height", self.local_z(f.height), String::new)?,
                ..f
            }),
            None => None,
        };
        let cornell_box = match scene.cornell_box {
            Some(b) => {
                let xy = |v: [f32; 2]| -> Result<[f32; 2]> {
                    Ok([
                        resolvable("environment", self.local_xy(v[0]), String::new)?,
                        resolvable("environment", self.local_xy(v[1]), String::new)?,
                    ])
                };
                Some(CornellBox {
                    x: xy(b.x)?,
                    y: xy(b.y)?,
                    z_top: resolvable("environment.z_top", self.local_z(b.z_top), String::new)?,
                    ..b
                })
            }
            None => None,
        };
        let pinhole = match scene.camera.pinhole {
            Some(p) => Some(Pinhole {
                center_z: resolvable(
                    "camera.optical_center",
                    self.local_z(p.center_z),
                    String::new,
                )?,
                ..p
            }),
            None => None,
        };
        let camera = Camera {
            pixel_size: 1.0,
            pinhole,
            ..scene.camera
        };
        Ok(Scene {
            camera,
            surface: HeightField {
                height,
                mask: s.mask.clone(),
                albedo: s.albedo.clone(),
            },
            floor,
            cornell_box,
            zero_height: resolvable("height", self.local_z(scene.zero_height), || {
                "from world height 0 (where the skirt ends without a floor)".to_string()
            })?,
        })
    }
}

/// `v` as float32 if it lies within [`MAX_FRAME_EXTENT`] of the working frame's origin;
/// otherwise the error names `field` (and `place()`, where the field has many values).
fn resolvable(field: &str, v: f64, place: impl FnOnce() -> String) -> Result<f32> {
    if v.abs() <= MAX_FRAME_EXTENT {
        return Ok(v as f32);
    }
    let place = place();
    let at = if place.is_empty() {
        String::new()
    } else {
        format!(" {place}")
    };
    Err(Error::input(field, format!("lies{at} {:.3e} pixel sizes from the object: the core's float32 geometry resolves at most {MAX_FRAME_EXTENT:e}", v.abs())))
}

/// The lights of rows `directions` and `irradiance`: light k has row k of each. Refuses,
/// naming `irradiance`, rows of different counts.
pub fn lights_from_rows(directions: &[[f32; 3]], irradiance: &[Rgb]) -> Result<Vec<Light>> {
    if directions.len() != irradiance.len() {
        return Err(Error::input(
            "irradiance",
            "needs one row per light direction",
        ));
    }
    Ok(directions
        .iter()
        .zip(irradiance)
        .map(|(&direction, &irradiance)| Light {
            direction: Vec3A::from(direction),
            irradiance,
        })
        .collect())
}

/// Checks that every light has a unit direction pointing up (z > 0) and a finite,
/// non-negative irradiance.
pub fn validate_lights(lights: &[Light]) -> Result<()> {
    lights
        .iter()
        .enumerate()
        .try_for_each(|(k, light)| check_light(k, light))
}

/// Checks distant light `k`, naming its field.
fn check_light(k: usize, light: &Light) -> Result<()> {
    let d = light.direction;
    if !d.is_finite() || (d.length() - 1.0).abs() > 1e-3 || d.z <= 0.0 {
        return Err(Error::input(
            &format!("lights[{k}].direction"),
            format!("{d:?} must be a unit vector with z > 0"),
        ));
    }
    if light.irradiance.iter().any(|e| !e.is_finite() || *e < 0.0) {
        return Err(Error::input(
            &format!("lights[{k}].irradiance"),
            "must be finite and non-negative",
        ));
    }
    Ok(())
}

/// Checks every emitter: a distant light as [`validate_lights`] does; a point light's
/// position finite, its intensity finite and non-negative.
pub fn validate_emitters(emitters: &[Emitter]) -> Result<()> {
    for (k, emitter) in emitters.iter().enumerate() {
        match emitter {
            Emitter::Distant(light) => check_light(k, light)?,
            Emitter::Point(light) => {
                if !light.position.is_finite() {
                    return Err(Error::input(
                        &format!("lights[{k}].position"),
                        format!("{:?} must be finite", light.position),
                    ));
                }
                if light.intensity.iter().any(|i| !i.is_finite() || *i < 0.0) {
                    return Err(Error::input(
                        &format!("lights[{k}].intensity"),
                        "must be finite and non-negative",
                    ));
                }
            }
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
