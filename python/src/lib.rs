//! `tress._tress`: the Python extension module behind the `tress` package (`python/tress/`).
//!
//! It reaches the same code paths as the `tress` binary — scene files through
//! `tress_loader::scene_desc`, integrators through the registry in `tress_loader::integrators`, the
//! render loop of `tress_core::render`, hair models through `tress_materials::HairModel` and
//! studies through [`tress_study`] — so a scene renders to the same pixels from Python
//! as from the command line.

mod convert;
mod hair_model;
mod scene;
mod study;

use pyo3::exceptions::{
    PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyPermissionError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::PyTypeInfo;
use std::error::Error;
use std::io::ErrorKind;
use tress_core::image_io::ImageError;
use tress_core::output_file::OutputError;

/// A Rust error as a Python exception, with the message the command line would print (the
/// error and its causes, `scene.ron: objects[0]: head.obj: No such file or directory (os
/// error 2)`). The exception's type is chosen by the first cause that says what kind of
/// failure it is, never by the message: an operating system's error by its kind
/// (`FileNotFoundError`, `PermissionError`, `IsADirectoryError`, else `OSError`, with its
/// code), a missing image (`FileNotFoundError`), a folder in an output's place
/// (`IsADirectoryError`) or another output refused (`OSError`); with none, the input was bad
/// (`ValueError`: a scene, a parameter, a setting).
fn to_py_err(error: &(dyn Error + 'static)) -> PyErr {
    let causes = || std::iter::successors(Some(error), |&e| e.source());
    let message = causes()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(": ");
    let kind = causes().find_map(failure_kind);
    let code = causes()
        .find_map(|e| e.downcast_ref::<std::io::Error>())
        .and_then(std::io::Error::raw_os_error);
    match kind {
        None => PyValueError::new_err(message),
        Some(ErrorKind::NotFound) => os_error::<PyFileNotFoundError>(code, message),
        Some(ErrorKind::PermissionDenied) => os_error::<PyPermissionError>(code, message),
        Some(ErrorKind::IsADirectory) => os_error::<PyIsADirectoryError>(code, message),
        Some(_) => os_error::<PyOSError>(code, message),
    }
}

/// An `OSError` of type `T`; with the operating system's error code, Python sets its `errno`
/// and `strerror`.
fn os_error<T: PyTypeInfo>(code: Option<i32>, message: String) -> PyErr {
    match code {
        Some(code) => PyErr::new::<T, _>((code, message)),
        None => PyErr::new::<T, _>(message),
    }
}

/// The kind of failure `cause` is, if it is one of the file system's: `None` for an error that
/// leaves that to its source, or is about the input's contents.
fn failure_kind(cause: &(dyn Error + 'static)) -> Option<ErrorKind> {
    if let Some(io) = cause.downcast_ref::<std::io::Error>() {
        // Bytes that are not text are a bad input, not a failure to read it.
        return (io.kind() != ErrorKind::InvalidData).then(|| io.kind());
    }
    match cause.downcast_ref::<ImageError>() {
        Some(ImageError::NotFound { .. }) => return Some(ErrorKind::NotFound),
        Some(_) => return None,
        None => {}
    }
    match cause.downcast_ref::<OutputError>()? {
        OutputError::Io { .. } => None,
        OutputError::Directory { .. } => Some(ErrorKind::IsADirectory),
        _ => Some(ErrorKind::Other),
    }
}

#[pymodule]
fn _tress(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add(
        "INTEGRATORS",
        tress_loader::integrators::IntegratorDesc::NAMES.to_vec(),
    )?;
    m.add("HAIR_MODELS", tress_materials::HairModel::names().to_vec())?;
    m.add_class::<scene::Scene>()?;
    m.add_class::<hair_model::HairModel>()?;
    m.add_function(wrap_pyfunction!(scene::load_scene, m)?)?;
    m.add_function(wrap_pyfunction!(study::run_study, m)?)?;
    Ok(())
}

/// The run's limits as the environment sets them (`TRESS_MEMORY_LIMIT_GIB`,
/// `TRESS_ALLOW_SLOW_TABLES`): the module reads them here and hands them to the libraries, as
/// the `tress` command does.
fn limits_from_env() -> tress_core::limits::Limits {
    use tress_core::limits::{Limits, ALLOW_SLOW_TABLES_VAR, MEMORY_LIMIT_VAR};
    Limits::from_environment_values(
        std::env::var(MEMORY_LIMIT_VAR).ok().as_deref(),
        std::env::var_os(ALLOW_SLOW_TABLES_VAR).is_some(),
    )
}

/// The warnings among `prep`'s notes (a stored table refused, one that could not be stored) as
/// Python `RuntimeWarning`s.
fn warn_notes(py: Python<'_>, prep: &tress_core::prepare::Preparation) -> PyResult<()> {
    for line in prep.take_notes() {
        if let Some(text) = line.strip_prefix("warning: ") {
            let message = std::ffi::CString::new(text.replace('\0', " ")).expect("NULs replaced");
            PyErr::warn(
                py,
                &py.get_type::<pyo3::exceptions::PyRuntimeWarning>(),
                &message,
                1,
            )?;
        }
    }
    Ok(())
}
