//! Efficiency-aware connection budgets of the pool integrators (PCBPT, SPCBPT): the number
//! of pool connections per camera vertex (0, 1, 2, 4 or 8) and the number of light paths
//! that are light traced (none, the pool's `M`, a quarter of the pixels, or one per pixel),
//! chosen from the second moments and costs measured in a few iterations (the idea of
//! Grittmann, Yazici, Georgiev and Slusallek, "Efficiency-aware multiple importance sampling
//! for bidirectional rendering algorithms", SIGGRAPH 2022). With no connections and no light
//! tracing an iteration is plain path tracing with next-event estimation.
//!
//! **Second moments.** A budget `b'` scales the counts of the connection strategies by
//! `a = N'/N` and those of light tracing by `c = L'/L`, and leaves the camera path's own
//! (`s = 0`, next-event estimation) as they are. Under the balance heuristic a sample's
//! weighted contribution is `v = f / Σ_k n_k p_k`, and with the MIS shares `u`, `k_c`, `l` of
//! its path (the weights of its strategies summed by kind, [`Shares`]) the combined density
//! under `b'` is `Σ_k n_k p_k · (u + a k_c + c l)`. So `Σ v² / (u + a k_c + c l)` over the
//! samples of a pixel estimates `∫ f² / Σ n'_k p_k`, the second moment of that pixel's
//! estimate under `b'`, from samples of the budget in use (Grittmann et al.'s estimator). A
//! path no strategy of `b'` can make gives an infinite moment, so a budget that would lose
//! light (a caustic of a point light with no light tracing) is never chosen.
//!
//! **Variance.** A pixel's estimate sums many contributions (one per strategy and path
//! length), so its second moment is no variance: the variance under the budget in use is
//! measured across the iterations instead, and a candidate's is that plus the change of
//! second moment, taken in two steps: to the candidate's light tracing (light paths are
//! independent samples), then to its connections, that change multiplied by
//! `--pc-budget-independence` (0.35, fitted on `staircase2`, where a factor of 1 predicted
//! 3.4× the variance of the budget in use for no connections and 1.4× for one, and
//! equal-time renders measured 1.75× and 1.15×). With `measured` the factor is the share of
//! the connections' second moment that is variance about each camera vertex's own mean
//! ([`Spread`]): given the camera vertex and the pool a vertex's `N` draws are independent,
//! so only that part changes with `N`. It came out 0.71–0.99 on the six measured scenes, so
//! the shared prefix is not what 0.35 makes up for.
//!
//! **Choice.** Per candidate, `Σ_pixels variance / (mean² + 0.01)` (the relMSE the images
//! are judged by, on luminance) times the cost of an iteration, from the operations the
//! measured iterations counted, priced by [`Prices`]. The least product wins. A pixel's
//! `mean` is its own over the measured iterations, or with `--pc-budget-smoothing r` the
//! average over its measured neighbours within `r`: a pixel's own mean of two iterations,
//! squared, is biased up by their variance, which weighs the noisiest pixels least (on
//! `staircase2`, with independence 1, the budget in use looked 2.7× less noisy than with
//! `r = 2`, and no connections was predicted 5.2× as noisy as four connections, against
//! 2.7× with `r = 2` and 1.8× in renders). Smoothed means with the measured independence
//! predict better without a fitted factor, but chose no better at equal time
//! (BENCHMARKS.md). The default is the realized model below with `r = 2`, which chose
//! better than the moments at equal time (four seeds). The choice is made from counts alone, never
//! from clocks, so it is the same on every machine and for every thread count, and a chunk
//! that re-runs the measured iterations makes it again. Iterations of different budgets are
//! each unbiased and averaged alike; the film divides every iteration's splats by the same
//! count of light paths ([`normalise_splats`]).
//!
//! **The realized model** (`--pc-budget-model realized`, [`Realized`]). A pixel's estimate
//! of an iteration is a sum `Y = Σ_i v_i`, and `Var Y = E[Σ v_i²] + E[Σ_{i≠j} v_i v_j] −
//! (E Y)²`. The moments above predict only the first term's change; but the squared mean
//! and the products of a camera path's contributions change with the weights too. Moving
//! weight from the paths a camera path samples well to light tracing or to more draws
//! lowers their second moment and their squared mean alike, which the moments count as a
//! gain: on a constructed estimator (`tests` below) they predict 1.9 for a variance of
//! 0.083. The realized model keeps the diagonal from every strategy's samples (`q`) and takes
//! the rest from the camera samples re-weighted as the candidate would weigh them (the
//! cross terms of the camera path's own strategies scaled by how much of their heavy tail two
//! iterations miss), so it needs no independence factor. Against renders of fixed plans without connections (per-sample
//! relative variance over that of PCBPT's defaults, BENCHMARKS.md) it comes within 3% on
//! `cornell-ply` but for path tracing, 5–9% high (renders: 4.08, with the path tracer), where
//! the moments come 17–37% low (smoothed means, independence 1) or half (the defaults); on
//! `staircase2` within 3% for path tracing and 4–8% low for the pool's light tracing (seeds 2
//! and 3; seed 1 put path tracing at 3.0 against 1.8); on `veach-ajar` 8 connections at
//! 0.66× the variance of 4 and 2 at 1.65× (renders: 0.63–0.77×, 1.37–1.49×; the moments 0.88×
//! and 1.21×).
//!
//! **Known error.** Both models find more light tracing more useful than renders do: from
//! the pool's 735 light paths to 14 400 on `staircase2` the realized model predicts 13–20%
//! less variance (three seeds) and the moments 20%, renders 8%. Neither knows that the
//! path-tracing plan renders with the path tracer (the power heuristic between next-event
//! estimation and BSDF sampling), not with the camera pass's balance heuristic: on
//! `staircase2` it has less variance than the camera pass with the pool's light tracing.

