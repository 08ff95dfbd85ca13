//! Path-space Metropolis light transport (Veach and Guibas 1997) with the mutations of
//! Manifold Exploration Metropolis (Jakob and Marschner 2012; contract §6 and `memlt.md`).
//!
//! A chain's state is one full path ([`path`]). The normalisation `b`, the image's mean
//! luminance, comes from `--bootstrap` independent BDPT samples. The start paths come from as
//! many independent paths of the bidirectional generator (a length, then every vertex
//! regenerated: [`bidirectional`]'s whole-path move), each chain's drawn in proportion to
//! `f / p`; their mean is a second, independent estimate of `b` (`seed_normalisation` in the
//! statistics). What each length and split of the generator found among them teaches the
//! independent mutation's generator ([`independent::Strategies`]), and the share of their
//! light in paths that only a camera walk makes decides whether that mutation runs
//! (`--independent-mutation auto`, [`independent_mutation_on`]); with `--learned-starts`
//! (the default) a second set of candidates from that generator gives the starts. Each step
//! proposes a mutation chosen uniformly among the mutators that suit the current path,
//! accepts it with probability `min(1, f(y) T(y→x) / f(x) T(x→y))` on luminances, and
//! splats both paths with their expected weights. `--chains` chains (64),
//! each with its own seed, run the same number of mutations; the worker threads splat them
//! into films of their own, whose exact sums make the image independent of the thread count.
//!
//! The direct light is by default a separate estimate ([`separate_light`]) whose share of
//! a time budget balances its noise against the chains' ([`direct_balance`]).
//!
//! Every kind of light the renderer has may light the scene: lights at infinity enter a
//! path as a vertex in their direction ([`path`]).
//!
//! By default the chains run two-stage Metropolis ([`crate::integrator::metropolis::two_stage`]): their target is
//! the luminance over a first stage's map of the image, `b` the mean of that, the start
//! paths drawn in proportion to it, and the chains' part of the image is finally scaled to
//! the bootstrap's plain mean luminance. `--two-stage false` gives the plain luminance.

pub mod bidirectional;
pub mod caustic;
pub mod direct_balance;
pub mod independent;
pub mod lens;
pub mod manifold_perturbation;
pub mod media;
pub mod multichain;
mod options;
pub mod path;
pub mod separate_light;
pub mod specular_pass;
mod stats;

pub use options::*;
pub use stats::*;

use crate::film::{Film, Splat};
use crate::integrator::bidir::Vertex;
use crate::integrator::metropolis::bootstrap::Keys;
use crate::integrator::metropolis::stays::{LongestStay, Stay, Stays, near, pixel_of};
use crate::integrator::metropolis::two_stage::Importance;
use crate::integrator::run::{Budget, RenderOutput, RunOptions};
use crate::integrator::run::{Integrator, Iterations, Rendered};
use crate::integrator::stats::{Counters, Details};
use crate::math::{Rgb, luminance};
use crate::sampling::{Distribution1D, Random, Sampler};
use crate::scene::Scene;
use bidirectional::Lengths;
use independent::{Split, Strategies};
use path::Measured;
use rayon::prelude::*;
use separate_light::SeparateLight;
use serde::Serialize;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// Longest path (in edges) the chains visit when the scene's `max_depth` is unlimited.
pub const MAX_EDGES: usize = 40;

/// The mutators.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mutator {
    Bidirectional,
    Lens,
    Caustic,
    MultiChain,
    /// The multi-chain perturbation's re-trace on to the light (`multichain.rs`).
    LightHit,
    Manifold,
    Independent,
}

impl Mutator {
    pub const ALL: [Mutator; 7] = [
        Mutator::Bidirectional,
        Mutator::Lens,
        Mutator::Caustic,
        Mutator::MultiChain,
        Mutator::LightHit,
        Mutator::Manifold,
        Mutator::Independent,
    ];
}

/// For each mutator, whether it suits a path and from where ([`suitable`]).
type Suits = [Option<usize>; Mutator::ALL.len()];

/// The mutators that suit a path (the bidirectional mutation suits every path) among those
/// `enabled`: for each, `None` when it does not, else the vertex it works from (0 for the
/// bidirectional, manifold and independent ones).
fn suitable(scene: &Scene, x: &[Vertex], enabled: [bool; Mutator::ALL.len()]) -> Suits {
    let on = |m: Mutator| enabled[m as usize];
    [
        on(Mutator::Bidirectional).then_some(0),
        if on(Mutator::Lens) { lens::suits(scene, x) } else { None },
        if on(Mutator::Caustic) { caustic::suits(scene, x) } else { None },
        if on(Mutator::MultiChain) { multichain::suits(scene, x) } else { None },
        if on(Mutator::LightHit) { multichain::suits_light_hit(scene, x) } else { None },
        (on(Mutator::Manifold) && manifold_perturbation::suits(scene, x)).then_some(0),
        on(Mutator::Independent).then_some(0),
    ]
}

