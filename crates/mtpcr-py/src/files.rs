//! PLY files and problem files.

use crate::convert::{
    colors_from_py, points_from_py, points_to_py, transform_to_py, transforms_to_py,
};
use crate::errors::to_py;
use mtpcr_core::eval::problem::Problem;
use mtpcr_core::io;
use numpy::{PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::path::{Path, PathBuf};

fn path_text(path: &Path) -> String {
    path.to_string_lossy().into_owned()
}

/// Reads the ``x y z`` of a PLY file's vertices (ASCII or binary, any scalar type; other
/// elements and properties are ignored) as an ``(N, 3)`` float64 array.
///
/// Raises ``OSError`` (``FileNotFoundError``, ...) when the file cannot be read and
/// ``ValueError`` when it is not a usable PLY file.
#[pyfunction]
pub(crate) fn read_ply(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArray2<f64>>> {
    let cloud = py.detach(|| io::read_ply(&path)).map_err(to_py)?;
    Ok(points_to_py(py, cloud.points()))
}

/// Reads the one scan of a point-cloud file as an ``(N, 3)`` float64 array: PLY, PCD
/// (ascii, binary, binary_compressed), E57, LAS/LAZ, XYZ/TXT/CSV or PTS, told by the file's
/// content, then its extension. An E57 file with several scans is an error: use
/// :func:`read_scans`.
///
/// Raises ``OSError`` when the file cannot be read and ``ValueError`` when it is malformed.
#[pyfunction]
pub(crate) fn read_points(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArray2<f64>>> {
    let cloud = py.detach(|| io::read_points(&path)).map_err(to_py)?;
    Ok(points_to_py(py, cloud.points()))
}

/// Reads every scan of a point-cloud file (the formats of :func:`read_points`; an E57 file
/// may hold several scans): a list of dicts with ``name`` (str), ``points`` (``(N, 3)``
/// float64), ``pose`` (the 4x4 scan-to-file-frame pose stored with an E57 scan, else
/// ``None``) and ``viewpoint`` (the scanner's position in the scan's frame, 3 floats, when
/// the file gives one: a PCD header's VIEWPOINT other than the default; else ``None``),
/// ready for ``register(*[s["points"] for s in scans], viewpoints=[s["viewpoint"] for s in
/// scans])``.
#[pyfunction]
pub(crate) fn read_scans(py: Python<'_>, path: PathBuf) -> PyResult<Vec<Bound<'_, PyDict>>> {
    let scans = py.detach(|| io::read_scans(&path)).map_err(to_py)?;
    scans
        .iter()
        .map(|scan| {
            let d = PyDict::new(py);
            d.set_item("name", &scan.name)?;
            d.set_item("points", points_to_py(py, scan.cloud.points()))?;
            match &scan.pose {
                Some(pose) => d.set_item("pose", transform_to_py(py, pose))?,
                None => d.set_item("pose", py.None())?,
            }
            d.set_item("viewpoint", scan.cloud.viewpoint())?;
            Ok(d)
        })
        .collect()
}

/// Writes points as a binary little-endian PLY file with double coordinates (created or
/// truncated).
///
/// ``points`` is anything numpy can view as an ``(N, 3)`` array of numbers; ``colors``, if
/// given, an ``(N, 3)`` array of integers in 0..=255 (uint8) written as ``red green blue``.
/// Raises ``ValueError`` for bad arrays and ``OSError`` when the file cannot be written.
#[pyfunction]
#[pyo3(signature = (path, points, colors=None))]
pub(crate) fn write_ply(
    py: Python<'_>,
    path: PathBuf,
    points: &Bound<'_, PyAny>,
    colors: Option<&Bound<'_, PyAny>>,
) -> PyResult<()> {
    let points = points_from_py(points, "points")?;
    let colors = match colors {
        Some(c) if !c.is_none() => Some(colors_from_py(c, "colors", points.len())?),
        _ => None,
    };
    py.detach(|| io::write_ply(&path, &points, colors.as_deref()))
        .map_err(to_py)
}

/// Reads a problem file (``shared/problems/*.json``): two or more scans and their ground
/// truth (poses rigid to 1e-3 are accepted and made exactly rigid; see ``Problem.notes``).
///
/// Scan paths are resolved against ``data_root`` when given, else against the parent of the
/// folder holding the problem file (the layout of ``shared/``). Raises ``OSError`` when the
/// file cannot be read and ``ValueError`` when its content is malformed.
#[pyfunction]
#[pyo3(signature = (path, data_root=None))]
pub(crate) fn load_problem(
    py: Python<'_>,
    path: PathBuf,
    data_root: Option<PathBuf>,
) -> PyResult<PyProblem> {
    let inner = py
        .detach(|| Problem::load(&path, data_root.as_deref()))
        .map_err(to_py)?;
    Ok(PyProblem { inner })
}

/// A registration problem with ground truth, from :func:`load_problem`. Read-only.
///
/// ``poses`` are scan-to-world (``x_world = pose_i @ [x_i, 1]``); ``ground_truth`` holds the
/// transform of each edge of the scans in file order (two scans: ``[T12]``; three or more, a
/// loop: ``[T12, T23, ..., Tn1]``) with ``T_ij = inv(pose_j) @ pose_i`` mapping scan i into
/// scan j, the same convention as :class:`Registration`.
#[pyclass(frozen, name = "Problem", module = "mtpcr")]
pub(crate) struct PyProblem {
    inner: Problem,
}

#[pymethods]
impl PyProblem {
    /// Short name of the problem (``"bunny-a"``).
    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    /// The scan files, resolved against the data root, as str.
    #[getter]
    fn scans(&self) -> Vec<String> {
        self.inner.scans.iter().map(|p| path_text(p)).collect()
    }

    /// Ground-truth scan-to-world poses, Nx4x4 float64.
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        transforms_to_py(py, &self.inner.poses)
    }

    /// Ground truth of each edge (``[T12, T23, T31]`` for three scans), Kx4x4 float64.
    #[getter]
    fn ground_truth<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        Ok(transforms_to_py(
            py,
            &self.inner.ground_truth().map_err(to_py)?,
        ))
    }

    /// What loading changed (poses re-orthonormalised), one sentence each.
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.inner.notes.clone()
    }

    /// Reads the scans: a tuple of ``(N, 3)`` float64 arrays.
    fn read_scans<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let clouds = py.detach(|| self.inner.read_scans()).map_err(to_py)?;
        PyTuple::new(py, clouds.iter().map(|c| points_to_py(py, c.points())))
    }

    fn __repr__(&self) -> String {
        let scans: Vec<String> = self
            .inner
            .scans
            .iter()
            .map(|p| format!("{:?}", path_text(p)))
            .collect();
        format!(
            "Problem(name={:?}, scans=[{}])",
            self.inner.name,
            scans.join(", ")
        )
    }
}