use super::bdpt::{Bdpt, Connector};
use super::mis::{Shares, StrategyCounts};
use super::pcbpt::PcOptions;
use super::pool::{LightPool, PoolPlan};
use crate::film::{Splat, Tile};
use crate::integrator::Counters;
use crate::integrator::path::PathTracer;
use crate::integrator::render_loop::{Ctx, TileResult, sample_tile};
use crate::sampling::Sampler;
use glam::Vec2;
use serde::Serialize;
use std::ops::Range;

/// Whether the pool integrators choose their budget (`--pc-budget`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BudgetMode {
    /// `--pc-connections` and the pool's light paths, as given.
    Off,
    /// Chosen after `--pc-budget-iterations` measured iterations.
    Auto,
}

/// How a candidate's variance is predicted (`--pc-budget-model`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BudgetModel {
    /// The measured variance plus the change of the contributions' second moments
    /// (`Σ v² / (u + a k + c l)`), the connections' part times `--pc-budget-independence`.
    Moments,
    /// The variance of each camera sample re-weighted as the candidate would weigh it, with
    /// its draws' spread for a changed number of connections, plus light tracing's second
    /// moment ([`Realized`]).
    Realized,
}

/// How much of the connections' predicted change of second moment counts
/// (`--pc-budget-independence`): a fixed share, or the share measured from their spread
/// within camera vertices ([`Spread`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum Independence {
    Fixed(f32),
    Measured(MeasuredWord),
}

/// The word `measured` (of [`Independence`] in experiment files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MeasuredWord {
    Measured,
}

impl Independence {
    pub const MEASURED: Independence = Independence::Measured(MeasuredWord::Measured);

    /// The fixed share, `None` when measured.
    pub fn fixed(&self) -> Option<f32> {
        match *self {
            Independence::Fixed(f) => Some(f),
            Independence::Measured(_) => None,
        }
    }
}

impl std::str::FromStr for Independence {
    type Err = String;
    fn from_str(s: &str) -> Result<Independence, String> {
        if s == "measured" {
            return Ok(Independence::MEASURED);
        }
        s.parse::<f32>()
            .map(Independence::Fixed)
            .map_err(|_| format!("expected a number from 0 to 1 or `measured`, not `{s}`"))
    }
}

impl std::fmt::Display for Independence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.fixed() {
            Some(x) => write!(f, "{x}"),
            None => f.write_str("measured"),
        }
    }
}

/// Connections per camera vertex a budget may choose.
pub const CONNECTION_CHOICES: [u32; 5] = [0, 1, 2, 4, 8];

/// Pixels whose moments are measured: those of every `k`-th row and column, at most about
/// this many.
const MEASURED_PIXELS: usize = 65_536;

/// The `0.01` of relMSE's denominator.
const REL_EPSILON: f64 = 0.01;

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
/// by iterations: a bias of a few percent when the plan changes the share of light tracing).
pub(crate) fn normalise_splats(splats: &mut [Splat], plan: &Plan, reference: usize) -> u64 {
    if plan.splat_paths > 0 && plan.splat_paths != reference {
        let k = reference as f32 / plan.splat_paths as f32;
        for sp in splats.iter_mut() {
            sp.value *= k;
        }
    }
    reference as u64
}

/// One camera sample of a pool integrator, into any sink.
pub(crate) trait CameraSample {
    fn sample(&mut self, pos: Vec2, rng: &mut Sampler, sink: &mut impl super::Sink, counters: &mut Counters);
}

