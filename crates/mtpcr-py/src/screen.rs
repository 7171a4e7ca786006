//! `screen_pairs()` and the screening as plain Python data (dicts, ints and numpy arrays: it
//! pickles, so Ray and multiprocessing carry it).

use crate::config::call_config;
use crate::convert::transforms_to_py;
use crate::engine::{callable, clouds_from_py, run_engine, Callbacks};
use mtpcr_core::{ScreenedPair, Screening, Transform};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

/// The pair screening of four or more clouds in no known order: the slow first step of
/// :func:`register` for a whole room (every pair's pose hypotheses from the clouds'
/// features), for the pairs given (``pairs``: ``(source, target)`` with clouds numbered from
/// 0 and ``source < target``; ``None``: every pair).
///
/// Screen disjoint sets of pairs anywhere (other processes, other machines: see
/// :func:`mtpcr.distributed.register_scene`) and pass the results, as a list, to
/// ``register(*clouds, screening=...)`` with the same clouds, seed and settings: its result is
/// exactly the one ``register`` gives screening every pair itself.
///
/// Returns plain data: a dict with ``fingerprint`` (what the screening belongs to: the
/// clouds as prepared with these settings), ``clouds`` (their number) and ``pairs``, one dict
/// per pair with ``source``, ``target``, ``poses`` (H, 4, 4: the hypotheses in the prepared,
/// centred frames, meaningful only to ``register``), ``overlaps`` (H) and ``supports`` (H, the
/// descriptor matches each explains). Clouds, ``seed``, ``config``, ``viewpoints`` and other
/// keywords as for :func:`register`; ``on_pair_screening(screened, total)`` as there, but its
/// return value is ignored (a screening is all or nothing; an exception in it, or Ctrl-C,
/// stops it and propagates).
#[pyfunction]
#[pyo3(signature = (*clouds, pairs=None, seed=None, on_pair_screening=None, config=None, viewpoints=None, **settings))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn screen_pairs<'py>(
    py: Python<'py>,
    clouds: &Bound<'py, PyTuple>,
    pairs: Option<&Bound<'py, PyAny>>,
    seed: Option<&Bound<'py, PyAny>>,
    on_pair_screening: Option<&Bound<'py, PyAny>>,
    config: Option<&Bound<'py, PyAny>>,
    viewpoints: Option<&Bound<'py, PyAny>>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let config = call_config(config, settings, seed, "screen_pairs")?;
    let callbacks = Callbacks {
        generation: None,
        pair_screening: callable(on_pair_screening, "on_pair_screening")?,
        // A screening is all or nothing: one with pairs left out would pass for complete.
        may_stop: false,
    };
    let pairs = pairs
        .filter(|p| !p.is_none())
        .map(pairs_from_py)
        .transpose()?;
    let clouds = clouds_from_py(clouds, viewpoints)?;
    let screening = run_engine(py, &callbacks, &[], |observer, interrupt| {
        mtpcr_core::screen_pairs(&clouds, &config, pairs.as_deref(), observer, interrupt)
    })?;
    screening_to_py(py, &screening, clouds.len())
}

fn pairs_from_py(obj: &Bound<'_, PyAny>) -> PyResult<Vec<(usize, usize)>> {
    let bad = || {
        PyValueError::new_err(
            "pairs must be a sequence of (source, target) pairs of cloud indices (from 0)",
        )
    };
    let list = obj
        .call_method0("__iter__")
        .map_err(|_| bad())?
        .try_iter()?;
    list.map(|p| {
        let p = p?;
        let v: Vec<Bound<'_, PyAny>> = p.try_iter().map_err(|_| bad())?.collect::<PyResult<_>>()?;
        match v.as_slice() {
            [s, t] => Ok((index(s).ok_or_else(bad)?, index(t).ok_or_else(bad)?)),
            _ => Err(bad()),
        }
    })
    .collect()
}

/// A non-negative integer (Python's or numpy's), else `None`.
fn index(v: &Bound<'_, PyAny>) -> Option<usize> {
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return None;
    }
    v.call_method0("__index__").ok()?.extract::<usize>().ok()
}

fn screening_to_py<'py>(
    py: Python<'py>,
    screening: &Screening,
    clouds: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let numpy = py.import("numpy")?;
    let pairs = PyList::empty(py);
    for p in &screening.pairs {
        let d = PyDict::new(py);
        d.set_item("source", p.source)?;
        d.set_item("target", p.target)?;
        d.set_item("poses", transforms_to_py(py, &p.poses))?;
        d.set_item(
            "overlaps",
            numpy.call_method1("array", (p.overlaps.clone(), "float64"))?,
        )?;
        d.set_item(
            "supports",
            numpy.call_method1("array", (p.supports.clone(), "int64"))?,
        )?;
        pairs.append(d)?;
    }
    let d = PyDict::new(py);
    d.set_item("fingerprint", screening.fingerprint)?;
    d.set_item("clouds", clouds)?;
    d.set_item("pairs", pairs)?;
    Ok(d)
}

