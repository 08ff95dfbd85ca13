//! Subspace-based probabilistic connections (SPCBPT; Su, Li and Wang, ACM TOG 41(4), 2022),
//! on PCBPT's light pool and connection pass ([`PoolPass`]).
//!
//! Instead of a PMF over every pool vertex per cache record, SPCBPT bins vertices into
//! subspaces and keeps one small matrix:
//!
//! 1. **Subspaces.** Two k-d trees over position and normal ([`SubspaceTree`]), built once
//!    before the first iteration from a pilot's vertices (camera vertices of a grid of pixels
//!    for the eye subspaces, a pilot pool for the light subspaces), `--sp-eye-subspaces` and
//!    `--sp-light-subspaces` leaves.
//! 2. **Selection.** A camera vertex of eye subspace `i` draws a light subspace `j` from row
//!    `i` of `Γ`, then a pool vertex `y` of `j` with `P(y | j)` proportional to its flux (with
//!    a uniform share, [`LightSubspaces`]): `P(y | z) = Γ_ij P(y | j)`, and the connection
//!    weighs `1 / (N M P(y | z))`.
//! 3. **Training.** `Γ` is uniform in iteration 0; after each of the first
//!    `--sp-training-iterations` iterations it is fitted to all their connections by the
//!    MIS-aware variance objective ([`Matrix::train`]), mixed with `--sp-uniform` of the
//!    uniform distribution. From then on the state is fixed: `Γ`, and what the MIS counts take
//!    from the last training iteration, so a chunk of a distributed render re-runs at most
//!    the training iterations and the one after them.
//! 4. **Budget** (`--pc-budget auto`, [`crate::integrator::budget`]). It measures the last two training
//!    iterations (`--sp-budget-in-training`; `false`: the two after training), their
//!    training samples kept as in any other ([`TrainingSampler`], carried in the tile's
//!    moments), and chooses once `Γ` is trained: where it takes path tracing, only the
//!    training iterations render with connections before the choice (four by default, not
//!    six).
//!
//! MIS counts (`--sp-mis`, as PCBPT's `--pc-mis`): `N / V̄` (uniform), `N κ_t / V̄`
//! (harmonic, `κ_t` measured on the previous iteration's unoccluded draws), `N M P(y | z)`
//! (resampling: the selection density itself, evaluated on the path with the frozen `Γ` and
//! the previous pool's per-path subspace totals, so that it is a function of the path alone;
//! the current pool's totals would make a connection's weight depend on the pool that holds
//! its own light vertex), `N M Γ_ij / V_j` (subspace: the same with the draw within the light
//! subspace taken as uniform, which needs no light throughputs), or harmonic corrected for
//! correlation. The two counts that follow the path's subspaces classify two vertices for
//! every strategy of every weighed path; the camera subpath's and the pool's vertices are
//! labelled with their subspaces once instead ([`Model::label`]).

mod options;
pub mod subspace;
pub use options::*;

use crate::error::Error;
use crate::film::Tile;
use crate::integrator::bidir::bdpt::{Bdpt, Connector};
use crate::integrator::bidir::mis::{Counts, FullPath, Heuristic, StrategyCounts};
use crate::integrator::bidir::pool::{
    CONCENTRATION_DEPTHS, LightPool, PILOT_ITERATION, PoolCounters, PoolSelection, concentration_depth,
    pass_concentration,
};
use crate::integrator::bidir::{Delivery, Sink, Vertex};
use crate::integrator::budget::{
    Budget, BudgetMode, BudgetStats, CameraSample, Operations, Plan, PoolTile, SplatShares, TracedPool, pool_tile,
};
use crate::integrator::pcbpt::Correlation;
use crate::integrator::pcbpt::cache::{Record, trace_records};
use crate::integrator::pcbpt::{PcMis, PcOptions, connection_counts, fill_counts, light_throughputs, throughput_at};
use crate::integrator::pool_base::{PoolBase, PoolStats};
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Warmup, Work};
use crate::integrator::run::RunOptions;
use crate::integrator::run::{Integrator, Iterations, Rendered};
use crate::integrator::spcbpt::subspace::{
    FEATURES, LightSubspaces, Matrix, SubspaceTree, TrainingSample, features, within_probability,
};
use crate::integrator::stats::{Counters, Details, IntegratorStats, RenderStats};
use crate::math::{Rgb, luminance};
use crate::sampling::{Random, Sampler};
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use serde::Serialize;
use std::ops::Range;
use std::time::Instant;

/// SPCBPT's statistics.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct SubspaceStats {
    pub eye_subspaces: usize,
    pub light_subspaces: usize,
    /// Rows of `Γ` fitted to training connections.
    pub trained_rows: usize,
    /// Light subspaces holding a vertex of the last pool.
    pub light_subspaces_used: usize,
    /// Training connections kept.
    pub training_samples: usize,
    /// Seconds spent building the trees and training `Γ`.
    pub training_seconds: f64,
    /// The matrix and the trees, in MiB.
    pub megabytes: f64,
}

/// The subspaces and `Γ`.
pub struct Model {
    pub eye: SubspaceTree,
    pub light: SubspaceTree,
    pub matrix: Matrix,
}

