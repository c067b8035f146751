//! The error type of `tress-groom`: every variant names the file or object it is about.

use std::path::PathBuf;

/// Errors from reading groom files, generating hair and validating strand geometry.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The file could not be opened or read. The message leaves the cause to the source, so
    /// that a chain printed whole (`{:#}`) names it once.
    #[error("{}", .path.display())]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The file was read but its contents are not a valid file of the expected format.
    #[error("{}: {reason}", .path.display())]
    Format {
        /// The file concerned.
        path: PathBuf,
        /// What is wrong, e.g. a truncated header or an unknown extension.
        reason: String,
    },
    /// The geometry of an object (a file's contents or a generated object) is unusable.
    #[error(transparent)]
    InvalidGeometry(#[from] InvalidGeometry),
    /// An option of an object is out of range.
    #[error(transparent)]
    InvalidOption(#[from] InvalidOption),
}

/// The geometry of an object (a file's contents or a generated object) is unusable. Shared with
/// `tress-accel`, whose meshes and spheres are refused the same way.
#[derive(Debug, thiserror::Error)]
#[error("{object}: {reason}")]
pub struct InvalidGeometry {
    /// Name of the object: its file, generator description or `sphere #n`.
    pub object: String,
    /// What makes it unusable.
    pub reason: String,
}

/// An option of an object is out of range. Shared with `tress-accel`, whose meshes and spheres
/// are refused the same way.
#[derive(Debug, thiserror::Error)]
#[error("{object}: invalid `{field}`: {reason}")]
pub struct InvalidOption {
    /// Name of the object: its file, generator description or `sphere #n`.
    pub object: String,
    /// The option at fault, e.g. `radius`.
    pub field: &'static str,
    /// The allowed range and the value given.
    pub reason: String,
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Shorthand for a [`Error::Format`] about `path`.
pub(crate) fn format_error(path: &std::path::Path, reason: impl Into<String>) -> Error {
    Error::Format {
        path: path.to_owned(),
        reason: reason.into(),
    }
}
