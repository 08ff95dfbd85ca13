//! Probabilistic connections for bidirectional path tracing (Popov et al. 2015; contract §3).
//!
//! One iteration renders one camera sample per pixel against a pool of `M` light subpaths
//! ([`LightPool`]). Instead of joining a camera vertex to its own light subpath, PCBPT draws
//! `N` pool vertices for it with a probability close to each connection's contribution:
//!
//! 1. **Records.** Camera subpaths through one jittered pixel per `k × k` tile give, at up to
//!    `D` depths, the cache records: position, normal, incoming direction and BSDF.
//! 2. **PMFs.** For every record `c` and pool vertex `v` the target
//!    `q_c(v) = lum(α_L(v) f_L(v → x_c) G(v, x_c) f_E(x_c; v → ω_c)) Vis(v, x_c)` is evaluated
//!    (in parallel over records) and stored as the record's normalised CMF.
//! 3. **Lookup.** A camera vertex blends the CMFs of its nearest records (a `kiddo` kd-tree)
//!    with weights `w_i = max(0, n·n_i) max(0, ω·ω_i) D_i` and the uniform distribution
//!    (supplemental Eq. 1–2). The blended CMF is never built: the binary search that inverts
//!    it evaluates it at the probed indices only, and the drawn vertex's probability is the
//!    difference of two such evaluations — exactly the probability with which it was drawn.
//! 4. **Connections.** `F(z) = (1/N) Σ_k w C(v_k, z) / (M PMF(z, v_k))`, on the shared
//!    [`Connector`]; `s = 0`, NEE and light tracing from the pool are BDPT's.
//!
//! MIS strategy counts ([`PcCounts`]): `N/V̄` (uniform); `N κ_t / V̄` with `κ_t` the harmonic
//! mean of `V · PMF` over the *previous* iteration's unoccluded pool connections from camera
//! vertices `z_{t-1}` (harmonic, the default: the draws count as if they were uniform over
//! the vertices they reach); or `N M P(y | z)` with `P` the blended PMF of the previous
//! iteration's cache evaluated on the path (resampling). All are functions of the path
//! alone, so the weights of a path's strategies sum to one.
//!
//! Why `κ` is the harmonic mean: a draw follows the blended PMF, so the mean of
//! `Vis / (V · PMF)` over draws is `Σ_v Vis(v) / V`, the share of the pool a camera vertex can
//! reach, and the share of draws that reach one is `P(Vis)`; their ratio, `κ`, is how many
//! times more often the cache's draws reach a vertex than uniform ones would.

pub mod cache;
pub mod correlation;
pub mod fit;
pub mod guiding;

use crate::bsdf::TransportMode;
use crate::error::Error;
use crate::film::Tile;
use crate::integrator::bidir::Vertex;
use crate::integrator::bidir::bdpt::{Bdpt, Connector};
use crate::integrator::bidir::mis::{FullPath, Heuristic, StrategyCounts};
use crate::integrator::bidir::pool::{
    CONCENTRATION_DEPTHS, LightPool, PoolSelection, concentration_depth, draw_one_by_one, pass_concentration,
};
use crate::integrator::budget::{
    Budget, BudgetOptions, BudgetStats, Operations, PRICES, Plan, PoolTile, SplatShares, TracedPool, pool_tile,
};
use crate::integrator::guided::TrainingSchedule;
use crate::integrator::pcbpt::fit::CacheFit;
use crate::integrator::pcbpt::guiding::{GuidingStats, PcGuiding};
use crate::integrator::pool_base::{PoolBase, PoolStats};
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Warmup, Work};
use crate::integrator::run::RunOptions;
use crate::integrator::run::{Integrator, Iterations, Rendered};
use crate::integrator::stats::{Counters, Details, IntegratorStats, RenderStats};
use crate::math::Rgb;
use crate::sampling::Random;
use crate::scene::Scene;
use serde::Serialize;
use std::ops::Range;
use std::time::Instant;

pub use crate::integrator::pcbpt::cache::{Blend, Cache, MAX_NEIGHBOURS, Nearest, Neighbours, Record, trace_records};
pub use crate::integrator::pcbpt::correlation::Correlation;

/// The distance term `D_i` of the interpolation weights (supplemental Eq. 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DistanceTerm {
    /// `d_i / max_j d_j`, as printed (grows with distance).
    Printed,
    /// `1 - d_i / max_j d_j` (falls off with distance).
    Falloff,
}

