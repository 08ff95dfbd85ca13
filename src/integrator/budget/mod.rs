//! Efficiency-aware connection budgets of the pool integrators (PCBPT, SPCBPT): the number
//! of pool connections per camera vertex (0, 1, 2, 4 or 8) and the number of light paths
//! that are light traced (none, the pool's `M`, a quarter of the pixels, or one per pixel),
//! chosen from the second moments and costs measured in a few iterations (the idea of
//! Grittmann, Yazici, Georgiev and Slusallek, "Efficiency-aware multiple importance sampling
//! for bidirectional rendering algorithms", SIGGRAPH 2022). With no connections and no light
//! tracing an iteration is plain path tracing with next-event estimation.
//!
//! The measurement (what the measured iterations record of each contribution) is in
//! [`measure`] (the second moments and the realized model), the costs in [`cost`]; this module
//! predicts each candidate's variance from them and chooses.
//!
//! **Variance.** A pixel's estimate sums many contributions (one per strategy and path
//! length), so its second moment is no variance: the variance under the budget in use is
//! measured across the iterations instead, and a candidate's is that plus the change of
//! second moment, taken in two steps: to the candidate's light tracing (light paths are
//! independent samples), then to its connections, that change multiplied by
//! `--pc-budget-independence` (0.35, fitted on `staircase2`: with a factor of 1 the change
//! overrates the variance of plans with fewer connections). With `measured` the factor is
//! the share of the connections' second moment that is variance about each camera vertex's
//! own mean ([`Spread`]): given the camera vertex and the pool a vertex's `N` draws are independent,
//! so only that part changes with `N`. (That share stays far above 0.35 on the scenes
//! measured, so the shared prefix is not what 0.35 makes up for: `docs/results/budget.md`.)
//!
//! **Choice.** Per candidate, `Σ_pixels variance / (mean² + 0.01)` (the relMSE the images
//! are judged by, on luminance) times the cost of an iteration, from the operations the
//! measured iterations counted, priced by [`Prices`]. The least product wins, but the
//! measured plan's is divided by `--pc-budget-margin` (1.1; [`pick`]): its variance is
//! measured, the others' only predicted, so a smaller predicted gain is within the
//! predictions' error, and where the plan stays the render is the one without a budget bit
//! for bit. The moments are those of every `k`-th row and column, at most about
//! `--pc-budget-pixels` (16 384), so that a measured iteration costs little more than an
//! ordinary one (a moment per candidate for every pixel would not). A pixel's
//! `mean` is its own over the measured iterations, or with `--pc-budget-smoothing r` the
//! average over its measured neighbours within `r`: a pixel's own mean of two iterations,
//! squared, is biased up by their variance, which weighs the noisiest pixels least and so
//! makes the plan in use look less noisy than the others. Smoothed means with the measured
//! independence need no fitted factor. The default is the realized model ([`measure`]) with
//! `r = 2` (the equal-time renders that chose it: `docs/results/budget.md`). The choice is
//! made from counts alone, never from clocks, so it is the same on every machine and for
//! every thread count, and a chunk that re-runs the measured iterations makes it again.
//! Iterations of different budgets are each unbiased and averaged alike; the film divides
//! every iteration's splats by the same count of light paths ([`normalise_splats`]).
//!
//! **Horizon.** Every moment is the one a render of `--pc-budget-horizon` samples per pixel
//! typically shows (the render's `--spp` but at least [`DEFAULT_HORIZON`], 256): a path
//! that a candidate samples far less densely than the plan in use counts only as often as
//! such a render finds it ([`measure::typical`]). Without it the paths that connections find
//! and the path tracer reaches through tiny densities make path tracing look worse than its
//! renders are.
//!
//! **Rarity** (`--pc-budget-rarity`, on by default). The horizon counts every sample as a
//! region the measured iterations found about once; a sample the measured plan found by
//! luck is rarer than that. Each measured pixel's largest contribution ([`Top`]) is
//! re-counted with the floor raised by `v / (t · mean)`, the mean the larger of the
//! pixel's smoothed mean and its own without that contribution ([`Budget::recount_rare_tops`]).
//! One such sample can hold much of what path tracing's prediction adds to the plan's
//! variance and turn the choice away from path tracing where it renders best.
//!
//! **Known error.** Both models find more light tracing more useful than renders do
//! (`docs/results/budget.md`). Neither knows that the path-tracing plan renders with the
//! path tracer (the power heuristic between next-event estimation and BSDF sampling), not
//! with the camera pass's balance heuristic, which can have less variance than the camera
//! pass with the pool's light tracing. The rarity recount also lowers path tracing's
//! prediction where the contributions that stand out are part of its real heavy tail, not
//! luck.

pub mod cost;
pub mod measure;
mod options;
pub mod shares;
pub use options::*;

pub use cost::{Operations, PRICES, Prices, SPCBPT_PRICES, SPCBPT_RESAMPLING_PRICES, SPCBPT_SUBSPACE_PRICES};
pub use measure::{BudgetSink, Realized, Spread, TileMoments, Top};
use measure::{RealizedSums, Weighing, accumulate, own_moment, typical};
pub use shares::{ShareRecorder, Shares, SplatShares, mis_shares, mis_shares_with};