/// A tile of iteration `first` as the budget has it: the path tracer's when the plan
/// [`Plan::path_tracing`], or `sample`'s with the measured pixels' contributions recorded in
/// a measured iteration; `None` otherwise (the integrator renders it its own way).
pub(crate) fn budget_tile(
    ctx: &Ctx,
    tile: Tile,
    first: u32,
    count: u32,
    budget: &Budget,
    sample: &mut impl CameraSample,
) -> Option<TileResult> {
    if !budget.measures(first) {
        return (budget.plan().path_tracing() && !ctx.layers).then(|| path_traced_tile(ctx, tile, first, count));
    }
    let mut moments = budget.tile_moments();
    let mut result = sample_tile(ctx, tile, first, count, |pos, rng, sink, counters| {
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
    result.extra = Some(Box::new(moments));
    Some(result)
}

/// A tile of a plan that [`Plan::path_tracing`]: the path tracer's samples (next-event
/// estimation and BSDF sampling under the power heuristic, `src/integrator/path.rs`), which
/// cost less than the bidirectional camera pass with its stored vertices and ratio walks.
fn path_traced_tile(ctx: &Ctx, tile: Tile, first: u32, count: u32) -> TileResult {
    let pt = PathTracer::new(&ctx.scene.integrator);
    sample_tile(ctx, tile, first, count, |pos, sampler, sink, counters| {
        let ray = ctx.scene.camera.generate_ray(pos);
        counters.camera_rays += 1;
        sink.l = pt.li(ctx.scene, ray, sampler, counters);
        true
    })
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

/// Relative cost of the operations an iteration counts, in extension rays (a closest-hit
/// ray and the vertex built at its hit). Measured with PCBPT on `staircase2` (320×180,
/// 24 spp, 2 threads) with 0, 1, 4 and 8 connections per camera vertex: the camera pass took
/// 1.68, 2.73, 4.37 and 6.53 s for 0, 2.52, 10.1 and 20.1 M pool shadow rays, so a traced
/// connection (its draw, both BSDFs, the shadow ray and the MIS weight) costs 0.216 µs; the
/// 4.69 M lookups that drawing needs 0.108 µs each; the pass without connections, 5.32 M
/// extension rays and 3.14 M next-event rays priced like connections, leaves 0.187 µs per
/// extension ray; a cache entry (its target and shadow ray) took 0.188 µs (1.0 M in 0.19 s).
#[derive(Clone, Copy, Debug)]
pub struct Prices {
    pub shadow: f64,
    pub lookup: f64,
    pub cache_entry: f64,
    /// The path tracer's camera pass over the bidirectional one's without connections: 124
    /// and 151 samples per pixel in 10 s on `staircase2` (320×180, 2 threads).
    pub path_tracer: f64,
}

pub const PRICES: Prices = Prices { shadow: 1.15, lookup: 0.58, cache_entry: 1.0, path_tracer: 0.82 };

/// Operations one iteration performed, summed over the measured iterations.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Operations {
    /// Camera and extension rays of the camera pass.
    pub camera_rays: u64,
    /// Shadow rays of the camera pass other than pool connections (next-event estimation).
    pub camera_shadow: u64,
    /// Shadow rays of pool connections.
    pub pool_shadow: u64,
    /// Camera vertices that drew connections.
    pub lookups: u64,
    /// Rays of the light paths.
    pub light_rays: u64,
    /// Shadow rays of light tracing.
    pub splat_shadow: u64,
    /// Cache entries built for the pool (PCBPT's records × pool vertices; 0 for SPCBPT).
    pub cache_entries: u64,
}

impl std::ops::AddAssign for Operations {
    fn add_assign(&mut self, o: Operations) {
        self.camera_rays += o.camera_rays;
        self.camera_shadow += o.camera_shadow;
        self.pool_shadow += o.pool_shadow;
        self.lookups += o.lookups;
        self.light_rays += o.light_rays;
        self.splat_shadow += o.splat_shadow;
        self.cache_entries += o.cache_entries;
    }
}

impl Operations {
    /// These operations with those of a camera pass's tiles added.
    pub(crate) fn with_camera_pass(mut self, results: &[TileResult]) -> Operations {
        for r in results {
            let c = &r.counters;
            self.camera_rays += c.camera_rays + c.extension_rays;
            self.camera_shadow += c.shadow_rays - c.pool_shadow_rays;
            self.pool_shadow += c.pool_shadow_rays;
            self.lookups += c.pool_lookups;
        }
        self
    }

    /// The cost of an iteration under `to`, in extension rays, from these operations made
    /// under `from`.
    pub fn cost(&self, from: &Plan, to: &Plan, prices: &Prices) -> f64 {
        let ratio = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
        let mut c = self.camera_rays as f64 + prices.shadow * self.camera_shadow as f64;
        if to.path_tracing() {
            return c * prices.path_tracer;
        }
        if to.connections > 0 {
            c += prices.shadow * self.pool_shadow as f64 * to.connections as f64 / from.connections.max(1) as f64;
            c += prices.cache_entry * self.cache_entries as f64 + prices.lookup * self.lookups as f64;
        }
        c += self.light_rays as f64 * ratio(to.traced(), from.traced());
        c += prices.shadow * self.splat_shadow as f64 * ratio(to.splat_paths, from.splat_paths);
        c
    }
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

/// A light-tracing splat's luminance and MIS shares.
#[derive(Clone, Copy, Debug)]
pub struct SplatShares {
    pub pos: Vec2,
    pub value: f32,
    pub shares: Shares,
}

/// The count scales `(a, c)` of each candidate against the plan in use.
fn scales(from: &Plan, candidates: &[Plan]) -> Vec<(f64, f64)> {
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
    candidates
        .iter()
        .map(|p| {
            (ratio(p.connections as f64, from.connections as f64), ratio(p.splat_paths as f64, from.splat_paths as f64))
        })
        .collect()
}

/// The camera path's own strategies' part of a contribution's second moment under a
/// candidate whose combined density is `d` times the plan in use's: `v² u / d²`.
#[inline]
fn own_moment(v: f32, s: &Shares, d: f64) -> f64 {
    if d > 0.0 && v.is_finite() && v > 0.0 { (v as f64).powi(2) * s.unidirectional as f64 / (d * d) } else { 0.0 }
}

/// Adds a contribution of luminance `v` and shares `s` to a pixel's moments: its value to
/// `x`, and `v² / (u + a k + c l)` for every candidate's scales to `q`.
#[inline]
fn accumulate(v: f32, s: &Shares, scales: &[(f64, f64)], x: &mut f64, q: &mut [f64]) {
    if !(v.is_finite() && v > 0.0) {
        return;
    }
    let v = v as f64;
    *x += v;
    for (q, &(a, c)) in q.iter_mut().zip(scales) {
        let d = s.combined(a, c);
        *q += if d > 0.0 { v * v / d } else { f64::INFINITY };
    }
}

/// How independent the pool connections of one camera vertex are, from their contributions
/// `v_1 … v_N` (the `N` draws of each camera vertex, those that found nothing counting as 0):
/// `raw` sums the second moment per draw, `Σ v_j² / N`, and `within` the unbiased variance
/// of the draws about their own camera vertex's mean, `(Σ v_j² − (Σ v_j)² / N) / (N − 1)`.
/// Given the camera vertex and the pool the draws are independent, so only `within` shrinks
/// with more draws; the moment estimator counts all of `raw` as if it did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Spread {
    pub raw: f64,
    pub within: f64,
}

impl Spread {
    fn add(&mut self, sum: f64, sum2: f64, draws: u32) {
        if draws < 2 {
            return;
        }
        let n = draws as f64;
        self.raw += sum2 / n;
        self.within += ((sum2 - sum * sum / n) / (n - 1.0)).max(0.0);
    }

    /// Adds `other`'s sums weighted by `k`.
    fn add_weighted(&mut self, other: &Spread, k: f64) {
        self.raw += other.raw * k;
        self.within += other.within * k;
    }

    /// The share of the connections' second moment that more or fewer draws change:
    /// `within / raw`, in `[0, 1]`; `None` with nothing measured.
    pub fn independence(&self) -> Option<f64> {
        (self.raw > 0.0).then(|| (self.within / self.raw).clamp(0.0, 1.0))
    }
}

/// The moments of one tile's measured pixels in one iteration.
pub struct TileMoments {
    scales: Vec<(f64, f64)>,
    /// Measured-pixel index of each entry.
    ids: Vec<u32>,
    x: Vec<f64>,
    /// `q` of entry `e` at `[e * C .. (e + 1) * C]`.
    q: Vec<f64>,
    /// Per entry: the pool connections' second moment per draw and their variance within
    /// camera vertices, summed over the entry's camera vertices ([`Spread`]).
    spread: Vec<Spread>,
    /// Per entry and candidate (like `q`): the camera sample as the candidate would weigh
    /// it, and its connections' correction for the candidate's number of draws ([`Realized`]).
    realized: Vec<Realized>,
    /// Connections each camera vertex draws under the plan in use.
    draws: u32,
    /// The camera vertex whose connections are being summed: its depth, `Σ v`, `Σ v²`.
    vertex: (usize, f64, f64),
    /// The same per candidate, of its weights' draws `v / (u + a k + c l)`.
    vertex_realized: Vec<(f64, f64)>,
}

impl TileMoments {
    /// No entries yet, for candidates' count scales `scales` and `draws` connections per
    /// camera vertex.
    fn new(scales: Vec<(f64, f64)>, draws: u32) -> TileMoments {
        let c = scales.len();
        TileMoments {
            scales,
            ids: Vec::new(),
            x: Vec::new(),
            q: Vec::new(),
            spread: Vec::new(),
            realized: Vec::new(),
            draws,
            vertex: (0, 0.0, 0.0),
            vertex_realized: vec![(0.0, 0.0); c],
        }
    }

    /// Starts the entry of measured pixel `id`.
    pub fn begin(&mut self, id: usize) {
        self.end_vertex();
        self.ids.push(id as u32);
        self.x.push(0.0);
        self.q.extend(std::iter::repeat_n(0.0, self.scales.len()));
        self.realized.extend(std::iter::repeat_n(Realized::default(), self.scales.len()));
        self.spread.push(Spread::default());
    }

    /// Adds a pool connection's contribution `v` (shares `s`) from the camera vertex at
    /// depth `t`. A camera vertex's draws arrive together; those that found nothing add
    /// nothing.
    fn connection(&mut self, t: usize, v: f32, s: &Shares) {
        if !(v.is_finite() && v > 0.0) {
            return;
        }
        if t != self.vertex.0 {
            self.end_vertex();
            self.vertex.0 = t;
        }
        let v = v as f64;
        self.vertex.1 += v;
        self.vertex.2 += v * v;
        for (acc, &(a, c)) in self.vertex_realized.iter_mut().zip(&self.scales) {
            let d = s.combined(a, c);
            if d > 0.0 {
                acc.0 += v / d;
                acc.1 += (v / d) * (v / d);
            }
        }
    }

    /// Adds the camera vertex being summed to the entry's [`Spread`] and, per candidate, its
    /// draws' correction to the entry's [`Realized`].
    pub fn end_vertex(&mut self) {
        let (_, sum, sum2) = std::mem::take(&mut self.vertex);
        let c = self.scales.len();
        if let (Some(spread), true) = (self.spread.last_mut(), sum2 > 0.0) {
            spread.add(sum, sum2, self.draws);
            let at = self.realized.len() - c;
            for ((r, acc), &(a, _)) in self.realized[at..].iter_mut().zip(&mut self.vertex_realized).zip(&self.scales) {
                r.add_pairs(std::mem::take(acc), a, self.draws);
            }
        }
        self.vertex_realized.iter_mut().for_each(|acc| *acc = (0.0, 0.0));
    }

    /// Adds a contribution of luminance `v` and shares `shares` made by a strategy of
    /// [`Shares::class`] `class` of the camera sample.
    fn record(&mut self, v: f32, shares: &Shares, class: usize) {
        let c = self.scales.len();
        let (Some(x), true) = (self.x.last_mut(), self.q.len() >= c) else { return };
        let at = self.q.len() - c;
        accumulate(v, shares, &self.scales, x, &mut self.q[at..]);
        if v.is_finite() && v > 0.0 {
            for (r, &(a, l)) in self.realized[at..].iter_mut().zip(&self.scales) {
                let d = shares.combined(a, l);
                let own = if class == 1 { a } else { 1.0 };
                if d > 0.0 && own > 0.0 {
                    let w = v as f64 * own / d;
                    r.sample += w;
                    r.diagonal += w * w;
                    if class == 0 {
                        r.own_sample += w;
                        r.own_diagonal += w * w;
                    }
                }
                r.own_moment += own_moment(v, shares, d);
            }
        }
    }
}

/// A camera sample as a candidate would weigh it (`--pc-budget-model realized`). Under a
/// budget that scales the connection counts by `a` and light tracing's by `c`, a contribution
/// `v` of the camera path's own strategies weighs `v' = v / (u + a k + c l)` and a
/// connection's `a v'` (the `N' = a N` draws estimated from the `N` made), so `sample` is the
/// candidate's estimate from the same camera path. A pixel's variance under the candidate is
/// `E[Σ_i v_i²] + E[Σ_{i≠j} v_i v_j] − (E Y)²`: the first, the diagonal, is the second moment
/// `Σ v² / (u + a k + c l)` that every strategy's samples estimate (light tracing's
/// included); the others come from the realized samples, `sample² − diagonal` over the
/// iterations and the product of different iterations' `sample`s. Given the camera vertex
/// the draws are independent, so their pairs' products, `N (N − 1)` of them made and
/// `N' (N' − 1)` wanted, are rescaled (`pairs`). Unlike the change of second moments alone
/// this keeps the squared means and the correlation of a camera path's contributions
/// (depths, draws of one vertex, the shared prefix): moving weight from the well-sampled
/// paths of the camera path to light tracing or to more draws lowers their second moment and
/// their squared mean as much, which the moments took for a gain.
///
/// The realized samples see the paths that the camera path's own strategies sample rarely
/// only as rarely, so in two iterations their sums miss much of a heavy tail. The diagonal
/// is taken from every strategy's samples for that reason; the cross terms cannot be, and
/// those with a contribution of the camera path's own strategies ([`Realized::cross`]) are
/// scaled by how much the realized samples miss of those strategies' diagonal (`own_moment`,
/// from every strategy's samples, over `own_diagonal`, realized; summed over the pixels as
/// relMSE weighs them: [`BudgetStats::missed`]). Without it the model put path tracing on
/// `cornell-ply` at 3.3× the variance of PCBPT's defaults (renders: 4.1×), with it at
/// 4.3–4.4× (the realized samples missed 42% of the camera path's diagonal). Scaling the
/// connections' cross terms too (they have no such tail) put 8 connections on `veach-ajar`
/// at 0.61× the variance of 4 and 2 at 1.76× (renders: 0.63–0.77×, 1.37–1.49×); without, at
/// 0.66× and 1.65×.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Realized {
    pub sample: f64,
    pub diagonal: f64,
    pub pairs: f64,
    /// The camera path's own strategies' share of `sample`, of `diagonal`, and of `q`
    /// (their second moment `Σ v² u / (u + a k + c l)²` from every strategy's samples).
    pub own_sample: f64,
    pub own_diagonal: f64,
    pub own_moment: f64,
}

impl Realized {
    /// The cross terms `sample² − diagonal` (draws' pairs rescaled), split into those with
    /// a contribution of the camera path's own strategies and the others (connections with
    /// connections).
    fn cross(&self) -> (f64, f64) {
        let (own, other) = (self.own_sample, self.sample - self.own_sample);
        let with_own = own * own - self.own_diagonal + 2.0 * own * other;
        (with_own, other * other - (self.diagonal - self.own_diagonal) + self.pairs)
    }
}

impl Realized {
    /// Adds one camera vertex's draws under a candidate, `Σ v'` and `Σ v'²` over its `n`
    /// draws, for `a n` draws: the products of pairs, `(Σ v')² − Σ v'²` of them made with
    /// weight `a²` in `sample²`, count `a n (a n − 1) / (n (n − 1))`.
    fn add_pairs(&mut self, (sum, sum2): (f64, f64), a: f64, n: u32) {
        if n < 2 || a == 1.0 {
            return;
        }
        let n = n as f64;
        self.pairs += (a * (a * n - 1.0) / (n - 1.0) - a * a) * (sum * sum - sum2);
    }
}

/// Wraps a camera sample's sink: passes everything on, and records each contribution's
/// luminance and shares into the tile's moments.
pub struct BudgetSink<'a, S> {
    pub inner: &'a mut S,
    pub moments: &'a mut TileMoments,
    pub pending: Shares,
}

