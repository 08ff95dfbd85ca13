//! Integrators and the render loop they share.
//!
//! The loop renders progressive passes: in each pass every pixel receives the same number
//! of samples; tiles are rendered in parallel (`rayon`) into their own image blocks and
//! merged in tile order. Every pixel sample draws its random numbers from a stream keyed by
//! (seed, pixel, sample index), so a fixed seed gives the same image whatever the number of
//! threads. A time budget (`--time`) runs whole passes until the budget is spent; a stop
//! flag (set by Ctrl-C) ends the render after the pass in flight.
//!
//! Light-tracing contributions (`t = 1`) are splatted: each tile (and each chunk of a light
//! pool) collects its splats in a list, and the lists are added to the film in order, so
//! splatting is as deterministic as the rest. Integrators with a light pool (`lvc`) trace
//! the pool at the start of every pass; each pass is then one iteration of one sample per
//! pixel.

pub mod bidir;
pub mod mlt;
pub mod path;

use crate::film::{Film, ImageBlock, STRATEGY_LAYERS, Splat, Tile, strategy_layer, strategy_layer_name, tiles};
use crate::math::Rgb;
use crate::sampling::Sampler;
use crate::scene::Scene;
use bidir::bdpt::{Bdpt, Connector, RouletteMap, Scratch};
use bidir::cache_fit::CacheFit;
use bidir::mis::{Counts, FullPath, Heuristic, StrategyCounts};
use bidir::pcbpt::{Blend, Cache, PcCounts, PcOptions, Pcbpt};
pub use bidir::pool::CONCENTRATION_DEPTHS;
use bidir::pool::{LightPool, Lvc};
use bidir::{Sink, WalkLimits};
use glam::Vec2;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The integrators selectable with `--integrator`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum IntegratorKind {
    /// Unidirectional path tracing with next-event estimation and MIS.
    Path,
    /// Light tracing: light subpaths connected to the camera (`t = 1`) only.
    Lighttrace,
    /// Bidirectional path tracing with every strategy.
    Bdpt,
    /// BDPT with efficiency-optimised Russian roulette on connections.
    Eorr,
    /// Light-vertex-cache BDPT: a shared pool of light paths, uniform connections.
    Lvc,
    /// Primary-sample-space Metropolis light transport over BDPT (or the path tracer).
    Pssmlt,
    /// Probabilistic connections: a shared pool, connections drawn from cached PMFs.
    Pcbpt,
}

impl IntegratorKind {
    /// The integrator a scene file's plugin name selects.
    pub fn from_plugin(name: &str) -> Option<IntegratorKind> {
        match name {
            "path" => Some(IntegratorKind::Path),
            "ptracer" => Some(IntegratorKind::Lighttrace),
            "bdpt" => Some(IntegratorKind::Bdpt),
            "pssmlt" => Some(IntegratorKind::Pssmlt),
            _ => None,
        }
    }
}

/// Per-thread work counters, summed after each pass.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Counters {
    pub samples: u64,
    pub camera_rays: u64,
    pub extension_rays: u64,
    pub shadow_rays: u64,
    /// Light subpaths traced.
    pub light_paths: u64,
    /// Connections whose shadow ray was traced (NEE, `t = 1`, `s,t >= 2`).
    pub connections: u64,
    /// Of those, connections found occluded.
    pub connections_occluded: u64,
    /// Connections left untraced by Russian roulette (EORR).
    pub connections_skipped: u64,
    /// Pool draws of a camera vertex that repeated an earlier draw of it and were merged
    /// into that connection (its weight counts both).
    pub draws_merged: u64,
    /// Pool draws whose connection was traced and found unoccluded, by the depth of the
    /// camera vertex (`[t - 2]` for `z_{t-1}`, deeper ones in the last entry).
    pub pool_hits: [u64; CONCENTRATION_DEPTHS],
    /// Sum over those draws of `1 / (V · PMF)`, the inverse of their selection probability
    /// relative to uniform selection (1 for uniform draws), by the same depths.
    pub pool_hits_inverse_concentration: [f64; CONCENTRATION_DEPTHS],
}

