//! `mtpcr.Config`: the core's `Config`, built and read through serde so that every field of the
//! Rust struct is a keyword argument and an attribute here, by the same name.

use crate::convert::{json_from_py, json_to_py};
use crate::errors::to_py;
use mtpcr_core::Config;
use pyo3::exceptions::{PyAttributeError, PyRuntimeError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString, PyTuple};
use serde_json::{Map, Value};

/// The config's fields and values by name (a `serde_json::Map` sorts its keys; see
/// [`config_to_dict`] for declaration order).
fn fields(config: &Config) -> PyResult<Map<String, Value>> {
    match serde_json::to_value(config) {
        Ok(Value::Object(map)) => Ok(map),
        Ok(_) => Err(PyRuntimeError::new_err("Config did not serialize to a map")),
        Err(e) => Err(PyRuntimeError::new_err(format!(
            "Config did not serialize: {e}"
        ))),
    }
}

/// The config as a Python dict, keys in declaration order (serde writes struct fields in
/// order; Python's `json` keeps it).
pub(crate) fn config_to_dict<'py>(
    py: Python<'py>,
    config: &Config,
) -> PyResult<Bound<'py, PyDict>> {
    let text = serde_json::to_string(config)
        .map_err(|e| PyRuntimeError::new_err(format!("Config did not serialize: {e}")))?;
    Ok(crate::convert::json_text_to_py(py, &text)?.cast_into::<PyDict>()?)
}

/// `base` with the Python `settings` (field name -> value) applied by the core's
/// `Config::with_overrides` and validated. An unknown name is a `TypeError`; a value of the
/// wrong type or out of range is a `ValueError`; both name the setting. `context` names the
/// callable in messages.
pub(crate) fn apply_settings(
    base: &Config,
    settings: &[(String, Bound<'_, PyAny>)],
    context: &str,
) -> PyResult<Config> {
    let mut overrides = Map::new();
    for (key, value) in settings {
        overrides.insert(key.clone(), json_from_py(key, value)?);
    }
    base.with_overrides(&overrides).map_err(|e| match e {
        mtpcr_core::Error::UnknownSetting { name, known } => PyTypeError::new_err(format!(
            "{context}() got an unexpected keyword argument '{name}' (settings are: {known})"
        )),
        other => to_py(other),
    })
}

/// The settings of a call like `register(*clouds, seed=..., config=..., **settings)`: the
/// keywords over `config` (default `Config()`), and `seed` when given and not `None`.
pub(crate) fn call_config(
    config: Option<&Bound<'_, PyAny>>,
    settings: Option<&Bound<'_, PyDict>>,
    seed: Option<&Bound<'_, PyAny>>,
    context: &str,
) -> PyResult<Config> {
    let base = base_config(config)?;
    let mut pairs = kwargs_pairs(settings)?;
    if let Some(seed) = seed.filter(|s| !s.is_none()) {
        pairs.push(("seed".to_string(), seed.clone()));
    }
    apply_settings(&base, &pairs, context)
}

/// The `config` argument of a function: an `mtpcr.Config`, or `None` (or absent) for
/// `Config()`; anything else is a `TypeError`.
pub(crate) fn base_config(config: Option<&Bound<'_, PyAny>>) -> PyResult<Config> {
    match config {
        None => Ok(Config::default()),
        Some(c) if c.is_none() => Ok(Config::default()),
        Some(c) => match c.cast::<PyConfig>() {
            Ok(c) => Ok(c.get().inner.clone()),
            Err(_) => Err(PyTypeError::new_err(format!(
                "config must be an mtpcr.Config, got {}",
                c.get_type().name()?
            ))),
        },
    }
}

/// `**kwargs` as (name, value) pairs.
pub(crate) fn kwargs_pairs<'py>(
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Vec<(String, Bound<'py, PyAny>)>> {
    let mut pairs = Vec::new();
    if let Some(kwargs) = kwargs {
        for (key, value) in kwargs.iter() {
            pairs.push((key.cast_into::<PyString>()?.to_string(), value));
        }
    }
    Ok(pairs)
}

/// Every setting of a registration run, validated on construction.
///
/// ``Config()`` (or ``Config.default()``) is the recommended setting, ``Config.paper()`` the
/// paper's reference setting; keyword arguments override single fields, e.g.
/// ``Config(generations=30, seed=7)``. The field names are those of the Rust ``Config`` (and the
/// CLI flags and config-file keys); read them as attributes (``config.generations``) or all at
/// once with ``to_dict()``. A bad value raises ``ValueError`` naming the field, an unknown name
/// ``TypeError``. Instances are immutable: use ``replace(**changes)`` for a modified copy.
#[pyclass(frozen, eq, name = "Config", module = "mtpcr")]
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct PyConfig {
    pub(crate) inner: Config,
}

#[pymethods]
impl PyConfig {
    #[new]
    #[pyo3(signature = (**settings))]
    fn new(settings: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let inner = apply_settings(&Config::default(), &kwargs_pairs(settings)?, "Config")?;
        Ok(PyConfig { inner })
    }

    /// The recommended setting (the same as ``Config()``).
    #[staticmethod]
    #[pyo3(name = "default")]
    fn default_config() -> Self {
        PyConfig {
            inner: Config::default(),
        }
    }

    /// The documentation of every field, by name, in declaration order (the same text as the
    /// Rust docs and the CLI help).
    #[staticmethod]
    fn field_docs(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        let dict = PyDict::new(py);
        for field in mtpcr_core::config::FIELDS {
            dict.set_item(field.name, field.text())?;
        }
        Ok(dict)
    }

    /// The authors' reference setting (the paper's Section IV-C).
    #[staticmethod]
    fn paper() -> Self {
        PyConfig {
            inner: Config::paper(),
        }
    }

    /// A copy with the given fields changed (validated like the constructor).
    #[pyo3(signature = (**changes))]
    fn replace(&self, changes: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let inner = apply_settings(&self.inner, &kwargs_pairs(changes)?, "replace")?;
        Ok(PyConfig { inner })
    }

    /// Every field and its value, in declaration order (``Config(**c.to_dict()) == c``).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        config_to_dict(py, &self.inner)
    }

    fn __getattr__<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        match fields(&self.inner)?.get(name) {
            Some(value) => json_to_py(py, value),
            None => Err(PyAttributeError::new_err(format!(
                "'Config' object has no attribute '{name}'"
            ))),
        }
    }

    fn __dir__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyList>> {
        let names = slf.get_type().dir()?;
        for key in fields(&slf.get().inner)?.keys() {
            names.append(key)?;
        }
        names.sort()?;
        Ok(names)
    }

    /// Pickles as `functools.partial(Config, **fields)` (so `copy` and `multiprocessing` work).
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let py = slf.py();
        let fields = config_to_dict(py, &slf.get().inner)?;
        let partial = py
            .import("functools")?
            .getattr("partial")?
            .call((slf.get_type(),), Some(&fields))?;
        Ok((partial, PyTuple::empty(py)))
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let dict = config_to_dict(py, &self.inner)?;
        let mut parts = Vec::new();
        for (key, value) in dict.iter() {
            parts.push(format!("{}={}", key.str()?, value.repr()?));
        }
        Ok(format!("Config({})", parts.join(", ")))
    }
}