use crate::film::{Splat, Tile};
use crate::integrator::bidir::Sink;
use crate::integrator::bidir::bdpt::{Bdpt, Connector};
use crate::integrator::bidir::mis::StrategyCounts;
use crate::integrator::bidir::pool::{LightPool, PoolCounters, PoolPlan, PoolSampler, PoolSelection};
use crate::integrator::path::PathTracer;
use crate::integrator::render_loop::{Ctx, Iterative, TileResult, Warmup, sample_tile};
use crate::integrator::stats::Counters;
use crate::sampling::Sampler;
use glam::Vec2;
use serde::Serialize;
use std::ops::Range;

/// What an iteration spends on the pool: connections per camera vertex, and light paths
/// that form the pool and that splat.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Plan {
    pub connections: u32,
    pub pool_paths: usize,
    pub splat_paths: usize,
}

impl Plan {
    /// What the plan asks of the light pool.
    pub fn pool(&self) -> PoolPlan {
        PoolPlan { pool_paths: self.pool_paths, splat_paths: self.splat_paths }
    }

    pub fn traced(&self) -> usize {
        self.pool().traced()
    }

    /// No connections and no light tracing: the path tracer's estimator.
    pub fn path_tracing(&self) -> bool {
        self.connections == 0 && self.splat_paths == 0
    }
}

/// Scales the splats of an iteration that light traces `plan.splat_paths` paths to what
/// `reference` paths would splat, and returns `reference`: the film divides every
/// iteration's splats by the same count of light paths, so each iteration's light tracing
/// stays an estimate of its share of the image whatever the plan (dividing by the paths
/// actually traced would weigh iterations by their light paths, and the camera pass's share
/// by iterations: a bias whenever the plan changes the share of light tracing).
pub(crate) fn normalise_splats(splats: &mut [Splat], plan: &Plan, reference: usize) -> u64 {
    if plan.splat_paths > 0 && plan.splat_paths != reference {
        let k = reference as f32 / plan.splat_paths as f32;
        for sp in splats.iter_mut() {
            sp.value *= k;
        }
    }
    reference as u64
}

/// The warm-up of a pool integrator whose budget is measured in iterations before
/// `window_end` (with [`BudgetMode::Auto`]) and whose counts take the previous iteration's
/// state (its camera pass too with `previous_tiles`): those iterations, with their camera
/// passes, then iteration `first - 1`.
pub(crate) fn warmup(mode: BudgetMode, window_end: u32, first: u32, previous_tiles: bool) -> Warmup {
    let previous = first.saturating_sub(1)..first;
    if mode == BudgetMode::Off {
        return Warmup::new(previous, previous_tiles);
    }
    let measured = 0..first.min(window_end);
    let mut ranges = vec![(measured.clone(), true)];
    if previous.start >= measured.end {
        ranges.push((previous, previous_tiles));
    }
    Warmup { ranges }
}

/// One camera sample of a pool integrator, into any sink.
pub(crate) trait CameraSample {
    fn sample(
        &mut self,
        pos: Vec2,
        rng: &mut Sampler,
        sink: &mut impl crate::integrator::bidir::Sink,
        counters: &mut Counters,
    );

    /// What the integrator learns from a tile's samples for later iterations (SPCBPT's
    /// training samples).
    type Learned: Send;

    /// What the integrator learned from the tile's samples, taken once the tile is done.
    fn learned(&mut self) -> Option<Self::Learned>;

    /// The tile's pool draws, taken once the tile is done.
    fn draws(&mut self) -> PoolCounters;
}

/// What a pool integrator's tile gives back ([`TileResult::data`]): the budget's moments
/// when it measured the tile, what the integrator learned from it
/// ([`CameraSample::learned`]), and its pool draws.
pub(crate) struct PoolTile<L> {
    pub moments: Option<TileMoments>,
    pub learned: Option<L>,
    pub draws: PoolCounters,
}

impl PoolTile<()> {
    /// The tile of an integrator that learns `L` from other tiles.
    pub fn nothing_learned<L>(self) -> PoolTile<L> {
        PoolTile { moments: self.moments, learned: None, draws: self.draws }
    }
}

impl<L> Default for PoolTile<L> {
    fn default() -> PoolTile<L> {
        PoolTile { moments: None, learned: None, draws: PoolCounters::default() }
    }
}

/// A tile of iteration `first` as the budget has it: the path tracer's when the plan
/// [`Plan::path_tracing`], or `sample`'s with the measured pixels' contributions recorded in
/// a measured iteration; `None` otherwise (the integrator renders it its own way).
fn budget_tile<S: CameraSample>(
    ctx: &Ctx,
    tile: Tile,
    first: u32,
    count: u32,
    budget: &Budget,
    sample: &mut S,
) -> Option<TileResult<PoolTile<S::Learned>>> {
    if !budget.measures(first) {
        return (budget.plan().path_tracing() && !ctx.layers)
            .then(|| path_traced_tile(ctx, tile, first, count).map(|()| PoolTile::default()));
    }
    let mut moments = budget.tile_moments(&tile);
    let result = sample_tile(ctx, tile, first, count, |pos, rng, sink, counters| {
        match budget.measured_pixel(pos) {
            Some(id) => {
                moments.begin(id);
                let mut sink = BudgetSink { inner: sink, moments: &mut moments, pending: Shares::default() };
                sample.sample(pos, rng, &mut sink, counters);
            }
            None => sample.sample(pos, rng, sink, counters),
        }
        true
    });
    moments.end_vertex();
    Some(result.map(|()| PoolTile { moments: Some(moments), learned: sample.learned(), draws: sample.draws() }))
}

