//! `render`: a loaded scene rendered as `pcbpt render` renders it (the same image for the
//! same seed, bit for bit), on a worker thread while the calling thread, without the GIL,
//! waits and answers Ctrl-C by stopping the render ([`crate::worker`]).

use crate::errors::{self, integer, warn};
use crate::images::to_array;
use crate::scene::Scene;
use crate::worker::run_on_worker;
use clap::ValueEnum;
use numpy::{PyArray3, PyArrayMethods};
use pcbpt::accel::Backend;
use pcbpt::display::DisplayServer;
use pcbpt::integrator::registry::INTEGRATORS;
use pcbpt::integrator::{self, Budget, IntegratorKind, Preview, RenderOptions, RenderOutput, RunOptions};
use pcbpt::sampling::SamplerKind;
use pcbpt::scene::IntegratorSpec;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

/// The names of the integrators, as `render` and `--integrator` take them.
#[pyfunction]
pub fn integrators() -> Vec<&'static str> {
    INTEGRATORS.iter().map(|r| r.kind.name()).collect()
}

/// Renders `scene`; returns the image (`height × width × 3` float32), the statistics as
/// the JSON text `--stats` writes and the AOV channels asked for (`height × width` float32
/// arrays by channel name). The keywords are `pcbpt.render`'s.
#[pyfunction]
#[pyo3(signature = (scene, integrator, spp, time, seed, threads, max_depth, rr_depth, sampler, progress, aov, noise_threshold, display_server, options))]
#[allow(clippy::too_many_arguments)] // the keywords of `pcbpt.render`
pub fn render<'py>(
    py: Python<'py>,
    scene: &Bound<'py, Scene>,
    integrator: Option<&str>,
    spp: Option<Bound<'py, PyAny>>,
    time: Option<f64>,
    seed: Option<Bound<'py, PyAny>>,
    threads: Bound<'py, PyAny>,
    max_depth: Option<Bound<'py, PyAny>>,
    rr_depth: Option<Bound<'py, PyAny>>,
    sampler: Option<&str>,
    progress: bool,
    aov: Option<Vec<String>>,
    noise_threshold: Option<f64>,
    display_server: Option<String>,
    options: Bound<'py, PyDict>,
) -> PyResult<(Bound<'py, PyArray3<f32>>, String, Bound<'py, PyDict>)> {
    let scene = scene.get();
    let named = integrator.map(|name| value_enum::<IntegratorKind>("integrator", name)).transpose()?;
    let kind = named.or(scene.file_integrator()).ok_or_else(|| {
        PyValueError::new_err(format!(
            "the scene's integrator \"{}\" has no implementation here; pick one with integrator=",
            scene.integrator_spec.plugin
        ))
    })?;
    let mut opts = RenderOptions {
        method: crate::options::method(kind, &options)?,
        run: RunOptions::new(budget(scene, spp, time)?),
    };
    let settings = Settings {
        integrator: spec_for_render(scene, named.is_some(), max_depth, rr_depth)?,
        sampler: sampler_kind(py, scene, kind, sampler)?,
    };
    opts.run.seed = match seed {
        Some(s) => integer("seed", &s, "an integer from 0 to 2^64 - 1")?,
        None => scene.sampler_spec.seed,
    };
    opts.run.threads = integer::<u16>("threads", &threads, "a number of threads from 0 (every core) to 65535")?.into();
    opts.run.progress = progress;
    if let Some(names) = aov {
        opts.run.aovs =
            pcbpt::aov::parse_list(&names.join(",")).map_err(|e| PyValueError::new_err(format!("aov: {e}")))?;
    }
    if let Some(t) = noise_threshold {
        if !(t > 0.0 && t.is_finite()) {
            return Err(PyValueError::new_err(format!("noise_threshold must be a positive relMSE, got {t}")));
        }
        opts.run.noise_threshold = Some(t);
    }
    let display = display_server
        .map(|address| {
            pcbpt::display::parse_address(&address).map_err(|e| PyValueError::new_err(format!("display_server: {e}")))
        })
        .transpose()?
        .map(|address| (address, display_name(scene)));
    let out = render_on_worker(py, scene.inner.clone(), settings, opts, display)?;
    let stats = stats_json(scene, &out);
    let aovs = PyDict::new(py);
    for (name, values) in &out.aovs {
        let array = numpy::PyArray1::from_slice(py, values).reshape([out.height as usize, out.width as usize])?;
        aovs.set_item(name, array)?;
    }
    Ok((to_array(py, out.width, out.height, &out.image)?, stats, aovs))
}

/// A value of a command-line enum by the name the command line takes.
pub fn value_enum<T: ValueEnum>(what: &str, name: &str) -> PyResult<T> {
    T::from_str(name, true).map_err(|_| {
        let names: Vec<String> =
            T::value_variants().iter().filter_map(|v| v.to_possible_value()).map(|v| v.get_name().into()).collect();
        PyValueError::new_err(format!("unknown {what} \"{name}\" (one of: {})", names.join(", ")))
    })
}

