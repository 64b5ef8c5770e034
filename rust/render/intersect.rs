//! Closest hits of batches of rays given in world units, traced in parallel.

use glam::vec3a;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::memory::try_vec;

use super::Renderer;

/// Rays a parallel task of [`Renderer::intersect`] traces as one batch.
const RAYS_PER_TASK: usize = 4096;

/// The closest hits of a batch of rays, in the rays' order.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchHits {
    /// Each ray's `t` at its hit, `origin + t·direction` in world units, ∞ on a miss.
    pub distances: Vec<f32>,
    /// Index of the triangle hit in the scene's mesh, −1 on a miss.
    pub triangles: Vec<i64>,
}

impl Renderer {
    /// Closest hits of the rays from `origins` along `directions` (x, y, z rows, world units,
    /// finite), traced on `threads` threads (rayon's pool, all cores, if `None`) in tasks of
    /// a few thousand rays. Refuses, by argument name, rows of different counts, a zero
    /// direction and no thread.
    pub fn intersect(
        &self,
        origins: &[f32],
        directions: &[f32],
        threads: Option<usize>,
    ) -> Result<BatchHits> {
        if origins.len() != directions.len() {
            return Err(Error::input("directions", "needs one row per origin"));
        }
        if let Some(row) = directions.chunks_exact(3).position(|d| d == [0.0; 3]) {
            return Err(Error::input(
                "directions",
                format!("row {row} is the zero vector"),
            ));
        }
        if threads == Some(0) {
            return Err(Error::input(
                "threads",
                "must be at least 1 (None: all cores)",
            ));
        }
        let (tracer, frame) = (self.tracer(), self.frame());
        let rays = origins.len() / 3;
        let mut t = try_vec(
            &format!("the distances of {rays} rays"),
            rays,
            f32::INFINITY,
        )?;
        let mut id = try_vec(&format!("the triangles of {rays} rays"), rays, -1i64)?;
        // A batch of rays (flat xyz rows) into its outputs.
        let batch = |t: &mut [f32], id: &mut [i64], o: &[f32], d: &[f32]| {
            let mut out = t.iter_mut().zip(id.iter_mut());
            let rays = o.chunks_exact(3).zip(d.chunks_exact(3)).map(|(o, d)| {
                (
                    frame.to_local(vec3a(o[0], o[1], o[2])),
                    vec3a(d[0], d[1], d[2]),
                )
            });
            tracer.closest_hits(rays, f32::INFINITY, |hit| {
                if let (Some((t, id)), Some(hit)) = (out.next(), hit) {
                    (*t, *id) = (frame.to_world_length(hit.t), hit.triangle as i64);
                }
            });
        };
        let parallel = |t: &mut [f32], id: &mut [i64]| {
            t.par_chunks_mut(RAYS_PER_TASK)
                .zip(id.par_chunks_mut(RAYS_PER_TASK))
                .zip(
                    origins
                        .par_chunks(3 * RAYS_PER_TASK)
                        .zip(directions.par_chunks(3 * RAYS_PER_TASK)),
                )
                .for_each(|((t, id), (o, d))| batch(t, id, o, d))
        };
        match threads {
            None => parallel(&mut t, &mut id),
            // One thread: one batch, without a pool or work splitting.
            Some(1) => batch(&mut t, &mut id, origins, directions),
            Some(n) => {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| Error::input("threads", format!("{e}")))?;
                pool.install(|| parallel(&mut t, &mut id));
            }
        }
        Ok(BatchHits {
            distances: t,
            triangles: id,
        })
    }
}
