//! Path guiding (`--integrator guided`): the path tracer with its directions drawn partly
//! from a spatio-directional tree learnt from earlier paths (Müller, Gross and Novák,
//! "Practical Path Guiding for Efficient Light-Transport Simulation", 2017).
//!
//! The render trains the tree first ([`training`]: passes of 1, 2, 4, … samples per pixel
//! in up to half the samples, or half a time budget), then renders the image from the
//! final pass alone, its paths guided by the last tree and recording nothing; the training
//! passes' images are not kept. The tree ([`sdtree`]) is a binary tree over space with a
//! quadtree of directions in each leaf; the sampling at a surface is a one-sample mixture
//! of the BSDF and the quadtree ([`mixture`]), next-event estimation weighed against the
//! mixture's density by the path tracer's power heuristic. The bounce loop is the path
//! tracer's ([`PathTracer::li_with`]).
//!
//! A chunk of a distributed render (`--chunk`) trains on the whole image before it renders
//! its iterations, so that every chunk samples from the same tree; iterations `0..T` of a
//! render of `N` are the training passes' and `T..N` the final pass's, and a chunk keeps
//! the final pass's iterations in its range. Participating media are not rendered (scenes
//! with them are refused).

pub mod camera_guide;
pub mod mixture;
pub mod sdtree;
pub mod training;

use crate::error::Error;
use crate::film::{Tile, tiles};
use crate::integrator::guided::camera_guide::TreeGuide;
use crate::integrator::guided::mixture::Guided;
use crate::integrator::guided::sdtree::{Refinement, SdTree};
use crate::integrator::guided::training::{Trained, Training, doubling_passes, train};
use crate::integrator::path::PathTracer;
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Work, sample_tile_with};
use crate::integrator::run::{Budget, Integrator, Iterations, Rendered, RunOptions};
use crate::integrator::stats::{Counters, Details, IntegratorStats, RenderStats};
use crate::sampling::sobol::SobolSampler;
use crate::sampling::{PixelSampler, Sampler, SamplerKind};
use crate::scene::Scene;
use serde::Serialize;
use std::ops::Range;
use std::time::Instant;

/// Options of the guided path tracer (`--integrator guided`); its depths are the path
/// tracer's (`--max-depth`, `--rr-depth`).
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct GuidedOptions {
    /// Probability of sampling the BSDF rather than the guiding tree at a guided vertex,
    /// in (0, 1]: at every vertex, or (with `--guided-learn-fraction true`) where a leaf has
    /// not learnt its own.
    #[arg(long = "guided-bsdf-fraction", default_value_t = GuidedOptions::default().bsdf_fraction)]
    pub bsdf_fraction: f32,
    /// c: a spatial leaf is split when a training pass of s samples per pixel records more
    /// than c·sqrt(s) path vertices in it.
    #[arg(long = "guided-spatial-threshold", default_value_t = GuidedOptions::default().spatial_threshold)]
    pub spatial_threshold: f64,
    /// ρ: a directional quadtree node is subdivided when it holds more than this fraction of
    /// its tree's recorded flux, in (0, 1].
    #[arg(long = "guided-flux-fraction", default_value_t = GuidedOptions::default().flux_fraction)]
    pub flux_fraction: f64,
    /// Deepest level of the directional quadtrees (1 to 30).
    #[arg(long = "guided-max-depth", default_value_t = GuidedOptions::default().max_tree_depth)]
    pub max_tree_depth: u32,
    /// Each spatial leaf learns its BSDF fraction from the training passes (the candidate
    /// 0.1, 0.2, …, 1 with the least estimated second moment of its vertices' reflected
    /// light); `false` keeps `--guided-bsdf-fraction` everywhere.
    #[arg(long = "guided-learn-fraction", default_value_t = GuidedOptions::default().learn_fraction, action = clap::ArgAction::Set)]
    pub learn_fraction: bool,
}

impl Default for GuidedOptions {
    fn default() -> GuidedOptions {
        GuidedOptions {
            bsdf_fraction: 0.5,
            spatial_threshold: 12000.0,
            flux_fraction: 0.01,
            max_tree_depth: 20,
            learn_fraction: true,
        }
    }
}

impl GuidedOptions {
    /// Checks the options.
    fn check(&self) -> Result<(), Error> {
        if !(self.bsdf_fraction > 0.0 && self.bsdf_fraction <= 1.0) {
            return Err(Error::Usage(format!(
                "--guided-bsdf-fraction must lie in (0, 1] (got {}): BSDF sampling covers what the tree misses",
                self.bsdf_fraction
            )));
        }
        if !(self.spatial_threshold > 0.0 && self.spatial_threshold.is_finite()) {
            return Err(Error::Usage(format!(
                "--guided-spatial-threshold must be a positive number (got {})",
                self.spatial_threshold
            )));
        }
        if !(self.flux_fraction > 0.0 && self.flux_fraction <= 1.0) {
            return Err(Error::Usage(format!(
                "--guided-flux-fraction must lie in (0, 1] (got {})",
                self.flux_fraction
            )));
        }
        if !(1..=30).contains(&self.max_tree_depth) {
            return Err(Error::Usage(format!("--guided-max-depth must lie in 1..=30 (got {})", self.max_tree_depth)));
        }
        Ok(())
    }

