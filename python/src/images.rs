//! Images as NumPy arrays (`height × width × 3` float32, rows from the top), and the
//! crate's image reading, writing and comparison on them.

use crate::errors::{self, check_exists};
use numpy::{PyArray1, PyArray3, PyArrayMethods, PyReadonlyArray3, PyUntypedArrayMethods};
use pcbpt::image_io::{self, Image};
use pcbpt::math::Rgb;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Pixels as an array of shape `(height, width, 3)`.
pub fn to_array<'py>(py: Python<'py>, width: u32, height: u32, pixels: &[Rgb]) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let flat: Vec<f32> = pixels.iter().flat_map(|p| p.to_array()).collect();
    PyArray1::from_vec(py, flat).reshape([height as usize, width as usize, 3])
}

/// An array of shape `(height, width, 3)` as an image; `what` names it in errors.
fn from_array(array: &PyReadonlyArray3<'_, f32>, what: &str) -> PyResult<Image> {
    let [h, w, c] = array.shape().try_into().unwrap_or([0, 0, 0]);
    let (Ok(width), Ok(height)) = (u32::try_from(w), u32::try_from(h)) else {
        return Err(PyValueError::new_err(format!("{what}: {w}x{h} pixels are too many")));
    };
    if c != 3 || w == 0 || h == 0 {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (height, width, 3) with at least one pixel, got {:?}",
            array.shape()
        )));
    }
    let a = array.as_array();
    let pixels = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| Rgb::new(a[[y, x, 0]], a[[y, x, 1]], a[[y, x, 2]]));
    Ok(Image::new(width, height, pixels.collect()))
}

/// `metric` of `image` against `reference`, or every metric but FLIP as a dict when
/// `metric` is None.
#[pyfunction]
#[pyo3(signature = (reference, image, metric))]
pub fn compare<'py>(
    py: Python<'py>,
    reference: PyReadonlyArray3<'py, f32>,
    image: PyReadonlyArray3<'py, f32>,
    metric: Option<&str>,
) -> PyResult<Bound<'py, PyAny>> {
    let r = from_array(&reference, "reference")?;
    let t = from_array(&image, "image")?;
    pcbpt::compare::check_same_size(&r, &t).map_err(errors::error)?;
    let m = pcbpt::compare::metrics(&r, &t).map_err(errors::error)?;
    let value = match metric {
        None => {
            let d = PyDict::new(py);
            d.set_item("relmse", m.relmse)?;
            d.set_item("mse", m.mse)?;
            d.set_item("mean_ratio", m.mean_ratio)?;
            d.set_item("reference_mean", m.reference_mean)?;
            d.set_item("test_mean", m.test_mean)?;
            d.set_item("non_finite", m.non_finite)?;
            return Ok(d.into_any());
        }
        Some("relmse") => m.relmse,
        Some("mse") => m.mse,
        Some("mean_ratio") => m.mean_ratio,
        Some("flip") => pcbpt::compare::flip(&r, &t, None).map_err(errors::error)?,
        Some(other) => {
            return Err(PyValueError::new_err(format!(
                "unknown metric \"{other}\" (one of: relmse, mse, mean_ratio, flip)"
            )));
        }
    };
    Ok(value.into_pyobject(py)?.into_any())
}

/// Reads an image as linear RGB (as `pcbpt compare` reads it).
#[pyfunction]
pub fn read_image(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArray3<f32>>> {
    check_exists(&path)?;
    let image = py.detach(|| image_io::read(&path)).map_err(errors::error)?;
    to_array(py, image.width, image.height, &image.pixels)
}

/// Writes an image (format by extension, as `pcbpt render -o` writes it).
#[pyfunction]
pub fn write_image(py: Python<'_>, path: PathBuf, image: PyReadonlyArray3<'_, f32>) -> PyResult<()> {
    let image = from_array(&image, "image")?;
    py.detach(|| image_io::write(&path, &image)).map_err(errors::error)
}
