//! `register()` and its result class.

use crate::config::{call_config, config_to_dict};
use crate::convert::{points_from_py, points_to_py, transform_to_py, transforms_to_py};
use crate::engine::{callable, clouds_from_py, costs_dict, run_engine, Callbacks};
use crate::errors::to_py;
use crate::screen::screening_from_py;
use mtpcr_core::{Config, Registration};

use numpy::ndarray::Array2;
use numpy::{PyArray2, PyArray3};
use pyo3::exceptions::{PyAttributeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

/// Merged points and the cloud each came from.
type Merged<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, numpy::PyArray1<i64>>);

/// Registers overlapping point clouds with no initial guess: ``register(a, b)`` for two
/// clouds, ``register(a, b, c, ...)`` (or ``register(*clouds)``) for three or more given in
/// loop order (cloud k overlaps cloud k+1, the last closes the loop with the first).
///
/// Returns a :class:`Registration`: one transform per edge (``T12``; or ``T12``, ``T23``,
/// ..., ``Tn1``) and one pose per cloud. ``T_ij`` maps points of cloud i into the frame of
/// cloud j (``x_j = T_ij @ [x_i, 1]``), in the clouds' own frames.
///
/// Each cloud is anything numpy can view as an ``(N, 3)`` array of real numbers (float or
/// int, C or Fortran order, nested lists, an object array of numbers; booleans, complex
/// numbers and strings are refused); it needs at least ``MIN_POINTS`` finite points of
/// magnitude at most 1e30, not all identical and not all on one line. A planar cloud is
/// registered with a ``UserWarning`` (its rotation about the plane normal is weakly
/// determined). ``seed`` fixes the run (the same seed, settings and clouds
/// give the same result, whatever ``num_threads``); without one the config's seed is used, or
/// one is drawn, and it is reported as ``Registration.seed``. ``config`` is a :class:`Config`
/// to start from (default ``Config()``); any other keyword is a ``Config`` field that
/// overrides it, e.g. ``generations=30``.
///
/// ``on_generation(generation, best_costs)`` is called after every generation
/// (``generation`` = 1, 2, ... up to ``generations``, or ``restarts * generations`` when
/// restarting, counted across restarts; ``best_costs`` = dict from task name (``J1-a``,
/// ``J2-a``, ..., ``J1-o``, ...: the aiding and original task of each edge) to the current
/// evolution's best cost of that task). Returning ``False`` stops the run after that
/// generation (the result then has ``completed=False``); returning ``None`` or ``True``
/// continues. An exception raised by the callback stops the run and propagates, and so does
/// Ctrl-C (``KeyboardInterrupt``, noticed after the current generation).
///
/// ``viewpoints`` says where each scanner stood, in its cloud's own frame, so that the
/// registration can check free space (a right pose puts no cloud's surface where another
/// scanner saw through); without them that check is absent. ``None`` (the default): unknown;
/// ``"origin"``: every cloud was taken from its own origin (depth-camera frames, 3DMatch
/// fragments); or a sequence with one entry per cloud, each ``None`` or 3 finite numbers
/// (e.g. ``[s["viewpoint"] for s in read_scans(path)]``). Anything else raises ``ValueError``.
///
/// ``on_pair_screening(screened, total)`` is called as four or more clouds given in no
/// known order are screened pair by pair for pose hypotheses (after each batch of pairs;
/// the slow part of a whole room); returning ``False`` stops the screening (the pairs not
/// screened are not used, the result has ``completed=False``).
///
/// ``screening``: the pair screening of these clouds made already by :func:`screen_pairs`
/// (one result, or a list of results for disjoint sets of pairs; four or more clouds in no
/// known order): the registration skips screening and gives exactly the result it would
/// have given screening every pair itself. It must come from the same clouds and settings
/// (a ``ValueError`` says when it does not).
///
/// The GIL is released while the engine runs. Bad clouds or settings raise ``ValueError``
/// naming the argument or setting; an unknown keyword raises ``TypeError``.
#[pyfunction]
#[pyo3(signature = (*clouds, seed=None, on_generation=None, on_pair_screening=None, config=None, viewpoints=None, screening=None, **settings))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn register(
    py: Python<'_>,
    clouds: &Bound<'_, PyTuple>,
    seed: Option<&Bound<'_, PyAny>>,
    on_generation: Option<&Bound<'_, PyAny>>,
    on_pair_screening: Option<&Bound<'_, PyAny>>,
    config: Option<&Bound<'_, PyAny>>,
    viewpoints: Option<&Bound<'_, PyAny>>,
    screening: Option<&Bound<'_, PyAny>>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyRegistration> {
    let config = call_config(config, settings, seed, "register")?;
    let callbacks = Callbacks {
        generation: callable(on_generation, "on_generation")?,
        pair_screening: callable(on_pair_screening, "on_pair_screening")?,
        may_stop: true,
    };
    if clouds.len() < 2 {
        return Err(PyTypeError::new_err(format!(
            "register() needs at least two clouds, got {} (pass them as separate arguments: \
             register(a, b) or register(*clouds))",
            clouds.len()
        )));
    }
    let clouds = clouds_from_py(clouds, viewpoints)?;
    let screening = screening.map(screening_from_py).transpose()?;
    let names = mtpcr_core::ViewGraph::for_views(clouds.len())
        .map_err(to_py)?
        .task_names();
    let inner = run_engine(
        py,
        &callbacks,
        &names,
        |observer, interrupt| match &screening {
            Some(screening) => {
                mtpcr_core::register_screened(&clouds, &config, screening, observer, interrupt)
            }
            None => mtpcr_core::register_interruptible(&clouds, &config, observer, interrupt),
        },
    )?;
    let mut used = config;
    used.seed = Some(inner.seed);
    Ok(PyRegistration {
        inner,
        config: used,
    })
}

