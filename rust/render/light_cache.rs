//! Direct light for every light at once, distant or point (contract §4, §4b).
//!
//! Whether each light is visible is traced once per cache point: at each vertex of the
//! object's mesh, and at each vertex of a grid on each panel of the surroundings (about a
//! pixel apart). The direct radiance leaving any surface point then costs K multiply-adds
//! and no rays: the Lambert term uses the surface's own normal and the visibility is
//! interpolated (barycentrically on the object, bilinearly on a panel). Points outside a
//! panel's cached window (the far floor) and the points the camera sees directly are shaded
//! with real shadow rays instead.
//!
//! An environment mesh's triangles no larger than the cache's spacing (a scan's) interpolate
//! the shadow the mesh casts on itself between their corners ([`EnvironmentVisibility`],
//! traced once a run) and trace the object's part of the shadow, which changes from pass
//! to pass, against the object alone. Larger triangles (a coarse light box) are shaded with
//! real shadow rays.

use std::f32::consts::PI;

use glam::Vec3A;
use rayon::prelude::*;

use std::sync::Arc;

use crate::scene::{Emitter, Rgb};
use crate::trace::environment::{lit, EnvironmentVisibility};
use crate::trace::mesh::{Mesh, Panel, SurfaceKind, NO_PANEL};
use crate::trace::Tracer;

/// Light visibility at the cache points, plus the light parameters needed to shade with it.
#[derive(Clone)]
pub struct LightCache {
    /// Unit direction toward each distant light (0 for a point light).
    directions: Vec<Vec3A>,
    /// Position of each point light (None for a distant light), and whether there is any:
    /// with none, the shading runs the loop over lights that vectorises.
    positions: Vec<Option<Vec3A>>,
    any_point: bool,
    /// x, y and z of each light's direction, light by light (the shading runs over lights).
    direction_xyz: [Vec<f32>; 3],
    /// Irradiance of each distant light, or intensity of each point light, divided by π
    /// (the Lambertian BRDF without the albedo), one vector per channel.
    radiance_scale: [Vec<f32>; 3],
    /// `vertex_visibility[v · K + k]` is 1 when light k is unoccluded from mesh vertex v.
    vertex_visibility: Vec<u8>,
    /// Per panel, `[(b · (nu + 1) + a) · K + k]` for grid vertex (a, b).
    panel_visibility: Vec<Vec<u8>>,
    /// At the environment mesh's vertices, the mesh alone occluding.
    environment_visibility: Option<Arc<EnvironmentVisibility>>,
    ray_offset: f32,
}

impl LightCache {
    /// Traces one shadow ray per cache point and light (in parallel); `ray_offset` is the
    /// distance by which shadow rays start off the surface. The emitters are in the mesh's
    /// frame; `environment_visibility` is theirs at the environment mesh's vertices.
    pub fn new(
        mesh: &Mesh,
        tracer: &Tracer,
        lights: &[Emitter],
        ray_offset: f32,
        environment_visibility: Option<Arc<EnvironmentVisibility>>,
    ) -> LightCache {
        let directions: Vec<Vec3A> = lights
            .iter()
            .map(|l| match l {
                Emitter::Distant(light) => light.direction.normalize(),
                Emitter::Point(_) => Vec3A::ZERO,
            })
            .collect();
        let positions: Vec<Option<Vec3A>> = lights
            .iter()
            .map(|l| match l {
                Emitter::Distant(_) => None,
                Emitter::Point(light) => Some(light.position),
            })
            .collect();
        let radiance_scale = [0, 1, 2].map(|c| lights.iter().map(|l| l.power()[c] / PI).collect());
        let direction_xyz = [0, 1, 2].map(|axis| directions.iter().map(|d| d[axis]).collect());
        let mut object_vertex = vec![false; mesh.positions.len()];
        for (tri, kind) in mesh.triangles.iter().zip(&mesh.kinds) {
            if matches!(kind, SurfaceKind::Object | SurfaceKind::Skirt) {
                tri.iter().for_each(|&v| object_vertex[v as usize] = true);
            }
        }
        let visibility_at = |points: &[Option<(Vec3A, Vec3A)>]| -> Vec<u8> {
            let k = directions.len();
            let mut out = vec![0u8; points.len() * k];
            out.par_chunks_mut(k.max(1))
                .zip(points)
                .for_each(|(row, point)| {
                    if let Some((p, n)) = point {
                        let origin = *p + *n * ray_offset;
                        for (k, slot) in row.iter_mut().enumerate() {
                            let (dir, t_max) = toward(&directions, &positions, k, origin);
                            *slot = u8::from(!tracer.occluded(origin, dir, t_max));
                        }
                    }
                });
            out
        };
        let vertex_points: Vec<_> = (0..mesh.positions.len())
            .map(|v| object_vertex[v].then(|| (mesh.positions[v], mesh.vertex_normals[v])))
            .collect();
        let vertex_visibility = visibility_at(&vertex_points);
        let panel_visibility = mesh
            .panels
            .iter()
            .map(|panel| {
                let (nu, nv) = panel.cells;
                let points: Vec<_> = (0..(nu + 1) * (nv + 1))
                    .map(|i| Some((panel.grid_point(i % (nu + 1), i / (nu + 1)), panel.normal)))
                    .collect();
                visibility_at(&points)
            })
            .collect();
        LightCache {
            any_point: positions.iter().any(Option::is_some),
            directions,
            positions,
            direction_xyz,
            radiance_scale,
            vertex_visibility,
            panel_visibility,
            environment_visibility,
            ray_offset,
        }
    }

