//! Surroundings given as a mesh (contract §3b), made ready for ray queries once, in world
//! coordinates, and shared by every renderer of the scene: the object changes from pass to
//! pass, the environment does not, so its BVH is built once a run, and so is the shadow it
//! casts on itself ([`EnvironmentVisibility`]).

use std::sync::{Arc, Mutex, PoisonError};

use glam::Vec3A;
use obvhs::triangle::Triangle;
use rayon::prelude::*;

use crate::error::Result;
use crate::memory::{prefetch, with_huge_pages};
use crate::scene::{Emitter, EnvironmentMesh, Rgb};
use crate::trace::bvh::TriangleBvh;
use crate::trace::make_ray;

/// How far, relative to the size of the box around the mesh, a shadow ray from a vertex
/// starts toward its light (the renderer's own offset, relative to the scene's size).
const VERTEX_RAY_OFFSET: f32 = 1e-4;
/// The same offset relative to a vertex's largest coordinate, which float32 resolves
/// however far from the origin the mesh lies.
const RELATIVE_VERTEX_RAY_OFFSET: f32 = 1e-6;

/// An environment mesh with its triangles' normals and BVH, in world coordinates. Its
/// triangles are numbered in the BVH's order and its vertices in the order those triangles
/// first use them, so that what a hit reads lies together in memory.
pub struct EnvironmentAccel {
    mesh: EnvironmentMesh,
    /// What shading a point of each triangle reads, one cache line a triangle.
    shading: Vec<TriangleShading>,
    bvh: TriangleBvh,
    /// The corners of the box around its vertices.
    bounds: (Vec3A, Vec3A),
    /// The light visibility at the vertices last traced.
    visibility: Mutex<Option<Arc<EnvironmentVisibility>>>,
}

/// A triangle's unit normal as wound (zero for a degenerate one, which is left out of the
/// BVH), the length of its longest edge, its vertices' albedo and its vertices.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
struct TriangleShading {
    normal: [f32; 3],
    longest_edge: f32,
    albedo: [Rgb; 3],
    vertices: [u32; 3],
}

impl TriangleShading {
    fn new(mesh: &EnvironmentMesh, vertices: [u32; 3]) -> TriangleShading {
        let [a, b, c] = vertices.map(|v| mesh.positions[v as usize]);
        TriangleShading {
            normal: (b - a).cross(c - a).normalize_or_zero().to_array(),
            longest_edge: a.distance(b).max(b.distance(c)).max(c.distance(a)),
            albedo: vertices.map(|v| mesh.albedo[v as usize]),
            vertices,
        }
    }
}

/// Whether each light reaches each vertex of an environment mesh past the mesh itself: the
/// shadow that the surroundings cast on themselves, which does not change from pass to pass.
/// The object's shadow does, and is traced at each point where this one is known.
pub struct EnvironmentVisibility {
    /// Vertex v's row, `visible[v · R..(v + 1) · R]` (R = `row_bytes`), has bit k % 8 of its
    /// byte k / 8 set when light k reaches it: eight times less memory than a byte a light,
    /// so that a scan's rows, read at random vertices, stay in the caches.
    visible: Vec<u8>,
    row_bytes: usize,
    /// The position or direction of each light it was traced for ([`light_geometry`]).
    traced_for: Vec<[f32; 4]>,
}

impl EnvironmentVisibility {
    /// The visibility of every light at vertex `v`, eight lights a byte: see [`lit`].
    #[inline(always)]
    pub fn at_vertex(&self, v: u32) -> &[u8] {
        &self.visible[v as usize * self.row_bytes..][..self.row_bytes]
    }
}

/// 1 when light `k` reaches the vertex of `row` (a row of [`EnvironmentVisibility::at_vertex`]),
/// else 0.
#[inline(always)]
pub fn lit(row: &[u8], k: usize) -> u8 {
    (row[k / 8] >> (k % 8)) & 1
}

