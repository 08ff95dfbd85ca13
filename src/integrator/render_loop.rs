//! The render loop every integrator but the Metropolis ones shares. It knows no particular
//! integrator: what one does per iteration is the [`Iterative`] interface (prepare a pass:
//! pools, caches, counts; render a tile; finish: keep what the next iteration needs), and
//! each integrator's state between iterations lives in that integrator's own file.
//!
//! An *iteration* is one sample per pixel. Iteration `i` of pixel `p` draws its random
//! numbers from the stream keyed by (seed, p, i), and everything an integrator keeps from one
//! iteration to the next is a function of the seed and the iteration index, so a render of
//! iterations `A..B` (a chunk of a distributed render) computes what one process rendering
//! `0..B` computes for those iterations. An integrator whose state at `A` comes from earlier
//! iterations names them ([`Iterative::warmup`]) and the loop re-runs them first without
//! keeping their images. The film's sums are exact ([`crate::film::ExactSum`]), so the films
//! of the chunks add up to the one-process film bit for bit.
//!
//! Iterations are grouped into passes: tiles of a pass are rendered in parallel (`rayon`)
//! into their own image blocks and merged in tile order, so a fixed seed gives the same
//! image whatever the number of threads. Pass boundaries depend only on the render's total
//! sample count (and on where an integrator's state changes), never on where a chunk starts.
//! A time budget (`--time`) runs whole passes of one iteration until the budget is spent; a
//! stop flag (set by Ctrl-C) ends the render after the pass in flight. Checkpoint snapshots
//! and a live preview ([`crate::integrator::run::Preview`]) develop the film between passes.
//!
//! For the variance AOV and the noise threshold the loop keeps two half-images
//! ([`crate::integrator::noise`]): passes are then of one iteration each (as with a time
//! budget; the film's exact sums make the image the same), and the odd ones also go into a
//! film of their own. With a noise threshold the render's relMSE estimate is taken after
//! every pass from the second on, and the render stops when it falls below the threshold.
//!
//! Light-tracing contributions (`t = 1`) are splatted: each tile (and each part of a light
//! pool) collects its splats in a list, and the lists are added to the film in order.

use crate::accel::{Hit, Ray};
use crate::error::Error;
use crate::film::{Film, ImageBlock, STRATEGY_LAYERS, Splat, Tile, strategy_layer, strategy_layer_name, tiles};
use crate::integrator::noise::Halves;
use crate::integrator::progress::Progress;
use crate::integrator::run::{Budget, RenderOutput, RunOptions, offer_preview, take_snapshots};
use crate::integrator::stats::{Counters, Details, PhaseRays, PhaseTimes, RenderStats};
use crate::math::Rgb;
use crate::sampling::{PixelSampler, Sampler};
use crate::scene::Scene;
use glam::Vec2;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// What the passes of one render share.
pub(crate) struct Ctx<'a> {
    pub scene: &'a Scene,
    pub seed: u64,
    /// Keep per-strategy layers.
    pub layers: bool,
    /// The whole render's samples per pixel when it has a fixed count (`--spp`; every chunk
    /// of a distributed render sees the whole count), `None` with `--time`.
    pub planned_spp: Option<u32>,
    /// The first iteration whose samples the render keeps (a chunk's start; the iterations
    /// before it are a warm-up).
    pub start: u32,
}

/// A prepared pass: what its tiles share, and the splats and counters of the preparation
/// (a light pool's light tracing, a cache's records).
pub(crate) struct Prepared<P> {
    pub pass: P,
    pub splats: Vec<Splat>,
    pub counters: Counters,
    /// The light paths the film divides this pass's splats by, when not the ones traced
    /// (`counters.light_paths`): an integrator whose light paths per iteration change
    /// scales its splats to a fixed count.
    pub splat_paths: Option<u64>,
}

impl<P> Prepared<P> {
    pub fn only(pass: P) -> Prepared<P> {
        Prepared { pass, splats: Vec::new(), counters: Counters::default(), splat_paths: None }
    }
}

/// Iterations to re-run before a chunk's first one, so that the integrator's state is the
/// one a single process would have there.
pub(crate) struct Warmup {
    /// Ranges of iterations, in order, each with whether their camera passes are needed too
    /// (or only their preparation).
    pub ranges: Vec<(Range<u32>, bool)>,
}

