//! The crate's errors as Python exceptions: a scene file's error is a `SceneError` (a
//! `ValueError`) whose message is the command line's (`FILE:LINE:COLUMN: what`), a bad
//! argument a `ValueError`, a file that does not exist a `FileNotFoundError`, a failed
//! write an `OSError`, a ray-tracing backend's failure a `RuntimeError`.

use pcbpt::error::Error;
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use std::ffi::CString;
use std::path::Path;

create_exception!(
    pcbpt,
    SceneError,
    PyValueError,
    "An error in a scene file or a file it reads. The message names the file, and the line and \
     column where there is one, as `pcbpt render` prints it; the attributes `file`, `line` and \
     `column` hold them (`line` and `column` None where the error has no place)."
);

/// `e` as a Python exception, an error about an input file being a `SceneError`.
pub fn scene_error(py: Python<'_>, e: Error) -> PyErr {
    match &e {
        Error::Input { loc, .. } => {
            let err = SceneError::new_err(e.to_string());
            let value = err.value(py);
            // Attributes of a fresh exception object: setting them does not fail.
            let _ = value.setattr("file", loc.file.display().to_string());
            let _ = value.setattr("line", loc.line);
            let _ = value.setattr("column", loc.col);
            err
        }
        _ => error(e),
    }
}

/// `e` as a Python exception, an error about an input file being a `ValueError` (an image
/// that cannot be read, say).
pub fn error(e: Error) -> PyErr {
    match e {
        Error::Input { .. } | Error::Usage(_) => PyValueError::new_err(e.to_string()),
        Error::Output { .. } => PyOSError::new_err(e.to_string()),
        Error::Accel(_) => PyRuntimeError::new_err(e.to_string()),
    }
}

/// A `FileNotFoundError` (errno, message and file name as Python's own) when `path` does
/// not exist; other failures are left to the reader, whose message names the file.
pub fn check_exists(path: &Path) -> PyResult<()> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(PyFileNotFoundError::new_err((
            e.raw_os_error().unwrap_or(2),
            "No such file or directory",
            path.display().to_string(),
        ))),
        _ => Ok(()),
    }
}

/// An integer argument of type `T`: a value out of `T`'s range is a `ValueError` saying
/// what the argument must be (`what`), not the `OverflowError` of Python's conversion; a
/// value that is no integer is a `TypeError`.
pub fn integer<T: TryFrom<i128>>(name: &str, value: &Bound<'_, PyAny>, what: &str) -> PyResult<T> {
    let n: i128 = value.extract()?;
    T::try_from(n).map_err(|_| PyValueError::new_err(format!("{name} must be {what}, got {n}")))
}

/// A `UserWarning` from the caller's line.
pub fn warn(py: Python<'_>, msg: &str) -> PyResult<()> {
    let msg = CString::new(msg.replace('\0', " ")).unwrap_or_default();
    PyErr::warn(py, &py.get_type::<PyUserWarning>(), &msg, 2)
}
