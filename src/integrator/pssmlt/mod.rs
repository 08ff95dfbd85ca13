//! Primary-sample-space Metropolis light transport (Kelemen et al. 2002; contract §6) over
//! the bidirectional estimator (every MIS-weighted strategy of one sample) or over the path
//! tracer (`--mlt-path-integrator path`).
//!
//! A state is a vector of uniform numbers in three streams (camera subpath, light subpath,
//! connections), mutated lazily: a coordinate is only brought up to date when the estimator
//! reads it. Large steps (probability `--large-step-prob`) draw fresh numbers; small steps
//! apply Kelemen's exponential perturbation (`s1 = 1/1024`, `s2 = 1/64`) once per iteration
//! missed. The scalar contribution of a state is the sum of the luminances of everything it
//! adds to the film. Both the current and the proposed state are splatted with their
//! expected weights; the image is scaled by the normalisation `b` estimated from
//! `--bootstrap` independent samples. `--chains` chains (64), each with its own seed, run the
//! same number of mutations; the worker threads splat them into films of their own, whose
//! exact sums make the image independent of the thread count.
//!
//! With `--two-stage true` (off by default) the scalar contribution is each luminance over a
//! first stage's map of the image at its film position ([`crate::integrator::metropolis::two_stage`]), and the image
//! is scaled to the mean luminance. The BDPT bootstrap and the first stage also serve MEMLT.

use crate::film::{Film, Splat};
use crate::integrator::bidir::bdpt::Scratch;
use crate::integrator::metropolis::bootstrap::{
    BOOTSTRAP_STREAM, ChainPaths, Contributions, Evaluator, bootstrap, evaluator, first_stage, mean_and_error,
};
use crate::integrator::metropolis::primary::PrimarySampler;
use crate::integrator::metropolis::stays::{self, LongestStay, Stay, Stays, pixel_of, share_in};
use crate::integrator::metropolis::{ChainOptions, MltBase, first_stage_line};
use crate::integrator::run::{Budget, RenderOutput, RunOptions};
use crate::integrator::run::{Integrator, Iterations, Rendered};
use crate::integrator::stats::Counters;
use crate::integrator::stats::{Details, IntegratorStats, RenderStats};
use crate::math::{Rgb, luminance};
use crate::sampling::{Distribution1D, Sampler};
use crate::scene::Scene;
use serde::Serialize;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// Options of PSSMLT (`--integrator pssmlt`).
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct PssmltOptions {
    /// MIS heuristic of the bidirectional estimator the chains drive.
    #[arg(long, value_enum, default_value_t = crate::integrator::bidir::mis::Heuristic::default())]
    pub heuristic: crate::integrator::bidir::mis::Heuristic,
    /// Probability of a large step.
    #[arg(long, default_value_t = PssmltOptions::default().large_step_prob)]
    pub large_step_prob: f32,
    /// The estimator the Markov chains drive.
    #[arg(long = "mlt-path-integrator", value_enum, default_value_t = PssmltOptions::default().base)]
    pub base: MltBase,
    #[command(flatten)]
    pub chain: ChainOptions,
    /// Two-stage Metropolis (Mitsuba 0.6's `twoStage`): a first stage of
    /// BDPT samples estimates the image at a reduced resolution, and the chains sample paths
    /// in proportion to their luminance over it. Off for PSSMLT, whose scalar contribution
    /// the contract fixes as the luminance.
    #[arg(long, default_value_t = PssmltOptions::default().two_stage, action = clap::ArgAction::Set)]
    pub two_stage: bool,
}

impl Default for PssmltOptions {
    fn default() -> PssmltOptions {
        PssmltOptions {
            heuristic: Default::default(),
            large_step_prob: 0.3,
            base: MltBase::Bdpt,
            chain: ChainOptions::default(),
            two_stage: false,
        }
    }
}

/// Statistics of a Metropolis render.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct MltStats {
    /// `b`: from the bootstrap and every large step (independent uniform samples too).
    pub normalisation: f64,
    /// `b` from the bootstrap alone (what the chains splat with before the final rescale).
    pub bootstrap_normalisation: f64,
    /// Independent samples of the bootstrap.
    pub bootstrap_samples: u64,
    pub chains: usize,
    pub mutations: u64,
    pub small_proposed: u64,
    pub small_accepted: u64,
    pub large_proposed: u64,
    pub large_accepted: u64,
    pub small_acceptance: f64,
    pub large_acceptance: f64,
    pub mutations_per_second: f64,
    pub bootstrap_seconds: f64,
    /// The longest any chain's current state stayed in one pixel.
    pub longest_stay: Option<LongestStay>,
    /// Two-stage Metropolis: the first stage's BDPT samples (0 without it). The
    /// normalisations are then means of luminance over the first stage's map.
    pub first_stage_samples: u64,
    /// The image's mean luminance, from the bootstrap and every large step (the
    /// normalisation without a first stage).
    pub mean_luminance: f64,
}

