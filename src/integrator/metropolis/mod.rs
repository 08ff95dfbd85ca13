//! What the Markov-chain integrators (PSSMLT, MEMLT; contract §6) share: the independent
//! samples that estimate the normalisation and seed the chains ([`bootstrap`]), two-stage
//! Metropolis's importance map ([`two_stage`]), the chains' longest stays ([`stays`]), the points of
//! primary sample space ([`primary`]), the options of the chains ([`ChainOptions`]) and the
//! loop that runs them ([`run_chains`]).

pub mod bootstrap;
pub mod primary;
pub mod stays;
pub mod two_stage;

use crate::film::Film;
use crate::integrator::progress::Progress;
use crate::integrator::run::{Budget, RenderOutput, RunOptions, Snapshot, offer_preview, take_snapshots};
use crate::integrator::stats::{Counters, Details, RenderStats};
use crate::math::Rgb;
use crate::scene::Scene;
use serde::Serialize;
use std::ops::Range;

/// Which estimator the Markov chain drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum MltBase {
    /// Bidirectional path tracing: every strategy of one sample, MIS-weighted.
    Bdpt,
    /// Unidirectional path tracing.
    Path,
}

/// What every Markov-chain integrator (PSSMLT, MEMLT) reads: the bootstrap, the chains and
/// two-stage Metropolis' first stage.
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct ChainOptions {
    /// Independent samples for the normalisation and the chains' start states.
    #[arg(long, default_value_t = ChainOptions::default().bootstrap)]
    pub bootstrap: usize,
    /// Markov chains, each started from a bootstrap path drawn in proportion to its
    /// contribution (the image does not depend on the thread count).
    #[arg(long, default_value_t = ChainOptions::default().chains)]
    pub chains: usize,
    /// Two-stage Metropolis: pixels per side of the first stage's cells (Mitsuba 0.6's
    /// `firstStageSizeReduction`).
    #[arg(long, default_value_t = ChainOptions::default().first_stage_reduction)]
    pub first_stage_reduction: u32,
}

impl Default for ChainOptions {
    fn default() -> ChainOptions {
        ChainOptions { bootstrap: 100_000, chains: 64, first_stage_reduction: 16 }
    }
}

impl ChainOptions {
    /// Refuses no bootstrap sample or no chain (PSSMLT and MEMLT alike).
    pub fn check_counts(&self) -> Result<(), crate::error::Error> {
        use crate::error::Error;
        if self.bootstrap == 0 {
            return Err(Error::Usage("--bootstrap must be at least 1".into()));
        }
        if self.chains == 0 {
            return Err(Error::Usage("--chains must be at least 1".into()));
        }
        if self.first_stage_reduction == 0 {
            return Err(Error::Usage("--first-stage-reduction must be at least 1 (pixels per side of a cell)".into()));
        }
        Ok(())
    }
}

/// Where a run of Markov chains stops, and what it starts from: `done` mutations of an
/// earlier run of the same chains (whose splats `into` holds), and a time (seconds since
/// the render's start) before the budget's, if any.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ChainSpan {
    pub done: u64,
    pub until: Option<f64>,
}

/// What a run of Markov chains did: the mutations done (with the span's earlier ones),
/// whether the render was interrupted, and the groups' films (their splats, already added
/// to `into`) with the number of chains in each.
pub(crate) struct ChainRun {
    pub done: u64,
    pub interrupted: bool,
    pub groups: Vec<(Film, usize)>,
}