/// How MIS counts PCBPT's connection strategies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PcMis {
    /// `n = N / V̄`: the selection probability is ignored (as in light-vertex-cache BDPT).
    Uniform,
    /// `n = N M P(y | z)`, `P` the blended PMF of the previous iteration's cache.
    Resampling,
    /// `n = N M P̄_t`, `P̄_t` the harmonic mean of the blended PMF over the previous
    /// iteration's unoccluded pool connections from camera depth `t`: as if the draws were
    /// uniform over the vertices they reach.
    Harmonic,
    /// `harmonic`'s counts corrected for the correlation of the `N` connections that share
    /// one camera vertex's prefix ([`Correlation`]).
    Correlated,
    /// SPCBPT only: `n = N M Γ_ij / V_j`, the selection density with the draw within the
    /// light subspace taken as uniform over its `V_j` vertices (no light throughputs).
    Subspace,
}

/// How a draw inverts the blended PMF of a lookup. Both draw from exactly the same
/// distribution (Eq. 2) and return its probability from the same lazy evaluation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PcSampling {
    /// Binary search over the blended CMF, evaluated lazily at the probed indices
    /// (`O(neighbours log V)` reads per draw).
    Cmf,
    /// The blend is a mixture: `u` picks a record (probability `w_i / Σ`) or the uniform
    /// distribution, then that record's CMF alone is inverted (`O(log V + neighbours)`).
    Mixture,
}

/// Options of PCBPT (`--integrator pcbpt`).
#[derive(Clone, Debug, Default, Serialize, clap::Args)]
pub struct PcbptOptions {
    /// MIS heuristic.
    #[arg(long, value_enum, default_value_t = Heuristic::default())]
    pub heuristic: Heuristic,
    #[command(flatten)]
    #[serde(flatten)]
    pub pc: PcOptions,
    #[command(flatten)]
    pub guiding: PcGuiding,
}

/// The light pool and its connections, shared by PCBPT and SPCBPT: light paths per
/// iteration (`M`), the pool's size and the connections per camera vertex (`N`).
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct PoolOptions {
    /// Light paths per iteration (M), the least (see --pool-vertices).
    #[arg(long = "light-paths", alias = "pc-light-paths", default_value_t = PoolOptions::default().light_paths)]
    pub light_paths: usize,
    /// Add light paths per iteration until a pool holds about this many vertices (judged on
    /// a pilot pool), up to one per pixel; 0 keeps --light-paths exactly. Where most light
    /// paths miss what the camera sees, a fixed M leaves a pool of a few hundred vertices
    /// that every pixel shares.
    #[arg(long = "pool-vertices", alias = "pc-pool-vertices", default_value_t = PoolOptions::default().pool_vertices)]
    pub pool_vertices: usize,
    /// Connections drawn per camera vertex (N; 0, with --budget off: none, the pool only
    /// light traces). With --budget auto (the default), the number the budget is measured
    /// with.
    #[arg(long = "connections", alias = "pc-connections", default_value_t = PoolOptions::default().connections)]
    pub connections: u32,
    /// Memory limit of a light pool, in MiB: settings whose pool would need more are refused.
    #[arg(long = "max-pool-mb", default_value_t = PoolOptions::default().max_pool_mb)]
    pub max_pool_mb: usize,
}

impl Default for PoolOptions {
    fn default() -> PoolOptions {
        PoolOptions { light_paths: 500, pool_vertices: 2000, connections: 4, max_pool_mb: 4096 }
    }
}

impl PoolOptions {
    /// Checks the options, naming the one at fault.
    pub fn validate(&self) -> Result<(), String> {
        if self.light_paths == 0 {
            return Err("--light-paths must be at least 1".into());
        }
        Ok(())
    }
}