/// The path lengths a scene's integrator settings allow.
pub fn lengths(scene: &Scene) -> Lengths {
    let spec = &scene.integrator;
    let max = if spec.max_depth < 0 { MAX_EDGES } else { (spec.max_depth as usize).min(MAX_EDGES) };
    Lengths { min: if spec.hide_emitters { 2 } else { 1 }, max, direct_separate: false, specular_separate: false }
}

/// Probability of drawing a start path of `k` edges: `∝ 2^-(k - min)`.
fn seed_length_pmf(lengths: Lengths, k: usize) -> f64 {
    if !(lengths.min..=lengths.max).contains(&k) {
        return 0.0;
    }
    let norm: f64 = (lengths.min..=lengths.max).map(|n| 0.5f64.powi((n - lengths.min) as i32)).sum();
    0.5f64.powi((k - lengths.min) as i32) / norm
}

/// An independent path: a length and a split from `strategies`, every vertex regenerated
/// from the light and the pinhole. The path, its contribution and its density.
pub fn independent_path<R: Random>(
    scene: &Scene,
    lengths: Lengths,
    strategies: &Strategies,
    rng: &mut R,
    counters: &mut Counters,
) -> Option<(Vec<Vertex>, Measured, f64)> {
    generated_path(scene, lengths, strategies, rng, counters).map(|(y, m, p, _)| (y, m, p))
}

/// [`independent_path`], with the length and split it drew.
fn generated_path<R: Random>(
    scene: &Scene,
    lengths: Lengths,
    strategies: &Strategies,
    rng: &mut R,
    counters: &mut Counters,
) -> Option<(Vec<Vertex>, Measured, f64, Split)> {
    let u = rng.next_1d() as f64;
    let walks = strategies.camera_walks();
    let (y, split) = if u < walks {
        let y = path::camera_walk_to_light(scene, lengths.max, rng, counters)?;
        let k = y.len() - 1;
        (y, (k, 0))
    } else {
        let (k, s) = strategies.sample((u - walks) / (1.0 - walks), rng.next_1d());
        let camera = path::camera_vertex(scene);
        (path::regenerate(scene, &[], std::slice::from_ref(&camera), s, k - s, rng, counters)?, (k, s))
    };
    if !lengths.covers(&y) {
        return None;
    }
    let m = path::contribution(scene, &y)?;
    let p = whole_path_density(scene, strategies, &y);
    (p > 0.0).then_some((y, m, p, split))
}

/// The density with which [`independent_path`] generates path `x` from `strategies` (0 for a
/// length it never draws).
pub fn whole_path_density(scene: &Scene, strategies: &Strategies, x: &[Vertex]) -> f64 {
    let k = x.len() - 1;
    let l = strategies.length(k);
    let walks = strategies.camera_walks();
    if walks == 0.0 {
        return if l > 0.0 { l * strategies.over_splits(k, path::split_densities(scene, x, 0, k)) } else { 0.0 };
    }
    let d: Vec<f64> = path::split_densities(scene, x, 0, k).collect();
    let splits = if l > 0.0 { (1.0 - walks) * l * strategies.over_splits(k, d.iter().copied()) } else { 0.0 };
    let walk = if path::walks_to_light(scene, x) { walks * d[0] } else { 0.0 };
    splits + walk
}

/// Scalar contribution of a path: its luminance (zero when not positive and finite).
#[inline]
fn scalar(m: &Measured) -> f64 {
    let l = luminance(m.f) as f64;
    if l.is_finite() && l > 0.0 { l } else { 0.0 }
}

/// The chains' target: the scalar contribution, over the first stage's map at the path's
/// film position in two-stage Metropolis.
#[inline]
fn target(m: &Measured, importance: Option<&Importance>) -> f64 {
    match importance {
        None => scalar(m),
        Some(map) => scalar(m) / map.at(m.raster) as f64,
    }
}

/// One Markov chain (its splats go to the film of the worker that runs it).
struct Chain {
    rng: Sampler,
    path: Vec<Vertex>,
    current: Measured,
    f: f64,
    /// The mutators that suit the current path ([`suitable`]), kept from its proposal.
    suits: Suits,
    counters: Counters,
    proposed: [u64; Mutator::ALL.len()],
    accepted: [u64; Mutator::ALL.len()],
    walks: manifold_perturbation::WalkStats,
    stays: Stays,
}

