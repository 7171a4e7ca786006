//! The one mapping from the core's [`Error`] to Python exceptions.

use mtpcr_core::Error;
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::PyErr;

/// `Io` -> `OSError` (with errno and file name, so a missing file is a `FileNotFoundError`);
/// bad clouds, bad settings, bad arguments and malformed files -> `ValueError`; an unknown
/// setting -> `TypeError`; anything else
/// (variants added later) -> `RuntimeError`.
pub(crate) fn to_py(err: Error) -> PyErr {
    match &err {
        Error::Io { path, source } => match source.raw_os_error() {
            Some(code) => {
                // io::Error prints "No such file or directory (os error 2)"; Python wants the
                // bare text, and builds "[Errno 2] No such file or directory: 'path'" itself.
                let text = source.to_string();
                let text = text
                    .strip_suffix(&format!(" (os error {code})"))
                    .unwrap_or(&text)
                    .to_string();
                PyOSError::new_err((code, text, path.display().to_string()))
            }
            None => PyOSError::new_err(err.to_string()),
        },
        Error::EmptyCloud { .. }
        | Error::TooFewPoints { .. }
        | Error::NonFiniteCoordinate { .. }
        | Error::DegenerateCloud { .. }
        | Error::CoordinateTooLarge { .. }
        | Error::CollinearCloud { .. }
        | Error::InvalidConfig { .. }
        | Error::MalformedFile { .. }
        | Error::InvalidInput(_) => PyValueError::new_err(err.to_string()),
        Error::UnknownSetting { .. } => PyTypeError::new_err(err.to_string()),
        Error::Interrupted => pyo3::exceptions::PyKeyboardInterrupt::new_err("interrupted"),
        _ => PyRuntimeError::new_err(err.to_string()),
    }
}