impl Counters {
    /// The harmonic mean of `V · PMF` over the unoccluded pool connections, over all depths
    /// and per camera depth (a depth without such connections gets the overall one); `None`
    /// without any.
    pub fn concentration(&self) -> Option<(f64, [f64; CONCENTRATION_DEPTHS])> {
        let hits: u64 = self.pool_hits.iter().sum();
        let inverse: f64 = self.pool_hits_inverse_concentration.iter().sum();
        if hits == 0 || inverse <= 0.0 {
            return None;
        }
        let all = hits as f64 / inverse;
        let mut by_depth = [all; CONCENTRATION_DEPTHS];
        for (k, c) in by_depth.iter_mut().enumerate() {
            if self.pool_hits[k] > 0 && self.pool_hits_inverse_concentration[k] > 0.0 {
                *c = self.pool_hits[k] as f64 / self.pool_hits_inverse_concentration[k];
            }
        }
        Some((all, by_depth))
    }
}

impl std::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Counters) {
        self.samples += o.samples;
        self.camera_rays += o.camera_rays;
        self.extension_rays += o.extension_rays;
        self.shadow_rays += o.shadow_rays;
        self.light_paths += o.light_paths;
        self.connections += o.connections;
        self.connections_occluded += o.connections_occluded;
        self.connections_skipped += o.connections_skipped;
        self.draws_merged += o.draws_merged;
        for k in 0..CONCENTRATION_DEPTHS {
            self.pool_hits[k] += o.pool_hits[k];
            self.pool_hits_inverse_concentration[k] += o.pool_hits_inverse_concentration[k];
        }
    }
}

/// Options of the bidirectional integrators.
#[derive(Clone, Debug, Serialize)]
pub struct BidirOptions {
    pub heuristic: Heuristic,
    /// EORR: the roulette threshold as a fraction of the pixel's running mean luminance.
    pub eorr_fraction: f32,
    /// LVC: light paths per iteration (0 = one per pixel).
    pub lvc_light_paths: usize,
    /// LVC: connections per camera vertex.
    pub lvc_connections: u32,
    /// Memory limit of a light pool, in MiB: settings whose pool would need more are refused.
    pub max_pool_mb: usize,
    /// PCBPT's options.
    pub pc: PcOptions,
}

impl Default for BidirOptions {
    fn default() -> BidirOptions {
        BidirOptions {
            heuristic: Heuristic::Power,
            eorr_fraction: 0.1,
            lvc_light_paths: 0,
            lvc_connections: 1,
            max_pool_mb: 4096,
            pc: PcOptions::default(),
        }
    }
}

/// Wall time spent in each phase of the render loop.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PhaseTimes {
    /// Tracing light pools (and their light-tracing splats).
    pub light_pool: f64,
    /// Tracing the record pixels and evaluating the cache's PMFs (PCBPT).
    pub cache: f64,
    /// Camera samples (tiles).
    pub camera_pass: f64,
    /// Merging blocks into the film and splatting.
    pub merge: f64,
}

/// Shadow rays traced in each phase of the render loop.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PhaseRays {
    pub light_pool: u64,
    pub cache: u64,
    pub camera_pass: u64,
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

/// How much to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    /// Samples per pixel.
    Spp(u32),
    /// Wall-clock seconds (whole passes of one sample per pixel).
    Time(f64),
}

#[derive(Clone)]
pub struct RenderOptions {
    pub integrator: IntegratorKind,
    pub budget: Budget,
    pub seed: u64,
    /// Worker threads (0 = all cores).
    pub threads: usize,
    pub tile_size: u32,
    pub progress: bool,
    /// Set from outside (a signal handler) to stop after the current pass.
    pub stop: Option<Arc<AtomicBool>>,
    pub bidir: BidirOptions,
    pub mlt: mlt::MltOptions,
    /// Keep one image per strategy `(s,t)` (bidirectional integrators).
    pub strategy_images: bool,
    /// Wall-clock times (seconds, ascending) at which to keep a snapshot of the image: the
    /// first pass that ends at or after each time is developed.
    pub checkpoints: Vec<f64>,
}

