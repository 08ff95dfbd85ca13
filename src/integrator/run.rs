//! What every integrator is given and gives back, below the registry that names them: the
//! [`Integrator`] interface (an options type that renders), the run's settings that are no
//! integrator's own ([`RunOptions`]: budget, seed, threads, tiles, progress, stop flag,
//! per-strategy images, checkpoints, a live preview, AOVs, the noise threshold) and the
//! finished render ([`RenderOutput`]).

use crate::aov::Aov;
use crate::error::Error;
use crate::film::Film;
use crate::integrator::stats::RenderStats;
use crate::math::Rgb;
use crate::sampling::Heuristic;
use crate::scene::Scene;
use serde::Serialize;
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

/// The settings of a render that belong to no integrator.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub budget: Budget,
    pub seed: u64,
    /// Worker threads (0 = all cores).
    pub threads: usize,
    pub tile_size: u32,
    pub progress: bool,
    /// Seconds between progress lines where standard error is not a terminal (a log).
    pub log_interval: f64,
    /// Set from outside (a signal handler) to stop after the current pass.
    pub stop: Option<Arc<AtomicBool>>,
    /// Keep one image per strategy `(s,t)` (bidirectional integrators).
    pub strategy_images: bool,
    /// Wall-clock times (seconds, ascending) at which to keep a snapshot of the image: the
    /// first pass that ends at or after each time is developed.
    pub checkpoints: Vec<f64>,
    /// A viewer shown the image as it renders (`--display-server`).
    pub preview: Option<Arc<dyn Preview>>,
    /// The AOVs to give beside the image ([`crate::aov`]).
    pub aovs: Vec<Aov>,
    /// Stop once the render's own relMSE estimate ([`crate::integrator::noise`]) falls
    /// below this (or at the budget, whichever comes first).
    pub noise_threshold: Option<f64>,
}

impl RunOptions {
    /// `budget` with seed 0, every core, 32-pixel tiles, no progress (a line every 10 s in a
    /// log when asked for) and nothing else asked for.
    pub fn new(budget: Budget) -> RunOptions {
        RunOptions {
            budget,
            seed: 0,
            threads: 0,
            tile_size: 32,
            progress: false,
            log_interval: 10.0,
            stop: None,
            strategy_images: false,
            checkpoints: Vec::new(),
            preview: None,
            aovs: Vec::new(),
            noise_threshold: None,
        }
    }

    /// Whether the render loop keeps two half-images (for the variance AOV or the noise
    /// threshold).
    pub fn halves(&self) -> bool {
        self.aovs.contains(&Aov::Variance) || self.noise_threshold.is_some()
    }
}

/// The iterations of a render to render (all of them when `None`).
pub type Iterations = Option<Range<u32>>;

/// What rendering gives.
pub type Rendered = Result<RenderOutput, Error>;

/// An integrator's options type, and how the integrator renders with them.
pub trait Integrator:
    clap::Args + clap::FromArgMatches + Default + Clone + std::fmt::Debug + Serialize + Send + Sync + 'static
{
    /// Whether the integrator samples with the bidirectional core's strategies (it needs a
    /// light to start light subpaths from, and reports connections and light paths).
    const BIDIRECTIONAL: bool;

    /// Whether the integrator renders participating media and null surfaces (scenes with
    /// them are refused otherwise).
    const MEDIA: bool = false;

    /// Whether the integrator renders iterations of one sample per pixel in the render loop
    /// (which can keep half-images for the variance AOV and the noise threshold); the
    /// Markov chains do not.
    const ITERATIVE: bool = true;

    /// Renders iterations `iterations` (all of them when `None`) of the run `run` describes
    /// with this integrator and these options. The statistics' `integrator` and `options`
    /// are the registry's to fill.
    fn render(&self, scene: &Scene, run: &RunOptions, iterations: Iterations) -> Rendered;

    /// The MIS heuristic, for an integrator that weighs strategies.
    fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
        None
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

/// A viewer of the image while it renders: after each pass (each round of a Markov-chain
/// render) the render loops develop the image and show it, when the viewer wants one.
pub trait Preview: Send + Sync + std::fmt::Debug {
    /// Whether the viewer wants an image now (the loops develop one only then).
    fn wants(&self) -> bool;
    /// The image after `spp` samples (or mutations) per pixel; must not block for long.
    fn show(&self, width: u32, height: u32, spp: u32, image: Vec<Rgb>);
}

/// Shows the image `develop` gives to the run's viewer, if it has one that wants it now.
pub(crate) fn offer_preview(opts: &RunOptions, width: u32, height: u32, spp: u32, develop: impl FnOnce() -> Vec<Rgb>) {
    if let Some(p) = &opts.preview
        && p.wants()
    {
        p.show(width, height, spp, develop());
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
    /// The per-pixel variance of `image` when the render kept half-images.
    pub variance: Option<Vec<Rgb>>,
    /// The AOV channels asked for, `(EXR channel name, one value per pixel)`.
    pub aovs: crate::image_io::Channels,
}
