//! `evaluate()`: the experiment protocol of `mtpcr experiment` (`mtpcr_core::eval::protocol`)
//! from Python, record for record; and `find_shared_dir()`.

use crate::convert::json_text_to_py;
use crate::errors::to_py;
use mtpcr_core::eval::problem::Problem;
use mtpcr_core::eval::protocol::{run_one, Suite};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Runs an experiment suite of the paper (``"accuracy"``, ``"quality"``, ``"noise"``,
/// ``"alpha"``, ``"sharing"``, ``"sampling"``) on problem files and returns one dict per run,
/// the same records ``mtpcr experiment`` writes to ``runs.jsonl`` (the same numbers for the
/// same suite, variant, problem and seed; only ``seconds`` differs).
///
/// Runs go variant by variant, problem by problem, seed by seed. ``runs`` gives seeds
/// ``0..runs`` (default: the suite's, as in the paper); ``seeds`` lists them instead.
/// ``variants`` keeps only the variants with these keys (e.g. ``["mtpcr-default"]``).
/// ``generations`` overrides every variant's generations (quick checks). Scan paths of the
/// problem files are resolved against ``data_root`` when given. ``on_run(record)`` is called
/// after each run; returning ``False`` stops the evaluation (the records so far are
/// returned). Every run uses one thread; Ctrl-C is noticed between runs.
#[pyfunction]
#[pyo3(signature = (suite, problems, *, runs=None, seeds=None, variants=None, generations=None, data_root=None, on_run=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn evaluate<'py>(
    py: Python<'py>,
    suite: &str,
    problems: Vec<PathBuf>,
    runs: Option<usize>,
    seeds: Option<Vec<u64>>,
    variants: Option<Vec<String>>,
    generations: Option<usize>,
    data_root: Option<PathBuf>,
    on_run: Option<Bound<'py, PyAny>>,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let suite = Suite::from_name(suite).map_err(to_py)?;
    if let Some(f) = &on_run {
        if !f.is_callable() {
            return Err(PyTypeError::new_err("on_run must be callable"));
        }
    }
    if runs == Some(0) {
        return Err(PyValueError::new_err("runs must be at least 1"));
    }
    let seeds: Vec<u64> =
        seeds.unwrap_or_else(|| (0..runs.unwrap_or_else(|| suite.default_runs()) as u64).collect());
    let mut chosen = suite.variants();
    if let Some(keys) = &variants {
        for k in keys {
            if !chosen.iter().any(|v| &v.key == k) {
                let known: Vec<&str> = chosen.iter().map(|v| v.key.as_str()).collect();
                return Err(PyValueError::new_err(format!(
                    "suite {} has no variant `{k}` (variants: {})",
                    suite.name(),
                    known.join(", ")
                )));
            }
        }
        chosen.retain(|v| keys.contains(&v.key));
    }
    let mut loaded = Vec::with_capacity(problems.len());
    for path in &problems {
        let problem = py
            .detach(|| Problem::load(path, data_root.as_deref()))
            .map_err(to_py)?;
        let truth = problem.ground_truth().map_err(to_py)?;
        let scans = py.detach(|| problem.read_scans()).map_err(to_py)?;
        loaded.push((problem, scans, truth));
    }
    let mut records = Vec::new();
    for variant in &chosen {
        for (problem, scans, truth) in &loaded {
            for &seed in &seeds {
                let record = py
                    .detach(|| {
                        run_one(
                            suite,
                            variant,
                            &problem.name,
                            scans,
                            truth,
                            seed,
                            generations,
                        )
                    })
                    .map_err(to_py)?;
                let text = serde_json::to_string(&record)
                    .map_err(|e| PyValueError::new_err(format!("record: {e}")))?;
                let dict = json_text_to_py(py, &text)?.cast_into::<PyDict>()?;
                records.push(dict.clone());
                py.check_signals()?;
                if let Some(f) = &on_run {
                    let answer = f.call1((dict,))?;
                    if !(answer.is_none() || answer.is_truthy()?) {
                        return Ok(records);
                    }
                }
            }
        }
    }
    Ok(records)
}

/// What an experiment suite runs: ``name``, ``default_runs`` (seeds ``0..default_runs``
/// unless told otherwise), ``paper_problems`` (the problem names the paper ran it on, used by
/// ``mtpcr experiment`` when no problems are given; ``None``: every problem) and
/// ``variants``, in run order: dicts with ``key``, ``label``, ``settings`` (the Config as a
/// dict, before the run's seed and ``generations`` override) and ``noise`` (the sigma added to
/// the scans, or ``None``). An unknown suite raises ``ValueError``.
#[pyfunction]
pub(crate) fn describe_suite<'py>(py: Python<'py>, suite: &str) -> PyResult<Bound<'py, PyAny>> {
    let suite = Suite::from_name(suite).map_err(to_py)?;
    let variants: Vec<serde_json::Value> = suite
        .variants()
        .iter()
        .map(|v| {
            serde_json::json!({
                "key": v.key,
                "label": v.label,
                "settings": v.config,
                "noise": v.noise,
            })
        })
        .collect();
    let info = serde_json::json!({
        "name": suite.name(),
        "default_runs": suite.default_runs(),
        "paper_problems": suite.paper_problems(),
        "variants": variants,
    });
    json_text_to_py(py, &info.to_string())
}

/// The team's shared data folder (holding ``problems/`` and ``data/``) as a str, or ``None``:
/// ``$MTPCR_SHARED_DIR`` when set, else the nearest ``shared/`` folder beside the current
/// directory or one of its ancestors.
#[pyfunction]
pub(crate) fn find_shared_dir() -> Option<String> {
    mtpcr_core::eval::shared::find_shared_dir().map(|p| p.to_string_lossy().into_owned())
}