impl RenderOptions {
    pub fn new(integrator: IntegratorKind, budget: Budget) -> RenderOptions {
        RenderOptions {
            integrator,
            budget,
            seed: 0,
            threads: 0,
            tile_size: 32,
            progress: false,
            stop: None,
            bidir: BidirOptions::default(),
            mlt: mlt::MltOptions::default(),
            strategy_images: false,
            checkpoints: Vec::new(),
        }
    }
}

/// Statistics of a finished render.
#[derive(Clone, Debug, Serialize)]
pub struct RenderStats {
    pub integrator: IntegratorKind,
    pub backend: String,
    pub threads: usize,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub passes: u32,
    pub seconds: f64,
    pub samples_per_second: f64,
    pub rays_per_second: f64,
    pub counters: Counters,
    pub phases: PhaseTimes,
    pub shadow_rays: PhaseRays,
    /// PCBPT's cache (when PCBPT ran).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cache: Option<CacheStats>,
    /// Options of the bidirectional integrators (when one ran).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bidir: Option<BidirOptions>,
    /// Light-pool size of the last iteration: light paths and connectible vertices.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pool: Option<(usize, usize)>,
    /// Metropolis statistics (PSSMLT).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mlt: Option<mlt::MltStats>,
    /// Samples dropped because they were NaN or infinite.
    pub invalid_samples: u64,
    /// The render stopped early (interrupted).
    pub interrupted: bool,
}

impl RenderStats {
    /// The statistics every render loop reports; the rest start empty.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        opts: &RenderOptions,
        scene: &Scene,
        threads: usize,
        counters: Counters,
        seconds: f64,
        spp: u32,
        invalid_samples: u64,
        interrupted: bool,
    ) -> RenderStats {
        let rays = counters.camera_rays + counters.extension_rays + counters.shadow_rays;
        RenderStats {
            integrator: opts.integrator,
            backend: scene.accel.backend().to_string(),
            threads,
            width: scene.film.width,
            height: scene.film.height,
            spp,
            passes: 1,
            seconds,
            samples_per_second: counters.samples as f64 / seconds.max(1e-9),
            rays_per_second: rays as f64 / seconds.max(1e-9),
            counters,
            phases: PhaseTimes::default(),
            shadow_rays: PhaseRays::default(),
            cache: None,
            bidir: None,
            pool: None,
            mlt: None,
            invalid_samples,
            interrupted,
        }
    }
}

/// A worker pool of `threads` threads (0 = all cores).
pub(crate) fn thread_pool(threads: usize) -> Result<rayon::ThreadPool, crate::error::Error> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| crate::error::Error::Usage(format!("cannot start {threads} threads: {e}")))
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
}

/// An integrator ready to estimate camera samples.
enum Estimator {
    Path(path::PathTracer),
    Bdpt(Bdpt),
    Lvc(Lvc),
    Pcbpt(Pcbpt),
}

impl Estimator {
    /// The light-pool integrators' light paths per iteration.
    fn pool_paths(&self) -> Option<(usize, &Bdpt)> {
        match self {
            Estimator::Lvc(l) => Some((l.light_paths, &l.bdpt)),
            Estimator::Pcbpt(p) => Some((p.opts.light_paths, &p.bdpt)),
            _ => None,
        }
    }
}

/// The strategy counts of a pass.
#[derive(Clone, Copy)]
enum PassCounts<'a> {
    Fixed(Counts),
    Pc(PcCounts<'a>),
}

impl StrategyCounts for PassCounts<'_> {
    #[inline]
    fn count(&self, path: &FullPath, s: usize, t: usize) -> f32 {
        match self {
            PassCounts::Fixed(c) => c.count(path, s, t),
            PassCounts::Pc(c) => c.count(path, s, t),
        }
    }

    fn all_ones(&self) -> bool {
        matches!(self, PassCounts::Fixed(c) if c.all_ones())
    }

    fn path_dependent(&self) -> bool {
        match self {
            PassCounts::Fixed(_) => false,
            PassCounts::Pc(c) => c.path_dependent(),
        }
    }

    fn fill(&self, path: &FullPath, needed: &dyn Fn(usize) -> bool, out: &mut [f32]) {
        match self {
            PassCounts::Fixed(c) => c.fill(path, needed, out),
            PassCounts::Pc(c) => c.fill(path, needed, out),
        }
    }
}