    /// The same visibility, shading with the irradiance `irradiance` of each distant light
    /// (the intensity of each point light, divided by `area`: the working frame's squared
    /// scale, as [`crate::scene::Frame::local_emitter`] does) instead.
    pub fn with_irradiance(&self, irradiance: &[Rgb], area: f64) -> LightCache {
        let radiance_scale = [0, 1, 2].map(|c| {
            irradiance
                .iter()
                .zip(&self.positions)
                .map(|(e, position)| match position {
                    None => e[c] / PI,
                    Some(_) => (f64::from(e[c]) / area) as f32 / PI,
                })
                .collect()
        });
        LightCache {
            radiance_scale,
            ..self.clone()
        }
    }

    /// Number of lights.
    pub fn light_count(&self) -> usize {
        self.directions.len()
    }

    /// Adds `weight` times the radiance leaving a point of triangle `t` (barycentrics `u`,
    /// `v`, albedo `albedo`, position `point`, unit normal `n` on the side seen) under each
    /// light alone to `acc`, laid out by channel then light (`acc[c · K + k]`). The
    /// visibility is interpolated between the cache points; with `exact_edges`, a light that
    /// they disagree about (a shadow's edge crosses there) gets a real shadow ray instead. An
    /// environment mesh's point: see [`Self::add_environment_radiance`].
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub fn add_direct_radiance(
        &self,
        mesh: &Mesh,
        tracer: &Tracer,
        t: usize,
        (u, v): (f32, f32),
        point: Vec3A,
        n: Vec3A,
        albedo: Rgb,
        exact_edges: bool,
        weight: Rgb,
        acc: &mut [f32],
    ) {
        if mesh.is_environment(t) {
            self.add_environment_radiance(
                mesh,
                tracer,
                t,
                (u, v),
                (point, n),
                albedo,
                exact_edges,
                weight,
                acc,
            );
            return;
        }
        let k_count = self.directions.len();
        let panel = mesh.panel_of[t];
        let origin = point + n * self.ray_offset;
        let traced = |k: usize| {
            let (dir, t_max) = toward(&self.directions, &self.positions, k, origin);
            f32::from(u8::from(!tracer.occluded(origin, dir, t_max)))
        };
        if panel == NO_PANEL {
            let [a, b, c] = mesh.triangles[t]
                .map(|i| &self.vertex_visibility[i as usize * k_count..][..k_count]);
            let w = 1.0 - u - v;
            if exact_edges {
                self.add_shaded::<true>(n, point, albedo, weight, acc, |k| {
                    if a[k] == b[k] && b[k] == c[k] {
                        f32::from(a[k])
                    } else {
                        traced(k)
                    }
                });
            } else {
                self.add_shaded::<false>(n, point, albedo, weight, acc, |k| {
                    w * a[k] as f32 + u * b[k] as f32 + v * c[k] as f32
                });
            }
            return;
        }
        let panel_index = panel as usize;
        let grid: &Panel = &mesh.panels[panel_index];
        let Some((gs, gt)) = grid.grid_coords(point) else {
            self.add_traced_direct_radiance(tracer, point, n, albedo, weight, acc);
            return;
        };
        let (nu, nv) = grid.cells;
        let (a, b) = ((gs as usize).min(nu - 1), (gt as usize).min(nv - 1));
        let (fs, ft) = (gs - a as f32, gt - b as f32);
        let vis = &self.panel_visibility[panel_index];
        let row = |a: usize, b: usize| &vis[(b * (nu + 1) + a) * k_count..][..k_count];
        let (v00, v10, v01, v11) = (row(a, b), row(a + 1, b), row(a, b + 1), row(a + 1, b + 1));
        let (w00, w10, w01, w11) = (
            (1.0 - fs) * (1.0 - ft),
            fs * (1.0 - ft),
            (1.0 - fs) * ft,
            fs * ft,
        );
        if exact_edges {
            self.add_shaded::<true>(n, point, albedo, weight, acc, |k| {
                if v00[k] == v10[k] && v00[k] == v01[k] && v00[k] == v11[k] {
                    f32::from(v00[k])
                } else {
                    traced(k)
                }
            });
        } else {
            self.add_shaded::<false>(n, point, albedo, weight, acc, |k| {
                w00 * v00[k] as f32
                    + w10 * v10[k] as f32
                    + w01 * v01[k] as f32
                    + w11 * v11[k] as f32
            });
        }
    }