/// A tile of iteration `first` of a pool integrator with `sampler`'s camera samples: the
/// budget's ([`budget_tile`]) when it measures the iteration or path traces, otherwise the
/// sampler's, with what it learned ([`CameraSample::learned`]).
pub(crate) fn pool_tile<S: CameraSample>(
    ctx: &Ctx,
    tile: Tile,
    first: u32,
    count: u32,
    budget: &Budget,
    mut sampler: S,
) -> TileResult<PoolTile<S::Learned>> {
    if let Some(result) = budget_tile(ctx, tile, first, count, budget, &mut sampler) {
        return result;
    }
    let result = sample_tile(ctx, tile, first, count, |pos, rng, sink, counters| {
        sampler.sample(pos, rng, sink, counters);
        true
    });
    let (learned, draws) = (sampler.learned(), sampler.draws());
    result.map(|()| PoolTile { moments: None, learned, draws })
}

/// A tile of a plan that [`Plan::path_tracing`]: the path tracer's samples (next-event
/// estimation and BSDF sampling under the power heuristic, `src/integrator/path/`, traced as
/// a wavefront), which
/// cost less than the bidirectional camera pass with its stored vertices and ratio walks.
fn path_traced_tile(ctx: &Ctx, tile: Tile, first: u32, count: u32) -> TileResult {
    let pt = PathTracer { wavefront: true, ..PathTracer::new(&ctx.scene.integrator) };
    Iterative::render_tile(&pt, ctx, &(), tile, first, count)
}

/// The budgets considered when the pool holds `m` light paths and the film `pixels` pixels:
/// every connection count with every light-tracing count; connections need the pool.
pub fn candidates(m: usize, pixels: usize) -> Vec<Plan> {
    let mut lights = vec![0, m];
    for l in [pixels / 4, pixels] {
        if l > m && !lights.contains(&l) {
            lights.push(l);
        }
    }
    let mut out = Vec::new();
    for n in CONNECTION_CHOICES {
        for &l in &lights {
            out.push(Plan { connections: n, pool_paths: if n > 0 { m } else { 0 }, splat_paths: l });
        }
    }
    out
}

/// An iteration's light pool as [`Budget::trace_pool`] traced it.
pub(crate) struct TracedPool {
    pub pool: LightPool,
    pub splats: Vec<Splat>,
    pub counters: Counters,
    pub splat_shares: Vec<SplatShares>,
    /// What the tracing spent, for the cost model (the camera pass's part is added later).
    pub operations: Operations,
    /// The light paths the film divides the splats by.
    pub splat_paths: u64,
}

/// What a choice found: the plan and, per candidate, the predicted relMSE sum and cost.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BudgetStats {
    /// The plan chosen (`None` before the choice, or with `--pc-budget off`).
    pub chosen: Option<Plan>,
    /// The plan of the measured iterations.
    pub measured_with: Option<Plan>,
    /// Predicted efficiency of the chosen plan over that of the measured one (> 1: better).
    pub predicted_gain: f64,
    /// The candidate predicted most efficient, chosen only when its gain (`best_gain`)
    /// exceeds `--pc-budget-margin`.
    pub best: Option<Plan>,
    pub best_gain: f64,
    /// `--pc-budget-margin`: the predicted gain another plan must exceed to replace the
    /// measured one.
    pub margin: f64,
    /// Pixels whose moments were measured (`--pc-budget-pixels`, at most about).
    pub measured_pixels: usize,
    /// The measured iterations' connections' variance within camera vertices over their
    /// second moment ([`Spread::independence`]); `None` with fewer than two draws per vertex.
    pub measured_independence: Option<f64>,
    /// The independence the choice used: given, measured, or 1 when neither.
    pub independence: f64,
    /// Per candidate: connections, splatting paths, predicted relative variance (summed over
    /// the measured pixels), cost per iteration (extension rays).
    pub candidates: Vec<(u32, usize, f64, f64)>,
    /// The model the choice used.
    pub model: Option<BudgetModel>,
    /// Per candidate, the relative variance both models predict: moments, realized.
    pub predictions: Vec<(f64, f64)>,
    /// Per candidate, the camera path's own strategies' second moment from every strategy's
    /// samples over that of the realized camera samples: how much of it they miss, which
    /// scales their cross terms in the realized model ([`Realized`]).
    pub missed: Vec<f64>,
    /// Samples per pixel the choice planned for (`--pc-budget-horizon`; 0: none, the
    /// expected moments).
    pub horizon: u32,
}

impl BudgetStats {
    /// The summary's line on the choice (none before one was made).
    pub fn line(&self) -> Option<String> {
        let (p, m) = (self.chosen?, self.measured_with?);
        let why = match self.best {
            Some(best) if best != p => format!(
                "kept: the best, {} and {}, predicted {:.2}×, is within the margin {:.2}",
                best.connections, best.splat_paths, self.best_gain, self.margin
            ),
            _ => format!("predicted efficiency {:.2}× theirs", self.predicted_gain),
        };
        Some(format!(
            "  budget: {} connections per camera vertex and {} light-traced paths per iteration (measured with {} and {}; {why}, {})",
            p.connections,
            p.splat_paths,
            m.connections,
            m.splat_paths,
            if self.horizon == 0 {
                "expected moments".to_string()
            } else {
                format!("planned for {} spp", self.horizon)
            }
        ))
    }
}

