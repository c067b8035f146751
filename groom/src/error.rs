//! The error type of `tress-groom`: every variant names the file or object it is about.

use std::path::PathBuf;

/// Errors from reading groom files, generating hair and validating strand geometry.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The file could not be opened or read.
    #[error("{}: {source}", .path.display())]
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
    #[error("{object}: {reason}")]
    InvalidGeometry {
        /// Name of the object: its file or generator description.
        object: String,
        /// What makes it unusable.
        reason: String,
    },
    /// An option of an object is out of range.
    #[error("{object}: invalid `{field}`: {reason}")]
    InvalidOption {
        /// Name of the object: its file or generator description.
        object: String,
        /// The option at fault, e.g. `radius`.
        field: &'static str,
        /// The allowed range and the value given.
        reason: String,
    },
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
