//! Guided PCBPT (`--pc-guiding`): before its first iteration, PCBPT has the guided path
//! tracer train a spatio-directional tree over the whole image (a share of the render's
//! time or samples), and its camera walks then sample their directions from that tree's
//! mixture with the BSDF ([`TreeGuide`], a [`crate::integrator::bidir::guide::Guide`]). The
//! probabilistic connections keep their selection: the camera walk learns where light comes
//! from, the cache where to connect. Every camera-side density of the bidirectional core is
//! the guide's, so the MIS weights stay those of the densities that generated each path.
//!
//! The training's passes are the guided path tracer's (seeded by the render's seed alone,
//! over the whole image), so every chunk of a distributed render trains the same tree.
//! Their samples are not added to the image.

use crate::error::Error;
use crate::integrator::guided::camera_guide::TreeGuide;
use crate::integrator::guided::training::Trained;
use crate::integrator::guided::{GuidedOptions, TrainingSchedule, train_camera_guide};
use crate::integrator::render_loop::Ctx;
use crate::integrator::run::{Budget, RunOptions};
use crate::scene::Scene;
use serde::Serialize;
use std::time::Instant;

/// Options of PCBPT's guided camera walks.
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct PcGuiding {
    /// Guide the camera walks by a spatio-directional tree that the guided path tracer
    /// trains before the first iteration (its settings are the --guided-* options).
    #[arg(long = "pc-guiding", default_value_t = false, action = clap::ArgAction::Set)]
    pub enabled: bool,
    /// The training's share of the render, in (0, 1): of the time with --time; with --spp N,
    /// path-traced training passes of 1, 2, 4, … samples per pixel up to this share of N,
    /// before PCBPT's N iterations.
    #[arg(long = "pc-guiding-training", default_value_t = PcGuiding::default().training)]
    pub training: f64,
    #[command(flatten)]
    pub tree: GuidedOptions,
}

impl Default for PcGuiding {
    fn default() -> PcGuiding {
        PcGuiding { enabled: false, training: 0.1, tree: GuidedOptions::default() }
    }
}

impl PcGuiding {
    /// Checks the options, naming the one at fault.
    pub fn validate(&self, scene: &Scene) -> Result<(), String> {
        if !(self.training > 0.0 && self.training < 1.0) {
            return Err(format!("--pc-guiding-training must lie in (0, 1) (got {})", self.training));
        }
        if !self.enabled {
            return Ok(());
        }
        if scene.volumetric {
            return Err(format!(
                "{}: --pc-guiding trains its guide with the guided path tracer, which does not render participating \
                 media; render this scene without it",
                scene.path.display()
            ));
        }
        Ok(())
    }

    /// How long the guide trains in a render by `run`: passes of 1, 2, 4, … samples per
    /// pixel up to the share of `--spp`, or the share of `--time`; `None` without guiding.
    pub fn schedule(&self, run: &RunOptions, start: Instant) -> Option<TrainingSchedule> {
        if !self.enabled {
            return None;
        }
        let (passes, seconds) = match run.budget {
            Budget::Spp(n) => (passes_within((self.training * n as f64).floor() as u32), None),
            Budget::Time(s) => (Vec::new(), Some(self.training * s)),
        };
        Some(TrainingSchedule { passes, seconds, stop: run.stop.clone(), start })
    }

    /// Trains the guide by `schedule`.
    pub(crate) fn train(&self, ctx: &Ctx, schedule: &TrainingSchedule) -> Result<(TreeGuide, GuidingStats), Error> {
        let (guide, trained) = train_camera_guide(ctx, &self.tree, schedule)?;
        let stats = GuidingStats::of(&guide, &trained);
        Ok((guide, stats))
    }
}

/// Doubling passes 1, 2, 4, … whose samples per pixel sum to at most `total` (at least one
/// pass of one sample).
fn passes_within(total: u32) -> Vec<u32> {
    let mut passes = vec![1u32];
    let mut sum = 1u64;
    loop {
        let next = 2 * *passes.last().expect("a pass") as u64;
        if sum + next > total as u64 {
            return passes;
        }
        passes.push(next as u32);
        sum += next;
    }
}

/// What the guide's training did and learnt.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct GuidingStats {
    pub training_passes: u32,
    /// Samples per pixel of the training passes (path traced).
    pub training_spp: u32,
    pub training_seconds: f64,
    /// Leaves of the spatial tree.
    pub spatial_leaves: usize,
    /// Nodes of the quadtrees the camera walks sample from, over all leaves.
    pub quadtree_nodes: usize,
    /// The median BSDF fraction the leaves learnt, if they learnt any.
    pub median_fraction: Option<f32>,
}

impl GuidingStats {
    fn of(guide: &TreeGuide, trained: &Trained) -> GuidingStats {
        let learnt = guide.tree.learnt_fractions();
        GuidingStats {
            training_passes: trained.passes,
            training_spp: trained.spp,
            training_seconds: trained.seconds,
            spatial_leaves: guide.tree.leaves.len(),
            quadtree_nodes: guide.tree.sampling_nodes(),
            median_fraction: learnt.get(learnt.len() / 2).copied(),
        }
    }

    /// The summary's line.
    pub fn line(&self) -> String {
        let mut line = format!(
            "  guided camera walks: {} training passes ({} spp, {:.2} s), {} spatial leaves, {} quadtree nodes",
            self.training_passes, self.training_spp, self.training_seconds, self.spatial_leaves, self.quadtree_nodes
        );
        if let Some(m) = self.median_fraction {
            line += &format!(", median learnt BSDF fraction {m}");
        }
        line
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn training_passes_double_within_their_share() {
        assert_eq!(passes_within(0), vec![1]);
        assert_eq!(passes_within(1), vec![1]);
        assert_eq!(passes_within(2), vec![1]);
        assert_eq!(passes_within(3), vec![1, 2]);
        assert_eq!(passes_within(16), vec![1, 2, 4, 8]);
        assert_eq!(passes_within(31), vec![1, 2, 4, 8, 16]);
    }
}
