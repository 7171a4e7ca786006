//! `register()` and its result class.

use crate::config::{apply_settings, config_to_dict, kwargs_pairs, PyConfig};
use crate::convert::{cloud_from_py, transform_to_py, transforms_to_py};
use crate::errors::to_py;
use mtpcr_core::{Config, Progress, Registration, TASK_NAMES};
use numpy::ndarray::Array2;
use numpy::{PyArray2, PyArray3};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::ops::ControlFlow;

/// `{task name: cost}` in the order of `TASK_NAMES`.
fn costs_dict<'py>(py: Python<'py>, costs: &[f64; 6]) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    for (name, cost) in TASK_NAMES.iter().zip(costs) {
        dict.set_item(*name, *cost)?;
    }
    Ok(dict)
}

/// Calls the user's `on_generation(generation, best_costs)`; `Ok(false)` asks to stop.
fn call_observer(py: Python<'_>, callback: &Py<PyAny>, progress: &Progress) -> PyResult<bool> {
    let costs = costs_dict(py, &progress.best_costs)?;
    let answer = callback.bind(py).call1((progress.generation, costs))?;
    Ok(answer.is_none() || answer.is_truthy()?)
}

/// Registers three overlapping point clouds that form a loop, with no initial guess.
///
/// Returns a :class:`Registration` with ``T12``, ``T23``, ``T31``; ``T_ij`` maps points of
/// cloud i into the frame of cloud j (``x_j = T_ij @ [x_i, 1]``), in the clouds' own frames.
///
/// Each cloud is anything numpy can view as an ``(N, 3)`` array of numbers (float32 or
/// float64, C or Fortran order, nested lists); it needs at least ``MIN_POINTS`` finite points
/// that are not all identical. ``seed`` fixes the run (the same seed, settings and clouds
/// give the same result, whatever ``num_threads``); without one the config's seed is used, or
/// one is drawn, and it is reported as ``Registration.seed``. ``config`` is a :class:`Config`
/// to start from (default ``Config()``); any other keyword is a ``Config`` field that
/// overrides it, e.g. ``generations=30``.
///
/// ``on_generation(generation, best_costs)`` is called after every generation
/// (``generation`` = 1, 2, ... up to ``generations``, or ``restarts * generations`` when
/// restarting, counted across restarts; ``best_costs`` = dict from task name, see
/// ``TASK_NAMES``, to the current run's best cost of that task). Returning ``False`` stops the run after
/// that generation (the result then has ``completed=False``); returning ``None`` or ``True``
/// continues. An exception raised by the callback stops the run and propagates, and so does
/// Ctrl-C (``KeyboardInterrupt``, noticed after the current generation).
///
/// The GIL is released while the engine runs. Bad clouds or settings raise ``ValueError``
/// naming the argument or setting; an unknown keyword raises ``TypeError``.
#[pyfunction]
#[pyo3(signature = (cloud1, cloud2, cloud3, *, seed=None, on_generation=None, config=None, **settings))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn register(
    py: Python<'_>,
    cloud1: &Bound<'_, PyAny>,
    cloud2: &Bound<'_, PyAny>,
    cloud3: &Bound<'_, PyAny>,
    seed: Option<&Bound<'_, PyAny>>,
    on_generation: Option<&Bound<'_, PyAny>>,
    config: Option<&Bound<'_, PyAny>>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyRegistration> {
    let base: Config = match config {
        None => Config::default(),
        Some(c) if c.is_none() => Config::default(),
        Some(c) => match c.cast::<PyConfig>() {
            Ok(c) => c.get().inner.clone(),
            Err(_) => {
                return Err(PyTypeError::new_err(format!(
                    "config must be an mtpcr.Config, got {}",
                    c.get_type().name()?
                )))
            }
        },
    };
    let mut pairs = kwargs_pairs(settings)?;
    if let Some(seed) = seed {
        if !seed.is_none() {
            pairs.push(("seed".to_string(), seed.clone()));
        }
    }
    let config = apply_settings(&base, &pairs, "register")?;
    let callback: Option<Py<PyAny>> = match on_generation {
        Some(f) if !f.is_none() => {
            if !f.is_callable() {
                return Err(PyTypeError::new_err(format!(
                    "on_generation must be callable, got {}",
                    f.get_type().name()?
                )));
            }
            Some(f.clone().unbind())
        }
        _ => None,
    };
    let clouds = [
        cloud_from_py(cloud1, "cloud1")?,
        cloud_from_py(cloud2, "cloud2")?,
        cloud_from_py(cloud3, "cloud3")?,
    ];

    // The engine runs without the GIL; the observer takes it back once per generation to
    // check for Ctrl-C and to call the user's callback. A Python error stops the run and is
    // raised once the engine has returned.
    let mut failure: Option<PyErr> = None;
    let outcome = py.detach(|| {
        let mut observer = |progress: &Progress| -> ControlFlow<()> {
            Python::attach(|py| {
                let verdict = py.check_signals().and_then(|()| match &callback {
                    Some(f) => call_observer(py, f, progress),
                    None => Ok(true),
                });
                match verdict {
                    Ok(true) => ControlFlow::Continue(()),
                    Ok(false) => ControlFlow::Break(()),
                    Err(e) => {
                        failure = Some(e);
                        ControlFlow::Break(())
                    }
                }
            })
        };
        mtpcr_core::register(&clouds, &config, Some(&mut observer))
    });
    if let Some(e) = failure {
        return Err(e);
    }
    py.check_signals()?;
    let inner = outcome.map_err(to_py)?;
    let mut used = config;
    used.seed = Some(inner.seed);
    Ok(PyRegistration {
        inner,
        config: used,
    })
}

