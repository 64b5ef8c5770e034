//! irtps core: the geometry, ray tracing, rendering and image I/O behind Iterative Ray
//! Tracing Photometric Stereo.
//!
//! The crate builds and tests without Python; the `python` feature adds the pyo3 bindings
//! (module `irtps._core`).

pub mod denoise;
pub mod error;
mod escape_cone;
pub mod geometry;
pub mod height_field_accel;
pub mod image_io;
mod lanes;
pub mod light_cache;
pub mod lobe;
pub mod memory;
pub mod ps;
pub mod render;
pub mod residual;
pub mod robust_ps;
pub mod sampler;
pub mod scene;
pub mod sparse_cholesky;
pub mod tracer;
pub mod tukey;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, Result};
pub use geometry::{Mesh, SurfaceKind};
pub use render::{RenderSettings, Renderer};
pub use scene::{Camera, CornellBox, Floor, HeightField, Light, Rgb, Scene};
pub use tracer::{Hit, Tracer};
