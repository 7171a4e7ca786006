//! `evaluate()`: the experiment protocol of `mtpcr experiment` (`mtpcr_core::eval::protocol`)
//! from Python, record for record; `evaluate_pairs()`: the pair benchmarks of `mtpcr eval
//! FOLDER` (`mtpcr_core::eval::pairs`); and `find_shared_dir()`.

use crate::config::call_config;
use crate::convert::json_text_to_py;
use crate::errors::to_py;
use mtpcr_core::eval::pairs::{run_benchmark, summarize, PairBenchmark, PairStep};
use mtpcr_core::eval::problem::Problem;
use mtpcr_core::eval::protocol::{run_one, Suite};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::ops::ControlFlow;
use std::path::PathBuf;

/// A serde value (a record, a summary) as the dict Python's `json` reads from it (NaN and
/// infinities become `None`).
fn serde_to_py<'py>(
    py: Python<'py>,
    value: &impl serde::Serialize,
    what: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let text =
        serde_json::to_string(value).map_err(|e| PyValueError::new_err(format!("{what}: {e}")))?;
    json_text_to_py(py, &text)
}

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
                let dict = serde_to_py(py, &record, "record")?.cast_into::<PyDict>()?;
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

/// Runs the pairs of a pair benchmark folder in the 3DMatch layout (3DMatch, 3DLoMatch: one
/// folder per scene with a ``gt.log``; or one scene's folder), as ``mtpcr eval FOLDER``
/// does: every pair registered with no initial guess and scored against ``gt.log``
/// (registered when RE < 15 degrees and TE < 0.3), the same numbers as the CLI for the same
/// settings, pairs and seed (only ``seconds`` differs).
///
/// Returns ``{"benchmark": name, "records": [...], "summary": {...}}``: one record per pair
/// in the benchmark's order (the fields of the CLI's ``--records`` lines: ``benchmark``,
/// ``pair`` (``scene/target-source``), ``seed``, ``moved``, ``re_deg``, ``te``,
/// ``registered``, ``confident``, ``reasons``, ``overlap``, ``residual``, ``constraint``,
/// ``support``, ``rival_support``, ``free_space``, ``free_share``, ``landed``,
/// ``tight_support``, ``seconds``, ``t_target_source`` (4x4 rows)), and
/// their summary:
/// ``pairs``, ``registered``, ``recall`` (percent), ``re_deg`` and ``te`` (means over the
/// registered pairs, ``None`` when there are none), ``median_seconds``, ``failed``,
/// ``failed_confident``, ``registered_doubted``.
///
/// ``pairs`` runs a seeded sample of that many pairs (the same pairs for the same seed;
/// default every pair); ``scenes`` keeps the scenes whose folder name contains one of these
/// strings. ``seed`` seeds the sample and every registration (default: the config's seed,
/// else 0). ``moved`` moves each source fragment by a seeded random rigid motion first (the
/// errors are still measured in the fragment's own frame, as the benchmark defines them).
/// Fragments are read from ``data_root/<scene>/cloud_bin_<k>.ply`` (default: the benchmark
/// folder's grandparent). Settings are ``Config`` fields as keywords, over ``config``
/// (default ``Config()``), as for :func:`register`.
///
/// ``on_pair(record)`` is called after each pair; returning ``False`` stops the evaluation
/// (the records so far are returned), ``None`` or ``True`` continues; an exception in it
/// stops it and propagates. The GIL is released while a pair runs; Ctrl-C is noticed
/// between pairs. A missing folder raises ``FileNotFoundError``; a folder with no ``gt.log``,
/// a malformed ``gt.log`` or no matching scene ``ValueError``; an unreadable fragment
/// ``OSError``.
#[pyfunction]
#[pyo3(signature = (benchmark, *, pairs=None, scenes=None, seed=None, moved=false, data_root=None, config=None, on_pair=None, **settings))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn evaluate_pairs<'py>(
    py: Python<'py>,
    benchmark: PathBuf,
    pairs: Option<usize>,
    scenes: Option<Vec<String>>,
    seed: Option<u64>,
    moved: bool,
    data_root: Option<PathBuf>,
    config: Option<&Bound<'py, PyAny>>,
    on_pair: Option<Bound<'py, PyAny>>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let mut config = call_config(config, settings, None, "evaluate_pairs")?;
    let on_pair: Option<Py<PyAny>> = match on_pair {
        Some(f) if !f.is_none() => {
            if !f.is_callable() {
                return Err(PyTypeError::new_err(format!(
                    "on_pair must be callable, got {}",
                    f.get_type().name()?
                )));
            }
            Some(f.unbind())
        }
        _ => None,
    };
    if pairs == Some(0) {
        return Err(PyValueError::new_err("pairs must be at least 1"));
    }
    let seed = seed.or(config.seed).unwrap_or(0);
    config.seed = None;
    let mut bench = py
        .detach(|| PairBenchmark::load(&benchmark, data_root.as_deref()))
        .map_err(to_py)?;
    bench
        .retain_scenes(&scenes.unwrap_or_default())
        .map_err(to_py)?;
    if let Some(n) = pairs {
        bench.sample(n, seed);
    }
    // The pairs run without the GIL; it is taken after each pair to hand its record over.
    let mut records: Vec<Py<PyAny>> = Vec::with_capacity(bench.cases.len());
    let mut failure: Option<PyErr> = None;
    let outcome = py.detach(|| {
        run_benchmark(&bench, &config, seed, moved, &[], &mut |step| {
            let PairStep::Done { record, .. } = step else {
                return ControlFlow::Continue(());
            };
            let go_on = Python::attach(|py| -> PyResult<bool> {
                let dict = serde_to_py(py, record, "record")?;
                records.push(dict.clone().unbind());
                py.check_signals()?;
                match &on_pair {
                    Some(f) => {
                        let answer = f.bind(py).call1((dict,))?;
                        Ok(answer.is_none() || answer.is_truthy()?)
                    }
                    None => Ok(true),
                }
            });
            match go_on {
                Ok(true) => ControlFlow::Continue(()),
                Ok(false) => ControlFlow::Break(()),
                Err(e) => {
                    failure = Some(e);
                    ControlFlow::Break(())
                }
            }
        })
    });
    if let Some(e) = failure {
        return Err(e);
    }
    let done = outcome.map_err(to_py)?;
    let result = PyDict::new(py);
    result.set_item("benchmark", &bench.name)?;
    result.set_item("records", records)?;
    result.set_item("summary", serde_to_py(py, &summarize(&done), "summary")?)?;
    Ok(result)
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
