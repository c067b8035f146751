//! `tress.HairModel`: a fiber scattering model evaluated, sampled and its pdf computed over
//! NumPy arrays, in the local fiber frame of `tress_core::bcsdf`.

use numpy::ndarray::{Array1, Array2};
use numpy::{AllowTypeChange, IntoPyArray, PyArrayLikeDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyFloat;
use rayon::prelude::*;
use std::sync::Arc;
use tress_core::math::{unit, Vec3};
use tress_core::Bcsdf;

/// A hair scattering model (BCSDF), written as in scene files:
/// `HairModel("Chiang(beta_m: 0.3, pigment: Melanin(eumelanin: 1.3))")`; the models are
/// `tress.HAIR_MODELS`.
///
/// Every method works in the local fiber frame: x = the fiber tangent (root → tip), z = toward
/// the viewer orthogonal to x, y = z × x; sin θ = ω.x, φ = atan2(ω.z, ω.y); `h` in [-1, 1] is
/// the signed offset of the hit across the fiber along y, so specular reflection leaves at
/// φ_i − φ_o = −2 asin h. Directions point away from the fiber and are normalised; `wo` is the
/// direction toward the viewer, `wi` toward the light.
///
/// Arguments are NumPy arrays (or anything `numpy.asarray` takes): directions of shape (N, 3)
/// or (3,), offsets `h` of shape (N,) or a number, random numbers `u` of shape (N, 4) or (4,).
/// Single values apply to every row; with no (N, …) argument the result is a single value.
#[pyclass(module = "tress", frozen)]
pub struct HairModel {
    model: tress_materials::HairModel,
    bcsdf: Arc<dyn Bcsdf>,
}

/// An array argument, read as f64 so that range checks see the value as given: f64 numbers
/// just below 1 round to 1.0 in f32.
type Input<'py> = PyArrayLikeDyn<'py, f64, AllowTypeChange>;

/// One argument's rows: a single value applying to every row, or one per row.
struct Rows<T> {
    values: Vec<T>,
    batched: bool,
}

impl<T: Copy> Rows<T> {
    fn get(&self, i: usize) -> T {
        self.values[if self.batched { i } else { 0 }]
    }
}

/// The rows of `array`: vectors of `K` components (shape (N, K) or (K,)), or numbers (K = 1:
/// shape (N,) or a scalar).
fn rows<const K: usize>(name: &str, array: &Input<'_>) -> PyResult<Rows<[f64; K]>> {
    let view = array.as_array();
    let shape = view.shape();
    let (count, batched) = match (K, shape) {
        (1, []) => (1, false),
        (1, [n]) => (*n, true),
        (k, [n]) if *n == k => (1, false),
        (k, [n, m]) if *m == k => (*n, true),
        _ => {
            let want = if K == 1 {
                "(N,) or a number".to_string()
            } else {
                format!("(N, {K}) or ({K},)")
            };
            return Err(PyValueError::new_err(format!(
                "{name} must have shape {want}, not {shape:?}"
            )));
        }
    };
    let flat: Vec<f64> = view.iter().copied().collect();
    let values = flat
        .chunks_exact(K)
        .map(|c| std::array::from_fn(|j| c[j]))
        .collect::<Vec<_>>();
    debug_assert_eq!(values.len(), count);
    Ok(Rows { values, batched })
}

/// Unit directions from `array`; zero-length or non-finite vectors are refused. Rounded to
/// f32 first and normalised by `tress_core::math::unit`, as `tress bcsdf eval` reads them, so
/// both accept the same directions.
fn directions(name: &str, array: &Input<'_>) -> PyResult<Rows<Vec3>> {
    let r = rows::<3>(name, array)?;
    let values = r
        .values
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            unit(Vec3::from_array(v.map(|x| x as f32))).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "{}{} = {v:?} is not a direction (zero length or not finite)",
                    name,
                    index(r.batched, i)
                ))
            })
        })
        .collect::<PyResult<_>>()?;
    Ok(Rows {
        values,
        batched: r.batched,
    })
}

/// Offsets `h`, each in [-1, 1] once rounded to f32, as `tress bcsdf eval` checks them: the
/// interval is closed, so rounding keeps every accepted value inside it.
fn offsets(array: &Input<'_>) -> PyResult<Rows<f32>> {
    let r = rows::<1>("h", array)?;
    let values: Vec<f32> = r.values.iter().map(|v| v[0] as f32).collect();
    if let Some(i) = values.iter().position(|v| !(-1.0..=1.0).contains(v)) {
        return Err(PyValueError::new_err(format!(
            "h{} = {} must lie in [-1, 1]",
            index(r.batched, i),
            r.values[i][0]
        )));
    }
    Ok(Rows {
        values,
        batched: r.batched,
    })
}

/// The largest f32 below 1.
const BELOW_ONE: f32 = 1.0 - f32::EPSILON / 2.0;

