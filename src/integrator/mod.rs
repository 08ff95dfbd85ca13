//! Integrators and the render loop they share.
//!
//! The loop renders progressive passes: in each pass every pixel receives the same number
//! of samples; tiles are rendered in parallel (`rayon`) into their own image blocks and
//! merged in tile order. Every pixel sample draws its random numbers from a stream keyed by
//! (seed, pixel, sample index), so a fixed seed gives the same image whatever the number of
//! threads. A time budget (`--time`) runs whole passes until the budget is spent; a stop
//! flag (set by Ctrl-C) ends the render after the pass in flight.

pub mod path;

use crate::film::{Film, ImageBlock, Tile, tiles};
use crate::math::Rgb;
use crate::sampling::Sampler;
use crate::scene::Scene;
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
}

impl IntegratorKind {
    /// The integrator a scene file's plugin name selects.
    pub fn from_plugin(name: &str) -> Option<IntegratorKind> {
        match name {
            "path" => Some(IntegratorKind::Path),
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
}

impl std::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Counters) {
        self.samples += o.samples;
        self.camera_rays += o.camera_rays;
        self.extension_rays += o.extension_rays;
        self.shadow_rays += o.shadow_rays;
    }
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
}

impl RenderOptions {
    pub fn new(integrator: IntegratorKind, budget: Budget) -> RenderOptions {
        RenderOptions { integrator, budget, seed: 0, threads: 0, tile_size: 32, progress: false, stop: None }
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
    /// Samples dropped because they were NaN or infinite.
    pub invalid_samples: u64,
    /// The render stopped early (interrupted).
    pub interrupted: bool,
}

/// A finished render.
pub struct RenderOutput {
    pub image: Vec<Rgb>,
    pub width: u32,
    pub height: u32,
    pub stats: RenderStats,
}

/// An integrator ready to estimate camera samples.
enum Estimator {
    Path(path::PathTracer),
}

impl Estimator {
    fn new(kind: IntegratorKind, scene: &Scene) -> Estimator {
        match kind {
            IntegratorKind::Path => Estimator::Path(path::PathTracer::new(&scene.integrator)),
        }
    }

    #[inline]
    fn sample(&self, scene: &Scene, pixel: (u32, u32), sampler: &mut Sampler, counters: &mut Counters) -> (Vec2, Rgb) {
        let pos = Vec2::new(pixel.0 as f32, pixel.1 as f32) + sampler.next_2d();
        let ray = scene.camera.generate_ray(pos);
        counters.camera_rays += 1;
        let l = match self {
            Estimator::Path(p) => p.li(scene, ray, sampler, counters),
        };
        (pos, l)
    }
}

fn render_tile(
    scene: &Scene,
    est: &Estimator,
    tile: Tile,
    seed: u64,
    first: u32,
    count: u32,
) -> (ImageBlock, Counters) {
    crate::accel::embree::set_flush_denormals();
    let mut block = ImageBlock::new(tile, scene.film.filter);
    let mut counters = Counters::default();
    let width = scene.film.width as u64;
    for y in tile.y0..tile.y0 + tile.height {
        for x in tile.x0..tile.x0 + tile.width {
            let pixel = y as u64 * width + x as u64;
            for s in first..first + count {
                let mut sampler = Sampler::new(&[seed, pixel, s as u64]);
                let (pos, l) = est.sample(scene, (x, y), &mut sampler, &mut counters);
                block.put(pos, l);
                counters.samples += 1;
            }
        }
    }
    (block, counters)
}

/// Renders the scene's image.
pub fn render(scene: &Scene, opts: &RenderOptions) -> Result<RenderOutput, crate::error::Error> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .build()
        .map_err(|e| crate::error::Error::Usage(format!("cannot start {} threads: {e}", opts.threads)))?;
    let threads = pool.current_num_threads();
    let (w, h) = (scene.film.width, scene.film.height);
    let est = Estimator::new(opts.integrator, scene);
    let tile_list = tiles(w, h, opts.tile_size.max(1));
    let mut film = Film::new(w, h, scene.film.filter);
    let mut counters = Counters::default();
    let start = Instant::now();
    let (pass_spp, total_passes) = match opts.budget {
        Budget::Spp(spp) => {
            // About 32 passes, each of at most ~1 M samples so that progress and Ctrl-C
            // stay responsive; the split depends only on spp and resolution.
            let cap = ((1u64 << 20) / (w as u64 * h as u64)).max(1) as u32;
            let per = spp.div_ceil(32).clamp(1, cap);
            (per, spp.div_ceil(per))
        }
        Budget::Time(_) => (1, u32::MAX),
    };
    let bar = progress_bar(opts, w, h);
    let mut done = 0u32;
    let mut passes = 0u32;
    let mut interrupted = false;
    pool.install(|| {
        while passes < total_passes {
            let count = match opts.budget {
                Budget::Spp(spp) => pass_spp.min(spp - done),
                Budget::Time(_) => 1,
            };
            let stopped = || opts.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst));
            // A pass interrupted part-way is discarded whole, so every pixel keeps the same
            // number of samples.
            let blocks: Option<Vec<(ImageBlock, Counters)>> = tile_list
                .par_iter()
                .map(|&t| (!stopped()).then(|| render_tile(scene, &est, t, opts.seed, done, count)))
                .collect();
            let Some(blocks) = blocks else {
                interrupted = true;
                break;
            };
            for (b, c) in &blocks {
                film.merge(b);
                counters += *c;
            }
            done += count;
            passes += 1;
            if let Some(bar) = &bar {
                match opts.budget {
                    Budget::Spp(_) => bar.set_position(done as u64),
                    Budget::Time(t) => {
                        bar.set_position((start.elapsed().as_secs_f64() / t * 1000.0).min(1000.0) as u64)
                    }
                }
                let secs = start.elapsed().as_secs_f64().max(1e-9);
                bar.set_message(format!("{done} spp, {:.2} M samples/s", counters.samples as f64 / secs / 1e6));
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
    });
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    let seconds = start.elapsed().as_secs_f64();
    let rays = counters.camera_rays + counters.extension_rays + counters.shadow_rays;
    let stats = RenderStats {
        integrator: opts.integrator,
        backend: scene.accel.backend().to_string(),
        threads,
        width: w,
        height: h,
        spp: done,
        passes,
        seconds,
        samples_per_second: counters.samples as f64 / seconds.max(1e-9),
        rays_per_second: rays as f64 / seconds.max(1e-9),
        counters,
        invalid_samples: film.invalid_samples,
        interrupted,
    };
    Ok(RenderOutput { image: film.develop(), width: w, height: h, stats })
}

fn progress_bar(opts: &RenderOptions, w: u32, h: u32) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    if !opts.progress || !std::io::stderr().is_terminal() {
        return None;
    }
    let (len, template) = match opts.budget {
        Budget::Spp(spp) => (spp as u64, format!("{w}×{h} {{bar:40}} {{pos}}/{{len}} spp, ETA {{eta}} — {{msg}}")),
        Budget::Time(_) => (1000, format!("{w}×{h} {{bar:40}} {{elapsed}} — {{msg}}")),
    };
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) = indicatif::ProgressStyle::with_template(&template) {
        bar.set_style(style);
    }
    Some(bar)
}