impl<S: super::Sink> super::Sink for BudgetSink<'_, S> {
    #[inline]
    fn add(&mut self, s: usize, t: usize, value: crate::math::Rgb) {
        self.moments.record(crate::math::luminance(value), &self.pending, Shares::class(s, t));
        self.inner.add(s, t, value);
    }

    fn splat(&mut self, s: usize, t: usize, pos: Vec2, value: crate::math::Rgb) {
        // Camera passes of the pool integrators do not splat; their light tracing is the
        // pool's, measured through `SplatShares`.
        self.inner.splat(s, t, pos, value);
    }

    fn add_emission(&mut self, camera: &[super::Vertex], value: crate::math::Rgb) {
        self.moments.record(crate::math::luminance(value), &self.pending, 0);
        self.inner.add_emission(camera, value);
    }

    fn add_connection(&mut self, light: &[super::Vertex], camera: &[super::Vertex], c: crate::math::Rgb, w: f32) {
        let v = crate::math::luminance(c * w);
        let class = Shares::class(light.len(), camera.len());
        self.moments.record(v, &self.pending, class);
        if class == 1 {
            self.moments.connection(camera.len(), v, &self.pending);
        }
        self.inner.add_connection(light, camera, c, w);
    }

    fn wants_shares(&self) -> bool {
        true
    }

    fn note_shares(&mut self, shares: Shares) {
        self.pending = shares;
    }
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
}