impl EnvironmentAccel {
    /// Checks `mesh` (naming the first bad vertex or triangle) and builds its BVH.
    pub fn new(mesh: EnvironmentMesh) -> Result<EnvironmentAccel> {
        mesh.validate()?;
        let shading: Vec<TriangleShading> = mesh
            .triangles
            .iter()
            .map(|&tri| TriangleShading::new(&mesh, tri))
            .collect();
        let (kept, degenerate): (Vec<u32>, Vec<u32>) =
            (0..mesh.triangles.len() as u32).partition(|&t| shading[t as usize].normal != [0.0; 3]);
        let tris = kept
            .iter()
            .map(|&t| {
                let [v0, v1, v2] = mesh.triangles[t as usize].map(|v| mesh.positions[v as usize]);
                Triangle { v0, v1, v2 }
            })
            .collect();
        let (mut bvh, order) = TriangleBvh::in_bvh_order(tris);
        bvh.onto_huge_pages()?;
        // The degenerate triangles, never hit, after the BVH's.
        let triangle_order: Vec<u32> = order
            .iter()
            .map(|&i| kept[i as usize])
            .chain(degenerate)
            .collect();
        let mesh = in_order(mesh, &triangle_order);
        // The same records in the new order, naming the renumbered vertices.
        let mut ordered = with_huge_pages(
            "the environment mesh's shading records",
            triangle_order.len(),
        )?;
        ordered.extend(
            triangle_order
                .iter()
                .zip(&mesh.triangles)
                .map(|(&t, &vertices)| TriangleShading {
                    vertices,
                    ..shading[t as usize]
                }),
        );
        let bounds = mesh
            .positions
            .iter()
            .fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), &p| {
                (lo.min(p), hi.max(p))
            });
        Ok(EnvironmentAccel {
            bvh,
            mesh,
            shading: ordered,
            bounds,
            visibility: Mutex::new(None),
        })
    }

    /// The visibility of each of `lights` (world units) at every vertex, the mesh alone
    /// occluding: traced the first time it is asked for these lights (one shadow ray per
    /// vertex and light, in parallel on rayon's pool, starting a little toward the light)
    /// and kept for the renderers that follow; the intensities do not matter.
    pub fn visibility(&self, lights: &[Emitter]) -> Result<Arc<EnvironmentVisibility>> {
        let key: Vec<[f32; 4]> = lights.iter().map(light_geometry).collect();
        let mut kept = self
            .visibility
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if let Some(visibility) = kept.as_ref().filter(|v| v.traced_for == key) {
            return Ok(Arc::clone(visibility));
        }
        let visibility = Arc::new(self.trace_visibility(lights, key)?);
        *kept = Some(Arc::clone(&visibility));
        Ok(visibility)
    }

    fn trace_visibility(
        &self,
        lights: &[Emitter],
        traced_for: Vec<[f32; 4]>,
    ) -> Result<EnvironmentVisibility> {
        let row_bytes = lights.len().div_ceil(8);
        let len = self.mesh.positions.len().saturating_mul(row_bytes);
        let mut visible = with_huge_pages(
            "the light visibility at the environment mesh's vertices",
            len,
        )?;
        visible.resize(len, 0u8);
        let (lo, hi) = self.bounds;
        let offset = VERTEX_RAY_OFFSET * (hi - lo).max_element();
        visible
            .par_chunks_mut(row_bytes.max(1))
            .zip(&self.mesh.positions)
            .for_each(|(row, &vertex)| {
                let start = offset.max(vertex.abs().max_element() * RELATIVE_VERTEX_RAY_OFFSET);
                for (k, light) in lights.iter().enumerate() {
                    let (direction, distance) = match light {
                        Emitter::Distant(light) => (light.direction.normalize(), f32::INFINITY),
                        Emitter::Point(light) => {
                            let offset = light.position - vertex;
                            let distance = offset.length();
                            (offset / distance.max(f32::MIN_POSITIVE), distance)
                        }
                    };
                    let reached = distance <= start
                        || !self.occluded(vertex + direction * start, direction, distance - start);
                    row[k / 8] |= u8::from(reached) << (k % 8);
                }
            });
        Ok(EnvironmentVisibility {
            visible,
            row_bytes,
            traced_for,
        })
    }

    /// The visibility rows of the corners of triangle `t` when its longest edge is at most
    /// `spacing` (world units): close enough for the visibility between them to be
    /// interpolated, as the renderer's light cache is between points about a pixel apart.
    #[inline(always)]
    pub fn corner_visibility<'a>(
        &self,
        visibility: &'a EnvironmentVisibility,
        t: usize,
        spacing: f32,
    ) -> Option<[&'a [u8]; 3]> {
        let shading = &self.shading[t];
        (shading.longest_edge <= spacing).then(|| shading.vertices.map(|v| visibility.at_vertex(v)))
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.mesh.triangles.len()
    }

    /// Whether it has no triangle.
    pub fn is_empty(&self) -> bool {
        self.mesh.triangles.is_empty()
    }

    /// The corners of the box around its vertices (world units).
    pub fn bounds(&self) -> (Vec3A, Vec3A) {
        self.bounds
    }

    /// Unit normal of triangle `t` as wound (both of its sides reflect).
    #[inline(always)]
    pub fn normal(&self, t: usize) -> Vec3A {
        Vec3A::from(self.shading[t].normal)
    }

    /// Albedo at barycentrics (`u`, `v`) of triangle `t`.
    #[inline(always)]
    pub fn albedo_at(&self, t: usize, u: f32, v: f32) -> Rgb {
        let [a, b, c] = self.shading[t].albedo;
        let w = 1.0 - u - v;
        [0, 1, 2].map(|ch| w * a[ch] + u * b[ch] + v * c[ch])
    }

    /// Corner positions of triangle `t` (world units).
    pub fn corners(&self, t: usize) -> [Vec3A; 3] {
        self.mesh.triangles[t].map(|i| self.mesh.positions[i as usize])
    }

    /// Position of vertex `v` (world units).
    pub fn position(&self, v: u32) -> Vec3A {
        self.mesh.positions[v as usize]
    }

    /// The nearest triangle along `origin + t·direction`, t in (0, `t_max`), world units:
    /// its index, distance and barycentrics.
    #[inline(always)]
    pub fn closest(
        &self,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
    ) -> Option<(u32, f32, f32, f32)> {
        // The shading record of each nearest triangle so far is asked for at once: a scan's
        // records lie far apart in memory, and the hit's is read right after the search.
        self.bvh
            .closest_hinted(make_ray(origin, direction, t_max), |t| {
                if let Some(shading) = self.shading.get(t as usize) {
                    prefetch(shading);
                }
            })
    }

    /// Whether a triangle lies along `origin + t·direction`, t in (0, `t_max`), world units.
    #[inline(always)]
    pub fn occluded(&self, origin: Vec3A, direction: Vec3A, t_max: f32) -> bool {
        self.bvh.any(make_ray(origin, direction, t_max))
    }
}