/// The budget of a pool integrator over a render: the plan in use, and the measurement that
/// replaces it.
pub struct Budget {
    pub mode: BudgetMode,
    /// Iterations whose samples are measured; the plan changes after the last.
    pub window: Range<u32>,
    plan: Plan,
    candidates: Vec<Plan>,
    /// The candidates' count scales and the horizon's floor ([`measure::typical`]).
    weighing: Weighing,
    /// The pixels of every `every`-th row and column are measured: `columns` of them a row.
    every: usize,
    columns: usize,
    width: usize,
    height: usize,
    pixels: usize,
    s1: Vec<f64>,
    s2: Vec<f64>,
    q: Vec<f64>,
    /// Per measured pixel and candidate (like `q`), for [`BudgetModel::Realized`]: the
    /// pixel's camera samples as the candidate weighs them ([`Realized`]), summed over the
    /// iterations.
    realized: Vec<RealizedSums>,
    model: BudgetModel,
    /// Per measured pixel, its pool connections' [`Spread`].
    spread: Vec<Spread>,
    /// Per measured pixel, its largest contribution over the iterations ([`Top`]).
    top: Vec<Top>,
    operations: Operations,
    /// The integrator's prices of the operations ([`Prices`]).
    prices: Prices,
    iterations: u32,
    /// `--pc-budget-independence`; `None`: measured ([`Spread`]).
    independence: Option<f64>,
    /// `--pc-budget-smoothing`: measured pixels each side whose means are averaged for
    /// relMSE's denominator ([`Budget::smoothed_means`]).
    smoothing: usize,
    /// `--pc-budget-rarity` ([`Budget::recount_rare_tops`]).
    rarity: bool,
    pub stats: BudgetStats,
}

impl Budget {
    /// A budget that starts with `plan` and, with `--pc-budget auto`, measures `window`, for
    /// a render of `planned_spp` samples per pixel (`None`: of `--time`; the horizon is at
    /// least [`DEFAULT_HORIZON`] unless given), pricing the integrator's operations by `prices`.
    pub fn new(
        opts: &BudgetOptions,
        prices: Prices,
        window: Range<u32>,
        plan: Plan,
        width: usize,
        height: usize,
        planned_spp: Option<u32>,
    ) -> Budget {
        let mode = opts.mode;
        let horizon = opts.horizon.unwrap_or(planned_spp.unwrap_or(0).max(DEFAULT_HORIZON));
        let floor = if horizon == 0 { 0.0 } else { (window.len() as f64 / horizon as f64).min(1.0) };
        let pixels = width * height;
        let candidates = if mode == BudgetMode::Auto { candidates(plan.pool_paths, pixels) } else { Vec::new() };
        let weighing = Weighing::new(&plan, &candidates, floor);
        let every = (pixels as f64 / opts.pixels.max(1) as f64).sqrt().ceil().max(1.0) as usize;
        let mut budget = Budget {
            mode,
            window,
            plan,
            candidates,
            weighing,
            every,
            columns: width.div_ceil(every),
            width,
            height,
            pixels,
            s1: Vec::new(),
            s2: Vec::new(),
            q: Vec::new(),
            realized: Vec::new(),
            model: opts.model,
            operations: Operations::default(),
            prices,
            iterations: 0,
            spread: Vec::new(),
            top: Vec::new(),
            independence: opts.independence.fixed().map(f64::from),
            smoothing: opts.smoothing as usize,
            rarity: opts.rarity,
            stats: BudgetStats { horizon, margin: f64::from(opts.margin), ..BudgetStats::default() },
        };
        budget.stats.measured_pixels = budget.measured();
        budget
    }

    pub fn plan(&self) -> Plan {
        self.plan
    }

    /// The light pool of iteration `first` under the plan: its paths traced (splatting in a
    /// measured iteration even in a warm-up, as its moments are part of the state), its
    /// splats scaled to `m` light paths ([`normalise_splats`]), each splat's shares when
    /// measured, and the operations of the tracing.
    pub(crate) fn trace_pool<C: StrategyCounts + Sync>(
        &self,
        ctx: &Ctx,
        conn: &Connector<C>,
        bdpt: &Bdpt,
        first: u32,
        keep: bool,
        m: usize,
    ) -> TracedPool {
        let measures = self.measures(first);
        let splat = (keep || measures).then_some((conn, bdpt, ctx.layers));
        let (pool, mut splats, counters, splat_shares) = LightPool::trace_plan(
            ctx.scene,
            &bdpt.limits,
            self.plan.pool(),
            ctx.seed,
            first as u64,
            splat,
            measures.then_some(&ShareRecorder),
        );
        let splat_paths = normalise_splats(&mut splats, &self.plan, m);
        let operations = Operations {
            light_rays: counters.camera_rays + counters.extension_rays,
            splat_shadow: counters.shadow_rays,
            ..Operations::default()
        };
        TracedPool { pool, splats, counters, splat_shares, operations, splat_paths }
    }

    /// After iteration `i`'s camera pass (`results`): adds it when it is measured.
    pub(crate) fn finish<L>(
        &mut self,
        i: u32,
        results: &[TileResult<PoolTile<L>>],
        splat_shares: &[SplatShares],
        ops: Operations,
    ) {
        if self.measures(i) {
            self.add_iteration(results, splat_shares, ops.with_camera_pass(results));
        }
    }

    /// The statistics, once a plan has been chosen.
    pub fn chosen_stats(&self) -> Option<BudgetStats> {
        self.stats.chosen.is_some().then(|| self.stats.clone())
    }

    /// Whether iteration `i`'s samples are measured.
    pub fn measures(&self, i: u32) -> bool {
        self.mode == BudgetMode::Auto && self.window.contains(&i)
    }

