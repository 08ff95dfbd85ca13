//! The estimator a Metropolis render's chains drive, and the independent samples PSSMLT and
//! MEMLT take of it before their chains (contract §6; `memlt.md`): the bootstrap that
//! estimates the normalisation `b` (the mean luminance of the paths the chains take), and
//! two-stage Metropolis' first stage, which maps that luminance over the image
//! ([`crate::integrator::metropolis::two_stage`]).
//!
//! A sample is one run of the BDPT estimator (or the path tracer, for PSSMLT over it) on a
//! [`PrimarySampler`]'s numbers through a uniformly random film position; [`Contributions`]
//! collects what it adds to the film, restricted to the paths the chains take
//! ([`ChainPaths`]: MEMLT leaves the direct light and the specular pass's paths to passes of
//! their own), with its scalar contribution. Samples run in parallel in fixed chunks, each
//! from its own stream, so every figure here is independent of the thread count.

use crate::film::Splat;
use crate::integrator::bidir::bdpt::{Bdpt, Connector, Scratch};
use crate::integrator::bidir::mis::{Counts, Heuristic};
use crate::integrator::bidir::walk::WalkLimits;
use crate::integrator::bidir::{Sink, Vertex};
use crate::integrator::metropolis::primary::PrimarySampler;
use crate::integrator::metropolis::two_stage::{Grid, Importance};
use crate::integrator::metropolis::{ChainOptions, MltBase};
use crate::integrator::run::{Budget, RunOptions};
use crate::integrator::stats::Counters;
use crate::math::{Rgb, luminance};
use crate::sampling::Random;
use crate::scene::Scene;
use glam::Vec2;
use rayon::prelude::*;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// A render's streams: `key(stream, i)` (the seed, the stream, and a distributed render's
/// chunk).
pub type Keys<'a> = &'a (dyn Fn(u64, u64) -> Vec<u64> + Sync);

/// The paths a Metropolis render's chains take (and its bootstrap counts) beside the passes
/// that render the others (MEMLT's direct-light and specular passes).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ChainPaths {
    /// Paths of fewer edges are left out ...
    pub min_edges: usize,
    /// ... but for two-edge paths whose middle vertex scatters through a Dirac lobe, when
    /// this is set (MEMLT's chains beside a direct-light pass that leaves those out).
    pub dirac_two_edges: bool,
    /// Paths of two edges or more that scatter through Dirac lobes alone count (not beside a
    /// specular pass).
    pub dirac_only: bool,
}

impl ChainPaths {
    /// Every path.
    pub const ALL: ChainPaths = ChainPaths { min_edges: 0, dirac_two_edges: false, dirac_only: true };
}

impl Default for ChainPaths {
    fn default() -> ChainPaths {
        ChainPaths::ALL
    }
}

/// What one state adds to the film, with its scalar contribution.
#[derive(Default)]
pub(crate) struct Contributions<'a> {
    pub(crate) splats: Vec<Splat>,
    /// Camera-side contributions of the current sample, summed at its film position.
    pixel: Rgb,
    pub(crate) pos: Vec2,
    /// The paths whose strategies count.
    paths: ChainPaths,
    /// Two-stage Metropolis: the first stage's map, which each splat's luminance is
    /// divided by in the scalar contribution.
    importance: Option<&'a Importance>,
    /// The plain sum of luminances of the last [`Contributions::finish`].
    pub(crate) luminance: f32,
}

impl Sink for Contributions<'_> {
    #[inline]
    fn add(&mut self, s: usize, t: usize, value: Rgb) {
        if s + t > self.paths.min_edges {
            self.pixel += value;
        }
    }

    #[inline]
    fn splat(&mut self, s: usize, t: usize, pos: Vec2, value: Rgb) {
        if s + t > self.paths.min_edges {
            self.splats.push(Splat { pos, value, layer: 0 });
        }
    }

    #[inline]
    fn add_emission(&mut self, camera: &[Vertex], value: Rgb) {
        // Only the camera walk finds a path whose every scattering is through a Dirac lobe.
        // (Looked at only where those paths are left out: PSSMLT counts every path.)
        if !self.paths.dirac_only && camera.len() > 2 && camera[1..camera.len() - 1].iter().all(|v| v.delta) {
            return;
        }
        if self.paths.dirac_two_edges && camera.len() == 3 && camera[1].delta {
            self.pixel += value;
        } else {
            self.add(0, camera.len(), value);
        }
    }
}

