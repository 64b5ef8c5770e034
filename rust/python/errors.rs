//! The Python exception of each core error, raised here and only here:
//! `irtps.errors.ArgumentError` for an argument, `DatasetError` for a file, `MemoryError` for
//! a buffer that could not be allocated.

use pyo3::exceptions::PyMemoryError;
use pyo3::prelude::*;

use crate::error::Error;

pyo3::import_exception!(irtps.errors, ArgumentError);
pyo3::import_exception!(irtps.errors, DatasetError);

/// `irtps.errors.ArgumentError(argument, problem)`: the message starts with the argument.
pub(super) fn argument_error(argument: &str, problem: impl Into<String>) -> PyErr {
    ArgumentError::new_err((argument.to_string(), problem.into()))
}

/// The Python exception of the core error `err`.
pub(super) fn to_py(err: Error) -> PyErr {
    match err {
        Error::Input { field, message } => argument_error(&field, message),
        Error::Io { .. } | Error::Format { .. } => DatasetError::new_err(err.to_string()),
        Error::Memory { .. } => PyMemoryError::new_err(err.to_string()),
    }
}

/// `err` with the core's input `field` renamed `argument`, the binding's name for it.
pub(super) fn renamed(err: Error, field: &str, argument: &str) -> Error {
    match err {
        Error::Input { field: f, message } if f == field => Error::input(argument, message),
        other => other,
    }
}