    /// The grid of measured pixels: columns and rows.
    fn grid(&self) -> (usize, usize) {
        (self.columns, self.height.div_ceil(self.every))
    }

    /// Measured pixels.
    fn measured(&self) -> usize {
        let (w, h) = self.grid();
        w * h
    }

    /// The measured-pixel index of film position `pos`, if it is measured.
    pub fn measured_pixel(&self, pos: Vec2) -> Option<usize> {
        let (x, y) = (pos.x.max(0.0) as usize, pos.y.max(0.0) as usize);
        if x >= self.width || y >= self.height || !x.is_multiple_of(self.every) || !y.is_multiple_of(self.every) {
            return None;
        }
        Some(y / self.every * self.columns + x / self.every)
    }

    /// Each measured pixel's mean over the iterations, the mean relMSE divides by: with
    /// `--pc-budget-smoothing r`, averaged over the measured pixels within `r` of it on the
    /// grid; its own with `r = 0`.
    fn smoothed_means(&self) -> Vec<f64> {
        let t = self.iterations as f64;
        let r = self.smoothing;
        if r == 0 {
            return self.s1.iter().map(|s| s / t).collect();
        }
        let (w, h) = self.grid();
        // Summed-area table of the pixel sums.
        let mut area = vec![0.0f64; (w + 1) * (h + 1)];
        for y in 0..h {
            for x in 0..w {
                area[(y + 1) * (w + 1) + x + 1] =
                    self.s1[y * w + x] + area[y * (w + 1) + x + 1] + area[(y + 1) * (w + 1) + x]
                        - area[y * (w + 1) + x];
            }
        }
        let mut out = vec![0.0; w * h];
        for y in 0..h {
            let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(h));
            for x in 0..w {
                let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
                let sum = area[y1 * (w + 1) + x1] - area[y0 * (w + 1) + x1] - area[y1 * (w + 1) + x0]
                    + area[y0 * (w + 1) + x0];
                out[y * w + x] = sum / ((y1 - y0) * (x1 - x0)) as f64 / t;
            }
        }
        out
    }

    /// Empty moments for `tile` of a measured iteration, with room for its measured pixels.
    pub fn tile_moments(&self, tile: &Tile) -> TileMoments {
        let span = |from: u32, len: u32| (from + len).div_ceil(self.every as u32) - from.div_ceil(self.every as u32);
        let pixels = span(tile.x0, tile.width) * span(tile.y0, tile.height);
        TileMoments::new(self.weighing.clone(), self.plan.connections, pixels as usize)
    }

    /// Adds a measured iteration: its tiles' moments (in `extra`, in tile order), its
    /// splats' shares and the operations it made; after the last iteration of the window,
    /// chooses the plan.
    fn add_iteration<L>(
        &mut self,
        results: &[TileResult<PoolTile<L>>],
        splats: &[SplatShares],
        operations: Operations,
    ) {
        let (n, c) = (self.measured(), self.candidates.len());
        if self.s1.is_empty() {
            self.s1 = vec![0.0; n];
            self.spread = vec![Spread::default(); n];
            self.s2 = vec![0.0; n];
            self.q = vec![0.0; n * c];
            self.realized = vec![RealizedSums::default(); n * c];
            self.top = vec![Top::default(); n];
        }
        let mut x = vec![0.0f64; n];
        // An iteration samples each pixel once, so each measured pixel has one entry: its
        // realized sums are the pixel's estimate of the iteration as each candidate weighs it.
        for r in results {
            let Some(m) = r.data.moments.as_ref() else { continue };
            for (e, &id) in m.ids.iter().enumerate() {
                let id = id as usize;
                x[id] += m.x[e];
                self.spread[id].add_weighted(&m.spread[e], 1.0);
                let top = m.top[e];
                self.top[id].offer(top.v, &top.shares);
                let (to, from) = (id * c..(id + 1) * c, e * c..(e + 1) * c);
                for (q, add) in self.q[to.clone()].iter_mut().zip(&m.q[from.clone()]) {
                    *q += add;
                }
                for (sums, y) in self.realized[to].iter_mut().zip(&m.realized[from]) {
                    sums.add(y);
                }
            }
        }
        // A splat adds `value · W·H / L` to its pixel's estimate of the iteration (the film
        // divides the splats of `L` light paths by `L / (W·H)` samples per pixel).
        let per_path = self.pixels as f32 / self.plan.splat_paths.max(1) as f32;
        for sp in splats {
            if let Some(id) = self.measured_pixel(sp.pos) {
                let v = sp.value * per_path;
                self.top[id].offer(v, &sp.shares);
                accumulate(v, &sp.shares, &self.weighing, &mut x[id], &mut self.q[id * c..(id + 1) * c]);
                for (sums, &(a, l)) in self.realized[id * c..(id + 1) * c].iter_mut().zip(&self.weighing.scales) {
                    sums.own_moment += own_moment(v, &sp.shares, sp.shares.combined(a, l), self.weighing.floor);
                }
            }
        }
        for (id, x) in x.into_iter().enumerate() {
            self.s1[id] += x;
            self.s2[id] += x * x;
        }
        self.operations += operations;
        self.iterations += 1;
        if self.iterations == self.window.len() as u32 {
            self.choose();
        }
    }

    /// Picks the candidate with the least predicted relMSE × cost, and frees the moments.
    ///
    /// A pixel's variance under the plan in use is measured across the iterations; under
    /// another plan it is predicted as that variance plus the difference of the two second
    /// moments. (The second moment alone is no variance: a pixel's estimate sums many
    /// contributions, one per strategy and path length, and their means do not cancel.)
    fn choose(&mut self) {
        let t = self.iterations as f64;
        let c = self.candidates.len();
        let from = self.plan;
        let current = self.candidates.iter().position(|p| *p == from).expect("the plan in use is a candidate");
        // Candidate `k`'s change is taken in two steps: to its light tracing with the
        // connections in use (`via[k]`; light paths are independent samples), then to its
        // connections, shrunk by the independence factor (they are correlated).
        let via: Vec<usize> = self
            .candidates
            .iter()
            .map(|p| {
                let same = |q: &Plan| q.connections == from.connections && q.splat_paths == p.splat_paths;
                self.candidates.iter().position(same).expect("every light-tracing count is a candidate")
            })
            .collect();
        let means = self.smoothed_means();
        self.recount_rare_tops(&means);
        let norm = |id: usize| 1.0 / (means[id] * means[id] + crate::compare::RELMSE_EPSILON);
        // The independence of connections: given, or their spread within camera vertices
        // over the pixels as relMSE weighs them.
        let mut spread = Spread::default();
        for (id, s) in self.spread.iter().enumerate() {
            spread.add_weighted(s, norm(id));
        }
        let independence = self.independence.or(spread.independence()).unwrap_or(1.0);
        let sample_variance = |s1: f64, s2: f64| ((s2 - s1 * s1 / t) / (t - 1.0).max(1.0)).max(0.0);
        let mut moments = vec![0.0f64; c];
        let mut realized = vec![0.0f64; c];
        // How much of the camera path's own strategies' second moment its realized samples
        // see, per candidate, over the pixels as relMSE weighs them ([`Realized`]).
        let mut seen = vec![(0.0f64, 0.0f64); c];
        for id in 0..self.s1.len() {
            for (s, o) in seen.iter_mut().zip(&self.realized[id * c..(id + 1) * c]) {
                s.0 += o.own_diagonal * norm(id);
                s.1 += o.own_moment * norm(id);
            }
        }
        let missed: Vec<f64> = seen.iter().map(|&(r, m)| if r > 0.0 { m / r } else { 1.0 }).collect();
        for id in 0..self.s1.len() {
            let measured = sample_variance(self.s1[id], self.s2[id]);
            let norm = norm(id);
            let at = id * c;
            let q = &self.q[at..at + c];
            // The realized model ([`Realized`]): diagonal, cross terms scaled by what the
            // realized samples miss, less the squared mean (products of different
            // iterations), the candidate's in place of the plan in use's on top of the
            // measured variance (which keeps what neither sees, such as the covariance of the
            // camera pass and the light pool).
            let own = |k: usize| self.realized[at + k].variance(q[k], missed[k], t);
            let base = measured - own(current);
            for k in 0..c {
                let change = if q[k].is_infinite() {
                    f64::INFINITY
                } else if q[via[k]].is_infinite() {
                    q[k] - q[current]
                } else {
                    (q[via[k]] - q[current]) + independence * (q[k] - q[via[k]])
                };
                moments[k] += (measured + change / t).max(0.0) * norm;
                realized[k] += if q[k].is_infinite() { f64::INFINITY } else { (base + own(k)).max(0.0) * norm };
            }
        }
        let variance = match self.model {
            BudgetModel::Moments => &moments,
            BudgetModel::Realized => &realized,
        };
        let per_iteration = |p: &Plan| self.operations.cost(&from, p, &self.prices) / t;
        let score = |k: usize| variance[k].max(0.0) * per_iteration(&self.candidates[k]);
        let mut best: Option<usize> = None;
        for k in 0..c {
            let s = score(k);
            if s.is_finite() && best.is_none_or(|b| s < score(b)) {
                best = Some(k);
            }
        }
        self.stats.measured_with = Some(from);
        self.stats.measured_independence = spread.independence();
        self.stats.independence = independence;
        self.stats.model = Some(self.model);
        self.stats.predictions = (0..c).map(|k| (moments[k], realized[k])).collect();
        self.stats.missed = missed;
        self.stats.candidates = (0..c)
            .map(|k| {
                let p = &self.candidates[k];
                (p.connections, p.splat_paths, variance[k], per_iteration(p))
            })
            .collect();
        if let Some(b) = best {
            let mut gains: Vec<f64> = (0..c).map(|k| score(current) / score(k).max(f64::MIN_POSITIVE)).collect();
            gains[current] = 1.0;
            // A measured plan that cannot make every measured path gives way to the best
            // that can.
            let chosen = if score(current).is_finite() { pick(&gains, current, self.stats.margin) } else { b };
            self.stats.best = Some(self.candidates[b]);
            self.stats.best_gain = gains[b];
            self.plan = self.candidates[chosen];
            self.stats.predicted_gain = gains[chosen];
        }
        self.stats.chosen = Some(self.plan);
        self.s1 = Vec::new();
        self.s2 = Vec::new();
        self.q = Vec::new();
        self.spread = Vec::new();
        self.realized = Vec::new();
        self.top = Vec::new();
    }

    /// Re-counts each measured pixel's largest contribution at the horizon with the floor
    /// its rarity gives ([`Top::rarity`]): against the larger of the pixel's smoothed mean
    /// `means` and its own mean without that contribution, so that only a sample that stands
    /// out from both its neighbours and the pixel's other samples counts as rarer than the
    /// measured iterations found it.
    fn recount_rare_tops(&mut self, means: &[f64]) {
        let (t, c, floor) = (self.iterations as f64, self.candidates.len(), self.weighing.floor);
        if floor <= 0.0 || !self.rarity {
            return;
        }
        for (id, top) in self.top.iter().enumerate() {
            let v = top.v as f64;
            let own = (self.s1[id] - v).max(0.0) / (t - 1.0).max(1.0);
            let rarity = top.rarity(means[id].max(own), t);
            if rarity <= 1.0 {
                continue;
            }
            let rare_floor = floor * rarity;
            let at = id * c;
            for (k, &(a, l)) in self.weighing.scales.iter().enumerate() {
                let d = top.shares.combined(a, l);
                if d <= 0.0 || self.q[at + k].is_infinite() {
                    continue;
                }
                self.q[at + k] -= v * v * (1.0 / typical(d, floor) - 1.0 / typical(d, rare_floor));
                self.realized[at + k].own_moment -=
                    own_moment(top.v, &top.shares, d, floor) - own_moment(top.v, &top.shares, d, rare_floor);
            }
        }
    }
}

