//! Running the engine for a Python call: the clouds with their viewpoints, the user's
//! progress callbacks, the GIL released and Ctrl-C watched (shared by `register()` and
//! `screen_pairs()`).

use crate::convert::{cloud_from_py, viewpoints_from_py};
use crate::errors::to_py;
use mtpcr_core::{Interrupt, Observer, Progress, Stage};
use pyo3::exceptions::{PyRuntimeError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::ops::ControlFlow;
use std::sync::Mutex;

/// How often the waiting thread checks for Ctrl-C.
const WAIT_SLICE: std::time::Duration = std::time::Duration::from_millis(50);

/// `{task name: cost}` in slot order.
pub(crate) fn costs_dict<'py>(
    py: Python<'py>,
    names: &[String],
    costs: &[f64],
) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    for (name, cost) in names.iter().zip(costs) {
        dict.set_item(name, *cost)?;
    }
    Ok(dict)
}

/// Calls the user's `on_generation(generation, best_costs)` or
/// `on_pair_screening(screened, total)`, the one for the progress's stage (if given);
/// `Ok(false)` asks to stop.
fn call_observer(
    py: Python<'_>,
    callbacks: &Callbacks,
    names: &[String],
    progress: &Progress,
) -> PyResult<bool> {
    let answer = match progress.stage {
        Stage::Generation => match &callbacks.generation {
            Some(f) => {
                let costs = costs_dict(py, names, &progress.best_costs)?;
                f.bind(py).call1((progress.generation, costs))?
            }
            None => return Ok(true),
        },
        Stage::PairScreening => match &callbacks.pair_screening {
            Some(f) => f
                .bind(py)
                .call1((progress.generation, progress.generations))?,
            None => return Ok(true),
        },
    };
    Ok(answer.is_none() || answer.is_truthy()?)
}

/// The user's progress callbacks.
pub(crate) struct Callbacks {
    pub(crate) generation: Option<Py<PyAny>>,
    pub(crate) pair_screening: Option<Py<PyAny>>,
    /// Whether a callback returning `False` stops the run.
    pub(crate) may_stop: bool,
}

/// `f` when it is callable (`None` when absent), else a `TypeError` naming the argument.
pub(crate) fn callable(f: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<Py<PyAny>>> {
    match f {
        Some(f) if !f.is_none() => {
            if !f.is_callable() {
                return Err(PyTypeError::new_err(format!(
                    "{name} must be callable, got {}",
                    f.get_type().name()?
                )));
            }
            Ok(Some(f.clone().unbind()))
        }
        _ => Ok(None),
    }
}

/// The clouds of `register(*clouds, viewpoints=...)` (or `screen_pairs`), each with its
/// viewpoint.
pub(crate) fn clouds_from_py(
    clouds: &Bound<'_, PyTuple>,
    viewpoints: Option<&Bound<'_, PyAny>>,
) -> PyResult<Vec<mtpcr_core::PointCloud>> {
    let viewpoints = viewpoints_from_py(viewpoints, clouds.len())?;
    clouds
        .iter()
        .zip(viewpoints)
        .enumerate()
        .map(|(i, (c, viewpoint))| {
            let cloud = cloud_from_py(&c, &format!("cloud{}", i + 1))?;
            Ok(match viewpoint {
                Some(v) => cloud.with_viewpoint(v),
                None => cloud,
            })
        })
        .collect()
}

/// Runs `work` (the engine) on a worker thread without the GIL; its observer takes the GIL
/// once per report to call the user's callbacks. This thread waits, checking for Ctrl-C
/// every 50 ms: a KeyboardInterrupt sets the engine's interrupt flag (it stops within a
/// step: sampling, a generation, a refinement iteration, a batch of pairs) and is raised
/// once it has.
pub(crate) fn run_engine<T: Send>(
    py: Python<'_>,
    callbacks: &Callbacks,
    names: &[String],
    work: impl FnOnce(Option<Observer<'_>>, Interrupt) -> mtpcr_core::Result<T> + Send,
) -> PyResult<T> {
    let failure: Mutex<Option<PyErr>> = Mutex::new(None);
    let interrupt = Interrupt::new();
    let outcome = std::thread::scope(|scope| {
        let worker = scope.spawn(|| {
            let mut observer = |progress: &Progress| -> ControlFlow<()> {
                if callbacks.generation.is_none() && callbacks.pair_screening.is_none() {
                    return ControlFlow::Continue(());
                }
                Python::attach(|py| match call_observer(py, callbacks, names, progress) {
                    Ok(true) => ControlFlow::Continue(()),
                    Ok(false) if !callbacks.may_stop => ControlFlow::Continue(()),
                    Ok(false) => ControlFlow::Break(()),
                    Err(e) => {
                        if let Ok(mut slot) = failure.lock() {
                            slot.get_or_insert(e);
                        }
                        ControlFlow::Break(())
                    }
                })
            };
            work(Some(&mut observer), interrupt.clone())
        });
        while !py.detach(|| {
            let start = std::time::Instant::now();
            while !worker.is_finished() && start.elapsed() < WAIT_SLICE {
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            worker.is_finished()
        }) {
            if let Err(e) = py.check_signals() {
                interrupt.interrupt();
                if let Ok(mut slot) = failure.lock() {
                    slot.get_or_insert(e);
                }
            }
        }
        worker.join()
    });
    if let Some(e) = failure.into_inner().ok().flatten() {
        return Err(e);
    }
    py.check_signals()?;
    let outcome =
        outcome.map_err(|_| PyRuntimeError::new_err("the registration thread panicked"))?;
    outcome.map_err(to_py)
}