impl<'a> Contributions<'a> {
    /// Collects the contributions of `paths`, with the first stage's map `importance` in
    /// two-stage Metropolis.
    pub(crate) fn new(paths: ChainPaths, importance: Option<&'a Importance>) -> Contributions<'a> {
        Contributions { paths, importance, ..Default::default() }
    }

    /// Moves the pixel's sum into the splat list; returns the sum of luminances (each over
    /// the first stage's map at its position, in two-stage Metropolis).
    fn finish(&mut self) -> f32 {
        if self.pixel != Rgb::ZERO {
            self.splats.push(Splat { pos: self.pos, value: self.pixel, layer: 0 });
        }
        self.pixel = Rgb::ZERO;
        let (plain, f) = match self.importance {
            None => {
                let plain: f32 = self.splats.iter().map(|s| luminance(s.value).max(0.0)).sum();
                (plain, plain)
            }
            Some(m) => self.splats.iter().fold((0.0f32, 0.0f32), |(plain, f), s| {
                let l = luminance(s.value).max(0.0);
                (plain + l, f + l / m.at(s.pos))
            }),
        };
        self.luminance = if plain.is_finite() { plain } else { 0.0 };
        if f.is_finite() { f } else { 0.0 }
    }
}

pub(crate) struct Evaluator<'a> {
    scene: &'a Scene,
    base: MltBase,
    bdpt: Bdpt,
    path: crate::integrator::path::PathTracer,
    heuristic: Heuristic,
}

impl Evaluator<'_> {
    /// Runs the estimator on the sampler's state, filling `out`; returns its contribution.
    pub(crate) fn eval(
        &self,
        rng: &mut PrimarySampler,
        scratch: &mut Scratch,
        out: &mut Contributions,
        c: &mut Counters,
    ) -> f32 {
        let scene = self.scene;
        out.splats.clear();
        out.pixel = Rgb::ZERO;
        rng.start_stream(0);
        let res = Vec2::new(scene.film.width as f32, scene.film.height as f32);
        out.pos = rng.next_2d() * res;
        c.samples += 1;
        match self.base {
            MltBase::Bdpt => {
                let conn = Connector::new(scene, self.heuristic, &Counts::Bdpt);
                self.bdpt.sample(&conn, out.pos, rng, scratch, out, c);
            }
            MltBase::Path => {
                let ray = scene.camera.generate_ray(out.pos);
                out.pixel = c.camera_path(|c| self.path.radiance(scene, ray, rng, c));
            }
        }
        out.finish()
    }
}

/// Runs `n` independent samples of the estimator in parallel, in chunks of 1024: sample
/// `i` a large step of `rng(i)`, its contributions in `out()`'s. Each chunk folds its
/// samples, in order, into an accumulator from `init` with `add` (the sample's scalar
/// contribution and its contributions). The accumulators in chunk order, and the work.
fn sample_chunks<'a, T: Send>(
    pool: &rayon::ThreadPool,
    ev: &Evaluator,
    n: usize,
    out: &(dyn Fn() -> Contributions<'a> + Sync),
    rng: &(dyn Fn(u64) -> PrimarySampler + Sync),
    init: impl Fn() -> T + Sync,
    add: impl Fn(&mut T, f32, &Contributions) + Sync,
) -> (Vec<T>, Counters) {
    let chunk = 1024usize;
    let parts: Vec<(T, Counters)> = pool.install(|| {
        (0..n.div_ceil(chunk))
            .into_par_iter()
            .map(|k| {
                let mut scratch = Scratch::default();
                let mut contributions = out();
                let mut c = Counters::default();
                let mut acc = init();
                for i in k * chunk..((k + 1) * chunk).min(n) {
                    let mut rng = rng(i as u64);
                    rng.start_iteration(true);
                    let f = ev.eval(&mut rng, &mut scratch, &mut contributions, &mut c);
                    add(&mut acc, f, &contributions);
                }
                (acc, c)
            })
            .collect()
    });
    let mut counters = Counters::default();
    let accs = parts
        .into_iter()
        .map(|(acc, c)| {
            counters += c;
            acc
        })
        .collect();
    (accs, counters)
}

/// Runs `n` independent samples of the estimator (large steps from the streams
/// `key(BOOTSTRAP_STREAM, i)`), in parallel; their scalar contributions in order (over the
/// first stage's map where there is one) and, with a map, their plain luminances (else
/// none: the scalar contributions are those).
pub(crate) fn bootstrap(
    pool: &rayon::ThreadPool,
    ev: &Evaluator,
    n: usize,
    large_step_prob: f32,
    paths: ChainPaths,
    importance: Option<&Importance>,
    key: Keys,
) -> (Vec<f32>, Vec<f32>, Counters) {
    let (parts, counters) = sample_chunks(
        pool,
        ev,
        n,
        &|| Contributions::new(paths, importance),
        &|i| PrimarySampler::new(&key(BOOTSTRAP_STREAM, i), large_step_prob),
        Vec::new,
        |fs: &mut Vec<(f32, f32)>, f, out| fs.push((f, out.luminance)),
    );
    let mut weights = Vec::with_capacity(n);
    let mut luminances = Vec::with_capacity(if importance.is_some() { n } else { 0 });
    for fs in parts {
        weights.extend(fs.iter().map(|p| p.0));
        if importance.is_some() {
            luminances.extend(fs.iter().map(|p| p.1));
        }
    }
    (weights, luminances, counters)
}

