//! Integrators, their options and statistics, and [`render`], which hands the chosen one
//! (the [`Method`] of [`registry`]) to its own [`Integrator::render`]: [`render_loop`] for
//! every integrator that renders iterations of one sample per pixel,
//! [`metropolis::run_chains`] for the Markov chains of [`pssmlt`] and [`memlt`].

pub mod bidir;
pub mod budget;
pub mod eorr;
pub mod lvc;
pub mod manifold;
pub mod memlt;
pub mod metropolis;
pub mod path;
pub mod pcbpt;
pub mod pool_base;
pub mod pssmlt;
pub mod registry;
pub(crate) mod render_loop;
pub mod spcbpt;
pub mod stats;

use crate::film::Film;
use crate::math::Rgb;
use crate::scene::Scene;
pub use bidir::pool::CONCENTRATION_DEPTHS;
pub use registry::{Integrator, IntegratorKind, Method};
pub use stats::{Counters, Details, IntegratorStats, PhaseRays, PhaseTimes, RenderStats};
use std::ops::Range;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

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
    let kind = opts.integrator();
    if kind.is_bidirectional() {
        bidir::bdpt::check_lights(scene, kind.name()).map_err(Error::Usage)?;
    }
    opts.method.render(scene, opts, iterations)
}