/// A screening from `screen_pairs`'s dict, or from a list of them (merged).
pub(crate) fn screening_from_py(obj: &Bound<'_, PyAny>) -> PyResult<Screening> {
    if obj.is_instance_of::<PyDict>() {
        return one_from_py(obj);
    }
    let parts: Vec<Screening> = obj
        .try_iter()
        .map_err(|_| not_a_screening(obj))?
        .map(|part| one_from_py(&part?))
        .collect::<PyResult<_>>()?;
    Screening::merge(parts).map_err(crate::errors::to_py)
}

fn not_a_screening(obj: &Bound<'_, PyAny>) -> PyErr {
    let kind = obj
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_default();
    PyTypeError::new_err(format!(
        "screening must be the dict screen_pairs() returns, or a list of them; got {kind}"
    ))
}

fn one_from_py(obj: &Bound<'_, PyAny>) -> PyResult<Screening> {
    let d = obj.cast::<PyDict>().map_err(|_| not_a_screening(obj))?;
    let fingerprint: u64 = entry(d, "fingerprint")?
        .extract()
        .map_err(|_| PyValueError::new_err("screening: `fingerprint` must be an integer"))?;
    let mut pairs = Vec::new();
    for (k, p) in entry(d, "pairs")?.try_iter()?.enumerate() {
        let p = p?;
        let p = p
            .cast::<PyDict>()
            .map_err(|_| PyValueError::new_err(format!("screening: pair {k} is not a dict")))?;
        let field = |key: &str| {
            entry(p, key)
                .map_err(|_| PyValueError::new_err(format!("screening: pair {k} has no `{key}`")))
        };
        let invalid = |what: &str| PyValueError::new_err(format!("screening: pair {k}: {what}"));
        let source = index(&field("source")?).ok_or_else(|| invalid("bad `source`"))?;
        let target = index(&field("target")?).ok_or_else(|| invalid("bad `target`"))?;
        let poses: Vec<f64> = flat(&field("poses")?, "float64", &[4, 4])
            .and_then(|l| {
                l.extract()
                    .map_err(|_| "must hold float64 numbers (counts >= 0)".into())
            })
            .map_err(|e| invalid(&format!("`poses` {e}")))?;
        let overlaps: Vec<f64> = flat(&field("overlaps")?, "float64", &[])
            .and_then(|l| {
                l.extract()
                    .map_err(|_| "must hold float64 numbers (counts >= 0)".into())
            })
            .map_err(|e| invalid(&format!("`overlaps` {e}")))?;
        let supports: Vec<usize> = flat(&field("supports")?, "int64", &[])
            .and_then(|l| {
                l.extract()
                    .map_err(|_| "must hold int64 numbers (counts >= 0)".into())
            })
            .map_err(|e| invalid(&format!("`supports` {e}")))?;
        pairs.push(ScreenedPair {
            source,
            target,
            poses: poses
                .chunks_exact(16)
                .map(Transform::from_row_slice)
                .collect(),
            overlaps,
            supports,
        });
    }
    Ok(Screening { fingerprint, pairs })
}

/// `d[key]`, or a `ValueError` naming the missing entry.
fn entry<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?
        .ok_or_else(|| PyValueError::new_err(format!("screening: the entry `{key}` is missing")))
}

/// The values of an `(H, *tail)` array of `dtype`, flat in C order, as a Python list; an
/// error text otherwise.
fn flat<'py>(
    obj: &Bound<'py, PyAny>,
    dtype: &str,
    tail: &[usize],
) -> Result<Bound<'py, PyAny>, String> {
    let py = obj.py();
    let array = py
        .import("numpy")
        .and_then(|np| np.call_method1("asarray", (obj,)))
        .map_err(|_| "is not an array".to_string())?;
    let shape: Vec<usize> = array
        .getattr("shape")
        .and_then(|s| s.extract())
        .map_err(|_| "is not an array".to_string())?;
    if shape.len() != 1 + tail.len() || shape[1..] != *tail {
        let want: Vec<String> = std::iter::once("H".to_string())
            .chain(tail.iter().map(|t| t.to_string()))
            .collect();
        return Err(format!(
            "must have shape ({}), got {shape:?}",
            want.join(", ")
        ));
    }
    let kind: String = array
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract())
        .unwrap_or_default();
    let numeric = if dtype == "int64" {
        matches!(kind.as_str(), "i" | "u")
    } else {
        matches!(kind.as_str(), "f" | "i" | "u")
    };
    if !numeric {
        return Err(format!("must hold {dtype} numbers"));
    }
    array
        .call_method0("ravel")
        .and_then(|a| a.call_method0("tolist"))
        .map_err(|_| format!("must hold {dtype} numbers"))
}