impl Model {
    /// Trees of up to `eye` and `light` leaves over the features of camera vertices
    /// `eye_vertices` and of the connectible vertices of `pool`; `Γ` uniform.
    pub fn new(scene: &Scene, eye_vertices: &[Record], pool: &LightPool, eye: usize, light: usize) -> Model {
        let eye_points: Vec<_> = eye_vertices.iter().map(|r| features(scene, &r.vertex, r.vertex.wo)).collect();
        let light_points: Vec<_> = (0..pool.connectible.len())
            .map(|k| {
                let prefix = pool.prefix(k);
                let y = &prefix[prefix.len() - 1];
                features(scene, y, light_towards(y, &prefix[prefix.len() - 2]))
            })
            .collect();
        let eye = SubspaceTree::build(eye_points, eye);
        let light = SubspaceTree::build(light_points, light);
        let matrix = Matrix::uniform(eye.len(), light.len());
        Model { eye, light, matrix }
    }

    /// The pool's connectible vertices by light subspace, with their flux.
    pub fn sort_pool(&self, scene: &Scene, pool: &LightPool) -> LightSubspaces {
        let mut alpha = Vec::new();
        let mut flux = Vec::with_capacity(pool.connectible.len());
        let mut subspace = Vec::with_capacity(pool.connectible.len());
        let mut path = usize::MAX;
        for &g in &pool.connectible {
            let g = g as usize;
            let start = pool.path_start[g] as usize;
            if start != path {
                // The throughputs of the whole path, once.
                path = start;
                let end = (start..pool.vertices.len())
                    .find(|&k| pool.path_start[k] as usize != start)
                    .unwrap_or(pool.vertices.len());
                let verts = &pool.vertices[start..end];
                alpha.clear();
                alpha.resize(verts.len(), Rgb::ZERO);
                light_throughputs(scene, &FullPath { light: verts, camera: &[] }, &mut alpha);
            }
            flux.push(luminance(alpha[g - start]).max(0.0));
            subspace.push(self.light_subspace(scene, &pool.vertices[start..=g]) as u32);
        }
        LightSubspaces::new(self.light.len(), &subspace, flux)
    }

    /// Labels `v` with its eye and light subspaces for either side of its shading normal
    /// ([`Vertex::label`]), so that the path-dependent MIS counts, which classify every
    /// vertex of a path for each of its strategies, read them instead.
    pub fn label(&self, scene: &Scene, v: &mut Vertex) {
        let n = v.frame.n;
        let f = [features(scene, v, n), features(scene, v, -n)];
        let class = |tree: &SubspaceTree, f: &[f32; FEATURES]| tree.classify(f) as u16;
        v.label = Some([
            class(&self.eye, &f[0]),
            class(&self.eye, &f[1]),
            class(&self.light, &f[0]),
            class(&self.light, &f[1]),
        ]);
    }

    /// Labels the connectible surface vertices of `vertices` ([`Model::label`]): no count
    /// asks for another's subspaces (an endpoint's, a purely specular vertex's), and one
    /// that did would classify it itself.
    pub fn label_connectible(&self, scene: &Scene, vertices: &mut [Vertex]) {
        for v in vertices.iter_mut().filter(|v| v.scatters() && v.is_connectible()) {
            self.label(scene, v);
        }
    }

    /// The subspace in `tree` (0: eye, 1: light) of `v` with its normal turned towards
    /// `towards`: the label where `v` has one, else the tree's descent.
    /// (Always inlined: called with `towards` through memory, the call waited for it.)
    #[inline(always)]
    fn class(&self, scene: &Scene, tree: usize, v: &Vertex, towards: Vec3) -> usize {
        match v.label {
            Some(c) => c[2 * tree + usize::from(v.frame.n.dot(towards) < 0.0)] as usize,
            None => self.classify(scene, tree, v, towards),
        }
    }

    /// The tree's descent for [`Model::class`], out of line.
    #[inline(never)]
    fn classify(&self, scene: &Scene, tree: usize, v: &Vertex, towards: Vec3) -> usize {
        [&self.eye, &self.light][tree].classify(&features(scene, v, towards))
    }

    /// The eye subspace of camera vertex `z`, its normal turned towards its walk's
    /// previous vertex.
    #[inline]
    pub fn eye_subspace(&self, scene: &Scene, z: &Vertex) -> usize {
        self.class(scene, 0, z, z.wo)
    }

    /// The light subspace of the last vertex of a light subpath `y_0..y_{s-1}` (`s >= 2`).
    #[inline]
    pub fn light_subspace(&self, scene: &Scene, light: &[Vertex]) -> usize {
        let s = light.len();
        self.light_class(scene, &light[s - 1], &light[s - 2])
    }

    /// The light subspace of light vertex `y` whose predecessor is `prev`.
    #[inline(always)]
    fn light_class(&self, scene: &Scene, y: &Vertex, prev: &Vertex) -> usize {
        self.class(scene, 1, y, light_towards(y, prev))
    }

    /// The eye subspace of eye vertex `z` whose successor towards the camera is `next`.
    #[inline(always)]
    fn eye_class(&self, scene: &Scene, z: &Vertex, next: &Vertex) -> usize {
        self.class(scene, 0, z, next.p - z.p)
    }

    fn megabytes(&self) -> f64 {
        (self.matrix.bytes() + self.eye.bytes() + self.light.bytes()) as f64 / (1024.0 * 1024.0)
    }
}