/// `mesh` with its triangles in the order `order` (a permutation of their indices) and its
/// vertices in the order those triangles first use them (any unused ones last).
fn in_order(mesh: EnvironmentMesh, order: &[u32]) -> EnvironmentMesh {
    let mut renumbered = vec![u32::MAX; mesh.positions.len()];
    let mut vertices = Vec::with_capacity(mesh.positions.len());
    let mut number = |v: u32| {
        if renumbered[v as usize] == u32::MAX {
            renumbered[v as usize] = vertices.len() as u32;
            vertices.push(v);
        }
        renumbered[v as usize]
    };
    let triangles: Vec<[u32; 3]> = order
        .iter()
        .map(|&t| mesh.triangles[t as usize].map(&mut number))
        .collect();
    (0..mesh.positions.len() as u32).for_each(|v| {
        number(v);
    });
    EnvironmentMesh {
        positions: vertices
            .iter()
            .map(|&v| mesh.positions[v as usize])
            .collect(),
        albedo: vertices.iter().map(|&v| mesh.albedo[v as usize]).collect(),
        triangles,
    }
}

/// What a light's shadows depend on: its position (w = 1) or its direction (w = 0).
fn light_geometry(light: &Emitter) -> [f32; 4] {
    match light {
        Emitter::Distant(light) => light.direction.extend(0.0).to_array(),
        Emitter::Point(light) => light.position.extend(1.0).to_array(),
    }
}
