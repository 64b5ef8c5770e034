//! irtps core: the geometry, ray tracing, rendering and image I/O behind Iterative Ray
//! Tracing Photometric Stereo.
//!
//! The crate builds and tests without Python; the `python` feature adds the pyo3 bindings
//! (module `irtps._core`).

pub mod error;
pub mod integrate;
pub mod io;
pub mod memory;
pub mod ps;
pub mod render;
pub mod sampler;
pub mod scene;
pub mod trace;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, Result};
pub use render::{RenderSettings, Renderer};
pub use scene::{Camera, CornellBox, Floor, HeightField, Light, Rgb, Scene};
pub use trace::mesh::{Mesh, SurfaceKind};
pub use trace::{Hit, Tracer};