/// What a chain's steps need besides the scene.
#[derive(Clone, Copy)]
struct StepSettings<'a> {
    lengths: Lengths,
    radii: lens::Radii,
    /// `b`, the luminance each splat carries.
    b: f32,
    enabled: [bool; Mutator::ALL.len()],
    lambda: f64,
    /// The manifold perturbation's `θ_diff`, in radians.
    theta_diff: f64,
    /// Two-stage Metropolis: the first stage's map.
    importance: Option<&'a Importance>,
    /// The independent mutation's generator.
    strategies: &'a Strategies,
}

impl Chain {
    /// A chain at `path` (measured as `current`), stepping with `rng`; `counters` holds the
    /// work its start took.
    fn new(
        scene: &Scene,
        rng: Sampler,
        path: Vec<Vertex>,
        current: Measured,
        counters: Counters,
        importance: Option<&Importance>,
        enabled: [bool; Mutator::ALL.len()],
    ) -> Chain {
        Chain {
            rng,
            f: target(&current, importance),
            suits: suitable(scene, &path, enabled),
            path,
            current,
            counters,
            proposed: [0; Mutator::ALL.len()],
            accepted: [0; Mutator::ALL.len()],
            walks: Default::default(),
            stays: Stays::default(),
        }
    }

    /// One step: a proposal, both paths splatted with their expected weights (each with
    /// luminance `b`), the proposal accepted or not.
    fn step(&mut self, scene: &Scene, set: &StepSettings<'_>, film: &mut Film) {
        let StepSettings { lengths, radii, b, .. } = *set;
        self.counters.samples += 1;
        // A mutator chosen uniformly among those that suit the current path; the proposal
        // is accepted with the suitability of both paths in its densities.
        let suits = self.suits;
        let n_x = suits.iter().flatten().count();
        if n_x == 0 {
            // No enabled mutator suits the path: the chain stays (its splat is the current
            // path's, with weight one).
            self.stays.record(pixel_of(self.current.raster), |_| 1.0);
            film.add_splats(&[Splat {
                pos: self.current.raster,
                value: self.current.f * (b as f64 / self.f) as f32,
                layer: 0,
            }]);
            return;
        }
        let pick = ((self.rng.next_1d() * n_x as f32) as usize).min(n_x - 1);
        let Some((m, at)) = Mutator::ALL.iter().zip(suits).filter_map(|(&m, s)| s.map(|i| (m, i))).nth(pick) else {
            return;
        };
        let (x, rng, c) = (&self.path, &mut self.rng, &mut self.counters);
        let proposal = match m {
            Mutator::Bidirectional => bidirectional::propose(scene, x, lengths, rng, c),
            Mutator::Lens => lens::propose(scene, x, self.current.raster, at, radii, rng, c),
            Mutator::Caustic => caustic::propose(scene, x, at, radii, rng, c),
            Mutator::MultiChain | Mutator::LightHit => {
                multichain::propose(scene, x, self.current.raster, at, radii, rng, c)
            }
            Mutator::Manifold => {
                manifold_perturbation::propose(scene, x, (set.lambda, set.theta_diff), rng, c, &mut self.walks)
            }
            Mutator::Independent => independent::propose(scene, x, lengths, set.strategies, rng, c),
        };
        self.proposed[m as usize] += 1;
        let (a, proposal) = match proposal {
            Some(p) => {
                let fy = if lengths.covers(&p.path) { target(&p.measured, set.importance) } else { 0.0 };
                let suits_y = suitable(scene, &p.path, set.enabled);
                let n_y = suits_y.iter().flatten().count();
                let num = fy * p.backward * n_x as f64;
                let den = self.f * p.forward * n_y as f64;
                let a = if fy > 0.0 && p.forward > 0.0 && num.is_finite() && den > 0.0 {
                    (num / den).min(1.0)
                } else {
                    0.0
                };
                (a, Some((p, fy, suits_y)))
            }
            None => (0.0, None),
        };
        let mut splats = [Splat {
            pos: self.current.raster,
            value: self.current.f * ((1.0 - a) * b as f64 / self.f) as f32,
            layer: 0,
        }; 2];
        let mut n = usize::from(a < 1.0);
        if let Some((p, fy, _)) = &proposal
            && a > 0.0
        {
            splats[n] = Splat { pos: p.measured.raster, value: p.measured.f * (a * b as f64 / fy) as f32, layer: 0 };
            n += 1;
        }
        film.add_splats(&splats[..n]);
        let to = proposal.as_ref().map(|(p, _, _)| pixel_of(p.measured.raster));
        self.stays.record(pixel_of(self.current.raster), |centre| {
            1.0 - a + if to.is_some_and(|t| near(t, centre)) { a } else { 0.0 }
        });
        if let Some((p, fy, suits_y)) = proposal
            && (self.rng.next_1d() as f64) < a
        {
            self.path = p.path;
            self.suits = suits_y;
            self.current = p.measured;
            self.f = fy;
            self.accepted[m as usize] += 1;
        }
    }
}