/// Runs Markov chains for the budget: `total` mutations (or the time budget, or the span's
/// end) in rounds of about one mutation per pixel, every chain running `step` the same
/// number of times per round, so that time budgets and Ctrl-C are checked regularly. The
/// chains are split into one contiguous group per worker thread (at least two groups, so
/// that two independent halves of the chains can be compared), each group's steps splatting
/// into a film of its own: a chain's steps do not depend on the group it is in, and the
/// films' sums are exact, so the image does not depend on the number of threads. After each
/// round the snapshots due (and the live preview's image, when it wants one) are developed
/// by `develop(chains, film)`, `film` being `into`
/// with the splats so far (and the mutations done as its light paths); at the end the
/// splats are added to `into`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_chains<C: Send>(
    pool: &rayon::ThreadPool,
    opts: &RunOptions,
    start: std::time::Instant,
    pixels: u64,
    total: u64,
    span: ChainSpan,
    chains: &mut [C],
    into: &mut Film,
    step: impl Fn(&mut C, &mut Film) + Sync,
    snapshots: &mut Vec<Snapshot>,
    develop: impl Fn(&[C], Film) -> Vec<Rgb>,
) -> ChainRun {
    use rayon::prelude::*;
    let count = chains.len() as u64;
    if count == 0 {
        return ChainRun { done: span.done, interrupted: false, groups: Vec::new() };
    }
    let mut films = vec![Film::new(into.width, into.height, into.filter); pool.current_num_threads().max(2)];
    let per_group = chains.len().div_ceil(films.len());
    let per_round = pixels.div_ceil(count);
    let (mut done, mut interrupted) = (span.done, false);
    // Mutations per pixel stand for samples per pixel in the bar and the log's lines.
    let progress = Progress::new(opts, into.width, into.height, 1, total.div_ceil(pixels) as u32, start);
    while done < total {
        let n = per_round.min((total - done).div_ceil(count));
        pool.install(|| {
            chains.par_chunks_mut(per_group).zip(films.par_iter_mut()).with_max_len(1).for_each(|(group, film)| {
                for ch in group {
                    for _ in 0..n {
                        step(ch, film);
                    }
                }
            })
        });
        done += n * count;
        progress.pass_done((done / pixels) as u32, done - span.done, None, start);
        if !opts.checkpoints.is_empty() {
            let elapsed = start.elapsed().as_secs_f64();
            take_snapshots(&opts.checkpoints, snapshots, elapsed, (done / pixels) as u32, || {
                let mut f = into.clone();
                f.add_splat_films(&films);
                f.light_paths = done;
                develop(chains, f)
            });
        }
        offer_preview(opts, into.width, into.height, (done / pixels) as u32, || {
            let mut f = into.clone();
            f.add_splat_films(&films);
            f.light_paths = done;
            develop(chains, f)
        });
        if opts.stop.as_ref().is_some_and(|s| s.load(std::sync::atomic::Ordering::SeqCst)) {
            interrupted = true;
            break;
        }
        let elapsed = start.elapsed().as_secs_f64();
        if let Budget::Time(t) = opts.budget
            && elapsed >= t
        {
            break;
        }
        if span.until.is_some_and(|u| elapsed >= u) {
            break;
        }
    }
    progress.finish();
    into.add_splat_films(&films);
    let sizes = chains.chunks(per_group).map(|g| g.len());
    ChainRun { done, interrupted, groups: films.into_iter().zip(sizes).collect() }
}

/// The output of a Markov-chain render (PSSMLT, MEMLT): its statistics, with the
/// iterations (mutations per pixel) it rendered and the integrator's `details`, and its image.
#[allow(clippy::too_many_arguments)]
pub(crate) fn chains_output(
    scene: &Scene,
    opts: &RunOptions,
    threads: usize,
    counters: Counters,
    seconds: f64,
    spp: u32,
    film: Film,
    image: Vec<Rgb>,
    snapshots: Vec<Snapshot>,
    interrupted: bool,
    iterations: Option<Range<u32>>,
    details: Details,
) -> RenderOutput {
    let stats = RenderStats {
        iterations: match opts.budget {
            Budget::Spp(spp) => Some(iterations.unwrap_or(0..spp)),
            Budget::Time(_) => None,
        },
        details,
        ..RenderStats::new(scene, threads, counters, seconds, spp, film.invalid_samples, interrupted)
    };
    let (width, height) = (scene.film.width, scene.film.height);
    RenderOutput {
        image,
        strategy_images: Vec::new(),
        snapshots,
        width,
        height,
        stats,
        film: Some(film),
        variance: None,
        aovs: Vec::new(),
    }
}

/// Two-stage Metropolis' line of a render's summary (none without a first stage).
pub fn first_stage_line(samples: u64, mean_luminance: f64) -> Option<String> {
    (samples > 0).then(|| {
        format!(
            "  two-stage: the chains' target is luminance over a map from a first stage of {samples} BDPT samples (b above is its mean); the chains' image is scaled to mean luminance {mean_luminance:.5}"
        )
    })
}
