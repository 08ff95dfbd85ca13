//! `pcbpt._native`: the renderer behind the Python package `pcbpt` (python/pcbpt/), which
//! documents the public API and hands its arguments to these functions.
//!
//! Loading reads a scene as `pcbpt render` does ([`scene`]); rendering runs the integrator
//! the command line would, with its options read by the same parser. Loads, renders and
//! experiments run on a worker thread while the calling thread waits without the GIL and
//! answers Ctrl-C ([`worker`]). Images cross as NumPy arrays of shape `(height, width, 3)`
//! ([`images`]). No error is a panic: the crate's errors become Python exceptions
//! ([`errors`]), and a panic on a worker thread becomes a `RuntimeError`.

mod errors;
mod experiment;
mod images;
mod options;
mod render;
mod scene;
mod worker;

use pyo3::prelude::*;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SceneError", m.py().get_type::<errors::SceneError>())?;
    m.add_class::<scene::Scene>()?;
    m.add_function(wrap_pyfunction!(scene::load, m)?)?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(render::integrators, m)?)?;
    m.add_function(wrap_pyfunction!(images::compare, m)?)?;
    m.add_function(wrap_pyfunction!(images::read_image, m)?)?;
    m.add_function(wrap_pyfunction!(images::write_image, m)?)?;
    m.add_function(wrap_pyfunction!(experiment::experiment, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
