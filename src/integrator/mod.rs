//! Integrators, their options and statistics, and [`render`], which hands the chosen one
//! (the [`Method`] of [`registry`]) to its own [`Integrator::render`]: [`render_loop`] for
//! every integrator that renders iterations of one sample per pixel,
//! [`metropolis::run_chains`] for the Markov chains of [`pssmlt`] and [`memlt`].

pub mod bidir;
pub mod budget;
pub mod eorr;
pub mod guided;
pub mod lvc;
pub mod manifold;
pub mod memlt;
pub mod metropolis;
pub mod noise;
pub mod path;
pub mod pcbpt;
pub mod pool_base;
pub(crate) mod progress;
pub mod pssmlt;
pub mod registry;
pub(crate) mod render_loop;
pub mod run;
pub mod spcbpt;
pub mod stats;
pub mod vcm;

use crate::scene::Scene;
pub use bidir::pool::CONCENTRATION_DEPTHS;
pub use registry::{IntegratorKind, Method};
pub use run::{Budget, Integrator, Preview, RenderOutput, RunOptions, Snapshot};
pub use stats::{Counters, Details, IntegratorStats, PhaseRays, PhaseTimes, RenderStats};
use std::ops::Range;

/// A render: the integrator with its options, and the run's other settings.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// The integrator and its options.
    pub method: Method,
    pub run: RunOptions,
}

impl RenderOptions {
    /// `integrator` with its default options, and [`RunOptions::new`]`(budget)`.
    pub fn new(integrator: IntegratorKind, budget: Budget) -> RenderOptions {
        RenderOptions { method: Method::default_for(integrator), run: RunOptions::new(budget) }
    }

    pub fn integrator(&self) -> IntegratorKind {
        self.method.kind()
    }
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
        let Budget::Spp(spp) = opts.run.budget else {
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
    check_noise_options(&opts.run, kind, iterations.is_some())?;
    if kind.is_bidirectional() {
        bidir::bdpt::check_lights(scene, kind.name()).map_err(Error::Usage)?;
    }
    let mut out = opts.method.render(scene, &opts.run, iterations)?;
    // The first-hit AOVs, from a pass of their own whatever the integrator.
    out.aovs = crate::aov::first_hits(scene, &opts.run.aovs, opts.run.seed, opts.run.threads)?;
    if let Some(v) = &out.variance
        && opts.run.aovs.contains(&crate::aov::Aov::Variance)
    {
        out.aovs.extend(crate::aov::variance_channels(v));
    }
    Ok(out)
}

/// Refuses what the render loop's half-images cannot give: the variance AOV and the noise
/// threshold of a Markov-chain integrator, of a chunk, or of a single sample per pixel; an
/// AOV of a chunk (partial renders keep the film's sums alone); a threshold that is not a
/// positive number.
fn check_noise_options(run: &RunOptions, kind: IntegratorKind, chunk: bool) -> Result<(), crate::error::Error> {
    use crate::error::Error;
    if let Some(t) = run.noise_threshold
        && !(t > 0.0 && t.is_finite())
    {
        return Err(Error::Usage(format!("--noise-threshold must be a positive relMSE, got {t}")));
    }
    if chunk && !run.aovs.is_empty() {
        return Err(Error::Usage("--aov is not kept in partial renders (--chunk, --iterations)".into()));
    }
    if !run.halves() {
        return Ok(());
    }
    let what = if run.noise_threshold.is_some() { "--noise-threshold" } else { "--aov variance" };
    if chunk {
        return Err(Error::Usage(format!("{what} needs the whole render, not a chunk of its iterations")));
    }
    if !kind.is_iterative() {
        return Err(Error::Usage(format!(
            "{what} needs an integrator that renders iterations of one sample per pixel; {}'s Markov chains do not",
            kind.name()
        )));
    }
    if run.budget == Budget::Spp(1) {
        return Err(Error::Usage(format!("{what} needs at least 2 samples per pixel (two half-images)")));
    }
    Ok(())
}