/// Start-path candidates: each one's weight `f / p` with the length and split it drew, the
/// work they took, and the share of their weights in paths that only a camera walk makes.
type Candidates = (Vec<(f32, Split)>, Counters, f64);

/// `n` start-path candidates from `strategies` (streams `key(i)`): each one's weight `f / p`
/// (0 where the generator failed) with the length and split it drew, and the share of the
/// weights in paths that only a camera walk makes ([`path::joined_nowhere`]).
fn candidates(
    scene: &Scene,
    pool: &rayon::ThreadPool,
    lengths: Lengths,
    strategies: &Strategies,
    importance: Option<&Importance>,
    n: usize,
    key: &(dyn Fn(u64) -> Vec<u64> + Sync),
) -> Candidates {
    let chunk = 1024usize;
    let parts: Vec<Candidates> = pool.install(|| {
        (0..n.div_ceil(chunk))
            .into_par_iter()
            .map(|c| {
                let mut counters = Counters::default();
                let mut walk_only = 0.0;
                let ws = (c * chunk..((c + 1) * chunk).min(n))
                    .map(|i| {
                        let mut rng = Sampler::new(&key(i as u64));
                        generated_path(scene, lengths, strategies, &mut rng, &mut counters).map_or(
                            (0.0, (0, 0)),
                            |(y, m, p, ks)| {
                                let w = (target(&m, importance) / p) as f32;
                                if path::joined_nowhere(scene, &y) {
                                    walk_only += w as f64;
                                }
                                (w, ks)
                            },
                        )
                    })
                    .collect();
                (ws, counters, walk_only)
            })
            .collect()
    });
    let mut all = Vec::with_capacity(n);
    let mut counters = Counters::default();
    let mut walk_only = 0.0;
    for (ws, c, w) in parts {
        all.extend(ws);
        counters += c;
        walk_only += w;
    }
    let total: f64 = all.iter().map(|&(w, _)| w as f64).sum();
    (all, counters, if total > 0.0 { walk_only / total } else { 0.0 })
}

const BOOTSTRAP_STREAM: u64 = 0x626f_6f74;

/// `b` and its standard error from the BDPT bootstrap: `--bootstrap` samples, and with a
/// time budget (of a whole render) more batches of as many until `--bootstrap-fraction` of
/// the time has passed since `start`; the same samples' mean luminance and its standard
/// error (with a first stage's map `b` is the mean of luminance over it); and the number of
/// batches, with the work the samples took.
#[allow(clippy::too_many_arguments)]
fn normalisation(
    scene: &Scene,
    opts: &RunOptions,
    mo: &MemltOptions,
    pool: &rayon::ThreadPool,
    lengths: Lengths,
    start: Instant,
    importance: Option<&Importance>,
    key: Keys,
) -> ((f64, f64), (f64, f64), usize, Counters) {
    let n = mo.chain.bootstrap;
    let (mut sum, mut variance, mut counters) = ([0.0; 2], [0.0; 2], Counters::default());
    let batches = crate::integrator::metropolis::bootstrap::in_batches(opts, start, mo.bootstrap_fraction, |batch| {
        let offset = batch * n as u64;
        let (target, plain, c) = crate::integrator::metropolis::bootstrap::bdpt_normalisation(
            scene,
            mo.heuristic,
            pool,
            n,
            lengths.chain_paths(),
            importance,
            &|s, i| key(s ^ BOOTSTRAP_STREAM, i + offset),
        );
        counters += c;
        for (i, (m, e)) in [target, plain].into_iter().enumerate() {
            sum[i] += m;
            variance[i] += e * e;
        }
    });
    let k = batches as f64;
    let estimate = |i: usize| (sum[i] / k, variance[i].sqrt() / k);
    (estimate(0), estimate(1), batches as usize, counters)
}

/// Two-stage Metropolis' final scale: the chains' part of `image` (what it adds to `direct`,
/// the direct-light pass's image) scaled so that its mean luminance is `luminance`, the
/// bootstrap's estimate of it (Mitsuba 0.6 develops its two-stage image so): the image's
/// brightness then rests on the plain mean luminance, as in one stage, rather than on the
/// noisier mean of luminance over the map and the chains' time-average of the map. Also
/// the factor.
fn rescaled(image: Vec<Rgb>, direct: &[Rgb], luminance: f64) -> (Vec<Rgb>, f64) {
    let n = image.len().max(1) as f64;
    let chains: f64 = image.iter().zip(direct).map(|(p, d)| crate::math::luminance(*p - *d) as f64).sum::<f64>() / n;
    let s = if chains > 0.0 && luminance > 0.0 { luminance / chains } else { 1.0 };
    let image = image.into_iter().zip(direct).map(|(p, d)| *d + (p - *d) * s as f32).collect();
    (image, s)
}