/// What a pass shares between its tiles.
struct PassData<'a> {
    pool: Option<&'a LightPool>,
    cache: Option<&'a Cache>,
    counts: PassCounts<'a>,
    roulette: Option<RouletteMap<'a>>,
    heuristic: Heuristic,
    layers: bool,
}

impl Estimator {
    fn new(kind: IntegratorKind, scene: &Scene, opts: &BidirOptions) -> Result<Estimator, crate::error::Error> {
        let spec = &scene.integrator;
        let max_depth = if spec.max_depth < 0 { u32::MAX } else { spec.max_depth as u32 };
        let bdpt = |light_only| Bdpt {
            limits: WalkLimits::new(max_depth, spec.rr_depth),
            max_depth,
            hide_emitters: spec.hide_emitters,
            light_only,
        };
        if kind != IntegratorKind::Path {
            bidir::bdpt::check_lights(scene, &format!("{kind:?}").to_lowercase())
                .map_err(crate::error::Error::Usage)?;
        }
        Ok(match kind {
            IntegratorKind::Path => Estimator::Path(path::PathTracer::new(spec)),
            IntegratorKind::Lighttrace => Estimator::Bdpt(bdpt(true)),
            IntegratorKind::Bdpt | IntegratorKind::Eorr => Estimator::Bdpt(bdpt(false)),
            IntegratorKind::Pssmlt => unreachable!("PSSMLT has its own render loop"),
            IntegratorKind::Pcbpt => {
                opts.pc.validate().map_err(crate::error::Error::Usage)?;
                Estimator::Pcbpt(Pcbpt { bdpt: bdpt(false), opts: opts.pc.clone() })
            }
            IntegratorKind::Lvc => {
                if opts.lvc_connections == 0 {
                    return Err(crate::error::Error::Usage("--lvc-connections must be at least 1".into()));
                }
                let pixels = scene.film.width as usize * scene.film.height as usize;
                let m = if opts.lvc_light_paths == 0 { pixels } else { opts.lvc_light_paths };
                Estimator::Lvc(Lvc { bdpt: bdpt(false), light_paths: m, connections: opts.lvc_connections })
            }
        })
    }
}

/// Sink of one camera sample: its radiance, its per-strategy parts, and its splats.
struct PixelSink<'a> {
    l: Rgb,
    parts: Vec<(u16, Rgb)>,
    layers: bool,
    splats: &'a mut Vec<Splat>,
}

impl Sink for PixelSink<'_> {
    #[inline]
    fn add(&mut self, s: usize, t: usize, value: Rgb) {
        self.l += value;
        if self.layers {
            self.parts.push((strategy_layer(s, t) as u16, value));
        }
    }

    #[inline]
    fn splat(&mut self, s: usize, t: usize, pos: Vec2, value: Rgb) {
        self.splats.push(Splat::of_strategy(s, t, pos, value, self.layers));
    }
}

struct TileResult {
    block: ImageBlock,
    splats: Vec<Splat>,
    counters: Counters,
}

/// A finished camera pass not yet in the film: the light pool's splats and the tiles'
/// results.
struct PendingPass {
    pool_splats: Vec<Splat>,
    pool_light_paths: u64,
    results: Vec<TileResult>,
}

/// Adds a finished pass to the film, in a fixed order (pool splats, then tile by tile), so
/// the sums are the same whatever the thread count; returns the seconds it took.
fn add_pass(film: &mut Film, pass: Option<PendingPass>) -> f64 {
    let Some(pass) = pass else { return 0.0 };
    let t = Instant::now();
    film.add_splats(&pass.pool_splats);
    film.light_paths += pass.pool_light_paths;
    for r in &pass.results {
        film.merge(&r.block);
        film.add_splats(&r.splats);
        film.light_paths += r.counters.light_paths;
    }
    t.elapsed().as_secs_f64()
}

