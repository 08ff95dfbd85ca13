//! Integrators, their options and statistics, and [`render`], which hands the chosen one to
//! its render loop: [`render_loop`] for every integrator that renders iterations of one
//! sample per pixel, [`mlt`]'s and [`memlt`]'s own for the Markov chains.

pub mod bidir;
pub mod budget;
pub mod eorr;
pub mod lvc;
pub mod manifold;
pub mod memlt;
pub mod metropolis;
pub mod path;
pub mod pcbpt;
pub mod pssmlt;
pub mod registry;
pub(crate) mod render_loop;
pub mod spcbpt;
pub mod stats;

use crate::film::Film;
use crate::math::Rgb;
use crate::scene::Scene;
use bidir::WalkLimits;
use bidir::bdpt::{Bdpt, BdptRender};
pub use bidir::pool::CONCENTRATION_DEPTHS;
use eorr::Eorr;
use lvc::{Lvc, LvcRender};
use pcbpt::{Pcbpt, PcbptRender};
pub use registry::Method;
use serde::Serialize;
use spcbpt::{Spcbpt, SpcbptRender};
pub use stats::{Counters, Details, IntegratorStats, PhaseRays, PhaseTimes, RenderStats};
use std::ops::Range;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// The integrators selectable with `--integrator`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum IntegratorKind {
    /// Unidirectional path tracing with next-event estimation and MIS.
    Path,
    /// Light tracing: light subpaths connected to the camera (`t = 1`) only.
    Lighttrace,
    /// Bidirectional path tracing with every strategy.
    Bdpt,
    /// BDPT with efficiency-optimised Russian roulette on connections.
    Eorr,
    /// Light-vertex-cache BDPT: a shared pool of light paths, uniform connections.
    Lvc,
    /// Primary-sample-space Metropolis light transport over BDPT (or the path tracer).
    Pssmlt,
    /// Probabilistic connections: a shared pool, connections drawn from cached PMFs.
    Pcbpt,
    /// Subspace-based probabilistic connections: connections drawn from a trained matrix
    /// over eye and light subspaces.
    Spcbpt,
    /// Path-space Metropolis with Manifold Exploration's mutations.
    Memlt,
}

impl IntegratorKind {
    /// The integrator a scene file's plugin name selects.
    pub fn from_plugin(name: &str) -> Option<IntegratorKind> {
        match name {
            "path" => Some(IntegratorKind::Path),
            "ptracer" => Some(IntegratorKind::Lighttrace),
            "bdpt" => Some(IntegratorKind::Bdpt),
            "pssmlt" => Some(IntegratorKind::Pssmlt),
            "mlt" => Some(IntegratorKind::Memlt),
            _ => None,
        }
    }

    /// The name `--integrator` takes.
    pub fn name(self) -> &'static str {
        match self {
            IntegratorKind::Path => "path",
            IntegratorKind::Lighttrace => "lighttrace",
            IntegratorKind::Bdpt => "bdpt",
            IntegratorKind::Eorr => "eorr",
            IntegratorKind::Lvc => "lvc",
            IntegratorKind::Pssmlt => "pssmlt",
            IntegratorKind::Pcbpt => "pcbpt",
            IntegratorKind::Spcbpt => "spcbpt",
            IntegratorKind::Memlt => "memlt",
        }
    }

    /// Whether the integrator samples with the bidirectional core's strategies (and reports
    /// connections and light paths).
    pub fn is_bidirectional(self) -> bool {
        !matches!(self, IntegratorKind::Path | IntegratorKind::Pssmlt | IntegratorKind::Memlt)
    }
}

/// How much to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    /// Samples per pixel.
    Spp(u32),
    /// Wall-clock seconds (whole passes of one sample per pixel).
    Time(f64),
}

#[derive(Clone)]
pub struct RenderOptions {
    /// The integrator and its options.
    pub method: Method,
    pub budget: Budget,
    pub seed: u64,
    /// Worker threads (0 = all cores).
    pub threads: usize,
    pub tile_size: u32,
    pub progress: bool,
    /// Set from outside (a signal handler) to stop after the current pass.
    pub stop: Option<Arc<AtomicBool>>,
    /// Keep one image per strategy `(s,t)` (bidirectional integrators).
    pub strategy_images: bool,
    /// Wall-clock times (seconds, ascending) at which to keep a snapshot of the image: the
    /// first pass that ends at or after each time is developed.
    pub checkpoints: Vec<f64>,
}

impl RenderOptions {
    pub fn new(integrator: IntegratorKind, budget: Budget) -> RenderOptions {
        RenderOptions {
            method: Method::default_for(integrator),
            budget,
            seed: 0,
            threads: 0,
            tile_size: 32,
            progress: false,
            stop: None,
            strategy_images: false,
            checkpoints: Vec::new(),
        }
    }

    pub fn integrator(&self) -> IntegratorKind {
        self.method.kind()
    }
}

/// The image as it stood at a checkpoint.
#[derive(Clone, Debug)]
pub struct Snapshot {
    pub seconds: f64,
    /// Samples (or mutations) per pixel done.
    pub spp: u32,
    pub image: Vec<Rgb>,
}