/// Mean and standard error of samples.
pub(crate) fn mean_and_error(xs: &[f32]) -> (f64, f64) {
    let n = xs.len().max(1) as f64;
    let mean = xs.iter().map(|&f| f as f64).sum::<f64>() / n;
    let square = xs.iter().map(|&f| f as f64 * f as f64).sum::<f64>() / n;
    (mean, ((square - mean * mean).max(0.0) / n).sqrt())
}

/// The mean luminance of the image's `paths` (Metropolis' normalisation `b`; with a first
/// stage's map, the mean of luminance over the map) estimated from `n` independent BDPT
/// samples, each through a uniformly random film position, with its standard error; the
/// same samples' mean luminance with its standard error (the same as the first without a
/// map); and the work the samples took.
pub(crate) fn bdpt_normalisation(
    scene: &Scene,
    heuristic: Heuristic,
    pool: &rayon::ThreadPool,
    n: usize,
    paths: ChainPaths,
    importance: Option<&Importance>,
    key: Keys,
) -> ((f64, f64), (f64, f64), Counters) {
    let ev = evaluator(scene, heuristic, MltBase::Bdpt);
    let (weights, luminances, counters) = bootstrap(pool, &ev, n, 1.0, paths, importance, key);
    let target = mean_and_error(&weights);
    let plain = if importance.is_some() { mean_and_error(&luminances) } else { target };
    (target, plain, counters)
}

/// Two-stage Metropolis' first stage: batches of `n` independent BDPT samples (the streams
/// `key(FIRST_STAGE_STREAM, i)`, each through a uniformly random film position), more of
/// them with a time budget until `fraction` of it has passed since `start` (one batch at
/// least), their luminance summed over the cells of the first stage's grid: the map (`None`
/// when they found no light), the samples and their work.
#[allow(clippy::too_many_arguments)]
pub(crate) fn first_stage(
    scene: &Scene,
    opts: &RunOptions,
    pool: &rayon::ThreadPool,
    (heuristic, chain): (Heuristic, &ChainOptions),
    paths: ChainPaths,
    start: Instant,
    fraction: f64,
    key: Keys,
) -> (Option<Importance>, u64, Counters) {
    let n = chain.bootstrap;
    let grid = Grid::new(scene.film.width, scene.film.height, chain.first_stage_reduction);
    let ev = evaluator(scene, heuristic, MltBase::Bdpt);
    let mut sums = vec![0.0f64; grid.len()];
    let mut counters = Counters::default();
    let batches = in_batches(opts, start, fraction, |batch| {
        let offset = batch * n as u64;
        let (parts, c) = sample_chunks(
            pool,
            &ev,
            n,
            &|| Contributions::new(paths, None),
            &|i| PrimarySampler::new(&key(FIRST_STAGE_STREAM, i + offset), 1.0),
            || vec![0.0f64; grid.len()],
            |cells, f, out| {
                if f > 0.0 {
                    for s in &out.splats {
                        let l = luminance(s.value) as f64;
                        if l.is_finite() && l > 0.0 {
                            cells[grid.cell_of(s.pos)] += l;
                        }
                    }
                }
            },
        );
        for part in parts {
            for (s, p) in sums.iter_mut().zip(part) {
                *s += p;
            }
        }
        counters += c;
    });
    let samples = batches * n as u64;
    (Importance::from_cells(grid, &sums, samples), samples, counters)
}

/// Runs `batch(0)`, `batch(1)`, … : one batch, and with a time budget more until `fraction`
/// of it has passed since `start` (or the render is stopped). The number of batches.
pub(crate) fn in_batches(opts: &RunOptions, start: Instant, fraction: f64, mut batch: impl FnMut(u64)) -> u64 {
    let until = match opts.budget {
        Budget::Time(t) => t * fraction,
        Budget::Spp(_) => 0.0,
    };
    let stopped = || opts.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst));
    let mut batches = 0u64;
    while batches == 0 || (start.elapsed().as_secs_f64() < until && !stopped()) {
        batch(batches);
        batches += 1;
    }
    batches
}

/// The estimator the chains drive, with the scene's depth limits.
pub(crate) fn evaluator<'a>(scene: &'a Scene, heuristic: Heuristic, base: MltBase) -> Evaluator<'a> {
    let spec = &scene.integrator;
    let max_depth = if spec.max_depth < 0 { u32::MAX } else { spec.max_depth as u32 };
    Evaluator {
        scene,
        base,
        bdpt: Bdpt {
            limits: WalkLimits::new(max_depth, spec.rr_depth),
            max_depth,
            hide_emitters: spec.hide_emitters,
            light_only: false,
        },
        path: crate::integrator::path::PathTracer::new(spec),
        heuristic,
    }
}

pub(crate) const BOOTSTRAP_STREAM: u64 = 0x626f_6f74;
const FIRST_STAGE_STREAM: u64 = 0x6669_7273;