    /// What [`train`] needs for a training of the path tracer `pt` over `tiles`.
    fn training<'a>(
        &self,
        pt: &'a PathTracer,
        tiles: &'a [Tile],
        stop: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
        start: Instant,
    ) -> Training<'a> {
        Training { pt, bsdf_fraction: self.bsdf_fraction, refinement: self.refinement(), tiles, stop, start }
    }

    fn refinement(&self) -> Refinement {
        Refinement {
            spatial_threshold: self.spatial_threshold,
            flux_fraction: self.flux_fraction,
            max_depth: self.max_tree_depth,
            learn_fraction: self.learn_fraction,
        }
    }
}

/// How much the render trains.
#[derive(Clone, Debug)]
enum Schedule {
    /// These passes' samples per pixel.
    Passes(Vec<u32>),
    /// Doubling passes within these seconds of the render's start.
    Seconds(f64),
}

/// The guided path tracer in the render loop: [`Iterative::begin`] trains the tree, and the
/// loop's iterations are the final pass's.
pub struct GuidedRender {
    pt: PathTracer,
    options: GuidedOptions,
    schedule: Schedule,
    run: RunOptions,
    start: Instant,
    tree: SdTree,
    trained: Trained,
}

impl GuidedRender {
    fn tile_with<S: PixelSampler>(&self, ctx: &Ctx, tile: Tile, first: u32, count: u32) -> TileResult {
        let mut cont = Guided::new(&self.tree, self.options.bsdf_fraction, false);
        sample_tile_with::<S>(ctx, tile, (first, count), None, |pos, sampler, sink, counters| {
            let ray = ctx.scene.camera.generate_ray(pos);
            sink.l = counters.camera_path(|c| self.pt.li_with(ctx.scene, ray, sampler, c, &mut cont));
            true
        })
    }

    fn train(&mut self, ctx: &Ctx) {
        let film = &ctx.scene.film;
        let tile_list = tiles(film.width, film.height, self.run.tile_size.max(1));
        let t = self.options.training(&self.pt, &tile_list, self.run.stop.clone(), self.start);
        let (passes, seconds) = match &self.schedule {
            Schedule::Passes(p) => (&p[..], None),
            Schedule::Seconds(s) => (&[][..], Some(*s)),
        };
        self.trained = train(ctx, &t, &mut self.tree, passes, seconds);
    }
}

impl Iterative for GuidedRender {
    type Pass = ();
    type TileData = ();

    fn begin(&mut self, ctx: &Ctx) -> Result<(), Error> {
        self.train(ctx);
        Ok(())
    }

    fn prepare(&self, _: &Ctx, _: u32, _: bool, _: &mut Work) -> Prepared<()> {
        Prepared::only(())
    }

    fn render_tile(&self, ctx: &Ctx, _: &(), tile: Tile, first: u32, count: u32) -> TileResult {
        match self.pt.sampler {
            SamplerKind::Independent => self.tile_with::<Sampler>(ctx, tile, first, count),
            SamplerKind::Sobol => self.tile_with::<SobolSampler>(ctx, tile, first, count),
        }
    }

    fn finish(&mut self, _: &Ctx, _: (), _: Range<u32>, _: &[TileResult]) {}

    fn details(&self) -> Details {
        let learnt = self.tree.learnt_fractions();
        Details::of(GuidedStats {
            training_passes: self.trained.passes,
            training_spp: self.trained.spp,
            training_seconds: self.trained.seconds,
            training: self.trained.counters,
            spatial_leaves: self.tree.leaves.len(),
            quadtree_nodes: self.tree.sampling_nodes(),
            learnt_fractions: learnt.len(),
            fraction_range: (!learnt.is_empty())
                .then(|| [learnt[0], learnt[learnt.len() / 2], learnt[learnt.len() - 1]]),
        })
    }
}

/// What a guided render reports.
#[derive(Clone, Debug, Serialize)]
pub struct GuidedStats {
    pub training_passes: u32,
    /// Samples per pixel of the training passes.
    pub training_spp: u32,
    pub training_seconds: f64,
    /// What the training passes traced.
    pub training: Counters,
    /// Leaves of the spatial tree.
    pub spatial_leaves: usize,
    /// Nodes of the quadtrees the final pass sampled from, over all leaves.
    pub quadtree_nodes: usize,
    /// The leaves that learnt a BSDF fraction (`--guided-learn-fraction`), and the least,
    /// median and greatest fraction learnt.
    pub learnt_fractions: usize,
    pub fraction_range: Option<[f32; 3]>,
}