/// Options of PCBPT (contract §3–§5): its light pool, its cache of PMFs and how connections
/// are drawn from it and counted by MIS, and its budget.
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct PcOptions {
    #[command(flatten)]
    pub pool: PoolOptions,
    /// One cache record pixel per stride × stride tile.
    #[arg(long = "pc-cache-stride", default_value_t = PcOptions::default().stride)]
    pub stride: u32,
    /// Camera vertices per record pixel that become records (z_1..z_D).
    #[arg(long = "pc-cache-depth", default_value_t = PcOptions::default().cache_depth)]
    pub cache_depth: u32,
    /// Shadow rays in the cache's target (Vis).
    #[arg(long = "pc-visibility", default_value_t = PcOptions::default().visibility, action = clap::ArgAction::Set)]
    pub visibility: bool,
    /// Weight of the uniform distribution blended into every lookup (Eq. 2).
    #[arg(long = "pc-uniform-blend", default_value_t = PcOptions::default().uniform_blend)]
    pub uniform_blend: f32,
    /// Nearest records blended per lookup.
    #[arg(long = "pc-neighbours", default_value_t = PcOptions::default().neighbours)]
    pub neighbours: usize,
    /// Distance term of the interpolation weights.
    #[arg(long = "pc-distance-term", value_enum, default_value_t = PcOptions::default().distance_term)]
    pub distance_term: DistanceTerm,
    /// MIS strategy counts of the probabilistic connections.
    #[arg(long = "pc-mis", value_enum, default_value_t = PcOptions::default().mis)]
    pub mis: PcMis,
    /// How a draw inverts the blended PMF (the same distribution either way).
    #[arg(long = "pc-sampling", value_enum, default_value_t = PcOptions::default().sampling)]
    pub sampling: PcSampling,
    /// Memory limit of the cache (records × pool vertices floats), in MiB.
    #[arg(long = "pc-max-cache-mb", default_value_t = PcOptions::default().max_cache_mb)]
    pub max_cache_mb: usize,
    #[command(flatten)]
    pub budget: BudgetOptions,
}

impl Default for PcOptions {
    fn default() -> PcOptions {
        PcOptions {
            pool: PoolOptions::default(),
            stride: 64,
            cache_depth: 5,
            visibility: true,
            uniform_blend: 0.75,
            neighbours: 3,
            distance_term: DistanceTerm::Falloff,
            mis: PcMis::Harmonic,
            sampling: PcSampling::Mixture,
            max_cache_mb: 1024,
            budget: BudgetOptions::default(),
        }
    }
}

impl PcOptions {
    /// Checks the options, naming the one at fault.
    pub fn validate(&self) -> Result<(), String> {
        if self.mis == PcMis::Subspace {
            return Err("--pc-mis subspace counts SPCBPT's subspaces: it is an option of --sp-mis".into());
        }
        self.pool.validate()?;
        self.budget.validate(self.pool.connections)?;
        if self.stride == 0 {
            return Err("--pc-cache-stride must be at least 1".into());
        }
        if !(self.uniform_blend > 0.0 && self.uniform_blend.is_finite()) {
            return Err(format!(
                "--pc-uniform-blend must be positive and finite (it keeps every vertex reachable), not {}",
                self.uniform_blend
            ));
        }
        if !(1..=MAX_NEIGHBOURS).contains(&self.neighbours) {
            return Err(format!("--pc-neighbours must be between 1 and {MAX_NEIGHBOURS}, not {}", self.neighbours));
        }
        Ok(())
    }

    /// Most records an iteration can make for a film of `width × height`.
    pub fn max_records(&self, width: u32, height: u32) -> usize {
        let per_axis = |n: u32| n.div_ceil(self.stride) as usize;
        per_axis(width) * per_axis(height) * self.cache_depth as usize
    }
}

/// The throughputs `α_L(x_k)`, `1 <= k < out.len()`, that a light subpath along the full
/// path's vertices would carry: emission and BSDFs with their cosines over the solid-angle
/// densities of sampling them, from positions alone (Russian roulette and the media's
/// transmittance left out).
pub fn light_throughputs(scene: &Scene, path: &FullPath, out: &mut [Rgb]) {
    out.fill(Rgb::ZERO);
    if out.len() < 2 {
        return;
    }
    let x0 = path.get(0);
    let mut alpha = if x0.at_infinity() {
        // The radiance from infinity over the densities of its direction and of the disk.
        let pdf = x0.pdf_light_origin(scene) * crate::integrator::bidir::disk_pdf(scene);
        if pdf <= 0.0 {
            return;
        }
        x0.infinite_emission(scene) / pdf
    } else {
        let Some(l) = x0.light_index(scene) else { return };
        let light = &scene.lights[l];
        let w = (path.get(1).p - x0.p).normalize_or_zero();
        let pdf = x0.pdf_light_origin(scene) * light.pdf_emission_direction(x0.ng, w);
        if pdf <= 0.0 {
            return;
        }
        light.emitted(x0.ng, x0.uv, w) * x0.cos_area(w) / pdf
    };
    out[1] = alpha;
    for i in 1..out.len() - 1 {
        let x = path.get(i);
        let wo = if i == 1 && x0.at_infinity() { x0.ng } else { (path.get(i - 1).p - x.p).normalize_or_zero() };
        let wi = (path.get(i + 1).p - x.p).normalize_or_zero();
        if !x.scatters() {
            return;
        }
        if x.kind == crate::integrator::bidir::VertexKind::Medium {
            // A phase function sampled exactly: the throughput is unchanged (the media's
            // transmittance is not a function of positions alone, and is left out).
            out[i + 1] = alpha;
            continue;
        }
        let bsdf = x.bsdf(scene);
        let (lo, li) = (x.frame.to_local(wo), x.frame.to_local(wi));
        let f = x.scatter_local(bsdf, wo, wi, lo, li, TransportMode::Importance);
        let pdf = bsdf.pdf(lo, li, x.at(), TransportMode::Importance);
        if pdf <= 0.0 || f == Rgb::ZERO {
            return;
        }
        alpha = alpha * f / pdf;
        out[i + 1] = alpha;
    }
}