/// PSSMLT's statistics, under `mlt` in the JSON.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct PssmltStats {
    pub mlt: MltStats,
}

impl IntegratorStats for PssmltStats {
    fn lines(&self, _: &RenderStats) -> Vec<String> {
        let m = &self.mlt;
        let mut lines = vec![format!(
            "  PSSMLT: b = {:.5}, {} chains, {} mutations ({:.3} M/s), acceptance small {:.1}% large {:.1}%, bootstrap {:.2} s",
            m.normalisation,
            m.chains,
            m.mutations,
            m.mutations_per_second / 1e6,
            m.small_acceptance * 100.0,
            m.large_acceptance * 100.0,
            m.bootstrap_seconds
        )];
        lines.extend(first_stage_line(m.first_stage_samples, m.mean_luminance));
        lines.extend(m.longest_stay.iter().flat_map(|l| l.lines("pssmlt")));
        lines
    }
}

/// Splats contributions scaled by `weight`.
fn deposit(film: &mut Film, contributions: &Contributions, weight: f32, buf: &mut Vec<Splat>) {
    if weight <= 0.0 || !weight.is_finite() {
        return;
    }
    buf.clear();
    buf.extend(contributions.splats.iter().map(|s| Splat { value: s.value * weight, ..*s }));
    film.add_splats(buf);
}

/// One Markov chain with its own film.
struct Chain<'a> {
    rng: PrimarySampler,
    decide: Sampler,
    current: Contributions<'a>,
    f: f32,
    scratch: Scratch,
    counters: Counters,
    stats: MltStats,
    /// Sum of the contributions of large-step proposals, and of their plain luminances.
    large_sum: f64,
    large_luminance: f64,
    /// Scratch: the proposal's contributions and the splats of a deposit.
    proposed: Contributions<'a>,
    buf: Vec<Splat>,
    stays: Stays,
}

impl Chain<'_> {
    /// One mutation: a proposal (large or small step), both states splatted with their
    /// expected weights, the proposal accepted or not.
    fn step(&mut self, ev: &Evaluator, b: f32, film: &mut Film) {
        let (proposed, buf) = (&mut self.proposed, &mut self.buf);
        self.rng.start_iteration(false);
        let large = self.rng.is_large_step();
        let fp = ev.eval(&mut self.rng, &mut self.scratch, proposed, &mut self.counters);
        let a = if self.f > 0.0 { (fp / self.f).min(1.0) } else { 1.0 };
        if fp > 0.0 {
            deposit(film, proposed, a * b / fp, buf);
        }
        if self.f > 0.0 {
            deposit(film, &self.current, (1.0 - a) * b / self.f, buf);
        }
        // The part of this step's splats that lands around the current stay's pixel.
        let (current, f) = (&self.current, self.f);
        self.stays.record(pixel_of(current.pos), |centre| {
            let moved = if fp > 0.0 { a as f64 * share_in(&proposed.splats, centre) } else { 0.0 };
            let stayed = if f > 0.0 { (1.0 - a) as f64 * share_in(&current.splats, centre) } else { 0.0 };
            moved + stayed
        });
        if large {
            self.stats.large_proposed += 1;
            self.large_sum += fp as f64;
            self.large_luminance += proposed.luminance as f64;
        } else {
            self.stats.small_proposed += 1;
        }
        if self.decide.next_1d() < a {
            self.rng.accept();
            std::mem::swap(&mut self.current, proposed);
            self.f = fp;
            if large {
                self.stats.large_accepted += 1;
            } else {
                self.stats.small_accepted += 1;
            }
        } else {
            self.rng.reject();
        }
    }
}

/// The normalisation refined with every large step: the bootstrap's `n_boot` samples of
/// mean `b` and the large-step proposals are all independent uniform samples.
fn refined_normalisation(chains: &[Chain], b: f64, n_boot: usize) -> f64 {
    refined(chains, b, n_boot, |ch| ch.large_sum)
}

/// The mean luminance refined so, from the bootstrap's mean luminance `l` (two-stage
/// Metropolis, where it differs from the normalisation).
fn refined_luminance(chains: &[Chain], l: f64, n_boot: usize) -> f64 {
    refined(chains, l, n_boot, |ch| ch.large_luminance)
}