/// Random numbers `u`, each in [0, 1) as given (f64). A number just below 1 that rounds to 1.0
/// in f32 becomes the largest f32 below 1, so that `rng.uniform(0, 1)` is always accepted.
fn randoms(array: &Input<'_>) -> PyResult<Rows<[f32; 4]>> {
    let r = rows::<4>("u", array)?;
    if let Some(i) = r
        .values
        .iter()
        .position(|u| !u.iter().all(|x| (0.0..1.0).contains(x)))
    {
        return Err(PyValueError::new_err(format!(
            "u{} = {:?}: random numbers must lie in [0, 1)",
            index(r.batched, i),
            r.values[i]
        )));
    }
    Ok(Rows {
        values: r
            .values
            .iter()
            .map(|u| u.map(|x| (x as f32).min(BELOW_ONE)))
            .collect(),
        batched: r.batched,
    })
}

/// `[i]` for a row of a batched argument, nothing for a single value.
fn index(batched: bool, i: usize) -> String {
    if batched {
        format!("[{i}]")
    } else {
        String::new()
    }
}

/// The arguments of `eval` and `pdf` (`wo`, `wi`, `h`) and their common row count.
type DirectionPairs = (Rows<Vec3>, Rows<Vec3>, Rows<f32>, Option<usize>);

fn direction_pairs(wo: &Input<'_>, wi: &Input<'_>, h: &Input<'_>) -> PyResult<DirectionPairs> {
    let (wo, wi, h) = (directions("wo", wo)?, directions("wi", wi)?, offsets(h)?);
    let n = row_count(&[
        ("wo", wo.batched, wo.values.len()),
        ("wi", wi.batched, wi.values.len()),
        ("h", h.batched, h.values.len()),
    ])?;
    Ok((wo, wi, h, n))
}

/// The arguments of `sample` and `sample_weight` (`wo`, `h`, `u`) and their common row count.
type SampleInputs = (Rows<Vec3>, Rows<f32>, Rows<[f32; 4]>, Option<usize>);

fn sample_inputs(wo: &Input<'_>, h: &Input<'_>, u: &Input<'_>) -> PyResult<SampleInputs> {
    let (wo, h, u) = (directions("wo", wo)?, offsets(h)?, randoms(u)?);
    let n = row_count(&[
        ("wo", wo.batched, wo.values.len()),
        ("h", h.batched, h.values.len()),
        ("u", u.batched, u.values.len()),
    ])?;
    Ok((wo, h, u, n))
}

/// The common row count of the arguments, `None` when none is batched.
fn row_count(args: &[(&str, bool, usize)]) -> PyResult<Option<usize>> {
    let mut count: Option<(&str, usize)> = None;
    for &(name, batched, n) in args {
        if !batched {
            continue;
        }
        match count {
            Some((first, m)) if m != n => {
                return Err(PyValueError::new_err(format!(
                    "{first} has {m} rows but {name} has {n}"
                )))
            }
            Some(_) => {}
            None => count = Some((name, n)),
        }
    }
    Ok(count.map(|(_, n)| n))
}

/// `f(0..n)`, on all cores when there is enough work; the values do not depend on the split.
fn map_rows<T: Send>(n: usize, f: impl Fn(usize) -> T + Sync + Send) -> Vec<T> {
    (0..n).into_par_iter().with_min_len(4096).map(f).collect()
}

/// RGB rows as an (N, 3) array, or the single row as a (3,) array.
fn rgb_array<'py>(py: Python<'py>, values: Vec<Vec3>, batched: bool) -> Bound<'py, PyAny> {
    let flat: Vec<f32> = values.iter().flat_map(|v| v.to_array()).collect();
    if batched {
        Array2::from_shape_vec((values.len(), 3), flat)
            .expect("three components per row")
            .into_pyarray(py)
            .into_any()
    } else {
        Array1::from_vec(flat).into_pyarray(py).into_any()
    }
}

/// Numbers as an (N,) array, or the single number as a float.
fn number_array<'py>(py: Python<'py>, values: Vec<f32>, batched: bool) -> Bound<'py, PyAny> {
    if batched {
        Array1::from_vec(values).into_pyarray(py).into_any()
    } else {
        PyFloat::new(py, f64::from(values[0])).into_any()
    }
}

#[pymethods]
impl HairModel {
    /// Parses and validates a model written as in scene files. `table_cache`: a folder where
    /// what the model precomputes (the fur's medulla tables) is read from and stored; by
    /// default none.
    #[new]
    #[pyo3(signature = (model, table_cache=None))]
    fn new(py: Python<'_>, model: &str, table_cache: Option<std::path::PathBuf>) -> PyResult<Self> {
        let parsed: tress_materials::HairModel =
            tress_loader::ron_options().from_str(model).map_err(|e| {
                PyValueError::new_err(format!(
                    "hair model '{model}': {e} (models: {})",
                    tress_materials::HairModel::names().join(", ")
                ))
            })?;
        let prep = tress_core::prepare::Preparation::with_limits(crate::limits_from_env())
            .with_table_dir(table_cache);
        let bcsdf = py
            .detach(|| parsed.build(&prep))
            .map_err(|e| PyValueError::new_err(format!("hair model '{model}': {e}")))?;
        crate::warn_notes(py, &prep)?;
        Ok(HairModel {
            model: parsed,
            bcsdf,
        })
    }