/// PCBPT's strategy counts, relative to one camera sample per pixel: `M/(W·H)` for light
/// tracing from the pool, 1 for `s = 0` and NEE, and for pool connections `N / V̄` (uniform),
/// `N M P(y | z)` from the previous iteration's cache (resampling) or `N κ_t / V̄` with `κ_t`
/// the harmonic mean of `V · PMF` over the previous iteration's unoccluded pool connections
/// from camera vertices `z_{t-1}` (harmonic).
#[derive(Clone, Copy)]
pub struct PcCounts<'a> {
    pub scene: &'a Scene,
    pub light_trace: f32,
    /// The count of the pool connections to `z_{t-1}`, at `[t - 2]` (deeper ones at the
    /// last entry), when not resampling: `N / V̄` (uniform) or `N κ_t / V̄` (harmonic), from
    /// the previous iteration.
    pub connect: [f32; CONCENTRATION_DEPTHS],
    /// `N M`.
    pub connections_times_paths: f32,
    /// The previous iteration's cache (resampling weights), `None` for uniform.
    pub previous: Option<&'a Cache>,
    /// The correlation correction of `--pc-mis correlated`.
    pub correlation: Option<Correlation>,
}

impl<'a> PcCounts<'a> {
    /// The counts of one iteration with `m` light paths over `pixels` pixels, from what the
    /// previous iteration measured: `vbar` (`V̄`), `concentration` (the harmonic mean of
    /// `V · PMF` over its unoccluded pool connections, by camera depth as in
    /// [`Counters::pool_hits`]) and its cache.
    pub fn for_iteration(
        scene: &'a Scene,
        opts: &PcOptions,
        m: usize,
        pixels: f32,
        vbar: f32,
        concentration: &[f32; CONCENTRATION_DEPTHS],
        previous: Option<&'a Cache>,
    ) -> PcCounts<'a> {
        let plan = Plan { connections: opts.pool.connections, pool_paths: m, splat_paths: m };
        PcCounts::for_plan(scene, opts, &plan, pixels, vbar, concentration, previous)
    }

    /// [`PcCounts::for_iteration`] of an iteration that spends `plan`.
    pub fn for_plan(
        scene: &'a Scene,
        opts: &PcOptions,
        plan: &Plan,
        pixels: f32,
        vbar: f32,
        concentration: &[f32; CONCENTRATION_DEPTHS],
        previous: Option<&'a Cache>,
    ) -> PcCounts<'a> {
        let n = plan.connections as f32;
        let connect = connection_counts(opts.mis, n, vbar, concentration);
        PcCounts {
            scene,
            light_trace: plan.splat_paths as f32 / pixels,
            connect,
            connections_times_paths: n * plan.pool_paths as f32,
            previous: previous.filter(|_| opts.mis == PcMis::Resampling),
            correlation: (opts.mis == PcMis::Correlated).then_some(Correlation { pixels, connections: n }),
        }
    }

    /// `n(s,t)`; `alpha` gives the light throughput at `y_{s-1}` (asked only for resampling).
    #[inline]
    fn count_with(&self, path: &FullPath, s: usize, t: usize, alpha: impl FnOnce() -> Rgb) -> f32 {
        match (s, t) {
            (_, 1) => self.light_trace,
            (0 | 1, _) => 1.0,
            _ => match self.previous {
                None => self.connect[concentration_depth(t)],
                Some(cache) => self.connections_times_paths * cache.selection_pmf(self.scene, path, s, alpha()),
            },
        }
    }
}