impl Warmup {
    pub fn new(iterations: Range<u32>, tiles: bool) -> Warmup {
        Warmup { ranges: vec![(iterations, tiles)] }
    }
}

/// Time and shadow rays of the passes' preparation.
#[derive(Default)]
pub(crate) struct Work {
    pub phases: PhaseTimes,
    pub shadow: PhaseRays,
}

/// What an integrator does per iteration, driven by [`run`].
pub(crate) trait Iterative: Send + Sync {
    /// What the tiles of a pass share (a light pool, a cache).
    type Pass: Send + Sync;

    /// What a tile gives back besides its image, splats and counters: what the integrator
    /// learns from it for later iterations (`()` for none).
    type TileData: Send;

    /// Before the first pass: pilot measurements and memory checks.
    fn begin(&mut self, _ctx: &Ctx) -> Result<(), Error> {
        Ok(())
    }

    /// The end of a pass that starts at iteration `first` and may run to `end`: an
    /// integrator whose state changes between iterations ends passes where it changes.
    fn pass_end(&self, _first: u32, end: u32) -> u32 {
        end
    }

    /// The iterations before `first` whose passes rebuild the state a one-process render
    /// has when it reaches `first`.
    fn warmup(&self, first: u32) -> Warmup {
        Warmup::new(first..first, false)
    }

    /// Prepares the pass starting at iteration `first`. `keep` is false in warm-up passes,
    /// whose images are not kept (splats may be skipped).
    fn prepare(&self, ctx: &Ctx, first: u32, keep: bool, work: &mut Work) -> Prepared<Self::Pass>;

    /// Renders iterations `first..first + count` of a tile.
    fn render_tile(
        &self,
        ctx: &Ctx,
        pass: &Self::Pass,
        tile: Tile,
        first: u32,
        count: u32,
    ) -> TileResult<Self::TileData>;

    /// After a pass's tiles (`results`, empty in a warm-up without tiles): keeps what the
    /// next iterations need.
    fn finish(&mut self, ctx: &Ctx, pass: Self::Pass, iterations: Range<u32>, results: &[TileResult<Self::TileData>]);

    /// The integrator's own statistics of the render, once its passes are done.
    fn details(&self) -> Details {
        Details::default()
    }
}

/// Sink of one camera sample: its radiance, its per-strategy parts, and its splats.
pub(crate) struct PixelSink<'a> {
    pub l: Rgb,
    parts: Vec<(u16, Rgb)>,
    layers: bool,
    splats: &'a mut Vec<Splat>,
}