/// The candidate a budget takes, from each candidate's predicted efficiency over the
/// measured plan's (`gains`; that of `current`, the measured plan, is 1): the greatest gain,
/// the measured plan's counted `margin` times. Its variance is measured, the others'
/// only predicted (their error against renders: `docs/results/budget.md`), so a gain within
/// the margin is within that error and the plan stays (and with it the image of
/// the render without a budget). A candidate whose gain is not finite is never taken.
pub(crate) fn pick(gains: &[f64], current: usize, margin: f64) -> usize {
    let credited = |k: usize| match gains[k] {
        g if !(g.is_finite() && g >= 0.0) => f64::NEG_INFINITY,
        g if k == current => g * margin,
        g => g,
    };
    // Ties go to the measured plan, then to the earlier candidate.
    (0..gains.len()).fold(current, |best, k| if credited(k) > credited(best) { k } else { best })
}

/// The pool integrators' camera pass, one sample at a time.
impl<C: StrategyCounts, P: PoolSelection> CameraSample for PoolSampler<'_, C, P> {
    type Learned = ();

    #[inline]
    fn sample(&mut self, pos: Vec2, rng: &mut Sampler, sink: &mut impl Sink, counters: &mut Counters) {
        PoolSampler::sample(self, pos, rng, sink, counters);
    }

    fn learned(&mut self) -> Option<()> {
        None
    }

    fn draws(&mut self) -> PoolCounters {
        std::mem::take(&mut self.draws)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_cover_path_tracing_and_need_a_pool_for_connections() {
        let c = candidates(500, 57_600);
        assert_eq!(c.len(), 5 * 4);
        assert!(c.contains(&Plan { connections: 0, pool_paths: 0, splat_paths: 0 }));
        assert!(c.contains(&Plan { connections: 4, pool_paths: 500, splat_paths: 500 }));
        assert!(c.contains(&Plan { connections: 8, pool_paths: 500, splat_paths: 57_600 }));
        assert!(c.iter().all(|p| (p.connections > 0) == (p.pool_paths > 0)));
        // A pool already as large as the film adds no larger light-tracing counts.
        assert_eq!(candidates(100, 100).len(), 5 * 2);
    }

    #[test]
    fn the_pick_keeps_the_measured_plan_within_the_margin() {
        // Candidate 1 is the measured plan.
        let pick = |g: [f64; 4], margin: f64| pick(&g, 1, margin);
        // Another plan predicted 5% better stays unused with a margin of 1.1, not with 1.
        assert_eq!(pick([0.5, 1.0, 1.05, 0.9], 1.1), 1);
        assert_eq!(pick([0.5, 1.0, 1.05, 0.9], 1.0), 2);
        // 20% and 30% better: the best of them is taken.
        assert_eq!(pick([0.5, 1.0, 1.2, 1.3], 1.1), 3);
        assert_eq!(pick([1.3, 1.0, 1.2, 0.3], 1.1), 0);
        // Exactly at the margin the measured plan stays; ties among others go to the first.
        assert_eq!(pick([0.5, 1.0, 1.1, 0.3], 1.1), 1);
        assert_eq!(pick([0.5, 1.0, 1.2, 1.2], 1.1), 2);
        // A candidate whose gain is not finite is never taken.
        assert_eq!(pick([f64::NAN, 1.0, f64::INFINITY, 1.2], 1.1), 3);
        assert_eq!(pick([1.0, 1.0, 1.0, 1.0], 1.0), 1);
    }

    /// A pixel's largest contribution that stands out from its neighbours and from the
    /// pixel's other samples is re-counted at the horizon with the floor its rarity gives,
    /// for every candidate that samples it less densely than that floor; one that does not
    /// stand out, the plan in use's own moments, and `--pc-budget-rarity false` stay.
    #[test]
    fn rare_tops_are_recounted_with_the_floor_their_rarity_gives() {
        let plan = Plan { connections: 4, pool_paths: 8, splat_paths: 8 };
        let shares = Shares { unidirectional: 0.001, connection: 0.999, light_trace: 0.0 };
        // What a contribution `v` adds to a candidate's moments under `floor`.
        let u = shares.unidirectional as f64;
        let counted = |v: f64, d: f64, floor: f64| (v * v / typical(d, floor), v * v * u / (d * typical(d, floor)));
        let recount = |rarity: bool| {
            let opts = BudgetOptions { mode: BudgetMode::Auto, rarity, ..BudgetOptions::default() };
            let mut b = Budget::new(&opts, PRICES, 1..3, plan, 5, 5, None);
            let (n, c, floor) = (b.measured(), b.candidates.len(), b.weighing.floor);
            b.iterations = 2;
            b.s1 = vec![2.0; n];
            b.q = vec![1.0; n * c];
            b.realized = vec![RealizedSums::default(); n * c];
            b.top = vec![Top::default(); n];
            // Pixel 12 holds a connection of 100 beside 1 of its camera path's own; pixel 3
            // two samples of 1, the larger of them a connection too.
            b.s1[12] = 101.0;
            b.top[12] = Top { v: 100.0, shares };
            b.top[3] = Top { v: 1.0, shares };
            for (k, &(a, l)) in b.weighing.scales.iter().enumerate() {
                let (q, own) = counted(100.0, shares.combined(a, l), floor);
                b.q[12 * c + k] += q;
                b.realized[12 * c + k].own_moment = own;
            }
            let means = b.smoothed_means();
            b.recount_rare_tops(&means);
            (b, means)
        };
        let (on, means) = recount(true);
        let (c, floor) = (on.candidates.len(), on.weighing.floor);
        assert!((floor - 2.0 / DEFAULT_HORIZON as f64).abs() < 1e-12);
        // Against the larger of its smoothed mean and its own without the connection (1).
        let rarity = 100.0 / (2.0 * means[12].max(1.0));
        assert!(rarity > 10.0, "{rarity}");
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
        for (k, &(a, l)) in on.weighing.scales.iter().enumerate() {
            let (q, own) = counted(100.0, shares.combined(a, l), floor * rarity);
            let r = &on.realized[12 * c + k];
            assert!(close(on.q[12 * c + k], 1.0 + q) && close(r.own_moment, own), "candidate {k}");
        }
        // The plan in use samples it as densely as measured: unchanged. Path tracing, 1000
        // times less densely, counts `v² / (floor · rarity)` instead of `v² / floor`.
        let current = on.candidates.iter().position(|p| *p == plan).unwrap();
        let path = on.candidates.iter().position(Plan::path_tracing).unwrap();
        assert!(close(on.q[12 * c + current], 1.0 + 1e4));
        assert!(close(on.q[12 * c + path], 1.0 + 1e4 / (floor * rarity)));
        // Pixel 3's largest sample is its mean's size: nothing changes there, nor anywhere
        // with the option off.
        assert!(on.q[3 * c..4 * c].iter().all(|&q| q == 1.0));
        let (off, _) = recount(false);
        for (k, &(a, l)) in off.weighing.scales.iter().enumerate() {
            assert!(close(off.q[12 * c + k], 1.0 + counted(100.0, shares.combined(a, l), floor).0));
        }
        // The largest offer is kept; what is not finite is ignored.
        let mut top = Top::default();
        for v in [1.0, 5.0, f32::NAN, 3.0, f32::INFINITY] {
            top.offer(v, &shares);
        }
        assert_eq!(top.v, 5.0);
        assert_eq!(top.rarity(1.0, 2.0), 2.5);
        assert_eq!(top.rarity(10.0, 2.0), 1.0);
        assert_eq!(Top::default().rarity(1.0, 2.0), 1.0);
    }

    #[test]
    fn smoothed_means_average_the_measured_neighbours() {
        let plan = Plan { connections: 4, pool_paths: 8, splat_paths: 8 };
        for (w, h, r) in [(7, 5, 0), (7, 5, 1), (7, 5, 2), (4, 9, 3), (600, 400, 2)] {
            let opts = BudgetOptions { mode: BudgetMode::Auto, smoothing: r, ..BudgetOptions::default() };
            let mut b = Budget::new(&opts, PRICES, 1..3, plan, w, h, None);
            let (gw, gh) = b.grid();
            assert_eq!(gw * gh, b.measured());
            let most = opts.pixels;
            assert!(b.measured() <= most && (w * h > most) == (b.every > 1));
            b.iterations = 2;
            b.s1 = (0..gw * gh).map(|i| ((i * 7919) % 13) as f64).collect();
            let got = b.smoothed_means();
            let r = r as i64;
            for y in 0..gh as i64 {
                for x in 0..gw as i64 {
                    let (mut sum, mut n) = (0.0, 0.0);
                    for yy in (y - r).max(0)..=(y + r).min(gh as i64 - 1) {
                        for xx in (x - r).max(0)..=(x + r).min(gw as i64 - 1) {
                            sum += b.s1[(yy * gw as i64 + xx) as usize];
                            n += 1.0;
                        }
                    }
                    let want = sum / n / 2.0;
                    let g = got[(y * gw as i64 + x) as usize];
                    assert!((g - want).abs() < 1e-9, "{w}x{h} r {r} at ({x}, {y}): {g} against {want}");
                }
            }
        }
        // Every measured pixel has an index of its own.
        let opts = BudgetOptions { mode: BudgetMode::Auto, ..BudgetOptions::default() };
        let b = Budget::new(&opts, PRICES, 1..3, plan, 600, 400, None);
        let ids: std::collections::HashSet<usize> = (0..400)
            .flat_map(|y| (0..600).map(move |x| Vec2::new(x as f32 + 0.5, y as f32 + 0.5)))
            .filter_map(|p| b.measured_pixel(p))
            .collect();
        assert_eq!(ids.len(), b.measured());
        assert!(ids.iter().all(|&i| i < b.measured()));
    }
}