impl StrategyCounts for PcCounts<'_> {
    #[inline]
    fn count(&self, path: &FullPath, s: usize, t: usize) -> f32 {
        self.count_with(path, s, t, || throughput_at(self.scene, path, s))
    }

    fn path_dependent(&self) -> bool {
        self.previous.is_some()
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
        let throughputs = self.previous.is_some();
        fill_counts(self.scene, path, needed, out, throughputs, |s, t, alpha| {
            self.count_with(path, s, t, || alpha[s - 1])
        });
    }
}

/// The light throughput `α_L(y_{s-1})` that strategy `s` of `path` has ([`light_throughputs`]).
pub(super) fn throughput_at(scene: &Scene, path: &FullPath, s: usize) -> Rgb {
    with_throughput_buffer(s, |alpha| {
        light_throughputs(scene, path, alpha);
        alpha[s - 1]
    })
}

/// [`StrategyCounts::fill`] of counts that may need the light throughputs: `out[s]`, for
/// every `s` that `needed` asks for, is `count(s, t, alpha)`. With `throughputs`, `alpha`
/// holds the path's light throughputs up to the last pool connection asked for, computed in
/// one pass (zero otherwise).
pub(super) fn fill_counts(
    scene: &Scene,
    path: &FullPath,
    needed: &dyn Fn(usize) -> bool,
    out: &mut [f32],
    throughputs: bool,
    count: impl Fn(usize, usize, &[Rgb]) -> f32,
) {
    let n = path.len();
    with_throughput_buffer(n, |alpha| {
        if throughputs && let Some(last) = (2..n.saturating_sub(1)).rev().find(|&s| needed(s)) {
            light_throughputs(scene, path, &mut alpha[..last]);
        }
        for (s, o) in out.iter_mut().enumerate().take(n) {
            if needed(s) {
                *o = count(s, n - s, alpha);
            }
        }
    })
}

/// The counts of pool connections from camera vertex `z_{t-1}`, at `[t - 2]`, for counts
/// that do not depend on the path: `N / V̄` (uniform; resampling's first iteration) or
/// `N κ_t / V̄` (harmonic, correlated); none without a measured `V̄`.
pub(super) fn connection_counts(
    mis: PcMis,
    n: f32,
    vbar: f32,
    concentration: &[f32; CONCENTRATION_DEPTHS],
) -> [f32; CONCENTRATION_DEPTHS] {
    std::array::from_fn(|k| match mis {
        _ if vbar <= 0.0 => 0.0,
        PcMis::Harmonic | PcMis::Correlated => n * concentration[k] / vbar,
        PcMis::Uniform | PcMis::Resampling | PcMis::Subspace => n / vbar,
    })
}

/// Calls `f` with room for the light throughputs of the first `n` vertices of a path: a
/// small array for the usual short paths (zeroing the full one for every weight costs more
/// than using it).
#[inline]
fn with_throughput_buffer<T>(n: usize, f: impl FnOnce(&mut [Rgb]) -> T) -> T {
    use crate::integrator::bidir::mis::{CAP, SHORT};
    if n <= SHORT { f(&mut [Rgb::ZERO; SHORT][..n]) } else { f(&mut [Rgb::ZERO; CAP][..n]) }
}

/// PCBPT in the render loop, on the pool integrators' base ([`PoolBase`]). Per iteration: a
/// light pool, the cache's records and PMFs over it, then the camera pass: BDPT's `s = 0`
/// and NEE per camera vertex, and connections to pool vertices drawn from the cache
/// (`--pc-connections`, or the budget's) with `CacheSelection`. What the counts of iteration `i` take from iteration `i - 1`
/// (`V̄`, the concentration `κ` of its camera pass's unoccluded draws, and its cache for the
/// resampling weights; a pilot pool's `V̄` before the first) is kept here; a chunk that
/// starts at `A` re-runs iteration `A - 1` for it (its camera pass only when `κ` is used),
/// which gives exactly what one process has: the pool, the records and the draws of `A - 1`
/// depend on the seed and `A - 1` alone, not on the counts. With `--pc-budget auto` the
/// iterations of the budget's window are measured, and a chunk re-runs them too.
pub struct PcbptRender {
    pub base: PoolBase,
    pub opts: PcOptions,
    vbar: f32,
    concentration: [f32; CONCENTRATION_DEPTHS],
    previous: Option<Cache>,
    cache_stats: Option<CacheStats>,
    /// Connections and light tracing per iteration (set in `begin`).
    budget: Option<Budget>,
    /// The guided camera walks' options and training, if guided.
    guiding: Option<(PcGuiding, TrainingSchedule)>,
    guiding_stats: Option<GuidingStats>,
}

