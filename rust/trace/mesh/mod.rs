//! Triangle geometry of a scene, built exactly as the contract says: the height-field
//! triangulation, the skirt under its boundary, the floor, the Cornell-box walls and the
//! triangles of an environment mesh.
//!
//! Large flat surfaces are tessellated to about a pixel so that per-vertex light caching
//! (see [`crate::render::light_cache`]) resolves shadows on them.
//!
//! This module holds the mesh's types and accessors; `build` builds it from a scene.

use std::sync::Arc;

use glam::Vec3A;

use crate::scene::Rgb;
use crate::trace::environment::EnvironmentAccel;

mod build;

/// What a triangle belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SurfaceKind {
    /// The height field seen by the camera.
    Object,
    /// The vertical wall under the object's boundary.
    Skirt,
    /// The floor plane.
    Floor,
    /// A Cornell-box wall.
    Wall,
}

/// An environment mesh (contract §3b) placed in a mesh's working frame: its triangles stay
/// in world units, in their BVH built once a run; a point of the frame is `to_world` there.
/// Its triangles follow the mesh's: triangle `t` of the environment is the mesh's
/// `triangles.len() + t`. They reflect on both sides, and their light is traced at each
/// point rather than cached.
#[derive(Clone)]
pub struct PlacedEnvironment {
    pub accel: Arc<EnvironmentAccel>,
    /// World units per working-frame unit.
    pub scale: f32,
    /// World z of the working frame's origin.
    pub z_origin: f32,
}

impl PlacedEnvironment {
    /// The world point of working-frame point `p`.
    #[inline(always)]
    pub fn to_world(&self, p: Vec3A) -> Vec3A {
        Vec3A::new(
            p.x * self.scale,
            p.y * self.scale,
            p.z * self.scale + self.z_origin,
        )
    }
}

impl std::fmt::Debug for PlacedEnvironment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "PlacedEnvironment({} triangles)", self.accel.len())
    }
}

/// An indexed triangle mesh with per-vertex albedo and per-triangle facing normals.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    /// Vertex positions (world units).
    pub positions: Vec<Vec3A>,
    /// Vertex albedo, interpolated barycentrically across each triangle.
    pub albedo: Vec<Rgb>,
    /// Unit direction in which a ray leaving the vertex is offset (mean of the adjacent
    /// facing normals).
    pub vertex_normals: Vec<Vec3A>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[u32; 3]>,
    /// Unit geometric normal of each triangle, on its reflecting (front) side.
    pub normals: Vec<Vec3A>,
    /// Surface each triangle belongs to.
    pub kinds: Vec<SurfaceKind>,
    /// The panel each triangle belongs to, or [`NO_PANEL`] for the object's triangles
    /// (whose light is cached per vertex).
    pub panel_of: Vec<u32>,
    /// The flat rectangles of the surroundings (floor and walls).
    pub panels: Vec<Panel>,
    /// Index of the height-field vertex of each pixel (`u32::MAX` when it has none).
    pub pixel_vertex: Vec<u32>,
    /// The pixel whose albedo each vertex carries (`u32::MAX` for the surroundings').
    pub albedo_pixel: Vec<u32>,
    /// Where the height field's and the skirt's triangles lie on the pixel grid, for tracers
    /// that exploit it (shared with them, not copied); None when the mesh was not built from
    /// a height field.
    pub grid: Option<Arc<HeightFieldGrid>>,
    /// Surroundings given as a mesh, whose triangles follow this mesh's.
    pub environment: Option<PlacedEnvironment>,
}

/// The height-field part of a [`Mesh`] on its pixel grid. Block (i, j) is the square between
/// the vertices of pixels (i..=i+1, j..=j+1); a meshed block holds two triangles and, on the
/// sides where it borders no meshed block, a skirt.
#[derive(Debug, Clone, Default)]
pub struct HeightFieldGrid {
    /// Pixels per row.
    pub width: usize,
    /// Pixel rows.
    pub height: usize,
    /// World x of the vertices of each pixel column (increasing).
    pub xs: Vec<f32>,
    /// World y of the vertices of each pixel row (decreasing: y grows upward).
    pub ys: Vec<f32>,
    /// Height of each pixel's vertex, row-major (meaningful where the pixel has a vertex).
    pub z: Vec<f32>,
    /// Height of the skirt's bottom edge.
    pub base: f32,
    /// Mesh index of the first of each block's two triangles, row-major over the
    /// (height − 1) × (width − 1) blocks, or [`NO_TRIANGLE`] for a block that is not meshed.
    /// The triangles are (i,j) (i+1,j) (i,j+1) and (i,j+1) (i+1,j) (i+1,j+1), in that order.
    pub block_triangles: Vec<u32>,
    /// The skirt: one entry per boundary edge, ordered by block.
    pub skirt: Vec<SkirtEdge>,
}

/// The side of a block along which a skirt runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlockSide {
    /// The edge along pixel row i (the larger y).
    Top,
    /// The edge along pixel row i + 1.
    Bottom,
    /// The edge along pixel column j (the smaller x).
    Left,
    /// The edge along pixel column j + 1.
    Right,
}

/// The skirt under one boundary edge of the height field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SkirtEdge {
    /// Row-major index of the meshed block whose side this is.
    pub block: u32,
    /// Which side of the block.
    pub side: BlockSide,
    /// Mesh indices of the skirt's triangles.
    pub triangles: std::ops::Range<u32>,
}