/// The result of :func:`register`. Read-only.
///
/// ``T_ij`` maps points of cloud i into the frame of cloud j: ``x_j = T_ij @ [x_i, 1]``. Each
/// edge's transform is an attribute named so (``T12``; for three clouds ``T12``, ``T23``,
/// ``T31``); ``transforms`` stacks them in edge order, ``edges`` describes them, and
/// ``poses`` put every cloud into cloud 1's frame (ready to merge). Costs are named by task:
/// ``J1-a``, ``J2-a``, ... are the aiding tasks, ``J1-o``, ``J2-o``, ... the original tasks
/// of edge 1, 2, ...; lower is better; they are the evolution's, before the refinement.
#[pyclass(frozen, name = "Registration", module = "mtpcr")]
pub(crate) struct PyRegistration {
    inner: Registration,
    config: Config,
}

#[pymethods]
impl PyRegistration {
    /// The transform of edge ``name`` (``T12``, ``T23``, ...), a 4x4 float64 array.
    fn __getattr__<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyArray2<f64>>> {
        (0..self.inner.edges.len())
            .find(|&k| self.inner.edge_name(k) == name)
            .map(|k| transform_to_py(py, &self.inner.edges[k].t_target_source))
            .ok_or_else(|| {
                let names: Vec<String> = (0..self.inner.edges.len())
                    .map(|k| self.inner.edge_name(k))
                    .collect();
                PyAttributeError::new_err(format!(
                    "'Registration' object has no attribute '{name}' (its transforms are {})",
                    names.join(", ")
                ))
            })
    }

