//! The pyo3 bindings (`irtps._core`): conversions only. Each binding converts its
//! arguments, releases the GIL and calls the core; every core error becomes, here and only
//! here, the Python exception that irtps raises for it: `irtps.errors.ArgumentError` for an
//! argument, `DatasetError` for a file, `MemoryError` for a buffer that could not be
//! allocated. Their types for Python are in python/irtps/_core.pyi.
//!
//! The modules: `errors`, the exception of each core error; `convert`, the conversions that
//! several bindings share; then a module per domain: `io` (image files), `ps` (photometric
//! stereo), `render` (the renderer and its ray queries), `estimate` (the inter-reflection
//! estimate compared and filtered), `integrate` (the sparse Cholesky factorisation and the
//! discontinuity-preserving integration).

use pyo3::exceptions::PyMemoryError;
use pyo3::prelude::*;

mod convert;
mod errors;
mod estimate;
mod integrate;
mod io;
mod ps;
mod render;

/// The compiled core of irtps.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // The core's threads are started at import: rayon starts them on first use, and panics
    // there when one cannot be started (its stack is address space, which a limit such as
    // `ulimit -v` may have run out of by then).
    if let Err(err) = rayon::ThreadPoolBuilder::new().build_global() {
        // An I/O error is a thread that could not be started; else the pool was running.
        if std::error::Error::source(&err).is_some() {
            return Err(PyMemoryError::new_err(format!(
                "the core's threads could not be started ({err})"
            )));
        }
    }
    m.add_function(wrap_pyfunction!(io::read_exr, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_png, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_png, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_images, m)?)?;
    m.add_function(wrap_pyfunction!(ps::photometric_stereo, m)?)?;
    m.add_function(wrap_pyfunction!(ps::photometric_stereo_per_pixel, m)?)?;
    m.add_function(wrap_pyfunction!(ps::tukey_with_lobe_check, m)?)?;
    m.add_function(wrap_pyfunction!(ps::check_lights, m)?)?;
    m.add_function(wrap_pyfunction!(estimate::compare_rendering, m)?)?;
    m.add_function(wrap_pyfunction!(estimate::denoise_indirect, m)?)?;
    m.add_class::<render::Renderer>()?;
    m.add_class::<render::Environment>()?;
    m.add_class::<integrate::SparseCholesky>()?;
    m.add_function(wrap_pyfunction!(integrate::integrate_bilateral, m)?)?;
    m.add("MAX_IMAGE_PIXELS", crate::io::MAX_IMAGE_PIXELS)?;
    Ok(())
}
