//! irtps core: the geometry, ray tracing, rendering and image I/O behind Iterative Ray
//! Tracing Photometric Stereo.
//!
//! The crate builds and tests without Python; the `python` feature adds the pyo3 bindings
//! (module `irtps._core`).
//!
//! The modules, each importing only those above it (`python` any of them):
//! - [`error`], [`memory`]: the core's errors, and allocations that fail as errors;
//! - [`sampler`]: the renderer's random numbers (also the tests' and benches');
//! - [`scene`]: the scene description of the data-set contract and its working frame;
//! - [`io`]: EXR and PNG images;
//! - [`ps`]: photometric stereo, a module per robust mode;
//! - [`integrate`]: the sparse Cholesky factorisation that normal integration solves with;
//! - [`trace`]: the scene's triangles and the ray queries over them;
//! - [`render`]: the forward renderer and its light cache, the comparison of a rendering
//!   with the images, and the filter of its inter-reflection estimate;
//! - `python` (feature `python`): the bindings, conversions only.

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
pub use scene::{Camera, CornellBox, Floor, HeightField, Light, Pinhole, Rgb, Scene};
pub use trace::mesh::{Mesh, SurfaceKind};
pub use trace::{Hit, Tracer};