/// The result of :func:`register`. Read-only.
///
/// ``T_ij`` maps points of cloud i into the frame of cloud j: ``x_j = T_ij @ [x_i, 1]``.
/// ``poses`` put every cloud into cloud 1's frame (ready to merge). Costs are named by
/// ``TASK_NAMES``: ``J1-a``..``J3-a`` are the aiding tasks, ``J1-o``..``J3-o`` the original
/// tasks (pair 1->2, 2->3, 3->1); lower is better.
#[pyclass(frozen, name = "Registration", module = "mtpcr")]
pub(crate) struct PyRegistration {
    inner: Registration,
    config: Config,
}

#[pymethods]
impl PyRegistration {
    /// 4x4 float64 array mapping cloud 1 into cloud 2's frame.
    #[getter(T12)]
    fn t12<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        transform_to_py(py, &self.inner.transforms[0])
    }

    /// 4x4 float64 array mapping cloud 2 into cloud 3's frame.
    #[getter(T23)]
    fn t23<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        transform_to_py(py, &self.inner.transforms[1])
    }

    /// 4x4 float64 array mapping cloud 3 into cloud 1's frame.
    #[getter(T31)]
    fn t31<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        transform_to_py(py, &self.inner.transforms[2])
    }

    /// ``[T12, T23, T31]`` as a 3x4x4 float64 array.
    #[getter]
    fn transforms<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        transforms_to_py(py, &self.inner.transforms)
    }

    /// Each cloud's transform into cloud 1's frame, ``[I, inv(T12), T31]``, as 3x4x4.
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        transforms_to_py(py, &self.inner.poses())
    }

    /// ``||T31 @ T23 @ T12 - I||_F``: how far the three transforms are from closing the loop.
    #[getter]
    fn loop_residual(&self) -> f64 {
        self.inner.loop_residual()
    }

    /// Best final cost of each task: dict from task name (``TASK_NAMES``) to float.
    #[getter]
    fn best_costs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        costs_dict(py, &self.costs())
    }

    /// Best cost of each task after the initial population (row 0) and after every
    /// generation: float64 array ``(generations_run + 1, 6)``, columns in ``TASK_NAMES`` order.
    #[getter]
    fn history<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let h = &self.inner.history;
        PyArray2::from_owned_array(py, Array2::from_shape_fn((h.len(), 6), |(i, k)| h[i][k]))
    }

    /// The six task names, the keys of ``best_costs`` and the columns of ``history``.
    #[getter]
    fn task_names<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, TASK_NAMES)
    }

    /// Loss evaluations made.
    #[getter]
    fn evaluations(&self) -> usize {
        self.inner.evaluations
    }

    /// Generations run (fewer than configured when the run was stopped).
    #[getter]
    fn generations_run(&self) -> usize {
        self.inner.generations_run
    }

    /// False when ``on_generation`` stopped the run before its last generation.
    #[getter]
    fn completed(&self) -> bool {
        self.inner.completed
    }

    /// Wall-clock seconds of the whole call (downsampling and indexing included).
    #[getter]
    fn seconds(&self) -> f64 {
        self.inner.seconds
    }

    /// The seed that reproduces this result.
    #[getter]
    fn seed(&self) -> u64 {
        self.inner.seed
    }

    /// Inlier radius of the losses, in the clouds' units.
    #[getter]
    fn eps(&self) -> f64 {
        self.inner.eps
    }

    /// Largest bounding-box side of the downsampled clouds, in the clouds' units.
    #[getter]
    fn shift(&self) -> f64 {
        self.inner.shift
    }

    /// The settings of the run as a dict, seed included (``Config(**r.settings)`` reruns it).
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        config_to_dict(py, &self.config)
    }

    fn __repr__(&self) -> String {
        let r = &self.inner;
        let costs: Vec<String> = TASK_NAMES
            .iter()
            .zip(self.costs())
            .map(|(name, cost)| format!("'{name}': {cost:.4}"))
            .collect();
        format!(
            "Registration(completed={}, generations_run={}/{}, seed={}, loop_residual={:.3e}, \
             seconds={:.2}, best_costs={{{}}})",
            if r.completed { "True" } else { "False" },
            r.generations_run,
            self.config.generations,
            r.seed,
            r.loop_residual(),
            r.seconds,
            costs.join(", "),
        )
    }
}

impl PyRegistration {
    /// Best final costs in the order of `TASK_NAMES` (aiding tasks, then original tasks).
    fn costs(&self) -> [f64; 6] {
        let b = &self.inner.best_costs;
        [
            b.aiding[0],
            b.aiding[1],
            b.aiding[2],
            b.original[0],
            b.original[1],
            b.original[2],
        ]
    }
}