/// A film's image, with two-stage Metropolis' final scale where `rescale` (the passes'
/// image beside the chains and the luminance) is given ([`rescaled`]); also the factor.
fn developed(film: &Film, rescale: Option<&(Vec<Rgb>, f64)>) -> (Vec<Rgb>, f64) {
    match rescale {
        Some((direct, l)) => rescaled(film.develop(), direct, *l),
        None => (film.develop(), 1.0),
    }
}
const SEED_STREAM: u64 = 0x7365_6564;
const LEARNED_SEED_STREAM: u64 = SEED_STREAM ^ 2;
const CHAIN_STREAM: u64 = 0x6368_6169;
const WALK_STREAM: u64 = 0x7761_6c6b;

/// What the direct-light balance measures a tenth into the chains' time: the direct pass's
/// two halves, the chains' (their images and mutations), the mutations done, and the chains'
/// seconds so far and the render's seconds left.
struct Measurement<'a> {
    halves: &'a (Vec<Rgb>, Vec<Rgb>),
    chain_halves: &'a [(Vec<Rgb>, f64); 2],
    done: u64,
    seconds: (f64, f64),
}

/// `--direct-balance` ([`direct_balance`]): both parts' relative variance per second against
/// the image so far (the direct light in `base`, with the chains' splats over
/// `measured.done` mutations) decide how much longer the direct pass runs; its new samples
/// go onto a new film, which takes the chains' splats so far and replaces `base`, and
/// two-stage's image of the direct light in `rescale` is developed again. The balance's
/// figures and the work the added samples took.
fn balance(
    scene: &Scene,
    opts: &RunOptions,
    key: Keys,
    light: &mut SeparateLight,
    measured: &Measurement,
    base: &mut Film,
    rescale: &mut Option<(Vec<Rgb>, f64)>,
) -> Result<(direct_balance::DirectBalance, Counters), crate::error::Error> {
    // The image so far, against which both parts' noise is relative.
    let mut film = base.clone();
    film.light_paths = measured.done;
    let (estimate, scale) = developed(&film, rescale.as_ref());
    let (chain_seconds, rest) = measured.seconds;
    let seconds = (light.seconds, chain_seconds, rest);
    let (mut b, asked) = direct_balance::measure(measured.halves, measured.chain_halves, &estimate, scale, seconds);
    let extra = (asked * light.samples as f64 / light.seconds).floor().min(u32::MAX as f64) as u32;
    let mut counters = Counters::default();
    if extra > 0 {
        let before = light.seconds;
        counters += light.more_direct(scene, opts, key, extra)?.1;
        b.extra_seconds = light.seconds - before;
        // The chains' splats so far onto the passes' new film.
        let mut film = light.film();
        if let Some((direct, _)) = rescale {
            *direct = film.develop();
        }
        film.add_film_splats(base);
        *base = film;
    }
    b.extra_samples = extra;
    Ok((b, counters))
}

/// Refuses MEMLT's options out of their ranges, and scenes it cannot render.
fn check_options(scene: &Scene, mo: &MemltOptions) -> Result<(), crate::error::Error> {
    use crate::error::Error;
    mo.chain.check_counts()?;
    crate::integrator::bidir::bdpt::check_lights(scene, "memlt").map_err(Error::Usage)?;
    let direct = mo.direct_samples;
    if direct == 0 || direct < -1 {
        return Err(Error::Usage(format!(
            "--direct-samples must be a positive sample count or -1 (direct light in the chains), got {direct}"
        )));
    }
    // `auto` may leave the independent mutation off: it does not count here.
    if !enabled(mo, mo.independent_mutation.unwrap_or(false)).iter().any(|&e| e) {
        return Err(Error::Usage("memlt needs at least one mutation (all are switched off; `--independent-mutation auto` may leave that one off too)".into()));
    }
    let fraction = mo.bootstrap_fraction;
    if !(0.0..1.0).contains(&fraction) {
        return Err(Error::Usage(format!("--bootstrap-fraction must be at least 0 and below 1, got {fraction}")));
    }
    let lambda = mo.lambda;
    if !(lambda.is_finite() && lambda > 0.0) {
        return Err(Error::Usage(format!("--lambda must be a positive number, got {lambda}")));
    }
    let defensive = mo.independent_defensive;
    if !(0.0..=1.0).contains(&defensive) {
        return Err(Error::Usage(format!("--independent-defensive must be a share from 0 to 1, got {defensive}")));
    }
    let walks = mo.independent_camera_walks;
    if !(0.0..=1.0).contains(&walks) {
        return Err(Error::Usage(format!("--independent-camera-walks must be a share from 0 to 1, got {walks}")));
    }
    let theta_diff = mo.theta_diff;
    if !(0.0..=180.0).contains(&theta_diff) {
        return Err(Error::Usage(format!("--theta-diff must be an angle from 0 to 180 degrees, got {theta_diff}")));
    }
    Ok(())
}