/// The render's budget: `spp` samples per pixel or `time` seconds, by default the scene's
/// sample count (the command line's checks and messages).
fn budget(scene: &Scene, spp: Option<Bound<'_, PyAny>>, time: Option<f64>) -> PyResult<Budget> {
    let spp: Option<u32> = spp.map(|s| integer("spp", &s, "a sample count from 1 to 2^32 - 1")).transpose()?;
    match (spp, time) {
        (Some(_), Some(_)) => Err(PyValueError::new_err("give spp or time, not both")),
        (_, Some(t)) if !(t > 0.0 && t.is_finite()) => {
            Err(PyValueError::new_err(format!("time must be a positive number of seconds, got {t}")))
        }
        (_, Some(t)) => Ok(Budget::Time(t)),
        (Some(0), _) => Err(PyValueError::new_err("spp must be at least 1")),
        (Some(s), None) => Ok(Budget::Spp(s)),
        (None, None) => Ok(Budget::Spp(scene.sampler_spec.spp)),
    }
}

/// The integrator's shared parameters for this render: the file's, with `max_depth` and
/// `rr_depth` if given. As with `--integrator`, naming the integrator drops the file's
/// `strict_normals` (the loader reads it only for the file's own path tracer).
fn spec_for_render(
    scene: &Scene,
    named: bool,
    max_depth: Option<Bound<'_, PyAny>>,
    rr_depth: Option<Bound<'_, PyAny>>,
) -> PyResult<IntegratorSpec> {
    let mut spec = scene.integrator_spec.clone();
    spec.strict_normals &= !named;
    if let Some(d) = max_depth {
        let what = "-1 (unlimited) or at least 0";
        spec.max_depth = integer("max_depth", &d, what)?;
        if spec.max_depth < -1 {
            return Err(PyValueError::new_err(format!("max_depth must be {what}, got {}", spec.max_depth)));
        }
    }
    if let Some(d) = rr_depth {
        spec.rr_depth = integer("rr_depth", &d, "a depth from 0 to 2^32 - 1")?;
    }
    Ok(spec)
}

/// The sampler of the render: `sampler` if given, else the file's. Sobol numbers are the
/// path tracer's: asked of another integrator it is an error, and the file's a warning.
fn sampler_kind(py: Python<'_>, scene: &Scene, kind: IntegratorKind, sampler: Option<&str>) -> PyResult<SamplerKind> {
    let chosen = sampler.map(|s| value_enum::<SamplerKind>("sampler", s)).transpose()?;
    let sampler_kind = chosen.unwrap_or(scene.sampler_spec.kind);
    if sampler_kind == SamplerKind::Sobol && kind != IntegratorKind::Path {
        let msg = format!("sampler sobol is the path tracer's; {} draws independent random numbers", kind.name());
        if chosen.is_some() {
            return Err(PyValueError::new_err(msg));
        }
        warn(py, &format!("the scene's {msg}"))?;
    }
    Ok(sampler_kind)
}

/// What a render changes in the loaded scene, set while it holds the scene's lock.
struct Settings {
    integrator: IntegratorSpec,
    sampler: SamplerKind,
}

/// The name of the image a viewer shows: the scene file's.
fn display_name(scene: &Scene) -> String {
    scene.path().file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "pcbpt".into())
}

/// Renders on a worker thread ([`run_on_worker`]); Ctrl-C stops the render after its
/// current pass. With `display` (the viewer's `HOST:PORT` and the image's name), the worker
/// connects to the viewer, streams the image to it as it renders and sends the final image,
/// as `--display-server` does.
fn render_on_worker(
    py: Python<'_>,
    scene: Arc<Mutex<pcbpt::scene::Scene>>,
    settings: Settings,
    mut opts: RenderOptions,
    display: Option<(String, String)>,
) -> PyResult<RenderOutput> {
    let stop = Arc::new(AtomicBool::new(false));
    opts.run.stop = Some(stop.clone());
    let out = run_on_worker(py, "pcbpt-render", "the render", Some(stop), move || {
        let mut scene = Scene::lock(&scene);
        scene.integrator = settings.integrator;
        scene.sampler.kind = settings.sampler;
        let (w, h) = (scene.film.width, scene.film.height);
        let viewer =
            display.and_then(|(address, name)| DisplayServer::connect(&address, &name, w, h, false).map(Arc::new));
        opts.run.preview = viewer.clone().map(|d| d as Arc<dyn Preview>);
        let out = integrator::render(&scene, &opts);
        if let (Some(v), Ok(out)) = (&viewer, &out) {
            v.finish(&out.image);
        }
        out
    })?;
    out.map_err(errors::error)
}

/// The statistics as `pcbpt render --stats` writes them (no output file).
fn stats_json(scene: &Scene, out: &RenderOutput) -> String {
    let l = &scene.stats;
    let embree_version = (scene.backend == Backend::Embree)
        .then(|| pcbpt::accel::embree::version().map(|v| v.to_string()).ok())
        .flatten();
    let json = serde_json::json!({
        "scene": scene.path(), "output": null, "load_seconds": scene.load_seconds(), "triangles": l.triangles,
        "load": { "read_seconds": l.read_seconds, "bvh_seconds": l.bvh_seconds, "vertices": l.vertices, "mesh_bytes": l.mesh_bytes },
        "degenerate_triangles": l.degenerate_triangles, "embree_version": embree_version, "render": out.stats,
    });
    serde_json::to_string(&json).unwrap_or_default()
}
