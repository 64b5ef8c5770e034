//! The mesh of a scene, built exactly as the contract says: the height-field triangulation,
//! the skirt under its boundary, the floor and the Cornell-box walls (an environment mesh is
//! placed beside them: [`super::PlacedEnvironment`]).

use std::sync::Arc;

use glam::{vec3a, Vec3A};

use crate::scene::{Rgb, Scene};

use super::{
    BlockSide, HeightFieldGrid, Mesh, Panel, SkirtEdge, SurfaceKind, NO_PANEL, NO_TRIANGLE,
};

/// Cells per side beyond which a flat surface is tessellated more coarsely than a pixel.
const MAX_CELLS_PER_SIDE: usize = 256;
/// Vertical subdivisions of a skirt quad at most.
const MAX_SKIRT_ROWS: usize = 32;
/// Size of the unbounded floor (no box) relative to its cached part near the object.
const FAR_FLOOR_SCALE: f32 = 1000.0;

impl Mesh {
    /// Builds the geometry of `scene`.
    pub fn from_scene(scene: &Scene) -> Mesh {
        let mut mesh = Mesh::default();
        mesh.add_height_field(scene);
        if let Some(b) = &scene.cornell_box {
            mesh.add_cornell_box(scene, b);
        }
        if let Some(f) = &scene.floor {
            mesh.add_floor(scene, f.height, f.albedo);
        }
        mesh.finish_vertex_normals();
        mesh
    }

    fn add_vertex(&mut self, p: Vec3A, albedo: Rgb, pixel: u32) -> u32 {
        self.positions.push(p);
        self.albedo.push(albedo);
        self.albedo_pixel.push(pixel);
        (self.positions.len() - 1) as u32
    }

    /// Adds a triangle wound so that its normal points to the `facing` side.
    fn add_triangle(&mut self, mut tri: [u32; 3], facing: Vec3A, kind: SurfaceKind, panel: u32) {
        let [a, b, c] = tri.map(|i| self.positions[i as usize]);
        let mut n = (b - a).cross(c - a);
        if n.dot(facing) < 0.0 {
            tri.swap(1, 2);
            n = -n;
        }
        let n = n.normalize_or_zero();
        if n == Vec3A::ZERO {
            return;
        }
        self.triangles.push(tri);
        self.normals.push(n);
        self.kinds.push(kind);
        self.panel_of.push(panel);
    }

    /// A rectangle `origin + [0,1]·edge_u + [0,1]·edge_v` as two triangles, facing `facing`,
    /// with its light cached on `cells` over the parameter window `grid_lo..grid_hi`.
    #[allow(clippy::too_many_arguments)]
    fn add_panel(
        &mut self,
        origin: Vec3A,
        edge_u: Vec3A,
        edge_v: Vec3A,
        albedo: Rgb,
        kind: SurfaceKind,
        window: ([f32; 2], [f32; 2]),
        cells: (usize, usize),
    ) -> usize {
        let normal = edge_u.cross(edge_v).normalize();
        let id = self.panels.len() as u32;
        self.panels.push(Panel {
            origin,
            edge_u,
            edge_v,
            normal,
            grid_lo: window.0,
            grid_hi: window.1,
            cells,
            unbounded: false,
        });
        let c = [
            origin,
            origin + edge_u,
            origin + edge_u + edge_v,
            origin + edge_v,
        ]
        .map(|p| self.add_vertex(p, albedo, u32::MAX));
        self.add_triangle([c[0], c[1], c[2]], normal, kind, id);
        self.add_triangle([c[0], c[2], c[3]], normal, kind, id);
        id as usize
    }