/// Renders with MEMLT: all of the budget, or for `iterations` `A..B` (a chunk of a
/// distributed render) `B - A` mutations per pixel by chains of their own, with their own
/// bootstrap (streams keyed by `A` as well).
pub fn render(
    scene: &Scene,
    opts: &RunOptions,
    mo: &MemltOptions,
    iterations: Option<std::ops::Range<u32>>,
) -> Result<RenderOutput, crate::error::Error> {
    use crate::error::Error;
    check_options(scene, mo)?;
    let n_boot = mo.chain.bootstrap;
    let direct = mo.direct_samples;
    let defensive = mo.independent_defensive;
    let pool = crate::workers::render_pool(opts.threads)?;
    let threads = pool.current_num_threads();
    let mut lengths = lengths(scene);
    let dirac = scene.shapes.iter().any(|sh| scene.bsdfs[sh.bsdf].lobes(glam::Vec2::ZERO).any(|l| l.is_delta()));
    // The specular pass, beside the direct-light pass, where a surface has a Dirac lobe.
    let specular = (direct > 0 && dirac).then_some(mo.specular_samples).filter(|&n| n > 0);
    if direct > 0 {
        // The chains start at three edges, so that no move proposes a path the direct pass
        // renders, but keep the two-edge paths through a Dirac lobe when no specular pass
        // takes them; beside one, their paths have a rough vertex.
        if dirac && specular.is_none() {
            lengths.min = lengths.min.max(2);
            lengths.direct_separate = true;
        } else {
            lengths.min = lengths.min.max(3);
            lengths.specular_separate = specular.is_some();
        }
    }
    let (w, h) = (scene.film.width, scene.film.height);
    let pixels = w as u64 * h as u64;
    let start = Instant::now();
    let stopped = || opts.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst));
    let chunk_key = iterations.as_ref().map_or(0, |r| r.start as u64);
    let key = |stream: u64, i: u64| {
        let mut k = vec![opts.seed, stream, i];
        if chunk_key > 0 {
            k.push(chunk_key);
        }
        k
    };
    // The direct light by the path tracer, and the specular pass, when asked for. With
    // `--direct-balance` under a time budget the direct pass runs twice, so that its noise can
    // be measured, and may go on once the chains' is known.
    let mut counters = Counters::default();
    let balanced = mo.direct_balance && direct > 0 && iterations.is_none() && matches!(opts.budget, Budget::Time(_));
    let (mut light, c) = SeparateLight::render(scene, opts, &key, direct, balanced, specular)?;
    counters += c;
    let mut base = light.film();
    if lengths.min > lengths.max {
        // No path is left to the chains.
        return finish(
            scene,
            opts,
            threads,
            base,
            MemltStats { direct_samples: light.samples, direct_seconds: light.seconds, ..Default::default() },
            counters,
            start,
            Vec::new(),
            stopped(),
            0,
            iterations,
            (Stay::default(), 0.0),
            None,
        );
    }
    // Two-stage Metropolis: the first stage takes the first half of the bootstrap's time;
    // its streams are the render's, not a chunk's, so that every chunk has the same map.
    let paths = lengths.chain_paths();
    let (importance, first_stage_samples) = if mo.two_stage {
        let fraction = mo.bootstrap_fraction / 2.0;
        let render_key = |stream: u64, i: u64| vec![opts.seed, stream, i];
        let (map, n, c) = crate::integrator::metropolis::bootstrap::first_stage(
            scene,
            opts,
            &pool,
            (mo.heuristic, &mo.chain),
            paths,
            start,
            fraction,
            &render_key,
        );
        counters += c;
        (map, n)
    } else {
        (None, 0)
    };
    let importance = importance.as_ref();
    let ((b, b_error), mean_luminance, boot_batches, c) =
        normalisation(scene, opts, mo, &pool, lengths, start, importance, &key);
    counters += c;
    // The direct light's image, beside which two-stage Metropolis scales the chains' part.
    let mut rescale = importance.map(|_| (base.develop(), mean_luminance.0));
    // Start-path candidates and their weights f / p: a first set from the start paths'
    // generator teaches the independent generator's lengths and splits, a second set from
    // that one gives the starts (their weights spread less).
    let uniform = Strategies::uniform(lengths);
    let (first, c, _) = candidates(scene, &pool, lengths, &uniform, importance, n_boot, &|i| key(SEED_STREAM, i));
    counters += c;
    // With `--independent-mutation auto`, camera walks to the first light measure the share
    // of their light in paths only such walks make (the split generator seldom makes those).
    let walk_only = if mo.independent_mutation.is_none() {
        let walks = Strategies::uniform(lengths).with_camera_walks(1.0);
        let (_, c, share) = candidates(scene, &pool, lengths, &walks, importance, n_boot, &|i| key(WALK_STREAM, i));
        counters += c;
        share
    } else {
        0.0
    };
    // The camera walks are the learned generator's where the independent mutation runs.
    let independent = independent_mutation_on(mo.independent_mutation, walk_only);
    let walks = if independent { mo.independent_camera_walks } else { 0.0 };
    let strategies = Strategies::from_candidates(lengths, &first, defensive).with_camera_walks(walks);
    let learned = mo.learned_starts;
    let (starts, start_stream) = if learned { (&strategies, LEARNED_SEED_STREAM) } else { (&uniform, SEED_STREAM) };
    let start_key = |i: u64| key(start_stream, i);
    let weights: Vec<f32> = if learned {
        let (set, c, _) = candidates(scene, &pool, lengths, starts, importance, n_boot, &start_key);
        counters += c;
        set.into_iter().map(|(w, _)| w).collect()
    } else {
        first.into_iter().map(|(w, _)| w).collect()
    };
    // The candidates' effective sample size `(Σw)² / Σw²`.
    let (sum, squares) = weights.iter().fold((0.0f64, 0.0f64), |(a, b), &w| (a + w as f64, b + w as f64 * w as f64));
    let start_ess = if squares > 0.0 { sum * sum / squares } else { 0.0 };
    let seed_b = weights.iter().map(|&x| x as f64).sum::<f64>() / n_boot as f64;
    let bootstrap_seconds = start.elapsed().as_secs_f64();
    let mut stats = MemltStats {
        normalisation: b,
        normalisation_error: b_error,
        seed_normalisation: seed_b,
        start_ess,
        start_candidates: n_boot,
        walk_only_share: walk_only,
        independent_mutation: independent,
        bootstrap_samples: (n_boot * boot_batches) as u64,
        chains: mo.chain.chains,
        bootstrap_seconds,
        min_edges: lengths.min,
        max_edges: lengths.max,
        first_stage_samples,
        mean_luminance: mean_luminance.0,
        mean_luminance_error: mean_luminance.1,
        direct_samples: light.samples,
        direct_seconds: light.seconds,
        ..Default::default()
    };
    let mut snapshots = Vec::new();
    let mut interrupted = stopped();
    let mut done = 0u64;
    let mut chains: Vec<Chain> = Vec::new();
    if b > 0.0 && seed_b > 0.0 && !interrupted {
        let on = enabled(mo, independent);
        let dist = Distribution1D::new(&weights);
        for i in 0..mo.chain.chains as u64 {
            // A start candidate in proportion to its weight, regenerated from its stream.
            let mut pick = Sampler::new(&key(CHAIN_STREAM, i));
            let (j, _) = dist.sample(pick.next_1d());
            let mut rng = Sampler::new(&start_key(j as u64));
            let mut c = Counters::default();
            let (path, current, _) = independent_path(scene, lengths, starts, &mut rng, &mut c)
                .ok_or_else(|| Error::Usage("a start path could not be regenerated".into()))?;
            let rng = Sampler::new(&key(CHAIN_STREAM ^ 1, i));
            chains.push(Chain::new(scene, rng, path, current, c, importance, on));
        }
        let total = match opts.budget {
            Budget::Spp(_) if let Some(r) = &iterations => r.len() as u64 * pixels,
            Budget::Spp(spp) => spp as u64 * pixels,
            Budget::Time(_) => u64::MAX,
        };
        let set = StepSettings {
            lengths,
            radii: lens::Radii::for_film(w, h),
            b: b as f32,
            enabled: on,
            lambda: mo.lambda,
            theta_diff: mo.theta_diff.to_radians(),
            importance,
            strategies: &strategies,
        };
        let run =
            |chains: &mut [Chain], base: &mut Film, span, rescale: &Option<(Vec<Rgb>, f64)>, snapshots: &mut _| {
                crate::integrator::metropolis::run_chains(
                    &pool,
                    opts,
                    start,
                    pixels,
                    total,
                    span,
                    chains,
                    base,
                    |ch, film| ch.step(scene, &set, film),
                    snapshots,
                    |_, f| developed(&f, rescale.as_ref()).0,
                )
            };
        let mut span = crate::integrator::metropolis::ChainSpan::default();
        let mut time_left = true;
        if let (Some(halves), Budget::Time(t)) = (light.halves.take(), opts.budget) {
            // A tenth of the chains' time, then the balance.
            let chains_start = start.elapsed().as_secs_f64();
            span.until = Some(chains_start + direct_balance::MEASURE_SHARE * (t - chains_start));
            let first = run(&mut chains, &mut base, span, &rescale, &mut snapshots);
            (done, interrupted) = (first.done, first.interrupted);
            span = crate::integrator::metropolis::ChainSpan { done, until: None };
            let now = start.elapsed().as_secs_f64();
            time_left = now < t;
            let chain_halves = direct_balance::chain_halves(&first.groups, done, chains.len());
            if let Some(chain_halves) = chain_halves.filter(|_| !interrupted && time_left && done > 0) {
                let measured = Measurement {
                    halves: &halves,
                    chain_halves: &chain_halves,
                    done,
                    seconds: (now - chains_start, t - now),
                };
                let (b, c) = balance(scene, opts, &key, &mut light, &measured, &mut base, &mut rescale)?;
                counters += c;
                stats.direct_balance = Some(b);
                stats.direct_samples = light.samples;
                stats.direct_seconds = light.seconds;
            }
        }
        if !interrupted && time_left {
            let rest = run(&mut chains, &mut base, span, &rescale, &mut snapshots);
            (done, interrupted) = (rest.done, rest.interrupted);
        }
    }
    let longest = crate::integrator::metropolis::stays::longest(chains.iter().map(|c| &c.stays));
    tally(&chains, &mut counters, &mut stats);
    let seconds = start.elapsed().as_secs_f64();
    stats.mutations_per_second = done as f64 / (seconds - stats.bootstrap_seconds).max(1e-9);
    // What one mutation's splat carries around the longest stay's pixel.
    let b_there = b * importance.map_or(1.0, |m| m.pixel(longest.pixel) as f64);
    finish(
        scene,
        opts,
        threads,
        base,
        stats,
        counters,
        start,
        snapshots,
        interrupted,
        done,
        iterations,
        (longest, b_there),
        rescale,
    )
}