impl<'a> PixelSink<'a> {
    /// An empty sink whose splats go to `splats`, keeping the strategies' parts when the
    /// render keeps its strategy `layers`.
    pub fn new(layers: bool, splats: &'a mut Vec<Splat>) -> PixelSink<'a> {
        PixelSink { l: Rgb::ZERO, parts: Vec::new(), layers, splats }
    }

    /// Empties the sink for the next camera sample (its splats stay where they went).
    #[inline]
    pub fn clear(&mut self) {
        self.l = Rgb::ZERO;
        self.parts.clear();
    }

    /// Adds the sample's radiance and parts to `block` at film position `pos`.
    #[inline]
    pub fn put(&self, block: &mut ImageBlock, pos: Vec2) {
        block.put_layers(pos, self.l, &self.parts);
    }

    /// Strategy `(s, t)`'s contribution to the pixel.
    #[inline]
    pub fn add(&mut self, s: usize, t: usize, value: Rgb) {
        self.l += value;
        if self.layers {
            self.parts.push((strategy_layer(s, t) as u16, value));
        }
    }

    /// Strategy `(s, t)`'s contribution to the film at `pos` (light tracing).
    #[inline]
    pub fn splat(&mut self, s: usize, t: usize, pos: Vec2, value: Rgb) {
        self.splats.push(Splat::of_strategy(s, t, pos, value, self.layers));
    }
}

/// A rendered tile of a pass, with the integrator's own data `D`.
pub(crate) struct TileResult<D = ()> {
    pub block: ImageBlock,
    pub splats: Vec<Splat>,
    pub counters: Counters,
    /// What the integrator learns from the tile for later iterations.
    pub data: D,
}

impl<D> TileResult<D> {
    /// The tile with its data mapped by `f`.
    pub fn map<E>(self, f: impl FnOnce(D) -> E) -> TileResult<E> {
        TileResult { block: self.block, splats: self.splats, counters: self.counters, data: f(self.data) }
    }
}

/// Renders iterations `first..first + count` of every pixel of `tile`: `sample` estimates one
/// camera sample at film position `pos` into the sink and says whether its radiance goes to
/// the image (light tracing only splats).
pub(crate) fn sample_tile(
    ctx: &Ctx,
    tile: Tile,
    first: u32,
    count: u32,
    sample: impl FnMut(Vec2, &mut Sampler, &mut PixelSink, &mut Counters) -> bool,
) -> TileResult {
    sample_tile_in(ctx, tile, (first, count), None, sample)
}

/// [`sample_tile`] with iteration `s` of a render of `spp` samples per pixel jittered in
/// cell `s` of the pixel's `n × n` cells (`n = ⌊√spp⌋`; iterations past `n²` uniform) when
/// `strata` is `Some(spp)`: a pixel that a small, bright feature covers in part (a light
/// seen in a mirror) gets its share of samples there with far less variance than
/// independent positions give.
pub(crate) fn sample_tile_in(
    ctx: &Ctx,
    tile: Tile,
    (first, count): (u32, u32),
    strata: Option<u32>,
    sample: impl FnMut(Vec2, &mut Sampler, &mut PixelSink, &mut Counters) -> bool,
) -> TileResult {
    sample_tile_with(ctx, tile, (first, count), strata, sample)
}

/// [`sample_tile_in`] with the random numbers of each camera sample from `S`.
pub(crate) fn sample_tile_with<S: PixelSampler>(
    ctx: &Ctx,
    tile: Tile,
    (first, count): (u32, u32),
    strata: Option<u32>,
    mut sample: impl FnMut(Vec2, &mut S, &mut PixelSink, &mut Counters) -> bool,
) -> TileResult {
    let mut block = tile_block(ctx, tile);
    let mut counters = Counters::default();
    let mut splats = Vec::new();
    let mut sink = PixelSink::new(ctx.layers, &mut splats);
    for (mut sampler, pos) in camera_samples::<S>(ctx, tile, (first, count), strata) {
        sink.clear();
        if sample(pos, &mut sampler, &mut sink, &mut counters) {
            sink.put(&mut block, pos);
        }
        counters.samples += 1;
    }
    TileResult { block, splats, counters, data: () }
}

/// One bounce of a wavefront: the lanes whose rays are traced (indices into the batch's
/// lanes), those that go on after it, their rays and the hits found, the buffers kept from
/// one bounce and one batch to the next.
#[derive(Default)]
pub(crate) struct Bounce {
    pub live: Vec<u32>,
    pub next: Vec<u32>,
    pub rays: Vec<Ray>,
    pub hits: Vec<Option<Hit>>,
}

impl Bounce {
    /// Asks the backend for the closest hits of the bounce's rays in one batch query,
    /// counted as camera rays (and flagged coherent) on a walk's first bounce, `camera`,
    /// else as extension rays.
    pub fn intersect(&mut self, scene: &Scene, camera: bool, counters: &mut Counters) {
        scene.accel.intersect_batch(&self.rays, camera, &mut self.hits);
        let n = self.rays.len() as u64;
        if camera {
            counters.camera_rays += n;
        } else {
            counters.extension_rays += n;
        }
    }
}

/// An empty image block for a tile, with the strategy layers when the render keeps them.
pub(crate) fn tile_block(ctx: &Ctx, tile: Tile) -> ImageBlock {
    let layers = if ctx.layers { STRATEGY_LAYERS } else { 0 };
    ImageBlock::with_layers(tile, ctx.scene.film.filter, layers)
}

/// The camera samples of iterations `first..first + count` of a tile, pixel by pixel (row
/// by row) and iteration by iteration: each one's sampler (past the two numbers of its
/// position) and its position on the film, in the first `strata` iterations (rounded
/// down to a square) in its cell of a square grid over the pixel.
pub(crate) fn camera_samples<S: PixelSampler>(
    ctx: &Ctx,
    tile: Tile,
    (first, count): (u32, u32),
    strata: Option<u32>,
) -> impl Iterator<Item = (S, Vec2)> {
    let n = strata.map_or(0, |spp| (spp as f64).sqrt() as u32);
    let width = ctx.scene.film.width as u64;
    let seed = ctx.seed;
    (tile.y0..tile.y0 + tile.height).flat_map(move |y| {
        (tile.x0..tile.x0 + tile.width).flat_map(move |x| {
            let pixel = y as u64 * width + x as u64;
            (first..first + count).map(move |s| {
                let mut sampler = S::for_sample(seed, pixel, s);
                let pos = Vec2::new(x as f32, y as f32) + offset_in_pixel(s, n, sampler.next_2d());
                (sampler, pos)
            })
        })
    })
}

/// Where sample `s` of a pixel lies in it for a `jitter` in the unit square: in cell `s` of
/// an `n × n` grid (row by row) for `s < n²`, anywhere otherwise.
#[inline]
fn offset_in_pixel(s: u32, n: u32, jitter: Vec2) -> Vec2 {
    if s < n * n {
        // Clamped below the cell's far edge: a jitter of 1 - 2^-24 rounds onto it.
        let cell = Vec2::new((s % n) as f32, (s / n) as f32);
        let edge = (cell + 1.0) / n as f32;
        ((cell + jitter) / n as f32).min(Vec2::new(edge.x.next_down(), edge.y.next_down()))
    } else {
        jitter
    }
}

/// Adds a pass's preparation splats and its tiles to a film, in a fixed order (preparation
/// splats, then tile by tile).
pub(crate) fn add_results<D>(film: &mut Film, splats: &[Splat], light_paths: u64, results: &[TileResult<D>]) {
    film.add_splats(splats);
    film.light_paths += light_paths;
    for r in results {
        film.merge(&r.block);
        film.add_splats(&r.splats);
        film.light_paths += r.counters.light_paths;
    }
}

/// A finished camera pass not yet in the film: the preparation's splats and the tiles, and
/// the iterations they hold.
struct PendingPass<D> {
    splats: Vec<Splat>,
    light_paths: u64,
    results: Vec<TileResult<D>>,
    iterations: Range<u32>,
}

/// Adds a finished pass to the film, and to the odd half when it is an odd iteration's (a
/// render keeping halves has passes of one iteration); returns the seconds it took.
fn add_pass<D>(film: &mut Film, halves: Option<&mut Halves>, pass: Option<PendingPass<D>>) -> f64 {
    let Some(pass) = pass else { return 0.0 };
    let t = Instant::now();
    add_results(film, &pass.splats, pass.light_paths, &pass.results);
    if let Some(h) = halves {
        let n = pass.iterations.len() as u32;
        h.iterations += n;
        if pass.iterations.start % 2 == 1 {
            debug_assert_eq!(n, 1, "halves are kept by passes of one iteration");
            add_results(&mut h.odd, &pass.splats, pass.light_paths, &pass.results);
            h.odd_iterations += n;
        }
    }
    t.elapsed().as_secs_f64()
}

/// Iterations per pass of a render of `total` samples per pixel at `w × h`: as many as fit
/// in ~1 M samples (so that Ctrl-C stays responsive), all of them when they fit. A tile
/// renders a pixel's samples of a pass one after the other, so the more a pass holds, the
/// more often a sample finds its pixel's first hits (their texels, their triangles) in cache
/// (the speed-up: `docs/results/path-tracer.md`). Passes start at multiples of it,
/// whatever range of iterations a chunk renders.
fn pass_size(total: u32, w: u32, h: u32) -> u32 {
    let cap = ((1u64 << 20) / (w as u64 * h as u64)).max(1) as u32;
    total.clamp(1, cap)
}

/// The passes that cover `range`: boundaries at multiples of `per` and wherever the
/// integrator ends one.
fn next_pass<M: Iterative>(method: &M, first: u32, range_end: u32, per: u32) -> u32 {
    let aligned = (first / per + 1) * per;
    method.pass_end(first, aligned.min(range_end)).clamp(first + 1, range_end)
}

/// Renders iterations `iterations` (all of the budget when `None`) with `method`.
pub(crate) fn run<M: Iterative>(
    scene: &Scene,
    opts: &RunOptions,
    mut method: M,
    bidirectional: bool,
    iterations: Option<Range<u32>>,
) -> Result<RenderOutput, Error> {
    let pool = crate::workers::render_pool(opts.threads)?;
    let threads = pool.current_num_threads();
    let (w, h) = (scene.film.width, scene.film.height);
    let layers = opts.strategy_images && bidirectional;
    let planned_spp = match opts.budget {
        Budget::Spp(spp) => Some(spp),
        Budget::Time(_) => None,
    };
    let tile_list = tiles(w, h, opts.tile_size.max(1));
    let mut film = Film::with_layers(w, h, scene.film.filter, if layers { STRATEGY_LAYERS } else { 0 });
    let mut halves = opts.halves().then(|| Halves::new(&film));
    let (range, per) = match opts.budget {
        Budget::Spp(spp) if halves.is_none() => (iterations.unwrap_or(0..spp), pass_size(spp, w, h)),
        Budget::Spp(spp) => (iterations.unwrap_or(0..spp), 1),
        Budget::Time(_) => (0..u32::MAX, 1),
    };
    let ctx = Ctx { scene, seed: opts.seed, layers, planned_spp, start: range.start };
    let mut counters = Counters::default();
    let mut work = Work::default();
    let start = Instant::now();
    let progress = Progress::new(opts, w, h, tile_list.len(), range.len() as u32, start);
    let mut first = range.start;
    let mut passes = 0u32;
    let mut interrupted = false;
    let mut snapshots = Vec::new();
    let mut noise = None;
    let mut below_threshold = false;
    let stopped = || opts.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst));
    let result = pool.install(|| -> Result<(), Error> {
        method.begin(&ctx)?;
        // A chunk that starts late rebuilds the state of the iterations before it.
        let warm = method.warmup(range.start);
        let t_warm = Instant::now();
        for (iterations, tiles) in warm.ranges {
            let mut i = iterations.start;
            while i < iterations.end {
                let end = next_pass(&method, i, iterations.end, per);
                let mut scratch = Work::default();
                let prepared = method.prepare(&ctx, i, false, &mut scratch);
                let results: Vec<TileResult<M::TileData>> = if tiles {
                    tile_list
                        .par_iter()
                        .with_max_len(1)
                        .map(|&t| method.render_tile(&ctx, &prepared.pass, t, i, end - i))
                        .collect()
                } else {
                    Vec::new()
                };
                method.finish(&ctx, prepared.pass, i..end, &results);
                i = end;
            }
        }
        work.phases.warmup += t_warm.elapsed().as_secs_f64();
        let mut pending: Option<PendingPass<M::TileData>> = None;
        while first < range.end {
            let end = next_pass(&method, first, range.end, per);
            let count = end - first;
            let prepared = method.prepare(&ctx, first, true, &mut work);
            let t_cam = Instant::now();
            // The previous pass goes into the film while this one renders (one thread merges,
            // then joins the tiles). A pass interrupted part-way is discarded whole, so every
            // pixel keeps the same number of samples.
            let (merge_seconds, results) = rayon::join(
                || add_pass(&mut film, halves.as_mut(), pending.take()),
                || -> Option<Vec<TileResult<M::TileData>>> {
                    tile_list
                        .par_iter()
                        .with_max_len(1)
                        .map(|&t| {
                            (!stopped()).then(|| {
                                let r = method.render_tile(&ctx, &prepared.pass, t, first, count);
                                progress.tile_done(count, start);
                                r
                            })
                        })
                        .collect()
                },
            );
            work.phases.merge += merge_seconds;
            work.phases.camera_pass += t_cam.elapsed().as_secs_f64();
            let Some(results) = results else {
                interrupted = true;
                break;
            };
            counters += prepared.counters;
            // The camera pass's counters, summed in tile order (the same sums whatever the
            // thread count).
            let mut pass_counters = Counters::default();
            for r in &results {
                pass_counters += r.counters;
            }
            counters += pass_counters;
            work.shadow.camera_pass += pass_counters.shadow_rays;
            method.finish(&ctx, prepared.pass, first..end, &results);
            pending = Some(PendingPass {
                splats: prepared.splats,
                light_paths: prepared.splat_paths.unwrap_or(prepared.counters.light_paths),
                results,
                iterations: first..end,
            });
            first = end;
            passes += 1;
            let done = first - range.start;
            take_snapshots(&opts.checkpoints, &mut snapshots, start.elapsed().as_secs_f64(), done, || {
                work.phases.merge += add_pass(&mut film, halves.as_mut(), pending.take());
                film.develop()
            });
            if let (Some(threshold), Some(halves)) = (opts.noise_threshold, halves.as_mut())
                && done >= 2
            {
                work.phases.merge += add_pass(&mut film, Some(&mut *halves), pending.take());
                let (_, estimate) = halves.estimate(&film);
                noise = Some(estimate);
                below_threshold = estimate < threshold;
            }
            offer_preview(opts, w, h, done, || {
                work.phases.merge += add_pass(&mut film, halves.as_mut(), pending.take());
                film.develop()
            });
            progress.pass_done(done, counters.samples, noise, start);
            if below_threshold {
                break;
            }
            if stopped() {
                interrupted = true;
                break;
            }
            // Halves need an iteration each.
            if let Budget::Time(t) = opts.budget
                && start.elapsed() >= Duration::from_secs_f64(t)
                && (halves.is_none() || done >= 2)
            {
                break;
            }
        }
        work.phases.merge += add_pass(&mut film, halves.as_mut(), pending.take());
        Ok(())
    });
    progress.finish();
    result?;
    let seconds = start.elapsed().as_secs_f64();
    let spp = first - range.start;
    let variance = halves.map(|h| {
        let (variance, estimate) = h.estimate(&film);
        noise = Some(estimate);
        variance
    });
    let stats = RenderStats {
        relmse_estimate: noise,
        noise_threshold_reached: opts.noise_threshold.map(|_| below_threshold),
        passes,
        phases: work.phases,
        shadow_rays: work.shadow,
        iterations: Some(range.start..first),
        details: method.details(),
        ..RenderStats::new(scene, threads, counters, seconds, spp, film.invalid_samples, interrupted)
    };
    let strategy_images =
        (0..film.layers()).map(|k| (strategy_layer_name(k), film.develop_layer(k))).collect::<Vec<_>>();
    Ok(RenderOutput {
        image: film.develop(),
        strategy_images,
        snapshots,
        width: w,
        height: h,
        stats,
        film: Some(film),
        variance,
        aovs: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stratified_samples_fill_every_cell_of_the_pixel_once() {
        // The first n² samples of a pixel: one in each cell of its n × n grid, inside the
        // pixel even for a jitter at the top of its range; later ones anywhere.
        let n = 4;
        let mut sampler = Sampler::new(&[5]);
        for s in 0..n * n {
            use crate::sampling::ONE_BELOW;
            for jitter in [sampler.next_2d(), Vec2::ZERO, Vec2::splat(ONE_BELOW)] {
                let o = offset_in_pixel(s, n, jitter);
                assert!(o.cmpge(Vec2::ZERO).all() && o.cmplt(Vec2::ONE).all(), "sample {s} at {o} leaves the pixel");
                let cell = (o.y * n as f32) as u32 * n + (o.x * n as f32) as u32;
                assert_eq!(cell, s, "sample {s} at {o} is not in its cell");
            }
        }
        let j = Vec2::new(0.9, 0.3);
        assert_eq!(offset_in_pixel(n * n, n, j), j, "past the grid a sample lies where its jitter says");
        assert_eq!(offset_in_pixel(0, 0, j), j, "without a grid");
    }

    struct Boundaries(Vec<u32>);

    impl Iterative for Boundaries {
        type Pass = ();
        type TileData = ();
        fn pass_end(&self, first: u32, end: u32) -> u32 {
            self.0.iter().copied().find(|&b| b > first).map_or(end, |b| b.min(end))
        }
        fn prepare(&self, _: &Ctx, _: u32, _: bool, _: &mut Work) -> Prepared<()> {
            Prepared::only(())
        }
        fn render_tile(&self, _: &Ctx, _: &(), _: Tile, _: u32, _: u32) -> TileResult {
            unreachable!()
        }
        fn finish(&mut self, _: &Ctx, _: (), _: Range<u32>, _: &[TileResult]) {}
    }

    /// The passes of a chunk are those of the one-process render that fall inside it.
    #[test]
    fn chunks_cut_passes_where_one_process_does() {
        let m = Boundaries(vec![1, 2, 4]);
        let passes = |r: Range<u32>| {
            let mut out = Vec::new();
            let mut i = r.start;
            while i < r.end {
                let e = next_pass(&m, i, r.end, 5);
                out.push(e);
                i = e;
            }
            out
        };
        let whole = passes(0..23);
        assert_eq!(whole, vec![1, 2, 4, 5, 10, 15, 20, 23]);
        for cut in 1..23 {
            let mut parts = passes(0..cut);
            parts.extend(passes(cut..23));
            let mut expected: Vec<u32> = whole.iter().copied().filter(|&e| e != cut).collect();
            expected.push(cut);
            expected.sort();
            assert_eq!(parts, expected, "cut at {cut}");
        }
    }
}