/// One PCBPT iteration's pool, cache, and what the budget measures of its preparation.
pub struct PcPass {
    pool: LightPool,
    cache: Cache,
    stats: CacheStats,
    splat_shares: Vec<SplatShares>,
    operations: Operations,
}

impl PcbptRender {
    /// PCBPT with options `opts` on `base`, whose light paths are the option's.
    pub fn new(base: PoolBase, opts: PcOptions) -> PcbptRender {
        PcbptRender {
            base,
            opts,
            vbar: 0.0,
            concentration: [1.0; CONCENTRATION_DEPTHS],
            previous: None,
            cache_stats: None,
            budget: None,
            guiding: None,
            guiding_stats: None,
        }
    }

    /// PCBPT whose camera walks follow a guide trained by `schedule` in `begin`.
    pub fn guided(mut self, guiding: PcGuiding, schedule: TrainingSchedule) -> PcbptRender {
        self.guiding = Some((guiding, schedule));
        self
    }

    /// The strategies of this render's walks, weighed with `counts`.
    fn connector<'a>(&'a self, scene: &'a Scene, counts: &'a PcCounts<'a>) -> Connector<'a, PcCounts<'a>> {
        Connector::for_walks(scene, self.base.heuristic, counts, &self.base.bdpt.limits)
    }

    fn budget(&self) -> &Budget {
        self.budget.as_ref().expect("begin set the budget")
    }

    fn counts<'a>(&'a self, scene: &'a Scene) -> PcCounts<'a> {
        let pixels = scene.film.width as f32 * scene.film.height as f32;
        let (plan, vbar, kappa) = (self.budget().plan(), self.vbar, &self.concentration);
        PcCounts::for_plan(scene, &self.opts, &plan, pixels, vbar, kappa, self.previous.as_ref())
    }

    /// Traces the record pixels of iteration `iteration` and evaluates their PMFs over
    /// `pool`. Records beyond what `--pc-max-cache-mb` holds (possible only when a pool is
    /// much larger than the pilot promised) are left out: lookups then blend fewer records.
    fn build_cache(&self, scene: &Scene, pool: &LightPool, seed: u64, iteration: u64) -> (Cache, CacheStats, Counters) {
        let o = &self.opts;
        let (mut records, mut counters) = if self.budget().plan().connections > 0 {
            trace_records(scene, &self.base.bdpt.limits, o, seed, iteration)
        } else {
            (Vec::new(), Counters::default())
        };
        let v = pool.connectible.len();
        let fit = (o.max_cache_mb as f64 * 1024.0 * 1024.0 / Cache::bytes(1, v)).floor() as usize;
        let dropped = records.len().saturating_sub(fit);
        records.truncate(fit);
        let blend = Blend { neighbours: o.neighbours, uniform: o.uniform_blend, distance_term: o.distance_term };
        let (cache, c) = Cache::build(scene, pool, records, blend, o.visibility);
        counters += c;
        let stats = CacheStats {
            records: cache.records.len(),
            empty_records: cache.totals.iter().filter(|&&q| q <= 0.0).count(),
            dropped_records: dropped,
            pool_vertices: v,
            megabytes: cache.memory() / (1024.0 * 1024.0),
        };
        (cache, stats, counters)
    }
}

impl Iterative for PcbptRender {
    type Pass = PcPass;
    type TileData = PoolTile<()>;

    /// Trains the guide of guided camera walks, measures `V̄` on a pilot pool, sets `M`
    /// from it, and checks the pool and the cache against their memory limits.
    fn begin(&mut self, ctx: &Ctx) -> Result<(), Error> {
        if let Some((guiding, schedule)) = &self.guiding {
            let (guide, stats) = guiding.train(ctx, schedule)?;
            self.base.bdpt.limits.guide = Some(std::sync::Arc::new(guide));
            self.guiding_stats = Some(stats);
        }
        let pilot = self.base.pilot(ctx, self.opts.pool.pool_vertices)?;
        let (o, m) = (&self.opts, self.base.light_paths);
        let (w, h) = (ctx.scene.film.width, ctx.scene.film.height);
        let fit = CacheFit { opts: o, light_paths: m, mean_vertices: pilot.mean_vertices() as f64, w, h };
        let (records, v, mb) = fit.size(o.stride, o.cache_depth, m);
        if mb > o.max_cache_mb as f64 {
            return Err(Error::Usage(format!(
                "the PCBPT cache of up to {records} records × about {v} pool vertices needs about {mb:.0} MiB, over the \
                 limit of {} MiB (--pc-max-cache-mb); {}",
                o.max_cache_mb,
                fit.suggestions()
            )));
        }
        self.vbar = pilot.mean_vertices();
        // Iteration 0's counts have no measured concentration: the budget measures from 1.
        let plan = Plan { connections: o.pool.connections, pool_paths: m, splat_paths: m };
        let window = 1..1 + o.budget.iterations;
        self.budget = Some(Budget::new(&o.budget, PRICES, window, plan, w as usize, h as usize, ctx.planned_spp));
        Ok(())
    }

