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

/// Per-thread work counters, summed after each pass.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Counters {
    pub samples: u64,
    pub camera_rays: u64,
    pub extension_rays: u64,
    pub shadow_rays: u64,
    /// Light subpaths traced.
    pub light_paths: u64,
    /// Connections whose shadow ray was traced (NEE, `t = 1`, `s,t >= 2`).
    pub connections: u64,
    /// Of those, connections found occluded.
    pub connections_occluded: u64,
    /// Connections left untraced by Russian roulette (EORR).
    pub connections_skipped: u64,
    /// Pool draws of a camera vertex that repeated an earlier draw of it and were merged
    /// into that connection (its weight counts both).
    pub draws_merged: u64,
    /// Pool draws whose connection was traced and found unoccluded, by the depth of the
    /// camera vertex (`[t - 2]` for `z_{t-1}`, deeper ones in the last entry).
    pub pool_hits: [u64; CONCENTRATION_DEPTHS],
    /// Sum over those draws of `1 / (V · PMF)`, the inverse of their selection probability
    /// relative to uniform selection (1 for uniform draws), by the same depths.
    pub pool_hits_inverse_concentration: [f64; CONCENTRATION_DEPTHS],
    /// Shadow rays of pool connections (of `shadow_rays`).
    pub pool_shadow_rays: u64,
    /// Camera vertices that drew pool connections.
    pub pool_lookups: u64,
}

impl Counters {
    /// The harmonic mean of `V · PMF` over the unoccluded pool connections, over all depths
    /// and per camera depth (a depth without such connections gets the overall one); `None`
    /// without any.
    pub fn concentration(&self) -> Option<(f64, [f64; CONCENTRATION_DEPTHS])> {
        let hits: u64 = self.pool_hits.iter().sum();
        let inverse: f64 = self.pool_hits_inverse_concentration.iter().sum();
        if hits == 0 || inverse <= 0.0 {
            return None;
        }
        let all = hits as f64 / inverse;
        let mut by_depth = [all; CONCENTRATION_DEPTHS];
        for (k, c) in by_depth.iter_mut().enumerate() {
            if self.pool_hits[k] > 0 && self.pool_hits_inverse_concentration[k] > 0.0 {
                *c = self.pool_hits[k] as f64 / self.pool_hits_inverse_concentration[k];
            }
        }
        Some((all, by_depth))
    }
}

impl std::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Counters) {
        self.samples += o.samples;
        self.camera_rays += o.camera_rays;
        self.extension_rays += o.extension_rays;
        self.shadow_rays += o.shadow_rays;
        self.light_paths += o.light_paths;
        self.connections += o.connections;
        self.connections_occluded += o.connections_occluded;
        self.connections_skipped += o.connections_skipped;
        self.draws_merged += o.draws_merged;
        self.pool_shadow_rays += o.pool_shadow_rays;
        self.pool_lookups += o.pool_lookups;
        for k in 0..CONCENTRATION_DEPTHS {
            self.pool_hits[k] += o.pool_hits[k];
            self.pool_hits_inverse_concentration[k] += o.pool_hits_inverse_concentration[k];
        }
    }
}

/// Wall time spent in each phase of the render loop.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PhaseTimes {
    /// Tracing light pools (and their light-tracing splats).
    pub light_pool: f64,
    /// Tracing the record pixels and evaluating the cache's PMFs (PCBPT).
    pub cache: f64,
    /// Camera samples (tiles).
    pub camera_pass: f64,
    /// Merging blocks into the film and splatting.
    pub merge: f64,
    /// Re-running the iterations before a chunk's first one that its state comes from.
    pub warmup: f64,
}

/// Shadow rays traced in each phase of the render loop.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PhaseRays {
    pub light_pool: u64,
    pub cache: u64,
    pub camera_pass: u64,
}

/// PCBPT's cache in the last iteration.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct CacheStats {
    pub records: usize,
    /// Records whose PMF is all zero (uniform fallback).
    pub empty_records: usize,
    /// Records left out to stay within `--pc-max-cache-mb`.
    pub dropped_records: usize,
    pub pool_vertices: usize,
    pub megabytes: f64,
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

/// Statistics of a finished render.
#[derive(Clone, Debug, Serialize)]
pub struct RenderStats {
    pub integrator: IntegratorKind,
    pub backend: String,
    pub threads: usize,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub passes: u32,
    pub seconds: f64,
    pub samples_per_second: f64,
    pub rays_per_second: f64,
    pub counters: Counters,
    pub phases: PhaseTimes,
    pub shadow_rays: PhaseRays,
    /// PCBPT's cache (when PCBPT ran).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cache: Option<CacheStats>,
    /// SPCBPT's subspaces and matrix (when SPCBPT ran).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub subspaces: Option<spcbpt::SubspaceStats>,
    /// The budget PCBPT or SPCBPT chose (`--pc-budget auto`).
    pub budget: Option<budget::BudgetStats>,
    /// The integrator's options.
    pub options: Method,
    /// Light-pool size of the last iteration: light paths and connectible vertices.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pool: Option<(usize, usize)>,
    /// Metropolis statistics (PSSMLT).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mlt: Option<pssmlt::MltStats>,
    /// Path-space Metropolis statistics (MEMLT).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub memlt: Option<memlt::MemltStats>,
    /// Samples dropped because they were NaN or infinite.
    pub invalid_samples: u64,
    /// The render stopped early (interrupted).
    pub interrupted: bool,
    /// The iterations rendered (samples per pixel, or mutations per pixel for the Markov
    /// chains), when known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iterations: Option<Range<u32>>,
}

impl RenderStats {
    /// The statistics every render loop reports; the rest start empty.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        opts: &RenderOptions,
        scene: &Scene,
        threads: usize,
        counters: Counters,
        seconds: f64,
        spp: u32,
        invalid_samples: u64,
        interrupted: bool,
    ) -> RenderStats {
        let rays = counters.camera_rays + counters.extension_rays + counters.shadow_rays;
        RenderStats {
            integrator: opts.integrator(),
            backend: scene.accel.backend().to_string(),
            threads,
            width: scene.film.width,
            height: scene.film.height,
            spp,
            passes: 1,
            seconds,
            samples_per_second: counters.samples as f64 / seconds.max(1e-9),
            rays_per_second: rays as f64 / seconds.max(1e-9),
            counters,
            phases: PhaseTimes::default(),
            shadow_rays: PhaseRays::default(),
            cache: None,
            subspaces: None,
            budget: None,
            options: opts.method.clone(),
            pool: None,
            mlt: None,
            memlt: None,
            invalid_samples,
            interrupted,
            iterations: None,
        }
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