fn render_tile(
    scene: &Scene,
    est: &Estimator,
    pass: &PassData,
    tile: Tile,
    seed: u64,
    first: u32,
    count: u32,
) -> TileResult {
    crate::accel::embree::set_flush_denormals();
    let layers = if pass.layers { STRATEGY_LAYERS } else { 0 };
    let mut block = ImageBlock::with_layers(tile, scene.film.filter, layers);
    let mut counters = Counters::default();
    let mut splats = Vec::new();
    let mut scratch = Scratch::default();
    let mut sink = PixelSink { l: Rgb::ZERO, parts: Vec::new(), layers: pass.layers, splats: &mut splats };
    let conn = Connector { scene, heuristic: pass.heuristic, counts: &pass.counts, roulette: pass.roulette };
    let width = scene.film.width as u64;
    for y in tile.y0..tile.y0 + tile.height {
        for x in tile.x0..tile.x0 + tile.width {
            let pixel = y as u64 * width + x as u64;
            for s in first..first + count {
                let mut sampler = Sampler::new(&[seed, pixel, s as u64]);
                let pos = Vec2::new(x as f32, y as f32) + sampler.next_2d();
                sink.l = Rgb::ZERO;
                sink.parts.clear();
                match est {
                    Estimator::Path(p) => {
                        let ray = scene.camera.generate_ray(pos);
                        counters.camera_rays += 1;
                        let l = p.li(scene, ray, &mut sampler, &mut counters);
                        block.put(pos, l);
                    }
                    Estimator::Bdpt(b) => {
                        b.sample(&conn, pos, &mut sampler, &mut scratch, &mut sink, &mut counters);
                        if !b.light_only {
                            block.put_layers(pos, sink.l, &sink.parts);
                        }
                    }
                    Estimator::Lvc(lvc) => {
                        let pool = pass.pool.expect("a pool integrator has a pool");
                        lvc.sample(&conn, pool, pos, &mut sampler, &mut scratch, &mut sink, &mut counters);
                        block.put_layers(pos, sink.l, &sink.parts);
                    }
                    Estimator::Pcbpt(pc) => {
                        let pool = pass.pool.expect("a pool integrator has a pool");
                        let cache = pass.cache.expect("PCBPT has a cache");
                        pc.sample(&conn, pool, cache, pos, &mut sampler, &mut scratch, &mut sink, &mut counters);
                        block.put_layers(pos, sink.l, &sink.parts);
                    }
                }
                counters.samples += 1;
            }
        }
    }
    TileResult { block, splats, counters }
}

/// Bytes a light pool spends per vertex (the vertex and its path-start index).
fn pool_vertex_bytes() -> usize {
    std::mem::size_of::<bidir::Vertex>() + std::mem::size_of::<u32>() * 2
}

/// Key of the pilot pool that measures `V̄` before the first iteration.
const PILOT_ITERATION: u64 = u64::MAX;

/// Checks a pool integrator's light pool (and PCBPT's cache) against their memory limits,
/// from the size per path measured on the pilot pool `pilot`, with a margin.
fn check_memory(
    est: &Estimator,
    opts: &BidirOptions,
    pilot: &LightPool,
    w: u32,
    h: u32,
) -> Result<(), crate::error::Error> {
    const MIB: f64 = 1024.0 * 1024.0;
    let Some((m, _)) = est.pool_paths() else { return Ok(()) };
    let per_path = pilot.vertices.len() as f64 / pilot.paths.max(1) as f64;
    let mb = 1.5 * m as f64 * per_path.max(1.0) * pool_vertex_bytes() as f64 / MIB;
    let option = if matches!(est, Estimator::Pcbpt(_)) { "--pc-light-paths" } else { "--lvc-light-paths" };
    if mb > opts.max_pool_mb as f64 {
        return Err(crate::error::Error::Usage(format!(
            "the light pool of {m} paths ({per_path:.1} vertices per path) needs about {mb:.0} MiB, over the limit of {} MiB \
             (--max-pool-mb); use fewer light paths ({option}) or raise the limit",
            opts.max_pool_mb
        )));
    }
    if let Estimator::Pcbpt(pc) = est {
        let fit = CacheFit { opts: &pc.opts, light_paths: m, mean_vertices: pilot.mean_vertices() as f64, w, h };
        let (records, v, mb) = fit.size(pc.opts.stride, pc.opts.cache_depth, m);
        if mb > pc.opts.max_cache_mb as f64 {
            return Err(crate::error::Error::Usage(format!(
                "the PCBPT cache of up to {records} records × about {v} pool vertices needs about {mb:.0} MiB, over the \
                 limit of {} MiB (--pc-max-cache-mb); {}",
                pc.opts.max_cache_mb,
                fit.suggestions()
            )));
        }
    }
    Ok(())
}