    fn pass_end(&self, first: u32, _: u32) -> u32 {
        first + 1
    }

    fn warmup(&self, first: u32) -> Warmup {
        let kappa = matches!(self.opts.mis, PcMis::Harmonic | PcMis::Correlated);
        crate::integrator::budget::warmup(self.opts.budget.mode, self.opts.budget.iterations + 1, first, kappa)
    }

    fn prepare(&self, ctx: &Ctx, first: u32, keep: bool, work: &mut Work) -> Prepared<PcPass> {
        let counts = self.counts(ctx.scene);
        let conn = self.connector(ctx.scene, &counts);
        let traced = self.base.trace(ctx, &conn, Some(self.budget()), first, keep, work);
        let TracedPool { pool, splats, mut counters, splat_shares, mut operations, splat_paths } = traced;
        let t = Instant::now();
        let (cache, stats, c) = self.build_cache(ctx.scene, &pool, ctx.seed, first as u64);
        operations.cache_entries = (stats.records * stats.pool_vertices) as u64;
        work.phases.cache += t.elapsed().as_secs_f64();
        work.shadow.cache += c.shadow_rays;
        counters += c;
        let pass = PcPass { pool, cache, stats, splat_shares, operations };
        Prepared { pass, splats, counters, splat_paths: Some(splat_paths) }
    }

    fn render_tile(&self, ctx: &Ctx, pass: &PcPass, tile: Tile, first: u32, count: u32) -> TileResult<PoolTile<()>> {
        let (pool, cache) = (&pass.pool, &pass.cache);
        let counts = self.counts(ctx.scene);
        let conn = self.connector(ctx.scene, &counts);
        let budget = self.budget();
        let select = CacheSelection { cache, paths: pool.paths.max(1) as f64, sampling: self.opts.sampling };
        let sampler = self.base.sampler(&conn, pool, budget.plan().connections, &select);
        pool_tile(ctx, tile, first, count, budget, sampler)
    }

    /// Keeps `V̄`, the cache and the concentration of the camera pass's draws (summed in
    /// tile order) for the next iteration, and gives a measured iteration to the budget.
    fn finish(&mut self, ctx: &Ctx, pass: PcPass, iterations: Range<u32>, results: &[TileResult<PoolTile<()>>]) {
        let PcPass { pool, cache, stats, splat_shares, operations } = pass;
        self.vbar = pool.mean_vertices();
        self.base.finish(ctx, &pool, &iterations, results.iter().map(|r| &r.data.draws));
        if let Some(kappa) = pass_concentration(results.iter().map(|r| &r.data.draws)) {
            self.concentration = kappa;
        }
        self.cache_stats = Some(stats);
        self.previous = Some(cache);
        let budget = self.budget.as_mut().expect("begin set the budget");
        budget.finish(iterations.start, results, &splat_shares, operations);
    }

    fn details(&self) -> Details {
        Details::of(PcbptStats {
            pool: self.base.stats,
            cache: self.cache_stats,
            budget: self.budget.as_ref().and_then(Budget::chosen_stats),
            guiding: self.guiding_stats,
        })
    }
}

/// Selection from the cache's blended PMFs: stratified draws, each weighing
/// `1 / (N M PMF)`.
struct CacheSelection<'a> {
    cache: &'a Cache,
    paths: f64,
    sampling: PcSampling,
}

