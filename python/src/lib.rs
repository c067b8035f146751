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

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use tress_core::output_file::OutputError;

/// A Rust error as a Python exception, with the message the command line would print: an
/// `OSError` when a file could not be read or written (with the OS error code, so Python raises
/// `FileNotFoundError`, `PermissionError`, …) or an output was refused (a folder, an input of
/// the study, a FIFO nobody reads), else a `ValueError` (bad input: a scene, a parameter, a
/// setting).
fn to_py_err(e: anyhow::Error) -> PyErr {
    let message = format!("{e:#}");
    let io = e
        .chain()
        .find_map(|cause| cause.downcast_ref::<std::io::Error>());
    let refused = e.chain().any(|cause| cause.is::<OutputError>());
    match (io.and_then(std::io::Error::raw_os_error), io) {
        (Some(code), _) => PyOSError::new_err((code, message)),
        (None, Some(_)) => PyOSError::new_err(message),
        (None, None) if refused => PyOSError::new_err(message),
        (None, None) => match os_error_code(&message) {
            Some(code) => PyOSError::new_err((code, message)),
            None => PyValueError::new_err(message),
        },
    }
}

/// The code in the `(os error N)` that ends an OS error's message. Building a scene reports the
/// causes of a failed object as text (`objects[0]: head.obj: No such file or directory (os
/// error 2)`), so a missing file is recognised there.
fn os_error_code(message: &str) -> Option<i32> {
    let start = message.rfind("(os error ")? + "(os error ".len();
    let end = start + message[start..].find(')')?;
    message[start..end].parse().ok()
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