/// Traces PCBPT's record pixels for iteration `iteration` and evaluates their PMFs over
/// `pool`. Records beyond what `--pc-max-cache-mb` holds (possible only when a pool is much
/// larger than the pilot promised) are left out: lookups then blend fewer records.
fn build_cache(
    scene: &Scene,
    pc: &Pcbpt,
    pool: &LightPool,
    seed: u64,
    iteration: u64,
) -> (Cache, CacheStats, Counters) {
    let (mut records, mut counters) = bidir::pcbpt::trace_records(scene, &pc.bdpt.limits, &pc.opts, seed, iteration);
    let v = pool.connectible.len();
    let fit = (pc.opts.max_cache_mb as f64 * 1024.0 * 1024.0 / Cache::bytes(1, v)).floor() as usize;
    let dropped = records.len().saturating_sub(fit);
    records.truncate(fit);
    let blend =
        Blend { neighbours: pc.opts.neighbours, uniform: pc.opts.uniform_blend, distance_term: pc.opts.distance_term };
    let (cache, c) = Cache::build(scene, pool, records, blend, pc.opts.visibility);
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

/// Renders the scene's image.
pub fn render(scene: &Scene, opts: &RenderOptions) -> Result<RenderOutput, crate::error::Error> {
    if opts.integrator == IntegratorKind::Pssmlt {
        return mlt::render(scene, opts);
    }
    let pool = thread_pool(opts.threads)?;
    let threads = pool.current_num_threads();
    let (w, h) = (scene.film.width, scene.film.height);
    let est = Estimator::new(opts.integrator, scene, &opts.bidir)?;
    let bidirectional = !matches!(est, Estimator::Path(_));
    let layers = opts.strategy_images && bidirectional;
    let tile_list = tiles(w, h, opts.tile_size.max(1));
    let mut film = Film::with_layers(w, h, scene.film.filter, if layers { STRATEGY_LAYERS } else { 0 });
    let mut counters = Counters::default();
    let mut phases = PhaseTimes::default();
    let start = Instant::now();
    let one_per_pass = est.pool_paths().is_some();
    let (pass_spp, total_passes) = match opts.budget {
        Budget::Spp(spp) if one_per_pass => (1, spp),
        Budget::Spp(spp) => {
            // About 32 passes, each of at most ~1 M samples so that progress and Ctrl-C
            // stay responsive; the split depends only on spp and resolution.
            let cap = ((1u64 << 20) / (w as u64 * h as u64)).max(1) as u32;
            let per = spp.div_ceil(32).clamp(1, cap);
            (per, spp.div_ceil(per))
        }
        Budget::Time(_) => (1, u32::MAX),
    };
    let pixels = w as f32 * h as f32;
    let counts = PassCounts::Fixed(if opts.integrator == IntegratorKind::Lighttrace {
        Counts::LightTrace
    } else {
        Counts::Bdpt
    });
    let bar = progress_bar(opts, w, h, tile_list.len());
    let mut done = 0u32;
    let mut passes = 0u32;
    let mut interrupted = false;
    let mut pool_size = None;
    let mut pool_error = None;
    let mut snapshots = Vec::new();
    let mut shadow = PhaseRays::default();
    let mut cache_stats = None;
    pool.install(|| {
        // The pool integrators' strategy counts use V̄ of the previous iteration (a pilot
        // pool before the first).
        let mut vbar = match est.pool_paths() {
            Some((m, bdpt)) => {
                let (p, _, _) = LightPool::trace::<Counts>(scene, &bdpt.limits, m, opts.seed, PILOT_ITERATION, None);
                match check_memory(&est, &opts.bidir, &p, w, h) {
                    Ok(()) => p.mean_vertices(),
                    Err(e) => {
                        pool_error = Some(e);
                        return;
                    }
                }
            }
            None => 0.0,
        };
        // PCBPT's resampling weights use the previous iteration's cache, its harmonic
        // weights the concentration of the previous camera pass's unoccluded draws by camera
        // depth (1, uniform, before the first).
        let mut previous: Option<Cache> = None;
        let mut concentration = [1.0f32; CONCENTRATION_DEPTHS];
        let mut pending: Option<PendingPass> = None;
        while passes < total_passes {
            let count = match opts.budget {
                Budget::Spp(spp) => pass_spp.min(spp - done),
                Budget::Time(_) => 1,
            };
            let stopped = || opts.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst));
            let t_pool = Instant::now();
            let mut pass_counts = counts;
            let mut pool_data = None;
            let mut pool_splats = Vec::new();
            let mut pool_counters = Counters::default();
            if let Some((m, bdpt)) = est.pool_paths() {
                pass_counts = match &est {
                    Estimator::Pcbpt(pc) => PassCounts::Pc(PcCounts::for_iteration(
                        scene,
                        &pc.opts,
                        m,
                        pixels,
                        vbar,
                        &concentration,
                        previous.as_ref(),
                    )),
                    _ => PassCounts::Fixed(Counts::Pool {
                        light_trace: m as f32 / pixels,
                        connect: if vbar > 0.0 { opts.bidir.lvc_connections as f32 / vbar } else { 0.0 },
                    }),
                };
                let conn = Connector { scene, heuristic: opts.bidir.heuristic, counts: &pass_counts, roulette: None };
                let (p, sp, c) =
                    LightPool::trace(scene, &bdpt.limits, m, opts.seed, passes as u64, Some((&conn, bdpt, layers)));
                vbar = p.mean_vertices();
                pool_size = Some((p.paths, p.connectible.len()));
                pool_data = Some(p);
                pool_splats = sp;
                pool_counters = c;
            }
            phases.light_pool += t_pool.elapsed().as_secs_f64();
            shadow.light_pool += pool_counters.shadow_rays;
            // PCBPT: records and their PMFs over this pool.
            let t_cache = Instant::now();
            let cache = match (&est, &pool_data) {
                (Estimator::Pcbpt(pc), Some(p)) => {
                    let (c, stats, cc) = build_cache(scene, pc, p, opts.seed, passes as u64);
                    cache_stats = Some(stats);
                    shadow.cache += cc.shadow_rays;
                    counters += cc;
                    Some(c)
                }
                _ => None,
            };
            phases.cache += t_cache.elapsed().as_secs_f64();
            // EORR: thresholds from the image of the passes so far (none before the first).
            let tau: Option<Vec<f32>> = (opts.integrator == IntegratorKind::Eorr && passes > 0).then(|| {
                phases.merge += add_pass(&mut film, pending.take());
                film.develop().iter().map(|c| crate::math::luminance(*c).max(0.0) * opts.bidir.eorr_fraction).collect()
            });
            let pass = PassData {
                pool: pool_data.as_ref(),
                cache: cache.as_ref(),
                counts: pass_counts,
                roulette: tau.as_deref().map(|tau| RouletteMap { tau, width: w, height: h }),
                heuristic: opts.bidir.heuristic,
                layers,
            };
            let t_cam = Instant::now();
            // The previous pass goes into the film while this one renders (one thread merges,
            // then joins the tiles). A pass interrupted part-way is discarded whole, so every
            // pixel keeps the same number of samples.
            let (merge_seconds, results) = rayon::join(
                || add_pass(&mut film, pending.take()),
                || -> Option<Vec<TileResult>> {
                    tile_list
                        .par_iter()
                        .map(|&t| {
                            (!stopped()).then(|| {
                                let r = render_tile(scene, &est, &pass, t, opts.seed, done, count);
                                // A pass of a large image takes long: the bar moves by tiles.
                                if let Some(bar) = &bar {
                                    match opts.budget {
                                        Budget::Spp(_) => bar.inc(count as u64),
                                        Budget::Time(secs) => bar.set_position(time_position(start, secs)),
                                    }
                                }
                                r
                            })
                        })
                        .collect()
                },
            );
            phases.merge += merge_seconds;
            phases.camera_pass += t_cam.elapsed().as_secs_f64();
            let Some(results) = results else {
                interrupted = true;
                break;
            };
            counters += pool_counters;
            // The camera pass's counters, summed in tile order (the same sums whatever the
            // thread count).
            let mut pass_counters = Counters::default();
            for r in &results {
                pass_counters += r.counters;
            }
            counters += pass_counters;
            shadow.camera_pass += pass_counters.shadow_rays;
            // The concentration of this pass's pool draws weights the next pass.
            if let Some((_, by_depth)) = pass_counters.concentration() {
                concentration = by_depth.map(|c| c as f32);
            }
            pending = Some(PendingPass { pool_splats, pool_light_paths: pool_counters.light_paths, results });
            done += count;
            passes += 1;
            take_snapshots(&opts.checkpoints, &mut snapshots, start.elapsed().as_secs_f64(), done, || {
                phases.merge += add_pass(&mut film, pending.take());
                film.develop()
            });
            if let Some(bar) = &bar {
                match opts.budget {
                    Budget::Spp(_) => bar.set_position(done as u64 * tile_list.len() as u64),
                    Budget::Time(t) => bar.set_position(time_position(start, t)),
                }
                let secs = start.elapsed().as_secs_f64().max(1e-9);
                bar.set_message(format!("{done} spp, {:.2} M samples/s", counters.samples as f64 / secs / 1e6));
            }
            if cache.is_some() {
                previous = cache;
            }
            if stopped() {
                interrupted = true;
                break;
            }
            if let Budget::Time(t) = opts.budget
                && start.elapsed() >= Duration::from_secs_f64(t)
            {
                break;
            }
        }
        phases.merge += add_pass(&mut film, pending.take());
    });
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    if let Some(e) = pool_error {
        return Err(e);
    }
    let seconds = start.elapsed().as_secs_f64();
    let stats = RenderStats {
        passes,
        phases,
        bidir: bidirectional.then(|| opts.bidir.clone()),
        pool: pool_size,
        shadow_rays: shadow,
        cache: cache_stats,
        ..RenderStats::new(opts, scene, threads, counters, seconds, done, film.invalid_samples, interrupted)
    };
    let strategy_images =
        (0..film.layers()).map(|k| (strategy_layer_name(k), film.develop_layer(k))).collect::<Vec<_>>();
    Ok(RenderOutput { image: film.develop(), strategy_images, snapshots, width: w, height: h, stats })
}

/// The render's progress bar on a terminal: in tiles rendered times their samples per
/// pixel (`tiles` per pass), or in thousandths of the time budget.
fn progress_bar(opts: &RenderOptions, w: u32, h: u32, tiles: usize) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    if !opts.progress || !std::io::stderr().is_terminal() {
        return None;
    }
    let (len, template) = match opts.budget {
        Budget::Spp(spp) => (
            spp as u64 * tiles as u64,
            format!("{w}×{h} {{wide_bar}} {{percent}}% of {spp} spp, ETA {{eta}} — {{msg}}"),
        ),
        Budget::Time(_) => (1000, format!("{w}×{h} {{wide_bar}} {{elapsed}} — {{msg}}")),
    };
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) = indicatif::ProgressStyle::with_template(&template) {
        bar.set_style(style);
    }
    bar.enable_steady_tick(Duration::from_secs(1));
    Some(bar)
}

/// The position of a time budget's progress bar: thousandths of `budget` seconds elapsed.
fn time_position(start: Instant, budget: f64) -> u64 {
    (start.elapsed().as_secs_f64() / budget * 1000.0).min(1000.0) as u64
}