    fn add_height_field(&mut self, scene: &Scene) {
        let cam = &scene.camera;
        let (w, h) = (cam.width, cam.height);
        let surface = &scene.surface;
        let masked = |i: usize, j: usize| surface.mask[i * w + j];
        // Block (i, j) holds pixels (i..=i+1, j..=j+1); it is meshed when all four are masked.
        let block = |i: isize, j: isize| -> bool {
            if i < 0 || j < 0 || i + 1 >= h as isize || j + 1 >= w as isize {
                return false;
            }
            let (i, j) = (i as usize, j as usize);
            masked(i, j) && masked(i + 1, j) && masked(i, j + 1) && masked(i + 1, j + 1)
        };
        self.pixel_vertex = vec![u32::MAX; w * h];
        for i in 0..h {
            for j in 0..w {
                let (ii, jj) = (i as isize, j as isize);
                let used = block(ii - 1, jj - 1)
                    || block(ii - 1, jj)
                    || block(ii, jj - 1)
                    || block(ii, jj);
                if used {
                    let p = i * w + j;
                    self.pixel_vertex[p] = self.add_vertex(
                        cam.surface_point(i, j, surface.height[p]),
                        surface.albedo[p],
                        p as u32,
                    );
                }
            }
        }
        let pixel_vertex = self.pixel_vertex.clone();
        let v = |i: usize, j: usize| pixel_vertex[i * w + j];
        // Facing +z, or for a pinhole its optical centre (the blocks' winding faces it).
        let facing = |mesh: &Mesh, corner: u32| match cam.pinhole {
            None => Vec3A::Z,
            Some(p) => vec3a(0.0, 0.0, p.center_z) - mesh.positions[corner as usize],
        };
        let (bw, bh) = (w.saturating_sub(1), h.saturating_sub(1));
        let mut block_triangles = vec![NO_TRIANGLE; bw * bh];
        let mut on_grid = true;
        for i in 0..bh {
            for j in 0..bw {
                if block(i as isize, j as isize) {
                    let first = self.triangles.len();
                    let t1 = [v(i, j), v(i + 1, j), v(i, j + 1)];
                    let t2 = [v(i, j + 1), v(i + 1, j), v(i + 1, j + 1)];
                    self.add_triangle(t1, facing(self, t1[0]), SurfaceKind::Object, NO_PANEL);
                    self.add_triangle(t2, facing(self, t2[2]), SurfaceKind::Object, NO_PANEL);
                    // Only a degenerate pixel size drops a block's triangle; the grid then
                    // cannot stand for the mesh.
                    on_grid &= self.triangles.len() == first + 2;
                    block_triangles[i * bw + j] = first as u32;
                }
            }
        }
        // Skirt under every boundary edge: an edge shared by exactly one meshed block.
        let base = scene.base_height();
        let mut skirt = Vec::new();
        for i in 0..h {
            for j in 0..w {
                let (ii, jj) = (i as isize, j as isize);
                // Horizontal edge (i, j)–(i, j+1): block (i−1, j) above it, (i, j) below it.
                if j + 1 < w && block(ii - 1, jj) != block(ii, jj) {
                    let (outward, owner) = if block(ii, jj) {
                        (Vec3A::Y, (i, j, BlockSide::Top))
                    } else {
                        (-Vec3A::Y, (i - 1, j, BlockSide::Bottom))
                    };
                    let triangles =
                        self.add_skirt(v(i, j), v(i, j + 1), outward, base, cam.pixel_size);
                    skirt.push(SkirtEdge {
                        block: (owner.0 * bw + owner.1) as u32,
                        side: owner.2,
                        triangles,
                    });
                }
                // Vertical edge (i, j)–(i+1, j): block (i, j−1) left of it, (i, j) right of it.
                if i + 1 < h && block(ii, jj - 1) != block(ii, jj) {
                    let (outward, owner) = if block(ii, jj) {
                        (-Vec3A::X, (i, j, BlockSide::Left))
                    } else {
                        (Vec3A::X, (i, j - 1, BlockSide::Right))
                    };
                    let triangles =
                        self.add_skirt(v(i, j), v(i + 1, j), outward, base, cam.pixel_size);
                    skirt.push(SkirtEdge {
                        block: (owner.0 * bw + owner.1) as u32,
                        side: owner.2,
                        triangles,
                    });
                }
            }
        }
        skirt.retain(|edge| !edge.triangles.is_empty());
        skirt.sort_by_key(|edge| edge.block);
        // A pinhole's vertices are not on a grid: its blocks go to the BVH.
        if on_grid && bw > 0 && bh > 0 && cam.pinhole.is_none() {
            self.grid = Some(Arc::new(HeightFieldGrid {
                width: w,
                height: h,
                xs: (0..w).map(|j| cam.surface_point(0, j, base).x).collect(),
                ys: (0..h).map(|i| cam.surface_point(i, 0, base).y).collect(),
                z: surface.height.clone(),
                base,
                block_triangles,
                skirt,
            }));
        }
    }

    /// Adds the skirt under the edge `top_a`–`top_b`; returns the range of its triangles.
    fn add_skirt(
        &mut self,
        top_a: u32,
        top_b: u32,
        outward: Vec3A,
        base: f32,
        pixel_size: f32,
    ) -> std::ops::Range<u32> {
        let first = self.triangles.len() as u32;
        let (pa, pb) = (
            self.positions[top_a as usize],
            self.positions[top_b as usize],
        );
        let (albedo_a, albedo_b) = (
            (
                self.albedo[top_a as usize],
                self.albedo_pixel[top_a as usize],
            ),
            (
                self.albedo[top_b as usize],
                self.albedo_pixel[top_b as usize],
            ),
        );
        let drop = pa.z.max(pb.z) - base;
        if drop <= 0.0 {
            return first..first;
        }
        let rows = ((drop / pixel_size).ceil() as usize).clamp(1, MAX_SKIRT_ROWS);
        let column = |mesh: &mut Mesh, top: Vec3A, (albedo, pixel): (Rgb, u32)| -> Vec<u32> {
            let z_top = top.z.max(base);
            (0..=rows)
                .map(|r| {
                    let z = z_top + (base - z_top) * r as f32 / rows as f32;
                    mesh.add_vertex(vec3a(top.x, top.y, z), albedo, pixel)
                })
                .collect()
        };
        let col_a = column(self, pa, albedo_a);
        let col_b = column(self, pb, albedo_b);
        for r in 0..rows {
            self.add_triangle(
                [col_a[r], col_b[r], col_a[r + 1]],
                outward,
                SurfaceKind::Skirt,
                NO_PANEL,
            );
            self.add_triangle(
                [col_b[r], col_b[r + 1], col_a[r + 1]],
                outward,
                SurfaceKind::Skirt,
                NO_PANEL,
            );
        }
        first..self.triangles.len() as u32
    }

