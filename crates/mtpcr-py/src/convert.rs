//! Conversions between Python values and the core's types: point arrays, transforms, and the
//! JSON values that carry settings through serde.

use mtpcr_core::{PointCloud, Transform};
use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray2, PyArray3, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyString};
use serde_json::Value;

/// A shape as Python prints it: `(5, 2)`, `(7,)`, `()`.
pub(crate) fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => {
            let parts: Vec<String> = shape.iter().map(usize::to_string).collect();
            format!("({})", parts.join(", "))
        }
    }
}

/// `numpy.asarray(obj, dtype=dtype)`, with a failure reported as a `ValueError` naming `name`
/// (the numpy error is kept as its cause).
fn as_numpy<'py>(
    obj: &Bound<'py, PyAny>,
    dtype: Option<&str>,
    name: &str,
    what: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let py = obj.py();
    let kwargs = PyDict::new(py);
    if let Some(dtype) = dtype {
        kwargs.set_item("dtype", dtype)?;
    }
    py.import("numpy")?
        .call_method("asarray", (obj,), Some(&kwargs))
        .map_err(|cause| {
            let err = PyValueError::new_err(format!(
                "{name} must be {what}, got {}: {cause}",
                type_name(obj)
            ));
            err.set_cause(py, Some(cause));
            err
        })
}

/// The array is being written by other Rust code (cannot happen from Python alone).
fn borrowed(name: &str, e: numpy::BorrowError) -> PyErr {
    PyValueError::new_err(format!("{name} cannot be read: {e}"))
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "an object".to_string())
}

/// What a points argument must be, for error messages.
const POINTS: &str = "an (N, 3) array of real numbers (or an object with one as `.points`)";

/// `array` (a numpy array) if its dtype holds real numbers: float, signed or unsigned int; an
/// object array whose elements are all such numbers is converted. Booleans, complex numbers,
/// strings, bytes, objects that are not numbers, dates and records are refused (numpy would
/// cast them silently) with a `ValueError` naming `name` and the dtype.
fn real_numbers<'py>(array: Bound<'py, PyAny>, name: &str) -> PyResult<Bound<'py, PyAny>> {
    let kind = |a: &Bound<'py, PyAny>| -> PyResult<String> {
        a.getattr("dtype")?.getattr("kind")?.extract()
    };
    let real = |kind: &str| matches!(kind, "f" | "i" | "u");
    let mut dtype = array.getattr("dtype")?.str()?.to_string();
    if kind(&array)? == "O" {
        // Numbers held as Python objects: numpy infers the elements' own dtype.
        let elements = array
            .py()
            .import("numpy")?
            .call_method1("asarray", (array.call_method0("tolist")?,));
        if let Ok(elements) = elements {
            if real(&kind(&elements)?) {
                return Ok(elements);
            }
            if kind(&elements)? != "O" {
                dtype = format!("{dtype} holding {}", elements.getattr("dtype")?.str()?);
            }
        }
    }
    if real(&kind(&array)?) {
        return Ok(array);
    }
    Err(PyValueError::new_err(format!(
        "{name} must be {POINTS}, got dtype {dtype} (booleans, complex numbers, strings and \
         objects that are not numbers are not coordinates)"
    )))
}