/// Where light vertex `y` whose predecessor is `prev` turns its normal for its features:
/// towards `prev` from their positions (or towards a light at infinity's direction), so
/// that a path's strategies classify the vertex the same way whichever walk made it.
#[inline]
fn light_towards(y: &Vertex, prev: &Vertex) -> Vec3 {
    if prev.at_infinity() { prev.ng } else { prev.p - y.p }
}

/// What the MIS counts of an iteration take from the one before (and, after training, from
/// the last training iteration for good).
#[derive(Clone, Debug)]
pub struct Measured {
    /// `V̄`.
    pub vbar: f32,
    /// `κ` by camera depth.
    pub concentration: [f32; CONCENTRATION_DEPTHS],
    /// `Q_j / M` of the pool.
    flux: Vec<f64>,
    /// `V_j / M` of the pool.
    vertices: Vec<f64>,
    /// `M / V_j` (zero for an empty subspace).
    per_vertex: Vec<f64>,
}

impl Measured {
    /// What pool `subspaces` of `paths` light paths gives, with the concentration
    /// `concentration` of its draws.
    pub fn of_pool(
        subspaces: &LightSubspaces,
        paths: usize,
        vbar: f32,
        concentration: [f32; CONCENTRATION_DEPTHS],
    ) -> Measured {
        let m = paths.max(1) as f64;
        let vertices: Vec<f64> = (0..subspaces.totals.len()).map(|j| subspaces.count(j) as f64 / m).collect();
        Measured {
            vbar,
            concentration,
            flux: subspaces.totals.iter().map(|q| q / m).collect(),
            per_vertex: vertices.iter().map(|&v| if v > 0.0 { 1.0 / v } else { 0.0 }).collect(),
            vertices,
        }
    }
}

/// SPCBPT's strategy counts, relative to one camera sample per pixel: `M/(W·H)` for light
/// tracing, 1 for `s = 0` and NEE, and for pool connections `N / V̄`, `N κ_t / V̄`,
/// `N M P(y | z)` or `N M Γ_ij / V_j` (see the module documentation).
pub struct SpCounts<'a> {
    scene: &'a Scene,
    light_trace: f32,
    connect: [f32; CONCENTRATION_DEPTHS],
    connections: f32,
    /// The model and the per-path subspace totals, for the counts that follow the path's
    /// subspaces (resampling and subspace), and which of the two.
    resampling: Option<(&'a Model, &'a Measured, Within)>,
    correlation: Option<Correlation>,
}

/// What the path-dependent counts take for the draw within the light subspace `j`: the
/// draw's own `P(y | j)` (resampling), or `1 / V_j`, as if it were uniform over the
/// subspace's vertices (subspace), which needs no light throughput.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Within {
    Flux,
    Uniform,
}

impl<'a> SpCounts<'a> {
    /// The counts of an iteration with `m` light paths and `n` connections per camera
    /// vertex, from what the previous iteration measured and the model.
    pub fn for_iteration(
        scene: &'a Scene,
        mis: PcMis,
        n: u32,
        m: usize,
        measured: &'a Measured,
        model: &'a Model,
    ) -> SpCounts<'a> {
        let pixels = scene.film.width as f32 * scene.film.height as f32;
        let n = n as f32;
        let connect = connection_counts(mis, n, measured.vbar, &measured.concentration);
        SpCounts {
            scene,
            light_trace: m as f32 / pixels,
            connect,
            connections: n,
            // Without connections their counts are all zero, whatever the path.
            resampling: match mis {
                _ if n == 0.0 => None,
                PcMis::Resampling => Some((model, measured, Within::Flux)),
                PcMis::Subspace => Some((model, measured, Within::Uniform)),
                _ => None,
            },
            correlation: (mis == PcMis::Correlated).then_some(Correlation { pixels, connections: n }),
        }
    }

    /// `N M P(y | z)` (or `N M Γ_ij / V_j`) of the pool connection `s` of `path`, `alpha`
    /// the light throughput at `y_{s-1}` (asked only for `P(y | z)`).
    #[inline]
    fn selection(
        &self,
        (model, measured, within): (&Model, &Measured, Within),
        path: &FullPath,
        s: usize,
        alpha: impl FnOnce() -> Rgb,
    ) -> f32 {
        let scene = self.scene;
        let (y, z) = (path.get(s - 1), path.get(s));
        let i = model.eye_class(scene, z, path.get(s + 1));
        let j = model.light_class(scene, y, path.get(s - 2));
        // `M P(y | j)` or `M / V_j`.
        let within = match within {
            Within::Flux => {
                within_probability(luminance(alpha()).max(0.0) as f64, measured.flux[j], measured.vertices[j])
            }
            Within::Uniform => measured.per_vertex[j],
        };
        (self.connections as f64 * model.matrix.gamma(i, j) as f64 * within) as f32
    }
}

impl SpCounts<'_> {
    /// `n(s,t)`; `alpha` gives the light throughput at `y_{s-1}` (asked only for resampling).
    #[inline]
    fn count_with(&self, path: &FullPath, s: usize, t: usize, alpha: impl FnOnce() -> Rgb) -> f32 {
        match (s, t) {
            (_, 1) => self.light_trace,
            (0 | 1, _) => 1.0,
            _ => match self.resampling {
                None => self.connect[concentration_depth(t)],
                Some(r) => self.selection(r, path, s, alpha),
            },
        }
    }

    /// Whether the counts follow the path's subspaces, so that its vertices are best
    /// labelled with them ([`Model::label`]).
    pub fn labels(&self) -> bool {
        self.resampling.is_some()
    }
}