    /// The edge transforms in edge order (``[T12, T23, T31]`` for three clouds), Kx4x4.
    #[getter]
    fn transforms<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        transforms_to_py(py, &self.inner.transforms())
    }

    /// One dict per edge: ``name`` (``"T12"``), ``source`` and ``target`` (clouds numbered
    /// from 0), ``t_target_source`` (4x4), and the evolution's ``original_cost`` and
    /// ``aiding_cost``.
    #[getter]
    fn edges<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .edges
            .iter()
            .enumerate()
            .map(|(k, e)| {
                let d = PyDict::new(py);
                d.set_item("name", self.inner.edge_name(k))?;
                d.set_item("source", e.source)?;
                d.set_item("target", e.target)?;
                d.set_item("t_target_source", transform_to_py(py, &e.t_target_source))?;
                d.set_item("original_cost", e.original_cost)?;
                d.set_item("aiding_cost", e.aiding_cost)?;
                Ok(d)
            })
            .collect()
    }

    /// The 4x4 transform mapping cloud ``source`` into cloud ``target``'s frame (clouds
    /// numbered from 0): the edge's own estimate, its inverse, or composed from the poses.
    fn t_target_source<'py>(
        &self,
        py: Python<'py>,
        target: usize,
        source: usize,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = self.inner.poses.len();
        if target >= n || source >= n {
            return Err(PyValueError::new_err(format!(
                "clouds are numbered 0..{n}, got target {target} and source {source}"
            )));
        }
        match self.inner.t_target_source(target, source) {
            Some(t) => Ok(transform_to_py(py, &t)),
            None => Err(PyValueError::new_err(format!(
                "cloud {target} or cloud {source} could not be placed (see unplaced)"
            ))),
        }
    }

    /// Each cloud's transform into cloud 1's frame (``poses[0]`` is the identity), Nx4x4
    /// (when cloud 1 is not placed, into the first placed cloud's frame: its pose is the
    /// identity);
    /// all NaN for a cloud that could not be placed (see ``unplaced``).
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        let nan = mtpcr_core::Transform::from_element(f64::NAN);
        let poses: Vec<_> = self.inner.poses.iter().map(|p| p.unwrap_or(nan)).collect();
        transforms_to_py(py, &poses)
    }

    /// ``points`` of cloud ``cloud`` (numbered from 0; an (N, 3) array or anything with
    /// ``.points``) mapped into cloud 1's frame by the cloud's pose, an (N, 3) float64 array.
    /// ValueError when that cloud was not placed.
    fn transform_points<'py>(
        &self,
        py: Python<'py>,
        cloud: usize,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let points = points_from_py(points, "points")?;
        let views = self.inner.poses.len();
        if cloud >= views {
            return Err(PyValueError::new_err(format!(
                "cloud {cloud} out of range: {views} clouds, numbered from 0"
            )));
        }
        let placed = self.inner.place(cloud, &points).ok_or_else(|| {
            PyValueError::new_err(format!("cloud {cloud} was not placed (see `unplaced`)"))
        })?;
        Ok(points_to_py(py, &placed))
    }

    /// The clouds given to ``register`` (same order) merged in cloud 1's frame: an (M, 3)
    /// float64 array and an (M,) int64 array of the cloud (from 0) each point came from.
    /// Unplaced clouds are left out.
    #[pyo3(signature = (*clouds))]
    fn merge<'py>(&self, py: Python<'py>, clouds: &Bound<'py, PyTuple>) -> PyResult<Merged<'py>> {
        let views = self.inner.poses.len();
        if clouds.len() != views {
            return Err(PyValueError::new_err(format!(
                "{} clouds given, the registration has {views}",
                clouds.len()
            )));
        }
        let points: Vec<Vec<[f64; 3]>> = clouds
            .iter()
            .enumerate()
            .map(|(k, c)| points_from_py(&c, &format!("cloud {k}")))
            .collect::<PyResult<_>>()?;
        let refs: Vec<&[[f64; 3]]> = points.iter().map(Vec::as_slice).collect();
        let (merged, from) = self.inner.merge(&refs).expect("one cloud per view");
        let from: Vec<i64> = from.into_iter().map(|k| k as i64).collect();
        Ok((
            points_to_py(py, &merged),
            numpy::PyArray1::from_vec(py, from),
        ))
    }

    /// Each placed cloud's pose in cloud 1's frame as a ``.log`` trajectory (the 3DMatch and
    /// Redwood format): per cloud a line ``k k n`` (index from 0, twice; number of clouds)
    /// and its 4x4 pose, one row per line; unplaced clouds are left out. Write it to a file
    /// for the tools that read such trajectories.
    fn trajectory_log(&self) -> String {
        mtpcr_core::io::trajectory_log(&self.inner.poses)
    }

    /// Open3D's pose graph as a dict: one node per cloud (its pose in cloud 1's frame; the
    /// identity for an unplaced cloud, which no edge touches) and one edge per pair used
    /// (``transformation`` maps the source cloud into the target's frame; ``information`` is
    /// the identity). ``json.dump`` it to a file, then ``open3d.io.read_pose_graph``.
    fn pose_graph<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let graph = mtpcr_core::io::pose_graph_json(&self.inner.poses, &self.inner.edges);
        crate::convert::json_text_to_py(py, &graph.to_string())
    }

    /// Whether the result can be believed: every pair overlaps and its surfaces lie on each
    /// other at the returned transforms, and every cloud was placed (``verdict`` says why
    /// not).
    #[getter]
    fn confident(&self) -> bool {
        self.inner.verdict.confident
    }

    /// The verdict: a dict with ``confident``, ``reasons`` (list of str, empty when
    /// confident) and ``edges`` (per pair: ``source``, ``target``, ``overlap``: fraction of
    /// points within eps of the other cloud, ``residual``: their median distance to its
    /// surface, relative to eps, ``self_residual``: the same for the two scans against
    /// themselves, the larger; what a perfect fit would leave; ``constraint``: how firmly the
    /// overlapping surfaces hold the pose against a slide, ``support``, ``rival_support``,
    /// ``free_space``, ``free_share``, ``landed`` and ``tight_support``, each None when not
    /// measured).
    #[getter]
    fn verdict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = serde_json::to_string(&self.inner.verdict)
            .map_err(|e| PyValueError::new_err(format!("verdict: {e}")))?;
        crate::convert::json_text_to_py(py, &text)
    }

    /// The cloud (numbered from 0) whose frame ``poses`` are in: 0, or the first placed cloud
    /// when cloud 0 could not be placed; ``None`` when none is placed.
    #[getter]
    fn reference_cloud(&self) -> Option<usize> {
        self.inner.reference_view()
    }

    /// The clouds that could not be placed: dicts with ``cloud`` (numbered from 0) and
    /// ``reason``; empty when every cloud was placed.
    #[getter]
    fn unplaced<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .unplaced
            .iter()
            .map(|u| {
                let d = PyDict::new(py);
                d.set_item("cloud", u.view)?;
                d.set_item("reason", &u.reason)?;
                Ok(d)
            })
            .collect()
    }

    /// ``||T_n1 ... T23 @ T12 - I||_F`` for three or more clouds in a loop (how far the
    /// transforms are from closing it; ~0 after refinement); ``None`` for two clouds.
    #[getter]
    fn loop_residual(&self) -> Option<f64> {
        self.inner.loop_residual()
    }

    /// The evolution's final best cost of each task (before refinement): dict from task name
    /// (``task_names``) to float.
    #[getter]
    fn best_costs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        costs_dict(py, &self.inner.task_names, &self.inner.best_costs())
    }

    /// Best cost of each task of the kept evolution (the restart with the lowest final
    /// original costs) after its initial population (row 0) and after every generation:
    /// float64 array ``(generations + 1, tasks)``, columns in ``task_names`` order.
    #[getter]
    fn history<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let h = &self.inner.history;
        let cols = h.first().map_or(0, Vec::len);
        PyArray2::from_owned_array(py, Array2::from_shape_fn((h.len(), cols), |(i, k)| h[i][k]))
    }

    /// The task names, the keys of ``best_costs`` and the columns of ``history``.
    #[getter]
    fn task_names<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, &self.inner.task_names)
    }

    /// Loss evaluations made (all restarts).
    #[getter]
    fn evaluations(&self) -> usize {
        self.inner.evaluations
    }

    /// Generations run, all restarts together (fewer than ``restarts * generations`` when the
    /// run was stopped).
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
        let costs: Vec<String> = r
            .task_names
            .iter()
            .zip(r.best_costs())
            .map(|(name, cost)| format!("'{name}': {cost:.4}"))
            .collect();
        let residual = r
            .loop_residual()
            .map_or("None".to_string(), |v| format!("{v:.3e}"));
        format!(
            "Registration(clouds={}, confident={}, completed={}, generations_run={} ({} restarts \
             x {}), seed={}, loop_residual={residual}, seconds={:.2}, best_costs={{{}}})",
            r.poses.len(),
            if r.verdict.confident { "True" } else { "False" },
            if r.completed { "True" } else { "False" },
            r.generations_run,
            self.config.restarts,
            self.config.generations,
            r.seed,
            r.seconds,
            costs.join(", "),
        )
    }
}
