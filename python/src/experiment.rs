//! `experiment`: an experiment file run as `pcbpt experiment FILE` runs it, on a worker
//! thread: Ctrl-C stops the render under way after its current pass, and the experiment
//! with it ([`crate::worker`]).

use crate::errors::{self, check_exists};
use crate::worker::run_on_worker;
use pcbpt::experiment::{ExperimentFile, RunResult};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Runs the experiment in `path`, writing into `output` (default: the file's); returns the
/// output folder and one dict per run.
#[pyfunction]
#[pyo3(signature = (path, output, quiet))]
pub fn experiment<'py>(
    py: Python<'py>,
    path: PathBuf,
    output: Option<PathBuf>,
    quiet: bool,
) -> PyResult<(PathBuf, Vec<Bound<'py, PyDict>>)> {
    check_exists(&path)?;
    let file = ExperimentFile::load(&path).map_err(errors::error)?;
    let folder = file.output_folder(&path, output.as_deref());
    let stop = Arc::new(AtomicBool::new(false));
    let (flag, target) = (stop.clone(), folder.clone());
    let runs = run_on_worker(py, "pcbpt-exp", "the experiment", Some(stop), move || {
        pcbpt::experiment::run_stoppable(&path, Some(&target), quiet, &flag)
    })?
    .map_err(errors::error)?;
    let runs = runs.iter().map(|r| run_dict(py, r)).collect::<PyResult<_>>()?;
    Ok((folder, runs))
}

/// A run's results as a dict (the columns of `results.md` and `convergence.csv`).
fn run_dict<'py>(py: Python<'py>, r: &RunResult) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("scene", &r.scene)?;
    d.set_item("method", &r.method)?;
    d.set_item("seed", r.seed)?;
    d.set_item("spp", r.spp)?;
    d.set_item("seconds", r.seconds)?;
    d.set_item("samples_per_second", r.samples_per_second)?;
    d.set_item("relmse", r.relmse)?;
    d.set_item("flip", r.flip)?;
    d.set_item("mean_ratio", r.mean_ratio)?;
    d.set_item("curve", r.curve.clone())?;
    Ok(d)
}