impl StrategyCounts for SpCounts<'_> {
    fn count(&self, path: &FullPath, s: usize, t: usize) -> f32 {
        self.count_with(path, s, t, || throughput_at(self.scene, path, s))
    }

    fn path_dependent(&self) -> bool {
        self.resampling.is_some()
    }

    fn density_dependent(&self) -> bool {
        self.correlation.is_some()
    }

    fn density_factors(&self, n: usize, pl: impl Fn(usize) -> f32, pe: impl Fn(usize) -> f32, out: &mut [f32]) {
        if let Some(c) = self.correlation {
            c.factors(n, pl, pe, out);
        }
    }

    /// Counts of a whole path with one pass for the light throughputs.
    fn fill(&self, path: &FullPath, needed: &dyn Fn(usize) -> bool, out: &mut [f32]) {
        let throughputs = matches!(self.resampling, Some((_, _, Within::Flux)));
        fill_counts(self.scene, path, needed, out, throughputs, |s, t, alpha| {
            self.count_with(path, s, t, || alpha[s - 1])
        });
    }
}

/// The draw of pool vertices for a camera vertex: a light subspace from `Γ`'s row, then a
/// vertex within it.
struct SubspaceSelection<'a> {
    scene: &'a Scene,
    model: &'a Model,
    subspaces: &'a LightSubspaces,
    paths: f64,
    /// Whether camera vertices are labelled with their subspaces (for counts that follow
    /// them).
    label: bool,
}

impl PoolSelection for SubspaceSelection<'_> {
    type Lookup = usize;

    fn lookup(&self, z: &Vertex) -> usize {
        self.model.eye_subspace(self.scene, z)
    }

    fn label(&self, camera: &mut [Vertex]) {
        if self.label {
            self.model.label_connectible(self.scene, camera);
        }
    }

    #[inline]
    fn draw<R: Random>(&self, &i: &usize, k: u32, n: u32, rng: &mut R) -> Option<(usize, f32)> {
        let u = ((k as f32 + rng.next_1d()) / n as f32).min(crate::sampling::ONE_BELOW);
        let (j, gamma) = self.model.matrix.draw(i, u);
        let (y, within) = self.subspaces.draw(j, rng.next_2d())?;
        let p = gamma as f64 * within;
        (p > 0.0).then(|| (1.0 / (n as f64 * self.paths * p)) as f32).map(|f| (y, f))
    }
}

/// A sink that keeps the training samples of the pool connections passing through it.
struct TrainingSink<'a, S> {
    inner: &'a mut S,
    scene: &'a Scene,
    model: &'a Model,
    samples: &'a mut Vec<TrainingSample>,
    /// The eye subspace of the camera vertex whose connections are arriving, with its depth:
    /// a sink serves one camera sample, whose vertices' draws arrive together, so each
    /// vertex is classified once, not once per draw.
    eye: Option<(usize, usize)>,
}

impl<S: Sink> Sink for TrainingSink<'_, S> {
    #[inline]
    fn add(&mut self, s: usize, t: usize, value: Rgb) {
        self.inner.add(s, t, value);
    }

    #[inline]
    fn splat(&mut self, s: usize, t: usize, pos: Vec2, value: Rgb) {
        self.inner.splat(s, t, pos, value);
    }

    #[inline]
    fn add_emission(&mut self, camera: &[Vertex], value: Rgb) {
        self.inner.add_emission(camera, value);
    }

    fn add_connection(&mut self, light: &[Vertex], camera: &[Vertex], c: Rgb, w: f32) {
        let f = luminance(c);
        if f > 0.0 && f.is_finite() && w > 0.0 {
            let t = camera.len();
            let i = match self.eye {
                Some((depth, i)) if depth == t => i,
                _ => {
                    let i = self.model.eye_subspace(self.scene, &camera[t - 1]);
                    self.eye = Some((t, i));
                    i
                }
            };
            let j = self.model.light_subspace(self.scene, light);
            let gamma = self.model.matrix.gamma(i, j);
            self.samples.push(TrainingSample { eye: i as u32, light: j as u32, gamma, f2: f * f, w });
        }
        self.inner.add_connection(light, camera, c, w);
    }

    fn observes(&self) -> bool {
        self.inner.observes()
    }

    fn observe<C: StrategyCounts>(&mut self, delivery: &Delivery<'_, C>) {
        self.inner.observe(delivery);
    }
}

/// The camera samples of a training iteration: `inner`'s, with the pool connections of
/// every `every`-th pixel of a film `width` wide kept as training samples.
/// A tile's data: the budget's moments and, in a training iteration, its training samples.
type SpTile = PoolTile<Vec<TrainingSample>>;

struct TrainingSampler<'a, S> {
    inner: S,
    scene: &'a Scene,
    model: &'a Model,
    width: usize,
    every: usize,
    samples: Vec<TrainingSample>,
}

impl<S: CameraSample> CameraSample for TrainingSampler<'_, S> {
    fn sample(&mut self, pos: Vec2, rng: &mut Sampler, sink: &mut impl Sink, counters: &mut Counters) {
        let pixel = pos.y as usize * self.width + pos.x as usize;
        if !pixel.is_multiple_of(self.every) {
            return self.inner.sample(pos, rng, sink, counters);
        }
        let (scene, model) = (self.scene, self.model);
        let mut sink = TrainingSink { inner: sink, scene, model, samples: &mut self.samples, eye: None };
        self.inner.sample(pos, rng, &mut sink, counters);
    }

    type Learned = Vec<TrainingSample>;

    fn learned(&mut self) -> Option<Vec<TrainingSample>> {
        Some(std::mem::take(&mut self.samples))
    }

    fn draws(&mut self) -> PoolCounters {
        self.inner.draws()
    }
}