    /// Adds `weight` × albedo × E/π × max(0, n·l) × visibility of each light to `acc`
    /// (`acc[c · K + k]`), at the surface point `point` (E = I/r² for a point light). With
    /// `TRACED` the visibility (a shadow ray) is asked for only where the light is in front;
    /// otherwise it is read for every light (a light behind gets 0 all the same) and, where
    /// every light is distant, the loop over lights vectorises.
    #[inline(always)]
    fn add_shaded<const TRACED: bool>(
        &self,
        n: Vec3A,
        point: Vec3A,
        albedo: Rgb,
        weight: Rgb,
        acc: &mut [f32],
        visibility: impl Fn(usize) -> f32,
    ) {
        let k_count = self.directions.len();
        // Every slice cut to K, so that the loop runs without bounds checks.
        let [x, y, z] = [0, 1, 2].map(|axis| &self.direction_xyz[axis][..k_count]);
        let [scale_r, scale_g, scale_b] = [0, 1, 2].map(|c| &self.radiance_scale[c][..k_count]);
        let (red, rest) = acc[..3 * k_count].split_at_mut(k_count);
        let (green, blue) = rest.split_at_mut(k_count);
        if self.any_point {
            // Each point light's direction and inverse-square falloff are those of `point`,
            // light by light.
            for k in 0..k_count {
                let (cosine, falloff) = match self.positions[k] {
                    None => (n.dot(self.directions[k]).max(0.0), 1.0),
                    Some(position) => {
                        let offset = position - point;
                        let squared = offset.length_squared().max(f32::MIN_POSITIVE);
                        ((n.dot(offset) / squared.sqrt()).max(0.0), 1.0 / squared)
                    }
                };
                let factor = if TRACED && cosine == 0.0 {
                    0.0
                } else {
                    cosine * falloff * visibility(k)
                };
                red[k] += albedo[0] * scale_r[k] * factor * weight[0];
                green[k] += albedo[1] * scale_g[k] * factor * weight[1];
                blue[k] += albedo[2] * scale_b[k] * factor * weight[2];
            }
            return;
        }
        for k in 0..k_count {
            let cosine = (n.x * x[k] + n.y * y[k] + n.z * z[k]).max(0.0);
            let factor = if TRACED && cosine == 0.0 {
                0.0
            } else {
                cosine * visibility(k)
            };
            red[k] += albedo[0] * scale_r[k] * factor * weight[0];
            green[k] += albedo[1] * scale_g[k] * factor * weight[1];
            blue[k] += albedo[2] * scale_b[k] * factor * weight[2];
        }
    }

