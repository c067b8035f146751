//! `tress.Scene` and `tress.load_scene`: scenes from files, dicts or RON text, rendered to
//! NumPy arrays by the render loop the command line uses.

use crate::convert::to_json;
use crate::to_py_err;
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray3};
use pyo3::exceptions::{PyRuntimeError, PyRuntimeWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::ffi::CString;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tress_core::prepare::Preparation;
use tress_core::render::{render_samples, SampleRender};
use tress_loader::integrators::IntegratorDesc;
use tress_loader::scene_desc::{self, BuiltScene, SceneDesc};

/// A scene, built and ready to render: its geometry, materials and lights, and the film and
/// integrator it was written with (which `render` can override).
///
/// Make one with `tress.load_scene(path)`, `Scene.from_dict(d)` or `Scene.from_ron(text)`.
/// Building happens once, there; each `render` reuses it, and the tables dual-scattering
/// integrators precompute are kept with the scene for later renders.
#[pyclass(module = "tress", frozen)]
pub struct Scene {
    desc: SceneDesc,
    /// What relative paths resolved against (its folder) and what error messages name.
    path: PathBuf,
    built: BuiltScene,
    prep: Preparation,
}

/// Loads and builds a scene file (RON), as `tress render` does.
///
/// Relative paths in it resolve against the file's folder. Raises `ValueError` for a malformed
/// or invalid scene (`file:line:column: message`), `OSError` (`FileNotFoundError`, …) for a
/// file that cannot be read. `table_cache`: a folder where precomputed tables (the fur model's
/// medulla tables) are read from and stored, so that later scenes and processes skip building
/// them; by default none (images do not depend on it).
#[pyfunction]
#[pyo3(signature = (path, table_cache=None))]
pub fn load_scene(py: Python<'_>, path: PathBuf, table_cache: Option<PathBuf>) -> PyResult<Scene> {
    let desc = scene_desc::load(&path).map_err(|e| to_py_err(&e))?;
    Scene::build(py, desc, path, table_cache)
}

impl Scene {
    fn build(
        py: Python<'_>,
        desc: SceneDesc,
        path: PathBuf,
        table_cache: Option<PathBuf>,
    ) -> PyResult<Scene> {
        let prep = Preparation::with_limits(crate::limits_from_env()).with_table_dir(table_cache);
        let built = py
            .detach(|| scene_desc::build(&desc, &path, &prep))
            .map_err(|e| to_py_err(&e))?;
        crate::warn_notes(py, &prep)?;
        Ok(Scene {
            desc,
            path,
            built,
            prep,
        })
    }

    /// The name errors give a scene made from `what` (`<dict>`, `<ron>`), in the folder its
    /// relative paths resolve against.
    fn virtual_path(base_dir: Option<PathBuf>, what: &str) -> PathBuf {
        // Without a folder, `<dict>` has an empty parent: relative paths stay relative, to the
        // current directory.
        base_dir.unwrap_or_default().join(what)
    }
}

#[pymethods]
impl Scene {
    /// A scene from a dict shaped like a scene file: structs are dicts, an enum variant is a
    /// one-key dict `{"Variant": {...}}` (or the string `"Variant"` when it has no fields),
    /// tuples and vectors are lists, e.g.
    ///
    ///     {"camera": {"look_from": [0, 0, 4], "look_at": [0, 0, 0], "fov": 35},
    ///      "film": {"width": 64, "height": 64, "spp": 16},
    ///      "materials": {"brown": {"Hair": {"Chiang": {"pigment": {"Melanin": {"eumelanin": 1.3}}}}}},
    ///      "objects": [{"Hair": {"source": {"Procedural": {"style": "Ball"}}, "material": "brown"}}],
    ///      "lights": [{"Sky": {}}]}
    ///
    /// Relative paths (hair files, meshes, environment maps) resolve against `base_dir`, by
    /// default the current directory. A value that does not fit raises `ValueError` naming where
    /// it sits (`objects[0].Hair.source: unknown variant ...`).
    #[staticmethod]
    #[pyo3(signature = (scene, base_dir=None, table_cache=None))]
    fn from_dict(
        py: Python<'_>,
        scene: &Bound<'_, PyDict>,
        base_dir: Option<PathBuf>,
        table_cache: Option<PathBuf>,
    ) -> PyResult<Scene> {
        let path = Self::virtual_path(base_dir, "<dict>");
        let value = to_json(scene.as_any(), "")?;
        let desc: SceneDesc = serde_path_to_error::deserialize(value).map_err(|e| {
            let at = e.path().to_string();
            let place = if at == "." {
                String::new()
            } else {
                format!("{at}: ")
            };
            PyValueError::new_err(format!("{}: {place}{}", path.display(), e.inner()))
        })?;
        Self::build(py, desc, path, table_cache)
    }

    /// A scene from the text of a scene file (RON). Relative paths resolve against `base_dir`,
    /// by default the current directory. Errors read `<ron>:line:column: message`.
    /// `table_cache` as for `load_scene`.
    #[staticmethod]
    #[pyo3(signature = (text, base_dir=None, table_cache=None))]
    fn from_ron(
        py: Python<'_>,
        text: &str,
        base_dir: Option<PathBuf>,
        table_cache: Option<PathBuf>,
    ) -> PyResult<Scene> {
        let path = Self::virtual_path(base_dir, "<ron>");
        let desc = scene_desc::parse(text)
            .map_err(|e| PyValueError::new_err(format!("{}:{e}", path.display())))?;
        Self::build(py, desc, path, table_cache)
    }

    /// The scene description as RON, as a scene file would hold it.
    fn to_ron(&self) -> PyResult<String> {
        tress_loader::ron_options()
            .to_string_pretty(&self.desc, ron::ser::PrettyConfig::default())
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// Film width in pixels.
    #[getter]
    fn width(&self) -> u32 {
        self.desc.film.width
    }

    /// Film height in pixels.
    #[getter]
    fn height(&self) -> u32 {
        self.desc.film.height
    }

    /// Samples per pixel the scene asks for.
    #[getter]
    fn spp(&self) -> u32 {
        self.desc.film.spp
    }

    /// Seed of the scene's film.
    #[getter]
    fn seed(&self) -> u64 {
        self.desc.film.seed
    }

    /// The scene's integrator, as RON (`Path(max_depth: 100, ...)`).
    #[getter]
    fn integrator(&self) -> PyResult<String> {
        tress_loader::ron_options()
            .to_string(&self.desc.integrator)
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// What was built: strands, segments, bounds, memory, build times (`tress info`).
    #[getter]
    fn summary(&self) -> &str {
        &self.built.summary
    }

    fn __repr__(&self) -> String {
        format!(
            "<tress.Scene {}: {}x{} at {} spp, {}>",
            self.path.display(),
            self.desc.film.width,
            self.desc.film.height,
            self.desc.film.spp,
            self.desc.integrator.name()
        )
    }

    /// Renders the scene; returns linear radiance as a float32 array of shape (height, width,
    /// 3), rows from the top of the image.
    ///
    /// Every argument overrides the scene's own setting: `spp` samples per pixel, `seed`,
    /// `integrator` (a name from `tress.INTEGRATORS` or RON such as `"Path(max_depth: 8)"`),
    /// `width`/`height` (the camera keeps its vertical field of view), `crop` a window
    /// `(x0, y0, x1, y1)` of the film (x1, y1 exclusive; the array then has that window's
    /// shape), `threads` the worker threads (default: all cores). The pixels depend only on the
    /// scene, the integrator and the seed: the same for any `threads` and `crop`, bit for bit.
    ///
    /// Rendering runs without the GIL; Ctrl-C (KeyboardInterrupt) stops it within a sample.
    #[pyo3(signature = (spp=None, seed=None, integrator=None, threads=None, crop=None, width=None, height=None))]
    #[allow(clippy::too_many_arguments)] // Python keyword arguments, each optional
    fn render<'py>(
        &self,
        py: Python<'py>,
        spp: Option<u32>,
        seed: Option<u64>,
        integrator: Option<&str>,
        threads: Option<usize>,
        crop: Option<[u32; 4]>,
        width: Option<u32>,
        height: Option<u32>,
    ) -> PyResult<Bound<'py, PyArray3<f32>>> {
        let here = self.path.display();
        let mut film = self.desc.film.clone();
        film.spp = spp.unwrap_or(film.spp);
        film.seed = seed.unwrap_or(film.seed);
        film.width = width.unwrap_or(film.width);
        film.height = height.unwrap_or(film.height);
        if crop.is_some() {
            film.crop = crop;
        }
        film.validate_for_render(&crate::limits_from_env())
            .map_err(|e| PyValueError::new_err(format!("{here}: film: {e}")))?;
        let integrator_desc = match integrator {
            Some(arg) => IntegratorDesc::parse_arg(arg).map_err(PyValueError::new_err)?,
            None => self.desc.integrator.clone(),
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(
                tress_loader::check_threads(threads.unwrap_or(0)).map_err(PyValueError::new_err)?,
            )
            .build()
            .map_err(|e| PyRuntimeError::new_err(format!("creating the thread pool: {e}")))?;
        let scene = &self.built.scene;
        let integrator = py
            .detach(|| pool.install(|| integrator_desc.build(scene, &self.prep)))
            .map_err(|e| {
                to_py_err(&tress_loader::Error::Integrator {
                    scene: self.path.clone(),
                    source: e,
                })
            })?;

        let cancel = AtomicBool::new(false);
        let samples = 0..u64::from(film.spp);
        let caller = std::thread::current();
        let done: SampleRender = std::thread::scope(|s| {
            let worker = s.spawn(|| {
                let result = pool.install(|| {
                    render_samples(scene, integrator.as_ref(), &film, samples, &cancel, &|_| {})
                });
                caller.unpark();
                result
            });
            // Wait without the GIL, waking now and then to let Python handle signals.
            while !worker.is_finished() {
                py.detach(|| std::thread::park_timeout(Duration::from_millis(100)));
                if let Err(interrupt) = py.check_signals() {
                    cancel.store(true, Ordering::SeqCst);
                    let _ = worker.join();
                    return Err(interrupt);
                }
            }
            match worker.join() {
                Ok(Some(done)) => Ok(done),
                Ok(None) => unreachable!("only an interrupt cancels, and it returned above"),
                Err(panic) => std::panic::resume_unwind(panic),
            }
        })?;

        let stats = &done.stats;
        if stats.nonfinite_samples > 0 {
            let message = format!(
                "{} of {} samples were NaN or infinite and were dropped (counted as black)",
                stats.nonfinite_samples, stats.samples
            );
            let message = CString::new(message).expect("no NUL in the message");
            PyErr::warn(py, &py.get_type::<PyRuntimeWarning>(), &message, 1)?;
        }
        let image = done.sums.image();
        let shape = (image.height as usize, image.width as usize, 3);
        let values: Vec<f32> = image.pixels.iter().flat_map(|p| p.to_array()).collect();
        let array = Array3::from_shape_vec(shape, values).expect("one RGB triple per pixel");
        Ok(array.into_pyarray(py))
    }
}