/// The budget of a pool integrator over a render: the plan in use, and the measurement that
/// replaces it.
pub struct Budget {
    pub mode: BudgetMode,
    /// Iterations whose samples are measured; the plan changes after the last.
    pub window: Range<u32>,
    plan: Plan,
    candidates: Vec<Plan>,
    scales: Vec<(f64, f64)>,
    /// The pixels of every `every`-th row and column are measured: `columns` of them a row.
    every: usize,
    columns: usize,
    width: usize,
    height: usize,
    pixels: usize,
    s1: Vec<f64>,
    s2: Vec<f64>,
    q: Vec<f64>,
    /// Per measured pixel and candidate (like `q`), for [`BudgetModel::Realized`]: the sums
    /// over the iterations of the pixel's camera samples as the candidate weighs them
    /// ([`Realized`]), of their squares, and of their cross terms (square less diagonal,
    /// draws' pairs rescaled).
    y1: Vec<f64>,
    y2: Vec<f64>,
    cross: Vec<(f64, f64)>,
    /// Per measured pixel and candidate: the camera path's own strategies' diagonal, as
    /// realized and from every strategy's samples, summed over the iterations.
    own: Vec<(f64, f64)>,
    model: BudgetModel,
    /// Per measured pixel, its pool connections' [`Spread`].
    spread: Vec<Spread>,
    operations: Operations,
    iterations: u32,
    /// `--pc-budget-independence`; `None`: measured ([`Spread`]).
    independence: Option<f64>,
    /// `--pc-budget-smoothing`: measured pixels each side whose means are averaged for
    /// relMSE's denominator ([`Budget::smoothed_means`]).
    smoothing: usize,
    pub stats: BudgetStats,
}