/// The chains' work into `counters`, and their manifold walks and mutations proposed and
/// accepted into `stats`.
fn tally(chains: &[Chain], counters: &mut Counters, stats: &mut MemltStats) {
    let mut proposed = [0u64; Mutator::ALL.len()];
    let mut accepted = [0u64; Mutator::ALL.len()];
    for ch in chains {
        *counters += ch.counters;
        stats.manifold_walks += ch.walks;
        for m in 0..Mutator::ALL.len() {
            proposed[m] += ch.proposed[m];
            accepted[m] += ch.accepted[m];
        }
    }
    stats.mutators = Mutator::ALL
        .iter()
        .map(|&m| {
            let (p, a) = (proposed[m as usize], accepted[m as usize]);
            MutatorStats {
                mutator: m,
                proposed: p,
                accepted: a,
                acceptance: if p == 0 { 0.0 } else { a as f64 / p as f64 },
            }
        })
        .collect();
}

/// The render's output: the film (direct light and the chains' splats over `done`
/// mutations) developed, with the statistics.
#[allow(clippy::too_many_arguments)]
fn finish(
    scene: &Scene,
    opts: &RunOptions,
    threads: usize,
    mut film: Film,
    mut stats: MemltStats,
    counters: Counters,
    start: Instant,
    snapshots: Vec<crate::integrator::run::Snapshot>,
    interrupted: bool,
    done: u64,
    iterations: Option<std::ops::Range<u32>>,
    (longest, b): (Stay, f64),
    rescale: Option<(Vec<Rgb>, f64)>,
) -> Result<RenderOutput, crate::error::Error> {
    let (w, h) = (scene.film.width, scene.film.height);
    let pixels = w as u64 * h as u64;
    film.light_paths = done;
    stats.mutations = done;
    let seconds = start.elapsed().as_secs_f64();
    let spp = (done / pixels) as u32;
    let (image, s) = developed(&film, rescale.as_ref().filter(|_| done > 0));
    stats.longest_stay = LongestStay::measure(longest, &image, (w, h), b * s, done);
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
        Details::of(MemltDetails { memlt: stats }),
    ))
}

impl Integrator for MemltOptions {
    const BIDIRECTIONAL: bool = false;
    const ITERATIVE: bool = false;
    const MEDIA: bool = true;

    fn render(&self, scene: &Scene, opts: &RunOptions, iterations: Iterations) -> Rendered {
        media::check(scene)?;
        render(scene, opts, self, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut crate::integrator::bidir::mis::Heuristic> {
        Some(&mut self.heuristic)
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_media;