    fn add_cornell_box(&mut self, scene: &Scene, b: &crate::scene::CornellBox) {
        let z0 = scene.base_height();
        let [x0, x1] = b.x;
        let [y0, y1] = b.y;
        let s = scene.camera.pixel_size;
        let up = Vec3A::Z * (b.z_top - z0);
        let (ex, ey) = (Vec3A::X * (x1 - x0), Vec3A::Y * (y1 - y0));
        let (nx, ny, nz) = (
            cells_for(x1 - x0, s),
            cells_for(y1 - y0, s),
            cells_for(b.z_top - z0, s),
        );
        let whole = ([0.0, 0.0], [1.0, 1.0]);
        let kind = SurfaceKind::Wall;
        // Edge order makes edge_u × edge_v point into the box.
        self.add_panel(vec3a(x0, y0, z0), ey, up, b.left, kind, whole, (ny, nz));
        self.add_panel(vec3a(x1, y0, z0), up, ey, b.right, kind, whole, (nz, ny));
        self.add_panel(vec3a(x0, y1, z0), ex, up, b.back, kind, whole, (nx, nz));
        self.add_panel(vec3a(x0, y0, z0), up, ex, b.front, kind, whole, (nz, nx));
    }

    fn add_floor(&mut self, scene: &Scene, z0: f32, albedo: Rgb) {
        let s = scene.camera.pixel_size;
        let kind = SurfaceKind::Floor;
        if let Some(b) = &scene.cornell_box {
            let (sx, sy) = (b.x[1] - b.x[0], b.y[1] - b.y[0]);
            let cells = (cells_for(sx, s), cells_for(sy, s));
            let origin = vec3a(b.x[0], b.y[0], z0);
            self.add_panel(
                origin,
                Vec3A::X * sx,
                Vec3A::Y * sy,
                albedo,
                kind,
                ([0.0, 0.0], [1.0, 1.0]),
                cells,
            );
            return;
        }
        // Unbounded floor: one large panel, cached only near the object.
        let (lo, hi) = self.near_floor_extent(scene);
        let reach = FAR_FLOOR_SCALE * (hi.0 - lo.0).max(hi.1 - lo.1);
        let (fx0, fy0, size) = (
            lo.0 - reach,
            lo.1 - reach,
            2.0 * reach + (hi.0 - lo.0).max(hi.1 - lo.1),
        );
        let window = (
            [(lo.0 - fx0) / size, (lo.1 - fy0) / size],
            [(hi.0 - fx0) / size, (hi.1 - fy0) / size],
        );
        let cells = (cells_for(hi.0 - lo.0, s), cells_for(hi.1 - lo.1, s));
        let id = self.add_panel(
            vec3a(fx0, fy0, z0),
            Vec3A::X * size,
            Vec3A::Y * size,
            albedo,
            kind,
            window,
            cells,
        );
        self.panels[id].unbounded = true;
    }

    /// The part of an unbounded floor whose light is cached: the camera's view of the floor
    /// and the object's longest likely shadows (three times its height) around it.
    fn near_floor_extent(&self, scene: &Scene) -> ((f32, f32), (f32, f32)) {
        let cam = &scene.camera;
        let base = scene.base_height();
        let (x0, y1) = cam.image_to_world(0.0, 0.0, base);
        let (x1, y0) = cam.image_to_world(cam.height as f32, cam.width as f32, base);
        let top = self
            .positions
            .iter()
            .map(|p| p.z)
            .fold(scene.base_height(), f32::max);
        let margin = 3.0 * (top - scene.base_height()) + cam.pixel_size;
        ((x0 - margin, y0 - margin), (x1 + margin, y1 + margin))
    }

    fn finish_vertex_normals(&mut self) {
        let mut sum = vec![Vec3A::ZERO; self.positions.len()];
        for (tri, n) in self.triangles.iter().zip(&self.normals) {
            for &i in tri {
                sum[i as usize] += *n;
            }
        }
        self.vertex_normals = sum.into_iter().map(|n| n.normalize_or(Vec3A::Z)).collect();
    }
}

fn cells_for(length: f32, pixel_size: f32) -> usize {
    ((length / pixel_size).ceil() as usize).clamp(1, MAX_CELLS_PER_SIDE)
}