    /// [`Self::add_direct_radiance`] at a point of environment triangle `t` (a mesh index)
    /// seen on the side of `n`. Where the triangle is no larger than the cache's spacing (a
    /// pixel of the working frame), the shadow the environment casts on itself is
    /// interpolated between its corners (with `exact_edges`, a light that they disagree about
    /// gets a real shadow ray), and a light that reaches the point past the environment gets
    /// a shadow ray against the object alone; a larger triangle gets real shadow rays.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn add_environment_radiance(
        &self,
        mesh: &Mesh,
        tracer: &Tracer,
        t: usize,
        (u, v): (f32, f32),
        (point, n): (Vec3A, Vec3A),
        albedo: Rgb,
        exact_edges: bool,
        weight: Rgb,
        acc: &mut [f32],
    ) {
        let corners = mesh
            .environment
            .as_ref()
            .zip(self.environment_visibility.as_ref());
        let corners = corners.and_then(|(placed, visibility)| {
            placed
                .accel
                .corner_visibility(visibility, t - mesh.triangles.len(), placed.scale)
        });
        let Some([a, b, c]) = corners else {
            self.add_traced_direct_radiance(tracer, point, n, albedo, weight, acc);
            return;
        };
        let origin = point + n * offset_at(self.ray_offset, point);
        let past = |k: usize, environment: bool| {
            let (dir, t_max) = toward(&self.directions, &self.positions, k, origin);
            let blocked = if environment {
                tracer.occluded(origin, dir, t_max)
            } else {
                tracer.occluded_apart_from_environment(origin, dir, t_max)
            };
            f32::from(u8::from(!blocked))
        };
        let w = 1.0 - u - v;
        self.add_shaded::<true>(n, point, albedo, weight, acc, |k| {
            let [a, b, c] = [a, b, c].map(|row| lit(row, k));
            if a == b && b == c {
                if a == 0 {
                    0.0
                } else {
                    past(k, false)
                }
            } else if exact_edges {
                past(k, true)
            } else {
                (w * a as f32 + u * b as f32 + v * c as f32) * past(k, false)
            }
        });
    }

    /// Like [`Self::add_direct_radiance`], but with one real shadow ray per light in front.
    #[inline(always)]
    pub fn add_traced_direct_radiance(
        &self,
        tracer: &Tracer,
        point: Vec3A,
        n: Vec3A,
        albedo: Rgb,
        weight: Rgb,
        acc: &mut [f32],
    ) {
        let origin = point + n * offset_at(self.ray_offset, point);
        self.add_shaded::<true>(n, point, albedo, weight, acc, |k| {
            let (dir, t_max) = toward(&self.directions, &self.positions, k, origin);
            f32::from(u8::from(!tracer.occluded(origin, dir, t_max)))
        });
    }
}

/// Offset, relative to a point's largest coordinate, beyond which float32 resolves a step off
/// the surface however far from the working frame's origin the point lies (the far floor, an
/// environment mesh much larger than the object).
const RELATIVE_RAY_OFFSET: f32 = 1e-6;

/// How far a ray leaving `point` starts off its surface: `ray_offset`, or more far from the
/// working frame's origin, where float32 is coarser.
#[inline(always)]
pub fn offset_at(ray_offset: f32, point: Vec3A) -> f32 {
    ray_offset.max(point.abs().max_element() * RELATIVE_RAY_OFFSET)
}

/// The unit direction from `origin` toward light `k` and how far a shadow ray goes: to
/// infinity for a distant light, to the light for a point.
#[inline(always)]
fn toward(
    directions: &[Vec3A],
    positions: &[Option<Vec3A>],
    k: usize,
    origin: Vec3A,
) -> (Vec3A, f32) {
    match positions[k] {
        None => (directions[k], f32::INFINITY),
        Some(position) => {
            let offset = position - origin;
            let distance = offset.length();
            (offset / distance.max(f32::MIN_POSITIVE), distance)
        }
    }
}