impl Budget {
    /// A budget that starts with `plan` and, with `--pc-budget auto`, measures `window`.
    pub fn new(opts: &PcOptions, window: Range<u32>, plan: Plan, width: usize, height: usize) -> Budget {
        let mode = opts.budget;
        let pixels = width * height;
        let candidates = if mode == BudgetMode::Auto { candidates(plan.pool_paths, pixels) } else { Vec::new() };
        let scales = scales(&plan, &candidates);
        let every = (pixels as f64 / MEASURED_PIXELS as f64).sqrt().ceil().max(1.0) as usize;
        Budget {
            mode,
            window,
            plan,
            candidates,
            scales,
            every,
            columns: width.div_ceil(every),
            width,
            height,
            pixels,
            s1: Vec::new(),
            s2: Vec::new(),
            q: Vec::new(),
            y1: Vec::new(),
            y2: Vec::new(),
            cross: Vec::new(),
            own: Vec::new(),
            model: opts.budget_model,
            operations: Operations::default(),
            iterations: 0,
            spread: Vec::new(),
            independence: opts.budget_independence.fixed().map(f64::from),
            smoothing: opts.budget_smoothing as usize,
            stats: BudgetStats::default(),
        }
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
        let (pool, mut splats, counters, splat_shares) =
            LightPool::trace_plan(ctx.scene, &bdpt.limits, self.plan.pool(), ctx.seed, first as u64, splat, measures);
        let splat_paths = normalise_splats(&mut splats, &self.plan, m);
        let operations = Operations {
            light_rays: counters.camera_rays + counters.extension_rays,
            splat_shadow: counters.shadow_rays,
            ..Operations::default()
        };
        TracedPool { pool, splats, counters, splat_shares, operations, splat_paths }
    }

