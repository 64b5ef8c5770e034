//! The error type of the core: every variant names the input it is about.

use std::fmt;
use std::path::Path;

/// An error raised by the core, always naming the file or field concerned.
#[derive(Debug, Clone, PartialEq)]
pub enum Error {
    /// A file could not be opened, read or written.
    Io { path: String, message: String },
    /// A file was read but its content is not acceptable (format, channels, values).
    Format { path: String, message: String },
    /// An in-memory input (an argument or a field) is not acceptable.
    Input { field: String, message: String },
    /// A buffer could not be allocated: `what` it was for and its size in bytes, when known.
    Memory { what: String, bytes: Option<usize> },
}

impl Error {
    /// An I/O failure on `path`.
    pub fn io(path: &Path, err: impl fmt::Display) -> Self {
        Error::Io {
            path: path.display().to_string(),
            message: err.to_string(),
        }
    }

    /// A content problem in the file at `path`.
    pub fn format(path: &Path, message: impl Into<String>) -> Self {
        Error::Format {
            path: path.display().to_string(),
            message: message.into(),
        }
    }

    /// A problem with the input named `field`.
    pub fn input(field: &str, message: impl Into<String>) -> Self {
        Error::Input {
            field: field.to_string(),
            message: message.into(),
        }
    }

    /// No memory for `bytes` bytes of `what`.
    pub fn memory(what: impl Into<String>, bytes: usize) -> Self {
        Error::Memory {
            what: what.into(),
            bytes: Some(bytes),
        }
    }

    /// No memory for `what`, of a size that a third-party crate did not tell.
    pub fn memory_of_unknown_size(what: impl Into<String>) -> Self {
        Error::Memory {
            what: what.into(),
            bytes: None,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io { path, message } | Error::Format { path, message } => {
                write!(f, "{path}: {message}")
            }
            Error::Input { field, message } => write!(f, "{field}: {message}"),
            Error::Memory {
                what,
                bytes: Some(bytes),
            } => write!(f, "{what}: could not allocate {bytes} bytes"),
            Error::Memory { what, bytes: None } => write!(f, "{what}: could not allocate it"),
        }
    }
}

impl std::error::Error for Error {}

/// The result type of the core.
pub type Result<T> = std::result::Result<T, Error>;