/// The iterations the budget measures, `iterations` of them: the last training iterations
/// (from the first when there are fewer) with `--sp-budget-in-training`, otherwise those
/// after training.
fn budget_window(o: &SpOptions, iterations: u32) -> Range<u32> {
    let start =
        if o.budget_in_training { o.training_iterations.saturating_sub(iterations) } else { o.training_iterations };
    start..start + iterations
}

/// Training watches every `k`-th pixel of a film of `pixels` pixels: all of them up to
/// [`TRAINING_PIXELS`].
fn training_stride(pixels: usize) -> usize {
    pixels.div_ceil(TRAINING_PIXELS).max(1)
}

/// One iteration's pool and its vertices by light subspace, and what the budget measures of
/// its preparation.
pub struct SpPass {
    pool: LightPool,
    subspaces: LightSubspaces,
    splat_shares: Vec<SplatShares>,
    operations: Operations,
}

/// SPCBPT in the render loop, on the pool integrators' base ([`PoolBase`]): per iteration a
/// light pool sorted by light subspace, then the camera pass with connections drawn by
/// subspace (`SubspaceSelection`); the training iterations keep training samples.
pub struct SpcbptRender {
    pub base: PoolBase,
    pub opts: SpOptions,
    model: Option<Model>,
    measured: Option<Measured>,
    samples: Vec<TrainingSample>,
    stats: SubspaceStats,
    /// Connections and light tracing per iteration (set in `begin`).
    budget: Option<Budget>,
}

impl SpcbptRender {
    /// SPCBPT with options `opts` on `base`, whose light paths are the option's.
    pub fn new(base: PoolBase, opts: SpOptions) -> SpcbptRender {
        SpcbptRender {
            base,
            opts,
            model: None,
            measured: None,
            samples: Vec::new(),
            stats: SubspaceStats::default(),
            budget: None,
        }
    }

    fn counts<'a>(&'a self, scene: &'a Scene) -> SpCounts<'a> {
        let measured = self.measured.as_ref().expect("begin measured the pilot");
        let plan = self.budget().plan();
        SpCounts::for_iteration(scene, self.opts.mis, plan.connections, plan.splat_paths, measured, self.model())
    }

    fn budget(&self) -> &Budget {
        self.budget.as_ref().expect("begin set the budget")
    }

    /// The end of the iterations that change the state: training, the iteration after it,
    /// and the budget's window.
    fn state_end(&self) -> u32 {
        let o = &self.opts;
        match self.opts.budget.mode {
            BudgetMode::Off => o.training_iterations + 1,
            BudgetMode::Auto => (o.training_iterations + 1).max(self.budget().window.end),
        }
    }

    fn model(&self) -> &Model {
        self.model.as_ref().expect("begin built the model")
    }

    /// Whether iteration `i` trains `Γ`.
    fn training(&self, i: u32) -> bool {
        i < self.opts.training_iterations
    }
}

impl Iterative for SpcbptRender {
    type Pass = SpPass;
    type TileData = SpTile;

    /// Sizes the pool from a pilot, checks the memory limits, and builds the subspace trees
    /// from pilot vertices.
    fn begin(&mut self, ctx: &Ctx) -> Result<(), Error> {
        let t = Instant::now();
        let pilot = self.base.pilot(ctx, self.opts.pool.pool_vertices)?;
        let m = self.base.light_paths;
        let o = &self.opts;
        let pc = &o.pool;
        let (scene, limits) = (ctx.scene, &self.base.bdpt.limits);
        let (w, h) = (scene.film.width as usize, scene.film.height as usize);
        // Training keeps at most one sample per connection of every camera vertex it watches.
        let per_iteration = (w * h).min(2 * TRAINING_PIXELS) as f64 * PILOT_DEPTH as f64 * pc.connections as f64;
        let samples_mb = per_iteration * o.training_iterations as f64 * SAMPLE_BYTES / (1024.0 * 1024.0);
        let need = o.matrix_mb() + samples_mb;
        if need > o.max_mb as f64 {
            return Err(Error::Usage(format!(
                "SPCBPT's matrix of {} × {} subspaces ({:.0} MiB) and the training samples of {} iterations (up to {:.0} \
                 MiB) need more than the limit of {} MiB (--sp-max-mb); use fewer subspaces (--sp-eye-subspaces, \
                 --sp-light-subspaces) or training iterations (--sp-training-iterations), or raise the limit",
                o.eye_subspaces,
                o.light_subspaces,
                o.matrix_mb(),
                o.training_iterations,
                samples_mb,
                o.max_mb
            )));
        }
        // The trees: eye vertices of a grid of pixels, light vertices of a larger pilot pool.
        let grid =
            PcOptions { stride: PILOT_STRIDE, cache_depth: PILOT_DEPTH, pool: pc.clone(), ..PcOptions::default() };
        let (records, _) = trace_records(scene, limits, &grid, ctx.seed, PILOT_ITERATION);
        let (light_pilot, _, _) =
            LightPool::trace::<Counts>(scene, limits, m * PILOT_POOLS, ctx.seed, PILOT_ITERATION - 1, None);
        self.model = Some(Model::new(scene, &records, &light_pilot, o.eye_subspaces, o.light_subspaces));
        // The budget measures the last training iterations, or those after `Γ` is trained.
        let plan = Plan { connections: pc.connections, pool_paths: m, splat_paths: m };
        let window = budget_window(o, o.budget.iterations);
        self.budget = Some(Budget::new(&o.budget, o.prices(), window, plan, w, h, ctx.planned_spp));
        let subspaces = self.model().sort_pool(scene, &pilot);
        self.measured =
            Some(Measured::of_pool(&subspaces, pilot.paths, pilot.mean_vertices(), [1.0; CONCENTRATION_DEPTHS]));
        let model = self.model();
        self.stats = SubspaceStats {
            eye_subspaces: model.eye.len(),
            light_subspaces: model.light.len(),
            training_seconds: t.elapsed().as_secs_f64(),
            megabytes: model.megabytes(),
            ..SubspaceStats::default()
        };
        Ok(())
    }