    fn __repr__(&self) -> String {
        let text = tress_loader::ron_options()
            .to_string(&self.model)
            .unwrap_or_else(|_| format!("{:?}", self.model));
        format!("tress.HairModel({text:?})")
    }

    /// Names of the lobes `eval` sums (R, TT, TRT, …).
    #[getter]
    fn lobes(&self) -> Vec<&'static str> {
        self.bcsdf.lobe_names().to_vec()
    }

    /// f(wo, wi) · cos θ_i at offsets `h`: RGB, shape (N, 3). The cosine is included, so a
    /// non-absorbing, energy-conserving fiber integrates to 1 over the sphere of `wi`.
    fn eval<'py>(
        &self,
        py: Python<'py>,
        wo: Input<'py>,
        wi: Input<'py>,
        h: Input<'py>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (wo, wi, h, n) = direction_pairs(&wo, &wi, &h)?;
        let bcsdf = self.bcsdf.as_ref();
        let values = py.detach(|| {
            map_rows(n.unwrap_or(1), |i| {
                bcsdf.eval(wo.get(i), wi.get(i), h.get(i))
            })
        });
        Ok(rgb_array(py, values, n.is_some()))
    }

    /// The solid-angle density with which `sample` produces `wi`: shape (N,).
    fn pdf<'py>(
        &self,
        py: Python<'py>,
        wo: Input<'py>,
        wi: Input<'py>,
        h: Input<'py>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (wo, wi, h, n) = direction_pairs(&wo, &wi, &h)?;
        let bcsdf = self.bcsdf.as_ref();
        let values = py.detach(|| {
            map_rows(n.unwrap_or(1), |i| {
                bcsdf.pdf(wo.get(i), wi.get(i), h.get(i))
            })
        });
        Ok(number_array(py, values, n.is_some()))
    }

    /// Importance-samples incident directions from four uniform numbers `u` in [0, 1) each.
    /// Returns `(wi, f, pdf)`: directions (N, 3), `eval(wo, wi, h)` (N, 3) and their
    /// solid-angle density (N,); the Monte Carlo weight is `f / pdf`. Where the model has no
    /// direction carrying energy, the row is zeros with pdf 0.
    fn sample<'py>(
        &self,
        py: Python<'py>,
        wo: Input<'py>,
        h: Input<'py>,
        u: Input<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let (wo, h, u, n) = sample_inputs(&wo, &h, &u)?;
        let bcsdf = self.bcsdf.as_ref();
        let samples = py.detach(|| {
            map_rows(n.unwrap_or(1), |i| {
                match bcsdf.sample(wo.get(i), h.get(i), u.get(i)) {
                    Some(s) => (s.wi, s.f, s.pdf),
                    None => (Vec3::ZERO, Vec3::ZERO, 0.0),
                }
            })
        });
        let batched = n.is_some();
        let wi = samples.iter().map(|s| s.0).collect();
        let f = samples.iter().map(|s| s.1).collect();
        let pdf = samples.iter().map(|s| s.2).collect();
        Ok((
            rgb_array(py, wi, batched),
            rgb_array(py, f, batched),
            number_array(py, pdf, batched),
        ))
    }

    /// The directions `sample` draws from the same numbers `u`, with the Monte Carlo weight a
    /// path tracer uses where it needs no density: `(wi, weight)`, (N, 3) each. Its mean equals
    /// that of `f / pdf` but not row by row (Chiang: the chosen lobe's `A_p / P(p)`). Rows
    /// where nothing is drawn are zeros.
    fn sample_weight<'py>(
        &self,
        py: Python<'py>,
        wo: Input<'py>,
        h: Input<'py>,
        u: Input<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let (wo, h, u, n) = sample_inputs(&wo, &h, &u)?;
        let bcsdf = self.bcsdf.as_ref();
        let samples = py.detach(|| {
            map_rows(n.unwrap_or(1), |i| {
                bcsdf
                    .sample_weight(wo.get(i), h.get(i), u.get(i))
                    .unwrap_or((Vec3::ZERO, Vec3::ZERO))
            })
        });
        let batched = n.is_some();
        let wi = samples.iter().map(|s| s.0).collect();
        let weight = samples.iter().map(|s| s.1).collect();
        Ok((rgb_array(py, wi, batched), rgb_array(py, weight, batched)))
    }
}
