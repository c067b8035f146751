//! The error type of `tress-accel`: every variant names the file or object it is about.

use std::path::PathBuf;

/// Errors from reading mesh files, validating geometry and options and building the Embree
/// scene.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The hair handed to the builder (or its child strands) is invalid.
    #[error(transparent)]
    Groom(#[from] tress_groom::Error),
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
    /// The OBJ file could not be loaded: `line` (1-based) is the line at fault where tress
    /// finds it.
    #[error("{}{}: cannot load OBJ: {reason}", .path.display(), .line.map_or(String::new(), |l| format!(":{l}")))]
    Obj {
        /// The OBJ file.
        path: PathBuf,
        /// The 1-based line at fault, when tress can find it.
        line: Option<usize>,
        /// The OBJ loader's message.
        reason: String,
    },
    /// The geometry of an object (a file's contents or a generated object) is unusable.
    #[error(transparent)]
    InvalidGeometry(#[from] tress_groom::InvalidGeometry),
    /// An option of an object is out of range.
    #[error(transparent)]
    InvalidOption(#[from] tress_groom::InvalidOption),
    /// Embree reported an error.
    #[error("Embree: {0}")]
    Embree(String),
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
