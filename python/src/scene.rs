//! `load`: a scene read as `pcbpt render` reads it, kept for any number of renders; read
//! on a worker thread so that Ctrl-C is answered at once ([`crate::worker`]).

use crate::errors::{self, check_exists, scene_error};
use crate::worker::run_on_worker;
use clap::ValueEnum;
use pcbpt::accel::{Backend, BuildOptions};
use pcbpt::integrator::IntegratorKind;
use pcbpt::scene::{IntegratorSpec, LoadOptions, LoadStats, SamplerSpec};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

/// A scene loaded by `pcbpt.load`, ready to render any number of times.
///
/// The attributes are what the file says (after the keyword defaults of `load`): the film's
/// `width` and `height`, the integrator it names (`integrator`, None when this renderer
/// lacks it; `plugin` is the name in the file), the sampler's `spp`, `seed` and kind
/// (`sampler`), the integrator's `max_depth` and `rr_depth`, and the loading's `triangles`,
/// `warnings` and `load_seconds`.
#[pyclass(module = "pcbpt", frozen)]
pub struct Scene {
    /// The render-ready scene: each render sets its integrator's shared parameters (which
    /// `render`'s keywords may change) while it holds the lock.
    pub(crate) inner: Arc<Mutex<pcbpt::scene::Scene>>,
    /// The file's integrator parameters and sampler, as loaded.
    pub(crate) integrator_spec: IntegratorSpec,
    pub(crate) sampler_spec: SamplerSpec,
    pub(crate) stats: LoadStats,
    pub(crate) backend: Backend,
    #[pyo3(get)]
    path: PathBuf,
    #[pyo3(get)]
    width: u32,
    #[pyo3(get)]
    height: u32,
    #[pyo3(get)]
    load_seconds: f64,
}

impl Scene {
    /// The scene for a render: the lock is only poisoned by a render that panicked, after
    /// which the scene is still whole (a render only reads it).
    pub(crate) fn lock(inner: &Mutex<pcbpt::scene::Scene>) -> MutexGuard<'_, pcbpt::scene::Scene> {
        inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    pub(crate) fn path(&self) -> &std::path::Path {
        &self.path
    }

    pub(crate) fn load_seconds(&self) -> f64 {
        self.load_seconds
    }

    /// The integrator the file names, if this renderer has it.
    pub(crate) fn file_integrator(&self) -> Option<IntegratorKind> {
        IntegratorKind::from_plugin(&self.integrator_spec.plugin)
    }
}

#[pymethods]
impl Scene {
    /// The integrator the file names (`render`'s default), as `render` names it; None when
    /// this renderer lacks it.
    #[getter]
    fn integrator(&self) -> Option<&'static str> {
        self.file_integrator().map(IntegratorKind::name)
    }

    /// The integrator's plugin name in the file (`path`, `ptracer`, …).
    #[getter]
    fn plugin(&self) -> &str {
        &self.integrator_spec.plugin
    }

    /// Samples per pixel of the file's sampler (`render`'s default).
    #[getter]
    fn spp(&self) -> u32 {
        self.sampler_spec.spp
    }

    /// Seed of the file's sampler (`render`'s default).
    #[getter]
    fn seed(&self) -> u64 {
        self.sampler_spec.seed
    }

    /// The file's sampler: `independent` or `sobol`.
    #[getter]
    fn sampler(&self) -> String {
        self.sampler_spec.kind.to_possible_value().map(|v| v.get_name().to_string()).unwrap_or_default()
    }

    /// Longest path in segments from the camera (-1: unlimited).
    #[getter]
    fn max_depth(&self) -> i32 {
        self.integrator_spec.max_depth
    }

    /// Depth from which Russian roulette may end paths.
    #[getter]
    fn rr_depth(&self) -> u32 {
        self.integrator_spec.rr_depth
    }

    /// Triangles of the scene's meshes.
    #[getter]
    fn triangles(&self) -> usize {
        self.stats.triangles
    }

    /// The loader's warnings (ignored properties, an integrator replaced, …).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.stats.warnings.clone()
    }

    /// The ray-tracing backend: `embree` or `obvhs`.
    #[getter]
    fn backend(&self) -> String {
        self.backend.to_string()
    }

    fn __repr__(&self) -> String {
        format!(
            "<pcbpt.Scene '{}': {}x{}, integrator {}, {} spp, seed {}, {} triangles>",
            self.path.display(),
            self.width,
            self.height,
            self.integrator().unwrap_or(&self.integrator_spec.plugin),
            self.sampler_spec.spp,
            self.sampler_spec.seed,
            self.stats.triangles
        )
    }
}

/// Loads the scene at `path` with the `-D` defaults `defines`, the film size `resolution`
/// (`WxH`), the backend `backend`, `threads` threads (0: every core); with
/// `override_integrator`, reads the file's `<integrator>` as `--integrator` does.
#[pyfunction]
#[pyo3(signature = (path, defines, resolution, backend, threads, override_integrator, progress))]
#[allow(clippy::too_many_arguments)] // the keywords of `pcbpt.load`
pub fn load(
    py: Python<'_>,
    path: PathBuf,
    defines: Vec<(String, String)>,
    resolution: Option<String>,
    backend: Option<String>,
    threads: &Bound<'_, PyAny>,
    override_integrator: bool,
    progress: bool,
) -> PyResult<Scene> {
    check_exists(&path)?;
    let options = LoadOptions {
        overrides: defines,
        backend: backend.as_deref().map(parse_backend).transpose()?.unwrap_or_default(),
        build: BuildOptions::default(),
        progress,
        integrator_override: override_integrator.then(|| "the integrator render() names".to_string()),
        resolution: resolution
            .as_deref()
            .map(pcbpt::scene::parse_resolution)
            .transpose()
            .map_err(PyValueError::new_err)?,
        threads: errors::integer::<u16>("threads", threads, "a number of threads from 0 (every core) to 65535")?.into(),
    };
    let t0 = Instant::now();
    // Loading cannot be stopped part-way: on Ctrl-C the worker is left to finish and its
    // scene dropped.
    let file = path.clone();
    let load_options = options.clone();
    let scene = run_on_worker(py, "pcbpt-load", "loading the scene", None, move || {
        pcbpt::scene::Scene::load(&file, &load_options)
    })?
    .map_err(|e| scene_error(py, e))?;
    for w in &scene.stats.warnings {
        crate::errors::warn(py, w)?;
    }
    Ok(Scene {
        integrator_spec: scene.integrator.clone(),
        sampler_spec: scene.sampler,
        stats: scene.stats.clone(),
        backend: options.backend,
        path,
        width: scene.film.width,
        height: scene.film.height,
        load_seconds: t0.elapsed().as_secs_f64(),
        inner: Arc::new(Mutex::new(scene)),
    })
}

/// A backend by name, as `--backend` reads it.
fn parse_backend(name: &str) -> PyResult<Backend> {
    Backend::from_str(name, true).map_err(|_| {
        let names: Vec<String> = Backend::value_variants()
            .iter()
            .filter_map(|b| b.to_possible_value())
            .map(|v| v.get_name().into())
            .collect();
        PyValueError::new_err(format!("unknown backend \"{name}\" (one of: {})", names.join(", ")))
    })
}