impl PoolSelection for CacheSelection<'_> {
    type Lookup = Neighbours;

    fn lookup(&self, z: &Vertex) -> Neighbours {
        self.cache.lookup_vertex(z)
    }

    #[inline]
    fn draw<R: Random>(&self, nb: &Neighbours, k: u32, n: u32, rng: &mut R) -> Option<(usize, f32)> {
        let (i, pmf) = self.cache.draw(nb, stratum(k, n, rng), self.sampling);
        self.factor(pmf, n).map(|f| (i, f))
    }

    /// With mixture sampling, up to [`DRAW_BATCH`] draws at a time through
    /// [`Cache::sample_mixture_all`]: the same draws, in the same order, as one by one.
    fn draw_all<R: Random>(&self, nb: &Neighbours, n: u32, rng: &mut R, mut out: impl FnMut(usize, f32)) {
        if self.sampling != PcSampling::Mixture {
            return draw_one_by_one(self, nb, n, rng, out);
        }
        let mut us = [0.0f64; DRAW_BATCH];
        let mut drawn = [(0usize, 0.0f64); DRAW_BATCH];
        for first in (0..n).step_by(DRAW_BATCH) {
            let m = (n - first).min(DRAW_BATCH as u32) as usize;
            for (j, u) in us[..m].iter_mut().enumerate() {
                *u = stratum(first + j as u32, n, rng);
            }
            self.cache.sample_mixture_all(nb, &us[..m], &mut drawn[..m]);
            for &(i, pmf) in &drawn[..m] {
                if let Some(f) = self.factor(pmf, n) {
                    out(i, f);
                }
            }
        }
    }
}

/// Draws [`CacheSelection::draw_all`] makes together.
pub(crate) const DRAW_BATCH: usize = 8;

/// Stratum `k` of `n` of `[0, 1)`, jittered with 48 random bits.
#[inline]
fn stratum<R: Random>(k: u32, n: u32, rng: &mut R) -> f64 {
    let xi = rng.next_1d() as f64 + rng.next_1d() as f64 * (1.0 / 16_777_216.0);
    (k as f64 + xi) / n as f64
}

impl CacheSelection<'_> {
    /// A draw's contribution factor `1 / (N M PMF)`, `None` for a draw of probability zero.
    #[inline]
    fn factor(&self, pmf: f64, n: u32) -> Option<f32> {
        (pmf > 0.0).then(|| (1.0 / (n as f64 * self.paths * pmf)) as f32)
    }
}

/// PCBPT's cache in the last iteration.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct CacheStats {
    pub records: usize,
    /// Records whose PMF is all zero (uniform fallback).
    pub empty_records: usize,
    /// Records left out to stay within `--pc-max-cache-mb`.
    pub dropped_records: usize,
    pub pool_vertices: usize,
    pub megabytes: f64,
}

/// PCBPT's statistics: the last iteration's pool and cache, and the budget's choice.
#[derive(Clone, Debug, Serialize)]
pub struct PcbptStats {
    pub pool: PoolStats,
    pub cache: Option<CacheStats>,
    /// The budget's choice (`--budget auto`).
    pub budget: Option<BudgetStats>,
    /// The guided camera walks' training (`--pc-guiding`).
    pub guiding: Option<GuidingStats>,
}

impl IntegratorStats for PcbptStats {
    fn lines(&self, _: &RenderStats) -> Vec<String> {
        let mut lines: Vec<String> = self.pool.line().into_iter().collect();
        if let Some(k) = &self.cache {
            lines.push(format!(
                "  PCBPT cache: {} records ({} empty, {} dropped for the memory limit) × {} pool vertices, {:.1} MiB; unoccluded draws' harmonic mean V·PMF {:.2}",
                k.records,
                k.empty_records,
                k.dropped_records,
                k.pool_vertices,
                k.megabytes,
                self.pool.draws.concentration().map_or(1.0, |(all, _)| all)
            ));
        }
        lines.extend(self.budget.as_ref().and_then(BudgetStats::line));
        lines.extend(self.guiding.as_ref().map(GuidingStats::line));
        lines
    }
}

impl Integrator for PcbptOptions {
    const BIDIRECTIONAL: bool = true;
    const MEDIA: bool = true;

    fn render(&self, scene: &Scene, opts: &RunOptions, iterations: Iterations) -> Rendered {
        self.pc.validate().map_err(Error::Usage)?;
        self.guiding.validate(scene).map_err(Error::Usage)?;
        let (bdpt, pool) = (Bdpt::for_scene(scene, false), &self.pc.pool);
        let base = PoolBase::new(bdpt, self.heuristic, pool.max_pool_mb, pool.light_paths);
        let mut method = PcbptRender::new(base, self.pc.clone());
        if let Some(schedule) = self.guiding.schedule(opts, Instant::now()) {
            method = method.guided(self.guiding.clone(), schedule);
        }
        crate::integrator::render_loop::run(scene, opts, method, true, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
        Some(&mut self.heuristic)
    }
}