fn refined(chains: &[Chain], boot: f64, n_boot: usize, large: impl Fn(&Chain) -> f64) -> f64 {
    let (mut sum, mut count) = (boot * n_boot as f64, n_boot as f64);
    for ch in chains {
        sum += large(ch);
        count += ch.stats.large_proposed as f64;
    }
    sum / count
}

/// The image developed from the chains' film: scaled by the refined normalisation over the
/// bootstrap's one (`b`, which the chains splatted with), or in two-stage Metropolis (`l`,
/// the bootstrap's mean luminance, given) so that its mean luminance is the refined mean
/// luminance, as Mitsuba 0.6 develops its two-stage image. Also the factor.
fn develop_chains(chains: &[Chain], film: &Film, b: f64, l: Option<f64>, n_boot: usize) -> (Vec<Rgb>, f64) {
    let image = film.develop();
    let s = match l {
        None if b > 0.0 => refined_normalisation(chains, b, n_boot) / b,
        None => 0.0,
        Some(l) => {
            let mean = image.iter().map(|p| luminance(*p) as f64).sum::<f64>() / image.len().max(1) as f64;
            if mean > 0.0 { refined_luminance(chains, l, n_boot) / mean } else { 1.0 }
        }
    };
    (image.into_iter().map(|p| p * s as f32).collect(), s)
}

const CHAIN_STREAM: u64 = 0x6368_6169;