/// Anything numpy can view as an `(N, 3)` array of real numbers (any float or int dtype, C
/// or Fortran order, nested lists, an object array of numbers), or an object with such a
/// `.points` attribute (an Open3D `PointCloud`, say), as points. Shape and dtype errors name
/// `name`; booleans, complex numbers, strings and other objects are refused.
pub(crate) fn points_from_py(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<[f64; 3]>> {
    // Arrays and lists are taken as they are; anything else with `.points` gives those.
    let is_array_like = obj.hasattr("__array__")?
        || obj.is_instance_of::<pyo3::types::PyList>()
        || obj.is_instance_of::<pyo3::types::PyTuple>();
    let source = if !is_array_like && obj.hasattr("points")? {
        obj.getattr("points")?
    } else {
        obj.clone()
    };
    let array = real_numbers(as_numpy(&source, None, name, POINTS)?, name)?;
    let array = as_numpy(&array, Some("float64"), name, POINTS)?.cast_into::<PyArrayDyn<f64>>()?;
    let shape = array.shape();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (N, 3), got {}",
            shape_text(shape)
        )));
    }
    let readonly = array.try_readonly().map_err(|e| borrowed(name, e))?;
    let view = readonly.as_array();
    Ok(view.outer_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// A cloud argument of `register`: converted, then checked by the core under the argument's
/// own name (empty, non-finite or huge coordinates, too few points, no extent, collinear).
/// A planar cloud ([`PointCloud::is_planar`]) is accepted with a `UserWarning`.
pub(crate) fn cloud_from_py(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<PointCloud> {
    let cloud = PointCloud::new(points_from_py(obj, name)?);
    cloud
        .validate(name, mtpcr_core::MIN_POINTS)
        .map_err(crate::errors::to_py)?;
    if cloud.is_planar() {
        let py = obj.py();
        let message = std::ffi::CString::new(format!(
            "{name} is planar: its rotation about the plane normal is weakly determined"
        ))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
        PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)?;
    }
    Ok(cloud)
}

/// What the `viewpoints` argument of `register` may be, for error messages.
const VIEWPOINTS: &str = "None, \"origin\" or a sequence with one entry per cloud, each None \
    or 3 finite numbers";

/// The `viewpoints` argument of `register` for `count` clouds: each cloud's viewpoint (the
/// scanner's position in the cloud's frame) or `None`. `None` gives none; `"origin"` puts
/// every scanner at its cloud's origin; a sequence gives one entry per cloud, each `None` or
/// anything numpy views as 3 finite real numbers. Anything else is a `ValueError` naming the
/// problem (`viewpoints[1] must be 3 finite numbers, got shape (2,)`).
pub(crate) fn viewpoints_from_py(
    obj: Option<&Bound<'_, PyAny>>,
    count: usize,
) -> PyResult<Vec<Option<[f64; 3]>>> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(vec![None; count]);
    };
    if obj.is_instance_of::<PyString>() {
        let text: String = obj.extract()?;
        return match text.as_str() {
            "origin" => Ok(vec![Some([0.0; 3]); count]),
            _ => Err(PyValueError::new_err(format!(
                "viewpoints must be {VIEWPOINTS}; got the string {text:?} (the only string \
                 accepted is \"origin\")"
            ))),
        };
    }
    let not_a_sequence = || {
        PyValueError::new_err(format!(
            "viewpoints must be {VIEWPOINTS}; got {}",
            type_name(obj)
        ))
    };
    let len = obj.len().map_err(|_| not_a_sequence())?;
    if len != count {
        return Err(PyValueError::new_err(format!(
            "viewpoints must have one entry per cloud: {count} clouds, {len} viewpoints"
        )));
    }
    (0..count)
        .map(|i| {
            let entry = obj.get_item(i).map_err(|_| not_a_sequence())?;
            if entry.is_none() {
                return Ok(None);
            }
            let name = format!("viewpoints[{i}]");
            let what = "3 finite numbers";
            let array = as_numpy(&entry, None, &name, what)?;
            let kind: String = array.getattr("dtype")?.getattr("kind")?.extract()?;
            if !matches!(kind.as_str(), "f" | "i" | "u") {
                let dtype = array.getattr("dtype")?.str()?.to_string();
                return Err(PyValueError::new_err(format!(
                    "{name} must be {what}, got dtype {dtype}"
                )));
            }
            let array =
                as_numpy(&array, Some("float64"), &name, what)?.cast_into::<PyArrayDyn<f64>>()?;
            if array.shape() != [3] {
                return Err(PyValueError::new_err(format!(
                    "{name} must be {what}, got shape {}",
                    shape_text(array.shape())
                )));
            }
            let readonly = array.try_readonly().map_err(|e| borrowed(&name, e))?;
            let v = readonly.as_array();
            let point = [v[0], v[1], v[2]];
            if point.iter().any(|x| !x.is_finite()) {
                return Err(PyValueError::new_err(format!(
                    "{name} must be {what}, got {point:?}"
                )));
            }
            Ok(Some(point))
        })
        .collect()
}