/// `block_triangles` value of a block that is not meshed.
pub const NO_TRIANGLE: u32 = u32::MAX;

/// `panel_of` value of a triangle that belongs to no panel.
pub const NO_PANEL: u32 = u32::MAX;

/// A flat rectangle of the surroundings, `origin + s·edge_u + t·edge_v` for s, t in [0, 1],
/// meshed as two triangles. Its light is cached on a grid of `cells` over the parameter
/// window `grid_lo..grid_hi` (the whole panel, or the part near the object for the far floor);
/// outside the window, shadows are traced at each hit. An `unbounded` panel is traced as its
/// whole plane.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    pub origin: Vec3A,
    pub edge_u: Vec3A,
    pub edge_v: Vec3A,
    /// Unit normal of the reflecting side.
    pub normal: Vec3A,
    pub grid_lo: [f32; 2],
    pub grid_hi: [f32; 2],
    pub cells: (usize, usize),
    /// Stands in for an unbounded plane: ray queries treat it as the whole plane.
    pub unbounded: bool,
}

impl Panel {
    /// Continuous grid coordinates of `point`, or None outside the cached window.
    #[inline]
    pub fn grid_coords(&self, point: Vec3A) -> Option<(f32, f32)> {
        let d = point - self.origin;
        let s = d.dot(self.edge_u) / self.edge_u.length_squared();
        let t = d.dot(self.edge_v) / self.edge_v.length_squared();
        let gs = (s - self.grid_lo[0]) / (self.grid_hi[0] - self.grid_lo[0]) * self.cells.0 as f32;
        let gt = (t - self.grid_lo[1]) / (self.grid_hi[1] - self.grid_lo[1]) * self.cells.1 as f32;
        let inside =
            (0.0..=self.cells.0 as f32).contains(&gs) && (0.0..=self.cells.1 as f32).contains(&gt);
        inside.then_some((gs, gt))
    }

    /// World position of grid vertex (`a`, `b`).
    pub fn grid_point(&self, a: usize, b: usize) -> Vec3A {
        let s =
            self.grid_lo[0] + (self.grid_hi[0] - self.grid_lo[0]) * a as f32 / self.cells.0 as f32;
        let t =
            self.grid_lo[1] + (self.grid_hi[1] - self.grid_lo[1]) * b as f32 / self.cells.1 as f32;
        self.origin + self.edge_u * s + self.edge_v * t
    }
}

impl Mesh {
    /// Albedo at barycentric coordinates (`u`, `v`) of triangle `t` (weights 1−u−v, u, v
    /// on its vertices 0, 1, 2).
    #[inline]
    pub fn albedo_at(&self, t: usize, u: f32, v: f32) -> Rgb {
        if let Some(environment) = self.environment.as_ref().filter(|_| self.is_environment(t)) {
            return environment.accel.albedo_at(t - self.triangles.len(), u, v);
        }
        let [a, b, c] = self.triangles[t].map(|i| self.albedo[i as usize]);
        let w = 1.0 - u - v;
        [0, 1, 2].map(|ch| w * a[ch] + u * b[ch] + v * c[ch])
    }

    /// Whether triangle `t` is the environment mesh's.
    #[inline(always)]
    pub fn is_environment(&self, t: usize) -> bool {
        t >= self.triangles.len()
    }

    /// The unit normal of triangle `t` on the side a ray along `direction` meets: its facing
    /// normal, or the opposite one for an environment mesh's triangle seen from behind; None
    /// for the back of a one-sided surface (black).
    #[inline(always)]
    pub fn seen_normal(&self, t: usize, direction: Vec3A) -> Option<Vec3A> {
        if let Some(environment) = self.environment.as_ref().filter(|_| self.is_environment(t)) {
            let n = environment.accel.normal(t - self.triangles.len());
            return Some(if n.dot(direction) < 0.0 { n } else { -n });
        }
        let n = self.normals[t];
        (n.dot(direction) < 0.0).then_some(n)
    }

    /// Corner positions of triangle `t`.
    #[inline]
    pub fn corners(&self, t: usize) -> [Vec3A; 3] {
        self.triangles[t].map(|i| self.positions[i as usize])
    }

    /// Axis-aligned bounds of the object and the cached part of the panels (the far floor and
    /// an environment mesh left out); infinite when the scene is empty.
    pub fn near_bounds(&self) -> (Vec3A, Vec3A) {
        let mut lo = Vec3A::splat(f32::INFINITY);
        let mut hi = Vec3A::splat(f32::NEG_INFINITY);
        for (t, tri) in self.triangles.iter().enumerate() {
            if self.panel_of[t] == NO_PANEL {
                for &i in tri {
                    lo = lo.min(self.positions[i as usize]);
                    hi = hi.max(self.positions[i as usize]);
                }
            }
        }
        for p in &self.panels {
            for corner in [p.grid_point(0, 0), p.grid_point(p.cells.0, p.cells.1)] {
                lo = lo.min(corner);
                hi = hi.max(corner);
            }
        }
        (lo, hi)
    }

    /// Gives every vertex of the object the albedo of its pixel in `albedo` (one per pixel);
    /// the surroundings keep theirs.
    pub fn set_object_albedo(&mut self, albedo: &[Rgb]) {
        for (vertex, &pixel) in self.albedo.iter_mut().zip(&self.albedo_pixel) {
            if let Some(rgb) = albedo.get(pixel as usize) {
                *vertex = *rgb;
            }
        }
    }
}

#[cfg(test)]
mod tests;