    fn pass_end(&self, first: u32, _: u32) -> u32 {
        first + 1
    }

    /// The state is fixed after the iteration that follows the training iterations and
    /// after the budget's window.
    fn warmup(&self, first: u32) -> Warmup {
        Warmup::new(0..first.min(self.state_end()), true)
    }

    fn prepare(&self, ctx: &Ctx, first: u32, keep: bool, work: &mut Work) -> Prepared<SpPass> {
        let counts = self.counts(ctx.scene);
        let conn = Connector::new(ctx.scene, self.base.heuristic, &counts);
        let traced = self.base.trace(ctx, &conn, Some(self.budget()), first, keep, work);
        let TracedPool { mut pool, splats, counters, splat_shares, operations, splat_paths } = traced;
        let t = Instant::now();
        if counts.labels() {
            self.model().label_connectible(ctx.scene, &mut pool.vertices);
        }
        let subspaces = self.model().sort_pool(ctx.scene, &pool);
        work.phases.cache += t.elapsed().as_secs_f64();
        let pass = SpPass { pool, subspaces, splat_shares, operations };
        Prepared { pass, splats, counters, splat_paths: Some(splat_paths) }
    }

    fn render_tile(&self, ctx: &Ctx, pass: &SpPass, tile: Tile, first: u32, count: u32) -> TileResult<SpTile> {
        let scene = ctx.scene;
        let counts = self.counts(scene);
        let conn = Connector::new(scene, self.base.heuristic, &counts);
        let model = self.model();
        let (subspaces, paths) = (&pass.subspaces, pass.pool.paths.max(1) as f64);
        let select = SubspaceSelection { scene, model, subspaces, paths, label: counts.labels() };
        let budget = self.budget();
        let sampler = self.base.sampler(&conn, &pass.pool, budget.plan().connections, &select);
        if self.training(first) {
            let width = scene.film.width as usize;
            let every = training_stride(width * scene.film.height as usize);
            let sampler = TrainingSampler { inner: sampler, scene, model, width, every, samples: Vec::new() };
            pool_tile(ctx, tile, first, count, budget, sampler)
        } else {
            pool_tile(ctx, tile, first, count, budget, sampler).map(PoolTile::nothing_learned)
        }
    }

    /// Until the state is fixed: keeps the pool's subspace totals and the concentration of
    /// the draws for the next iteration's counts, and retrains `Γ` on every training sample
    /// so far (in tile order).
    fn finish(&mut self, ctx: &Ctx, pass: SpPass, iterations: Range<u32>, results: &[TileResult<SpTile>]) {
        let i = iterations.start;
        self.base.finish(ctx, &pass.pool, &iterations, results.iter().map(|r| &r.data.draws));
        self.stats.light_subspaces_used = pass.subspaces.used();
        let budget = self.budget.as_mut().expect("begin set the budget");
        budget.finish(i, results, &pass.splat_shares, pass.operations);
        if i > self.opts.training_iterations {
            return;
        }
        let previous = self.measured.as_ref().map_or([1.0; CONCENTRATION_DEPTHS], |m| m.concentration);
        let concentration = pass_concentration(results.iter().map(|r| &r.data.draws)).unwrap_or(previous);
        self.measured =
            Some(Measured::of_pool(&pass.subspaces, pass.pool.paths, pass.pool.mean_vertices(), concentration));
        if !self.training(i) {
            return;
        }
        let t = Instant::now();
        for r in results {
            if let Some(s) = &r.data.learned {
                self.samples.extend_from_slice(s);
            }
        }
        let model = self.model.as_mut().expect("begin built the model");
        model.matrix = Matrix::train(model.eye.len(), model.light.len(), &self.samples, self.opts.uniform);
        self.stats.trained_rows = model.matrix.trained_rows;
        self.stats.training_samples = self.samples.len();
        self.stats.training_seconds += t.elapsed().as_secs_f64();
        if i + 1 == self.opts.training_iterations {
            self.samples = Vec::new();
        }
    }

    fn details(&self) -> Details {
        Details::of(SpcbptStats {
            pool: self.base.stats,
            subspaces: self.stats,
            budget: self.budget.as_ref().and_then(Budget::chosen_stats),
        })
    }
}