/// Per-point RGB colours: an `(expected, 3)` array of integers in 0..=255.
pub(crate) fn colors_from_py(
    obj: &Bound<'_, PyAny>,
    name: &str,
    expected: usize,
) -> PyResult<Vec<[u8; 3]>> {
    let array = as_numpy(obj, None, name, "an (N, 3) array of integers in 0..=255")?;
    let kind: String = array.getattr("dtype")?.getattr("kind")?.extract()?;
    if kind != "u" && kind != "i" {
        let dtype = array.getattr("dtype")?.str()?.to_string();
        return Err(PyValueError::new_err(format!(
            "{name} must hold integers in 0..=255 (uint8), got dtype {dtype}"
        )));
    }
    let array = array
        .call_method1("astype", ("int64",))?
        .cast_into::<PyArrayDyn<i64>>()?;
    let shape = array.shape();
    if shape.len() != 2 || shape[1] != 3 || shape[0] != expected {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape ({expected}, 3) (one RGB triple per point), got {}",
            shape_text(shape)
        )));
    }
    let readonly = array.try_readonly().map_err(|e| borrowed(name, e))?;
    let view = readonly.as_array();
    let mut colors = Vec::with_capacity(expected);
    for (i, row) in view.outer_iter().enumerate() {
        let mut rgb = [0u8; 3];
        for (k, slot) in rgb.iter_mut().enumerate() {
            *slot = u8::try_from(row[k]).map_err(|_| {
                PyValueError::new_err(format!("{name}[{i}, {k}] = {} is outside 0..=255", row[k]))
            })?;
        }
        colors.push(rgb);
    }
    Ok(colors)
}

/// Points as an `(N, 3)` float64 array.
pub(crate) fn points_to_py<'py>(py: Python<'py>, points: &[[f64; 3]]) -> Bound<'py, PyArray2<f64>> {
    let array = Array2::from_shape_fn((points.len(), 3), |(i, k)| points[i][k]);
    PyArray2::from_owned_array(py, array)
}

/// A transform as a 4x4 float64 array.
pub(crate) fn transform_to_py<'py>(py: Python<'py>, t: &Transform) -> Bound<'py, PyArray2<f64>> {
    PyArray2::from_owned_array(py, Array2::from_shape_fn((4, 4), |(i, j)| t[(i, j)]))
}

/// Transforms as a Kx4x4 float64 array.
pub(crate) fn transforms_to_py<'py>(
    py: Python<'py>,
    ts: &[Transform],
) -> Bound<'py, PyArray3<f64>> {
    PyArray3::from_owned_array(
        py,
        Array3::from_shape_fn((ts.len(), 4, 4), |(k, i, j)| ts[k][(i, j)]),
    )
}

/// A JSON value as the equivalent Python object (dicts keep the JSON text's key order).
pub(crate) fn json_to_py<'py>(py: Python<'py>, value: &Value) -> PyResult<Bound<'py, PyAny>> {
    json_text_to_py(py, &value.to_string())
}

/// JSON text parsed by Python's `json` module.
pub(crate) fn json_text_to_py<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (text,))
}

/// A setting's Python value as JSON: `None`, bool, int (Python or numpy), finite float (Python
/// or numpy) or str. Errors name `field`.
pub(crate) fn json_from_py(field: &str, v: &Bound<'_, PyAny>) -> PyResult<Value> {
    if v.is_none() {
        return Ok(Value::Null);
    }
    if v.is_instance_of::<PyBool>() {
        return Ok(Value::Bool(v.extract::<bool>()?));
    }
    if v.is_instance_of::<PyString>() {
        return Ok(Value::String(v.extract::<String>()?));
    }
    if !v.is_instance_of::<PyFloat>() && v.hasattr("__index__")? {
        let int = v.call_method0("__index__")?;
        if let Ok(u) = int.extract::<u64>() {
            return Ok(Value::from(u));
        }
        if let Ok(i) = int.extract::<i64>() {
            return Ok(Value::from(i));
        }
        return Err(PyValueError::new_err(format!(
            "invalid setting `{field}`: the integer {} is out of range",
            int.str()?
        )));
    }
    if v.hasattr("__float__")? {
        let x: f64 = v.extract()?;
        return serde_json::Number::from_f64(x)
            .map(Value::Number)
            .ok_or_else(|| {
                PyValueError::new_err(format!(
                    "invalid setting `{field}`: must be a finite number, got {x}"
                ))
            });
    }
    Err(PyTypeError::new_err(format!(
        "setting `{field}` must be a number, a bool, a str or None, got {}",
        type_name(v)
    )))
}