/// Takes the snapshots whose checkpoint time has come.
pub(crate) fn take_snapshots(
    checkpoints: &[f64],
    snapshots: &mut Vec<Snapshot>,
    seconds: f64,
    spp: u32,
    develop: impl FnOnce() -> Vec<Rgb>,
) {
    let due = checkpoints.iter().filter(|&&t| t <= seconds).count();
    if due > snapshots.len() {
        let image = develop();
        // Checkpoints passed within one pass share its image.
        while snapshots.len() < due {
            snapshots.push(Snapshot { seconds, spp, image: image.clone() });
        }
    }
}

/// A finished render.
pub struct RenderOutput {
    pub image: Vec<Rgb>,
    /// Per-strategy images `(name, pixels)` when asked for; they sum to `image`.
    pub strategy_images: Vec<(String, Vec<Rgb>)>,
    /// Images at the requested checkpoints.
    pub snapshots: Vec<Snapshot>,
    pub width: u32,
    pub height: u32,
    pub stats: RenderStats,
    /// The film's sums (what a chunk of a distributed render keeps).
    pub film: Option<Film>,
}

/// Renders the scene's image.
pub fn render(scene: &Scene, opts: &RenderOptions) -> Result<RenderOutput, crate::error::Error> {
    render_iterations(scene, opts, None)
}

/// Renders iterations `iterations` of the render `opts` describes (all of them when `None`):
/// for a sample budget of `n` samples per pixel, a chunk `A..B` of `0..n` gives the very
/// film sums the one-process render adds for those iterations.
pub fn render_iterations(
    scene: &Scene,
    opts: &RenderOptions,
    iterations: Option<Range<u32>>,
) -> Result<RenderOutput, crate::error::Error> {
    use crate::error::Error;
    if let Some(r) = &iterations {
        let Budget::Spp(spp) = opts.budget else {
            return Err(Error::Usage("a chunk of iterations needs a sample count, not a time budget".into()));
        };
        if r.start >= r.end || r.end > spp {
            return Err(Error::Usage(format!(
                "iterations {}..{} are not a non-empty part of the render's 0..{spp}",
                r.start, r.end
            )));
        }
    }
    let spec = &scene.integrator;
    let max_depth = if spec.max_depth < 0 { u32::MAX } else { spec.max_depth as u32 };
    let bdpt = |light_only| Bdpt {
        limits: WalkLimits::new(max_depth, spec.rr_depth),
        max_depth,
        hide_emitters: spec.hide_emitters,
        light_only,
    };
    let kind = opts.integrator();
    if kind.is_bidirectional() {
        bidir::bdpt::check_lights(scene, kind.name()).map_err(Error::Usage)?;
    }
    match &opts.method {
        Method::Pssmlt(o) => pssmlt::render(scene, opts, o, iterations),
        Method::Memlt(o) => memlt::render(scene, opts, o, iterations),
        Method::Path(_) => render_loop::run(scene, opts, path::PathTracer::new(spec), false, iterations),
        Method::Lighttrace(_) => {
            let method = BdptRender { bdpt: bdpt(true), heuristic: Default::default() };
            render_loop::run(scene, opts, method, true, iterations)
        }
        Method::Bdpt(o) => {
            let method = BdptRender { bdpt: bdpt(false), heuristic: o.heuristic };
            render_loop::run(scene, opts, method, true, iterations)
        }
        Method::Eorr(o) => {
            if o.pilot_spp == 0 && iterations.as_ref().is_some_and(|r| r.start > 0) {
                return Err(Error::Usage(
                    "EORR's running-mean thresholds (--eorr-pilot-spp 0) depend on every earlier pass: render \
                     them in one process, or give the pilot a sample count"
                        .into(),
                ));
            }
            if !(o.fraction >= 0.0 && o.fraction.is_finite()) {
                return Err(Error::Usage(format!("--eorr-fraction must be a non-negative number, got {}", o.fraction)));
            }
            let method = Eorr::new(bdpt(false), o.heuristic, o.fraction, o.pilot_spp, scene);
            render_loop::run(scene, opts, method, true, iterations)
        }
        Method::Lvc(o) => {
            if o.connections == 0 {
                return Err(Error::Usage("--connections must be at least 1".into()));
            }
            let pixels = scene.film.width as usize * scene.film.height as usize;
            let m = if o.light_paths == 0 { pixels } else { o.light_paths };
            let lvc = Lvc { bdpt: bdpt(false), light_paths: m, connections: o.connections };
            render_loop::run(scene, opts, LvcRender::new(lvc, o.heuristic, o.max_pool_mb), true, iterations)
        }
        Method::Pcbpt(o) => {
            o.pc.validate().map_err(Error::Usage)?;
            let pc = Pcbpt { bdpt: bdpt(false), opts: o.pc.clone() };
            render_loop::run(scene, opts, PcbptRender::new(pc, o.heuristic, o.pc.pool.max_pool_mb), true, iterations)
        }
        Method::Spcbpt(o) => {
            o.sp.validate().map_err(Error::Usage)?;
            let sp = Spcbpt { bdpt: bdpt(false), opts: o.sp.clone() };
            render_loop::run(scene, opts, SpcbptRender::new(sp, o.heuristic, o.sp.pool.max_pool_mb), true, iterations)
        }
    }
}