/// SPCBPT's statistics: the last pool, the subspaces and matrix, the budget's choice.
#[derive(Clone, Debug, Serialize)]
pub struct SpcbptStats {
    pub pool: PoolStats,
    pub subspaces: SubspaceStats,
    /// The budget's choice (`--budget auto`).
    pub budget: Option<BudgetStats>,
}

impl IntegratorStats for SpcbptStats {
    fn lines(&self, _: &RenderStats) -> Vec<String> {
        let mut lines: Vec<String> = self.pool.line().into_iter().collect();
        lines.extend(self.budget.as_ref().and_then(BudgetStats::line));
        let k = &self.subspaces;
        lines.push(format!(
            "  SPCBPT: {} eye × {} light subspaces ({} light subspaces in the last pool), {} trained rows from {} connections, {:.2} s building and training, matrix and trees {:.2} MiB",
            k.eye_subspaces,
            k.light_subspaces,
            k.light_subspaces_used,
            k.trained_rows,
            k.training_samples,
            k.training_seconds,
            k.megabytes
        ));
        lines
    }
}

/// A model over a pool of `m` light paths (seed 3) and the camera vertices of every
/// `stride`-th pixel, with up to `subspaces` eye and light subspaces and `Γ` trained on made-up
/// connections (weights `w(x)` of a made-up contribution `x`), so that its rows are far from
/// uniform; and the pool.
#[cfg(test)]
pub(crate) fn test_model(
    scene: &Scene,
    m: usize,
    stride: u32,
    subspaces: (usize, usize),
    w: impl Fn(f32) -> f32,
) -> (Model, LightPool) {
    let limits = crate::integrator::bidir::walk::WalkLimits::new(8, 3);
    let (pool, _, _) = LightPool::trace::<Counts>(scene, &limits, m, 3, 0, None);
    let grid = PcOptions { stride, ..PcOptions::default() };
    let (records, _) = trace_records(scene, &limits, &grid, 3, 0);
    let mut model = Model::new(scene, &records, &pool, subspaces.0, subspaces.1);
    let (e, l) = (model.eye.len(), model.light.len());
    assert!(e > 4 && l > 8, "{e} eye and {l} light subspaces");
    let samples: Vec<TrainingSample> = (0..e * l)
        .map(|k| {
            let x = ((k * 7919) % 97) as f32 / 97.0;
            let (eye, light) = ((k / l) as u32, (k % l) as u32);
            TrainingSample { eye, light, gamma: 1.0 / l as f32, f2: x.powi(6), w: w(x) }
        })
        .collect();
    model.matrix = Matrix::train(e, l, &samples, 0.1);
    (model, pool)
}

impl Integrator for SpcbptOptions {
    const BIDIRECTIONAL: bool = true;
    const MEDIA: bool = true;

    fn render(&self, scene: &Scene, opts: &RunOptions, iterations: Iterations) -> Rendered {
        self.sp.validate().map_err(Error::Usage)?;
        let (bdpt, pool) = (Bdpt::for_scene(scene, false), &self.sp.pool);
        let base = PoolBase::new(bdpt, self.heuristic, pool.max_pool_mb, pool.light_paths);
        let method = SpcbptRender::new(base, self.sp.clone());
        crate::integrator::render_loop::run(scene, opts, method, true, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
        Some(&mut self.heuristic)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::bidir::pool::draw_one_by_one;
    use crate::integrator::bidir::walk::{WalkLimits, camera_subpath};
    use crate::integrator::pcbpt::cache::tests::scene;
    use crate::integrator::stats::Counters;
    use crate::sampling::Sampler;
    use crate::sampling::chi2::discrete_chi2_of;

    /// A model over a pool of 400 light paths with `Γ` trained on made-up connections, the
    /// pool sorted by subspace, and what it measures.
    fn setup(scene: &Scene) -> (Model, LightPool, LightSubspaces, Measured) {
        let (model, pool) = test_model(scene, 400, 4, (16, 24), |_| 1.0);
        let subspaces = model.sort_pool(scene, &pool);
        let measured = Measured::of_pool(&subspaces, pool.paths, pool.mean_vertices(), [1.0; CONCENTRATION_DEPTHS]);
        (model, pool, subspaces, measured)
    }

    /// The draws over `pool`, its camera vertices unlabelled.
    fn selection<'a>(
        scene: &'a Scene,
        model: &'a Model,
        subspaces: &'a LightSubspaces,
        pool: &LightPool,
    ) -> SubspaceSelection<'a> {
        SubspaceSelection { scene, model, subspaces, paths: pool.paths as f64, label: false }
    }

    /// Camera vertices `z_1, z_2` of a few camera subpaths, with their prefixes.
    fn camera_prefixes(scene: &Scene) -> Vec<Vec<Vertex>> {
        let limits = WalkLimits::new(8, 3);
        let mut out = Vec::new();
        let mut counters = Counters::default();
        for k in 0..40u64 {
            let mut rng = Sampler::new(&[77, k]);
            let pos = Vec2::new(rng.next_1d() * 64.0, rng.next_1d() * 48.0);
            let mut path = Vec::new();
            camera_subpath(scene, pos, &limits, &mut rng, &mut path, &mut counters);
            for t in 2..=path.len().min(3) {
                if path[t - 1].is_connectible() {
                    out.push(path[..t].to_vec());
                }
            }
        }
        assert!(out.len() > 30, "{} camera vertices", out.len());
        out
    }

