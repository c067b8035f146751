//! `tress.study` (its Rust half): runs a study as `tress study` does, without the figures.

use crate::to_py_err;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use tress_study::{self as study, NotesOnStderr, StudySettings};

/// Runs the study file `path` as `tress study` does, without drawing figures (the module links
/// no plotting), and returns a dict: `folder`, `report`, `results_csv`, `summary_csv` (paths)
/// and the counts `rendered` and `reused`. The `tress.study` wrapper adds the summary rows.
/// `table_cache`: a folder where precomputed tables are read from and stored (default none).
#[pyfunction]
#[pyo3(signature = (path, quick=false, out=None, threads=None, verbose=false, table_cache=None))]
pub fn run_study<'py>(
    py: Python<'py>,
    path: PathBuf,
    quick: bool,
    out: Option<PathBuf>,
    threads: Option<usize>,
    verbose: bool,
    table_cache: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let settings = StudySettings {
        study: path,
        quick,
        out,
        threads: threads
            .map(tress_loader::check_threads)
            .transpose()
            .map_err(PyValueError::new_err)?,
        verbose,
        limits: crate::limits_from_env(),
        table_dir: table_cache,
    };
    let outputs = py
        .detach(|| study::run(&settings, &NotesOnStderr, None))
        .map_err(|e| match &e {
            // A transparent variant starts its chain past the error it wraps, whose type
            // decides the exception.
            study::Error::Output(output) => to_py_err(output),
            study::Error::Image(image) => to_py_err(image),
            other => to_py_err(other),
        })?;
    let dict = PyDict::new(py);
    dict.set_item("folder", outputs.folder)?;
    dict.set_item("report", outputs.report)?;
    dict.set_item("results_csv", outputs.results_csv)?;
    dict.set_item("summary_csv", outputs.summary_csv)?;
    dict.set_item("rendered", outputs.rendered)?;
    dict.set_item("reused", outputs.reused)?;
    Ok(dict)
}
