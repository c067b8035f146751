//! Python values → the serde data model, so that a scene written as a dict deserialises into
//! the very types a scene file does.

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use serde_json::{Map, Number, Value};

/// `obj` as a JSON value: dicts with string keys, lists and tuples, strings, numbers, booleans
/// and `None`; path-like objects become their path, NumPy arrays and scalars their
/// `tolist()`. `at` names where `obj` sits (`objects[0].radius`) for the error.
pub fn to_json(obj: &Bound<'_, PyAny>, at: &str) -> PyResult<Value> {
    nested(obj, at, 0)
}

/// Deeper than any scene is written: a dict that contains itself, or a list nested 100 000
/// deep, overflowed the stack and killed the interpreter.
const MAX_DEPTH: usize = 64;

fn nested(obj: &Bound<'_, PyAny>, at: &str, depth: usize) -> PyResult<Value> {
    let here = |what: &str| format!("{}: {what}", if at.is_empty() { "scene" } else { at });
    if depth > MAX_DEPTH {
        return Err(PyValueError::new_err(here(&format!(
            "nested more than {MAX_DEPTH} levels deep (does it contain itself?)"
        ))));
    }
    if obj.is_none() {
        return Ok(Value::Null);
    }
    // Before integers: `bool` is a subclass of `int`.
    if let Ok(b) = obj.cast::<PyBool>() {
        return Ok(Value::Bool(b.is_true()));
    }
    if obj.is_instance_of::<PyInt>() {
        if let Ok(v) = obj.extract::<i64>() {
            return Ok(Value::from(v));
        }
        if let Ok(v) = obj.extract::<u64>() {
            return Ok(Value::from(v));
        }
        return Err(PyValueError::new_err(here(&format!(
            "{obj} does not fit in 64 bits"
        ))));
    }
    if let Ok(f) = obj.cast::<PyFloat>() {
        let v = f.value();
        return Number::from_f64(v)
            .map(Value::Number)
            .ok_or_else(|| PyValueError::new_err(here(&format!("{v} is not a finite number"))));
    }
    if let Ok(s) = obj.cast::<PyString>() {
        return Ok(Value::String(s.to_str()?.to_owned()));
    }
    if let Ok(d) = obj.cast::<PyDict>() {
        let mut map = Map::new();
        for (k, v) in d.iter() {
            let key: String = k
                .extract()
                .map_err(|_| PyTypeError::new_err(here(&format!("key {k:?} is not a string"))))?;
            let inner = if at.is_empty() {
                key.clone()
            } else {
                format!("{at}.{key}")
            };
            map.insert(key, nested(&v, &inner, depth + 1)?);
        }
        return Ok(Value::Object(map));
    }
    let items = if let Ok(l) = obj.cast::<PyList>() {
        Some(l.iter().collect::<Vec<_>>())
    } else {
        obj.cast::<PyTuple>().ok().map(|t| t.iter().collect())
    };
    if let Some(items) = items {
        return items
            .iter()
            .enumerate()
            .map(|(i, v)| nested(v, &format!("{at}[{i}]"), depth + 1))
            .collect::<PyResult<Vec<_>>>()
            .map(Value::Array);
    }
    let py = obj.py();
    if obj.is_instance(&py.import("os")?.getattr("PathLike")?)? {
        let path = py.import("os")?.call_method1("fspath", (obj,))?;
        return nested(&path, at, depth + 1);
    }
    // NumPy arrays and scalars (a `numpy.float32` is not a Python float).
    if obj.hasattr("tolist")? {
        let plain = obj.call_method0("tolist")?;
        if !plain.is(obj) {
            return nested(&plain, at, depth + 1);
        }
    }
    Err(PyTypeError::new_err(here(&format!(
        "a value of type {} cannot be part of a scene",
        obj.get_type().name()?
    ))))
}