    #[test]
    fn pool_draws_follow_the_matrix_and_the_flux_chi2() {
        let scene = scene();
        let (model, pool, subspaces, _) = setup(&scene);
        let select = selection(&scene, &model, &subspaces, &pool);
        let v = pool.connectible.len();
        let mut rng = Sampler::new(&[5]);
        let mut tested = 0;
        let cameras = camera_prefixes(&scene);
        const STEP: usize = 6;
        let tests = cameras.len().div_ceil(STEP);
        for camera in cameras.iter().step_by(STEP) {
            let i = select.lookup(&camera[camera.len() - 1]);
            let n = 200_000u32;
            let mut counts = vec![0u64; v];
            draw_one_by_one(&select, &i, n, &mut rng, |k, f| {
                counts[k] += 1;
                // The factor is 1 / (N M P) with P the draw's probability.
                let p = 1.0 / (f as f64 * n as f64 * pool.paths as f64);
                let j = model.light_subspace(&scene, pool.prefix(k));
                let want = model.matrix.gamma(i, j) as f64 * subspaces.within(j, k);
                assert!((p / want - 1.0).abs() < 1e-3, "draw of vertex {k}: probability {p} vs {want}");
            });
            let subspace_of = |k: usize| model.light_subspace(&scene, pool.prefix(k));
            let expected: Vec<f64> = (0..v)
                .map(|k| model.matrix.gamma(i, subspace_of(k)) as f64 * subspaces.within(subspace_of(k), k) * n as f64)
                .collect();
            discrete_chi2_of(&counts, &expected, tests).assert_pass();
            // Negative control: uniform draws within each subspace are rejected.
            let uniform_within: Vec<f64> = (0..v)
                .map(|k| {
                    let j = subspace_of(k);
                    model.matrix.gamma(i, j) as f64 / subspaces.count(j) as f64 * n as f64
                })
                .collect();
            assert!(
                !discrete_chi2_of(&counts, &uniform_within, tests).passed(),
                "uniform draws within subspaces were not rejected"
            );
            tested += 1;
        }
        assert!(tested >= 5);
    }

    #[test]
    fn resampling_counts_are_the_draws_selection_density() {
        // With the pool's own totals, `N M P(y | z)` evaluated on the connected path is the
        // probability with which the connection drew `y` (up to a camera vertex seen at a
        // grazing angle, whose normal may turn the other way when judged from positions).
        let scene = scene();
        let (model, pool, subspaces, measured) = setup(&scene);
        let select = selection(&scene, &model, &subspaces, &pool);
        let n = 4u32;
        let counts = SpCounts::for_iteration(&scene, PcMis::Resampling, n, pool.paths, &measured, &model);
        // `subspace` is the same density with the draw within the subspace uniform.
        let uniform = SpCounts::for_iteration(&scene, PcMis::Subspace, n, pool.paths, &measured, &model);
        let mut rng = Sampler::new(&[6]);
        let (mut checked, mut off) = (0, 0);
        for camera in camera_prefixes(&scene) {
            let i = select.lookup(&camera[camera.len() - 1]);
            draw_one_by_one(&select, &i, n, &mut rng, |k, f| {
                let light = pool.prefix(k);
                if light.len() < 2 {
                    return;
                }
                let path = FullPath { light, camera: &camera };
                let count = counts.count(&path, light.len(), camera.len()) as f64;
                let drawn = 1.0 / f as f64;
                checked += 1;
                off += ((count / drawn - 1.0).abs() > 1e-3) as usize;
                let j = model.light_subspace(&scene, light);
                let want = n as f64 * model.matrix.gamma(i, j) as f64 * pool.paths as f64 / subspaces.count(j) as f64;
                let got = uniform.count(&path, light.len(), camera.len()) as f64;
                off += ((got / want - 1.0).abs() > 1e-3) as usize;
            });
        }
        assert!(checked > 100 && off * 100 <= checked, "{off} of {checked} counts differ from the draws' densities");
    }

    #[test]
    fn labels_give_the_subspaces_the_trees_give() {
        let scene = scene();
        let (model, pool, _, _) = setup(&scene);
        let mut vertices: Vec<Vertex> = camera_prefixes(&scene).into_iter().flatten().collect();
        vertices.extend(pool.vertices.iter().filter(|y| y.scatters()));
        let mut rng = Sampler::new(&[11]);
        let (mut checked, mut turned, mut swapped_differ) = (0, 0, 0);
        for v in &vertices {
            let mut labelled = *v;
            model.label(&scene, &mut labelled);
            // Negative control: a label with the normal's two sides swapped.
            let mut swapped = labelled;
            swapped.label = labelled.label.map(|[a, b, c, d]| [b, a, d, c]);
            for _ in 0..8 {
                let towards = crate::sampling::square_to_uniform_sphere(rng.next_2d());
                turned += (v.frame.n.dot(towards) < 0.0) as usize;
                for tree in 0..2 {
                    let want = model.class(&scene, tree, v, towards);
                    assert_eq!(model.class(&scene, tree, &labelled, towards), want, "tree {tree} towards {towards}");
                    swapped_differ += (model.class(&scene, tree, &swapped, towards) != want) as usize;
                    checked += 1;
                }
            }
        }
        assert!(checked > 2000 && turned > checked / 8, "{checked} classes, {turned} with the normal turned");
        assert!(swapped_differ > checked / 20, "swapped labels differ in only {swapped_differ} of {checked}");
    }
}
