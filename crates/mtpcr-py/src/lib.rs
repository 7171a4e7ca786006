//! Python bindings of mtpcr: the extension module `mtpcr._mtpcr`, re-exported by the pure-Python
//! package `mtpcr` (`python/mtpcr`).
//!
//! Thin by design: this crate converts numpy arrays and Python values into the core's types,
//! releases the GIL around the engine, maps [`mtpcr_core::Error`] to Python exceptions once
//! (`ValueError` for bad input and malformed files, `OSError` for unreadable or unwritable
//! files, `RuntimeError` for the rest) and wraps the results in read-only classes. Every
//! registration decision lives in `mtpcr-core`.
//!
//! Settings travel through serde: a keyword argument is a `Config` field by name, merged over
//! the defaults and deserialized by the core's own `Deserialize`, so a field added to the
//! core's `Config` is a Python keyword (and a `Config` attribute) with no change here.

mod config;
mod convert;
mod engine;
mod errors;
mod evaluate;
mod files;
mod run;
mod screen;

use pyo3::prelude::*;
use pyo3::types::PyTuple;

/// Multi-view point cloud registration by evolutionary multitasking (MTPCR).
///
/// The compiled core of the `mtpcr` package; import from `mtpcr` instead.
#[pymodule]
fn _mtpcr(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add(
        "TASK_NAMES",
        PyTuple::new(
            py,
            mtpcr_core::ViewGraph::ring(3)
                .expect("3 views")
                .task_names(),
        )?,
    )?;
    m.add("MIN_POINTS", mtpcr_core::MIN_POINTS)?;
    m.add_class::<config::PyConfig>()?;
    m.add_class::<run::PyRegistration>()?;
    m.add_class::<files::PyProblem>()?;
    m.add_function(wrap_pyfunction!(run::register, m)?)?;
    m.add_function(wrap_pyfunction!(screen::screen_pairs, m)?)?;
    m.add_function(wrap_pyfunction!(files::read_ply, m)?)?;
    m.add_function(wrap_pyfunction!(files::read_points, m)?)?;
    m.add_function(wrap_pyfunction!(files::read_scans, m)?)?;
    m.add_function(wrap_pyfunction!(files::write_ply, m)?)?;
    m.add_function(wrap_pyfunction!(files::load_problem, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate::evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate::evaluate_pairs, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate::find_shared_dir, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate::describe_suite, m)?)?;
    Ok(())
}