/// Renders with PSSMLT: all of the budget, or for `iterations` `A..B` (a chunk of a
/// distributed render) `B - A` mutations per pixel by chains of their own, with their own
/// bootstrap (streams keyed by `A` as well), whose films merge by their normalisations.
pub fn render(
    scene: &Scene,
    opts: &RunOptions,
    mo: &PssmltOptions,
    iterations: Option<std::ops::Range<u32>>,
) -> Result<RenderOutput, crate::error::Error> {
    if !(mo.large_step_prob > 0.0 && mo.large_step_prob <= 1.0) {
        return Err(crate::error::Error::Usage(format!(
            "--large-step-prob must be in (0, 1], got {}",
            mo.large_step_prob
        )));
    }
    mo.chain.check_counts()?;
    if mo.base == MltBase::Bdpt {
        crate::integrator::bidir::bdpt::check_lights(scene, "pssmlt").map_err(crate::error::Error::Usage)?;
    }
    let pool = crate::workers::render_pool(opts.threads)?;
    let threads = pool.current_num_threads();
    let ev = evaluator(scene, mo.heuristic, mo.base);
    let (w, h) = (scene.film.width, scene.film.height);
    let pixels = w as u64 * h as u64;
    let start = Instant::now();
    let stopped = || opts.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst));
    // Chunk `A..B` of a render, `A > 0`, runs chains (and a bootstrap) of its own.
    let chunk_key = iterations.as_ref().map_or(0, |r| r.start as u64);
    let key = |stream: u64, i: u64| {
        let mut k = vec![opts.seed, stream, i];
        if chunk_key > 0 {
            k.push(chunk_key);
        }
        k
    };

    // Two-stage Metropolis: a first stage of as many BDPT samples as the bootstrap has. Its
    // streams are the render's, not a chunk's: every chunk of a distributed render has the
    // same map, so that the parts' histograms and normalisations merge.
    let mut counters = Counters::default();
    let (importance, first_stage_samples) = if mo.two_stage {
        let render_key = |stream: u64, i: u64| vec![opts.seed, stream, i];
        let (map, n, c) =
            first_stage(scene, opts, &pool, (mo.heuristic, &mo.chain), ChainPaths::ALL, start, 0.0, &render_key);
        counters += c;
        (map, n)
    } else {
        (None, 0)
    };
    let importance = importance.as_ref();
    // Bootstrap: independent samples estimate b and give the chains their start states.
    let (weights, luminances, c) =
        bootstrap(&pool, &ev, mo.chain.bootstrap, mo.large_step_prob, ChainPaths::ALL, importance, &key);
    counters += c;
    // Two-stage Metropolis: the bootstrap's mean luminance, to which the image is scaled.
    let plain = importance.map(|_| mean_and_error(&luminances).0);
    let b = mean_and_error(&weights).0;
    let bootstrap_seconds = start.elapsed().as_secs_f64();
    let mut film = Film::new(w, h, scene.film.filter);
    let mut stats = MltStats {
        normalisation: b,
        bootstrap_normalisation: b,
        bootstrap_samples: weights.len() as u64,
        chains: mo.chain.chains,
        first_stage_samples,
        bootstrap_seconds,
        ..Default::default()
    };
    let mut snapshots = Vec::new();
    let mut interrupted = stopped();
    let mut longest = Stay::default();
    let mut image = None;
    if b > 0.0 && !interrupted {
        let dist = Distribution1D::new(&weights);
        let total = match opts.budget {
            Budget::Spp(_) if let Some(r) = &iterations => r.len() as u64 * pixels,
            Budget::Spp(spp) => spp as u64 * pixels,
            Budget::Time(_) => u64::MAX,
        };
        let mut chains: Vec<Chain> = (0..mo.chain.chains as u64)
            .map(|i| {
                let mut pick = Sampler::new(&key(CHAIN_STREAM, i));
                let (j, _) = dist.sample(pick.next_1d());
                let mut rng = PrimarySampler::new(&key(BOOTSTRAP_STREAM, j as u64), mo.large_step_prob);
                rng.start_iteration(true);
                let mut scratch = Scratch::default();
                let mut current = Contributions::new(ChainPaths::ALL, importance);
                let mut counters = Counters::default();
                let f = ev.eval(&mut rng, &mut scratch, &mut current, &mut counters);
                rng.accept();
                // The chain's own mutation stream from here on.
                rng.reseed(&key(CHAIN_STREAM ^ 1, i));
                Chain {
                    rng,
                    decide: Sampler::new(&key(CHAIN_STREAM ^ 2, i)),
                    current,
                    f,
                    scratch,
                    counters,
                    stats: MltStats::default(),
                    large_sum: 0.0,
                    large_luminance: 0.0,
                    proposed: Contributions::new(ChainPaths::ALL, importance),
                    buf: Vec::new(),
                    stays: Stays::default(),
                }
            })
            .collect();
        let bf = b as f32;
        let n_boot = weights.len();
        let run = crate::integrator::metropolis::run_chains(
            &pool,
            opts,
            start,
            pixels,
            total,
            crate::integrator::metropolis::ChainSpan::default(),
            &mut chains,
            &mut film,
            |ch, film| ch.step(&ev, bf, film),
            &mut snapshots,
            |chains, f| develop_chains(chains, &f, b, plain, n_boot).0,
        );
        let done = run.done;
        interrupted = run.interrupted;
        stats.normalisation = refined_normalisation(&chains, b, n_boot);
        stats.mean_luminance = plain.map_or(stats.normalisation, |l| refined_luminance(&chains, l, n_boot));
        longest = stays::longest(chains.iter().map(|c| &c.stays));
        for ch in &chains {
            counters += ch.counters;
            stats.small_proposed += ch.stats.small_proposed;
            stats.small_accepted += ch.stats.small_accepted;
            stats.large_proposed += ch.stats.large_proposed;
            stats.large_accepted += ch.stats.large_accepted;
        }
        stats.mutations = done;
        film.light_paths = done;
        image = Some(develop_chains(&chains, &film, b, plain, n_boot));
    }
    let seconds = start.elapsed().as_secs_f64();
    let ratio = |a: u64, p: u64| if p == 0 { 0.0 } else { a as f64 / p as f64 };
    stats.small_acceptance = ratio(stats.small_accepted, stats.small_proposed);
    stats.large_acceptance = ratio(stats.large_accepted, stats.large_proposed);
    stats.mutations_per_second = stats.mutations as f64 / (seconds - bootstrap_seconds).max(1e-9);
    let spp = (stats.mutations / pixels) as u32;
    // The chains splatted with the bootstrap's b; the final b also counts the large steps.
    let (image, s) = image.unwrap_or_else(|| {
        let s = if b > 0.0 { 1.0 } else { 0.0 };
        (film.develop().into_iter().map(|p| p * s as f32).collect(), s)
    });
    // Each mutation put the bootstrap's `b` (times the map there), so scaled, into the image.
    let b_there = b * s * importance.map_or(1.0, |m| m.pixel(longest.pixel) as f64);
    stats.longest_stay = LongestStay::measure(longest, &image, (w, h), b_there, stats.mutations);
    Ok(crate::integrator::metropolis::chains_output(
        scene,
        opts,
        threads,
        counters,
        seconds,
        spp,
        film,
        image,
        snapshots,
        interrupted,
        iterations,
        Details::of(PssmltStats { mlt: stats }),
    ))
}

impl Integrator for PssmltOptions {
    const BIDIRECTIONAL: bool = false;
    const MEDIA: bool = true;
    const ITERATIVE: bool = false;

    fn render(&self, scene: &Scene, opts: &RunOptions, iterations: Iterations) -> Rendered {
        render(scene, opts, self, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut crate::integrator::bidir::mis::Heuristic> {
        Some(&mut self.heuristic)
    }
}

#[cfg(test)]
mod tests;