impl IntegratorStats for GuidedStats {
    fn lines(&self, _: &RenderStats) -> Vec<String> {
        let mut line = format!(
            "  guiding: {} training passes ({} spp, {:.2} s), {} spatial leaves, {} quadtree nodes",
            self.training_passes, self.training_spp, self.training_seconds, self.spatial_leaves, self.quadtree_nodes
        );
        if let Some([least, median, greatest]) = self.fraction_range {
            line += &format!(
                "; {} leaves learnt BSDF fractions {least}–{greatest} (median {median})",
                self.learnt_fractions
            );
        }
        vec![line]
    }
}

/// The tree that a render of `scene` with seed `seed` trains in passes of `passes` samples
/// per pixel (on the current thread pool), for measurements of what the guiding learns.
pub fn train_tree(scene: &Scene, options: &GuidedOptions, passes: &[u32], seed: u64) -> Result<SdTree, Error> {
    let ctx = Ctx { scene, seed, layers: false, planned_spp: None, start: 0 };
    let schedule = TrainingSchedule { passes: passes.to_vec(), seconds: None, stop: None, start: Instant::now() };
    Ok(train_camera_guide(&ctx, options, &schedule)?.0.tree)
}

/// How long a guide's training lasts: doubling passes of these samples per pixel or, with
/// `seconds`, doubling passes within that many seconds of `start`; stopped early by `stop`.
#[derive(Clone, Debug)]
pub struct TrainingSchedule {
    pub passes: Vec<u32>,
    pub seconds: Option<f64>,
    pub stop: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    pub start: Instant,
}

/// The guide of the bidirectional core's camera walks: the tree that the guided path tracer
/// trains over the whole image of `ctx.scene` (with `ctx.seed`, as the guided render's own
/// training), by `schedule`; and what the training did.
pub(crate) fn train_camera_guide(
    ctx: &Ctx,
    options: &GuidedOptions,
    schedule: &TrainingSchedule,
) -> Result<(TreeGuide, Trained), Error> {
    options.check()?;
    let scene = ctx.scene;
    let pt = PathTracer { sampler: scene.sampler.kind, ..PathTracer::new(&scene.integrator) };
    let tile_list = tiles(scene.film.width, scene.film.height, 32);
    let t = options.training(&pt, &tile_list, schedule.stop.clone(), schedule.start);
    let mut tree = SdTree::new(scene.bounds.center, scene.bounds.radius);
    let trained = train(ctx, &t, &mut tree, &schedule.passes, schedule.seconds);
    Ok((TreeGuide { tree, bsdf_fraction: options.bsdf_fraction }, trained))
}

/// The final pass's iterations within `range` of a render whose first `t` iterations train.
fn final_iterations(range: &Range<u32>, t: u32) -> Range<u32> {
    range.start.max(t) - t..range.end.max(t) - t
}

impl Integrator for GuidedOptions {
    const BIDIRECTIONAL: bool = false;

    fn render(&self, scene: &Scene, run: &RunOptions, iterations: Iterations) -> Rendered {
        self.check()?;
        let start = Instant::now();
        let (schedule, final_run, range) = match run.budget {
            Budget::Spp(n) => {
                let passes = doubling_passes(n);
                let t: u32 = passes.iter().sum();
                let range = iterations.clone().unwrap_or(0..n);
                let final_run = RunOptions { budget: Budget::Spp(n - t), ..run.clone() };
                (Schedule::Passes(passes), final_run, Some((range.clone(), final_iterations(&range, t), t)))
            }
            Budget::Time(s) => (Schedule::Seconds(0.5 * s), run.clone(), None),
        };
        let method = GuidedRender {
            pt: PathTracer { sampler: scene.sampler.kind, ..PathTracer::new(&scene.integrator) },
            options: self.clone(),
            schedule,
            run: run.clone(),
            start,
            tree: SdTree::new(scene.bounds.center, scene.bounds.radius),
            trained: Trained::default(),
        };
        let mut out = crate::integrator::render_loop::run(
            scene,
            &final_run,
            method,
            false,
            range.as_ref().map(|(_, f, _)| f.clone()),
        )?;
        let Some(trained) = out.stats.details.get::<GuidedStats>().cloned() else {
            return Ok(out);
        };
        // The statistics speak of the whole render: training iterations and counts included.
        let s = &mut out.stats;
        let done = s.iterations.clone().unwrap_or(0..s.spp);
        s.iterations = Some(match &range {
            Some((whole, kept, _)) if kept.is_empty() => whole.clone(),
            Some((whole, _, t)) => whole.start..done.end + t,
            None => 0..done.end + trained.training_spp,
        });
        s.spp = s.iterations.as_ref().map_or(s.spp, |r| r.len() as u32);
        s.passes += trained.training_passes;
        s.counters += trained.training;
        s.set_rates();
        Ok(out)
    }
}

#[cfg(test)]
mod tests;