    /// After iteration `i`'s camera pass (`results`): adds it when it is measured.
    pub(crate) fn finish(&mut self, i: u32, results: &[TileResult], splat_shares: &[SplatShares], ops: Operations) {
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

    /// Empty moments for a tile of a measured iteration.
    pub fn tile_moments(&self) -> TileMoments {
        TileMoments::new(self.scales.clone(), self.plan.connections)
    }

    /// Adds a measured iteration: its tiles' moments (in `extra`, in tile order), its
    /// splats' shares and the operations it made; after the last iteration of the window,
    /// chooses the plan.
    fn add_iteration(&mut self, results: &[TileResult], splats: &[SplatShares], operations: Operations) {
        let (n, c) = (self.measured(), self.candidates.len());
        if self.s1.is_empty() {
            self.s1 = vec![0.0; n];
            self.spread = vec![Spread::default(); n];
            self.s2 = vec![0.0; n];
            self.q = vec![0.0; n * c];
            self.y1 = vec![0.0; n * c];
            self.y2 = vec![0.0; n * c];
            self.cross = vec![(0.0, 0.0); n * c];
            self.own = vec![(0.0, 0.0); n * c];
        }
        let mut x = vec![0.0f64; n];
        let mut y = vec![Realized::default(); n * c];
        for r in results {
            let Some(m) = r.extra.as_ref().and_then(|e| e.downcast_ref::<TileMoments>()) else { continue };
            for (e, &id) in m.ids.iter().enumerate() {
                let id = id as usize;
                x[id] += m.x[e];
                self.spread[id].add_weighted(&m.spread[e], 1.0);
                let (to, from) = (id * c..(id + 1) * c, e * c..(e + 1) * c);
                for (q, add) in self.q[to.clone()].iter_mut().zip(&m.q[from.clone()]) {
                    *q += add;
                }
                for (y, r) in y[to].iter_mut().zip(&m.realized[from]) {
                    y.sample += r.sample;
                    y.diagonal += r.diagonal;
                    y.pairs += r.pairs;
                    y.own_sample += r.own_sample;
                    y.own_diagonal += r.own_diagonal;
                    y.own_moment += r.own_moment;
                }
            }
        }
        // A splat adds `value · W·H / L` to its pixel's estimate of the iteration (the film
        // divides the splats of `L` light paths by `L / (W·H)` samples per pixel).
        let per_path = self.pixels as f32 / self.plan.splat_paths.max(1) as f32;
        for sp in splats {
            if let Some(id) = self.measured_pixel(sp.pos) {
                let v = sp.value * per_path;
                accumulate(v, &sp.shares, &self.scales, &mut x[id], &mut self.q[id * c..(id + 1) * c]);
                for (y, &(a, l)) in y[id * c..(id + 1) * c].iter_mut().zip(&self.scales) {
                    y.own_moment += own_moment(v, &sp.shares, sp.shares.combined(a, l));
                }
            }
        }
        for (id, x) in x.into_iter().enumerate() {
            self.s1[id] += x;
            self.s2[id] += x * x;
        }
        for (k, y) in y.into_iter().enumerate() {
            self.y1[k] += y.sample;
            self.y2[k] += y.sample * y.sample;
            let (with_own, other) = y.cross();
            self.cross[k].0 += with_own;
            self.cross[k].1 += other;
            self.own[k].0 += y.own_diagonal;
            self.own[k].1 += y.own_moment;
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
        let norm = |id: usize| 1.0 / (means[id] * means[id] + REL_EPSILON);
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
            for (s, o) in seen.iter_mut().zip(&self.own[id * c..(id + 1) * c]) {
                s.0 += o.0 * norm(id);
                s.1 += o.1 * norm(id);
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
            let own = |k: usize| {
                let (y1, y2) = (self.y1[at + k], self.y2[at + k]);
                let (with_own, other) = self.cross[at + k];
                (q[k] + missed[k] * with_own + other) / t - (y1 * y1 - y2) / (t * (t - 1.0)).max(1.0)
            };
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
        let per_iteration = |p: &Plan| self.operations.cost(&from, p, &PRICES) / t;
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
            self.plan = self.candidates[b];
            self.stats.predicted_gain = score(current) / score(b).max(f64::MIN_POSITIVE);
        }
        self.stats.chosen = Some(self.plan);
        self.s1 = Vec::new();
        self.s2 = Vec::new();
        self.q = Vec::new();
        self.spread = Vec::new();
        self.y1 = Vec::new();
        self.y2 = Vec::new();
        self.cross = Vec::new();
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

    /// The estimator of another budget's second moment is exact for a path sampled by two
    /// strategies with known densities: the balance-heuristic samples of budget `n` predict
    /// `∫ f² / Σ n' p` for budget `n'`.
    #[test]
    fn moments_of_another_budget_match_their_integral() {
        // On [0, 1]: f(x) = 1 + x; "unidirectional" samples uniform (p_u = 1, count 1),
        // "connections" with density p_k(x) = 2x (count n = 2).
        let f = |x: f64| 1.0 + x;
        let (pu, pk) = (|_x: f64| 1.0, |x: f64| 2.0 * x);
        let n = 2.0;
        let mut rng = crate::sampling::Sampler::new(&[5]);
        let scales = [(0.0, 0.0), (0.5, 0.0), (1.0, 0.0), (4.0, 0.0)];
        let mut q = [0.0f64; 4];
        let mut x = 0.0;
        let runs = 200_000;
        let shares = |y: f64| {
            let total = pu(y) + n * pk(y);
            Shares { unidirectional: (pu(y) / total) as f32, connection: (n * pk(y) / total) as f32, light_trace: 0.0 }
        };
        for _ in 0..runs {
            // One unidirectional sample and `n` connection samples per run.
            let y = rng.next_1d() as f64;
            let v = f(y) / (pu(y) + n * pk(y));
            accumulate(v as f32, &shares(y), &scales, &mut x, &mut q);
            for _ in 0..n as usize {
                let y = (rng.next_1d() as f64).sqrt();
                let v = f(y) / (pu(y) + n * pk(y));
                accumulate(v as f32, &shares(y), &scales, &mut x, &mut q);
            }
        }
        assert!((x / runs as f64 - 1.5).abs() < 0.01, "mean {}", x / runs as f64);
        for (k, &(a, _)) in scales.iter().enumerate() {
            // ∫ (1+x)² / (1 + a n 2x) dx by the midpoint rule.
            let m = 100_000;
            let exact: f64 = (0..m)
                .map(|i| {
                    let y = (i as f64 + 0.5) / m as f64;
                    f(y) * f(y) / (pu(y) + a * n * pk(y))
                })
                .sum::<f64>()
                / m as f64;
            let est = q[k] / runs as f64;
            assert!((est / exact - 1.0).abs() < 0.01, "scale {a}: {est} against {exact}");
        }
    }

    /// The realized model predicts another budget's variance where the change of second
    /// moments does not: a camera sample of one "unidirectional" sample and `N` independent
    /// "connection" draws, with the balance heuristic, re-weighted for `N' = a N` draws,
    /// against the exact variance of the `N'`-draw estimator. The moments leave out the
    /// squared means, which change with the weights: they must miss by more.
    #[test]
    fn realized_variance_of_another_budget_matches_its_integral() {
        let f = |x: f64| 1.0 + x;
        let (pu, pk) = (|_x: f64| 1.0, |x: f64| 2.0 * x);
        let n = 4u32;
        let scales = vec![(1.0, 0.0), (0.0, 0.0), (0.25, 0.0), (0.5, 0.0), (2.0, 0.0)];
        let c = scales.len();
        let mut rng = crate::sampling::Sampler::new(&[11]);
        let runs = 2_000_000;
        let shares = |y: f64, draws: f64| {
            let total = pu(y) + draws * pk(y);
            Shares {
                unidirectional: (pu(y) / total) as f32,
                connection: (draws * pk(y) / total) as f32,
                light_trace: 0.0,
            }
        };
        let (mut y1, mut y2, mut cross, mut x1, mut x2, mut q) =
            (vec![0.0; c], vec![0.0; c], vec![(0.0, 0.0); c], 0.0, 0.0, vec![0.0; c]);
        let mut seen = vec![(0.0, 0.0); c];
        let mut m = TileMoments::new(scales.clone(), n);
        for run in 0..runs {
            if run % 10_000 == 0 {
                m = TileMoments::new(scales.clone(), n);
            }
            m.begin(0);
            let y = rng.next_1d() as f64;
            m.record((f(y) / (pu(y) + n as f64 * pk(y))) as f32, &shares(y, n as f64), 0);
            for _ in 0..n {
                let y = (rng.next_1d() as f64).sqrt();
                let v = (f(y) / (pu(y) + n as f64 * pk(y))) as f32;
                m.record(v, &shares(y, n as f64), 1);
                m.connection(2, v, &shares(y, n as f64));
            }
            m.end_vertex();
            let e = m.ids.len() - 1;
            x1 += m.x[e];
            x2 += m.x[e] * m.x[e];
            for k in 0..c {
                let r = m.realized[e * c + k];
                y1[k] += r.sample;
                y2[k] += r.sample * r.sample;
                let (with_own, other) = r.cross();
                assert!((with_own + other - (r.sample * r.sample - r.diagonal + r.pairs)).abs() < 1e-9);
                cross[k].0 += with_own;
                cross[k].1 += other;
                seen[k].0 += r.own_diagonal;
                seen[k].1 += r.own_moment;
                q[k] += m.q[e * c + k];
            }
        }
        let t = runs as f64;
        let variance = |s1: f64, s2: f64| (s2 - s1 * s1 / t) / (t - 1.0);
        let measured = variance(x1, x2);
        let integral = |g: &dyn Fn(f64) -> f64| {
            let m = 100_000;
            (0..m).map(|i| g((i as f64 + 0.5) / m as f64)).sum::<f64>() / m as f64
        };
        for (k, &(a, _)) in scales.iter().enumerate() {
            let n2 = a * n as f64;
            let g = |x: f64| f(x) / (pu(x) + n2 * pk(x));
            let var_u = integral(&|x| g(x) * g(x)) - integral(&g).powi(2);
            let var_k = integral(&|x| g(x) * g(x) * pk(x)) - integral(&|x| g(x) * pk(x)).powi(2);
            let exact = var_u + n2 * var_k;
            let missed = seen[k].1 / seen[k].0;
            assert!((missed - 1.0).abs() < 0.02, "a = {a}: the realized samples missed {missed}");
            let realized = (q[k] + missed * cross[k].0 + cross[k].1) / t - (y1[k] * y1[k] - y2[k]) / (t * (t - 1.0));
            let moments = measured + (q[k] - q[0]) / t;
            assert!((realized / exact - 1.0).abs() < 0.03, "a = {a}: realized {realized} against {exact}");
            if a != 1.0 {
                assert!((moments / exact - 1.0).abs() > 0.1, "a = {a}: moments {moments} close to {exact}");
            }
        }
    }

    /// A budget without the only strategy that makes a path predicts an infinite moment.
    #[test]
    fn losing_a_paths_only_strategy_costs_an_infinite_moment() {
        let mut x = 0.0;
        let mut q = [0.0; 2];
        let s = Shares { unidirectional: 0.0, connection: 0.0, light_trace: 1.0 };
        accumulate(1.0, &s, &[(1.0, 1.0), (1.0, 0.0)], &mut x, &mut q);
        assert_eq!(q[0], 1.0);
        assert!(q[1].is_infinite());
    }

    #[test]
    fn smoothed_means_average_the_measured_neighbours() {
        let plan = Plan { connections: 4, pool_paths: 8, splat_paths: 8 };
        for (w, h, r) in [(7, 5, 0), (7, 5, 1), (7, 5, 2), (4, 9, 3), (600, 400, 2)] {
            let opts = PcOptions { budget: BudgetMode::Auto, budget_smoothing: r, ..PcOptions::default() };
            let mut b = Budget::new(&opts, 1..3, plan, w, h);
            let (gw, gh) = b.grid();
            assert_eq!(gw * gh, b.measured());
            assert!(b.measured() <= MEASURED_PIXELS && (w * h > MEASURED_PIXELS) == (b.every > 1));
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
        let opts = PcOptions { budget: BudgetMode::Auto, ..PcOptions::default() };
        let b = Budget::new(&opts, 1..3, plan, 600, 400);
        let ids: std::collections::HashSet<usize> = (0..400)
            .flat_map(|y| (0..600).map(move |x| Vec2::new(x as f32 + 0.5, y as f32 + 0.5)))
            .filter_map(|p| b.measured_pixel(p))
            .collect();
        assert_eq!(ids.len(), b.measured());
        assert!(ids.iter().all(|&i| i < b.measured()));
    }

    #[test]
    fn spread_separates_camera_vertices_and_counts_draws_that_found_nothing() {
        let mut m = TileMoments::new(vec![(1.0, 1.0)], 4);
        // Pixel 0: a camera vertex whose four draws agree (no spread at all).
        m.begin(0);
        for _ in 0..4 {
            m.connection(2, 0.5, &Shares::default());
        }
        // Pixel 1: one draw of four finds light at depth 2, two of four at depth 3.
        m.begin(1);
        m.connection(2, 2.0, &Shares::default());
        m.connection(3, 1.0, &Shares::default());
        m.connection(3, 1.0, &Shares::default());
        m.end_vertex();
        assert_eq!(m.spread[0], Spread { raw: 0.25, within: 0.0 });
        assert_eq!(m.spread[0].independence(), Some(0.0));
        // Depth 2: Σv² = 4, Σv = 2: raw 1, within (4 − 1) / 3 = 1. Depth 3: Σv² = 2, Σv = 2:
        // raw 0.5, within (2 − 1) / 3.
        let s = m.spread[1];
        assert!((s.raw - 1.5).abs() < 1e-12 && (s.within - (1.0 + 1.0 / 3.0)).abs() < 1e-12, "{s:?}");
        assert!((s.independence().unwrap() - 8.0 / 9.0).abs() < 1e-12);
        // Nothing measured, or one draw per vertex: no estimate.
        assert_eq!(Spread::default().independence(), None);
        let mut one = Spread::default();
        one.add(1.0, 1.0, 1);
        assert_eq!(one.independence(), None);
    }

    #[test]
    fn costs_scale_each_part_with_what_the_plan_changes() {
        let from = Plan { connections: 4, pool_paths: 500, splat_paths: 500 };
        let ops = Operations {
            camera_rays: 1000,
            camera_shadow: 500,
            pool_shadow: 2000,
            lookups: 0,
            light_rays: 100,
            splat_shadow: 50,
            cache_entries: 300,
        };
        let p = Prices { shadow: 0.5, lookup: 0.0, cache_entry: 0.25, path_tracer: 0.8 };
        assert_eq!(ops.cost(&from, &from, &p), 1000.0 + 250.0 + 1000.0 + 75.0 + 100.0 + 25.0);
        let pt = Plan { connections: 0, pool_paths: 0, splat_paths: 0 };
        assert_eq!(ops.cost(&from, &pt, &p), 1000.0);
        let more = Plan { connections: 8, pool_paths: 500, splat_paths: 2000 };
        assert_eq!(ops.cost(&from, &more, &p), 1250.0 + 2000.0 + 75.0 + 400.0 + 100.0);
    }
}
