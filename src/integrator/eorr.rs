//! BDPT with efficiency-optimised Russian roulette on connections (EORR, contract §4): a
//! connection whose MIS-weighted contribution (luminance) falls below a per-pixel threshold
//! `τ = fraction × (the pixel's mean luminance)` is traced with probability `c / τ` and
//! divided by it ([`crate::integrator::bidir::bdpt::RouletteMap`]); this file holds what the render loop keeps
//! between iterations: the pixel means the thresholds come from.
//!
//! The means come from a pilot: the render's own first `P` samples per pixel
//! (`--eorr-pilot-spp`), the thresholds renewed when the pilot reaches 1, 2, 4, … samples
//! and `P`; the first sample of every pixel has no roulette. Every later iteration uses the
//! means of all `P`. A chunk of a distributed render that starts at iteration `A` re-renders
//! the pilot's iterations before `A` (at most `P` per pixel) and gets the thresholds one
//! process has there. With `P = 0` the thresholds are renewed after every iteration from
//! every earlier one (a running mean; each iteration is a pass of its own): no bounded
//! pilot, so such a render is not cut into chunks.

use crate::film::{Film, Tile};
use crate::integrator::RenderOptions;
use crate::integrator::bidir::bdpt::{Bdpt, Connector, RouletteMap, Scratch};
use crate::integrator::bidir::mis::{Counts, Heuristic};
use crate::integrator::registry::{Integrator, Iterations, Rendered};
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Warmup, Work, add_results, sample_tile};
use crate::math::luminance;
use crate::scene::Scene;
use std::ops::Range;

/// Options of EORR (`--integrator eorr`).
#[derive(Clone, Debug, serde::Serialize, clap::Args)]
pub struct EorrOptions {
    /// MIS heuristic.
    #[arg(long, value_enum, default_value_t = Heuristic::default())]
    pub heuristic: Heuristic,
    /// Russian-roulette threshold as a fraction of the pixel's mean luminance.
    #[arg(long = "eorr-fraction", default_value_t = EorrOptions::default().fraction)]
    pub fraction: f32,
    /// The pixel means come from the first this many samples per pixel (0: from every
    /// earlier pass, a running mean, which a render cut into chunks cannot use).
    #[arg(long = "eorr-pilot-spp", default_value_t = EorrOptions::default().pilot_spp)]
    pub pilot_spp: u32,
}

impl Default for EorrOptions {
    fn default() -> EorrOptions {
        EorrOptions { heuristic: Heuristic::default(), fraction: 0.1, pilot_spp: 16 }
    }
}

/// EORR in the render loop.
pub struct Eorr {
    pub bdpt: Bdpt,
    pub heuristic: Heuristic,
    /// `τ` as a fraction of the pixel's mean luminance.
    pub fraction: f32,
    /// Samples per pixel of the pilot (0: every earlier pass).
    pub pilot_spp: u32,
    /// The pilot's iterations so far.
    pilot: Film,
    /// The thresholds, per pixel (none before the first sample).
    tau: Option<Vec<f32>>,
}

impl Eorr {
    pub fn new(bdpt: Bdpt, heuristic: Heuristic, fraction: f32, pilot_spp: u32, scene: &Scene) -> Eorr {
        let pilot = Film::new(scene.film.width, scene.film.height, scene.film.filter);
        Eorr { bdpt, heuristic, fraction, pilot_spp, pilot, tau: None }
    }

    fn in_pilot(&self, iteration: u32) -> bool {
        self.pilot_spp == 0 || iteration < self.pilot_spp
    }
}

impl Iterative for Eorr {
    type Pass = ();
    type TileData = ();

    /// Passes in the pilot end where the thresholds are renewed: at powers of two and at `P`;
    /// with a running mean (`P = 0`) after every iteration.
    fn pass_end(&self, first: u32, end: u32) -> u32 {
        if self.pilot_spp == 0 {
            return first + 1;
        }
        if first >= self.pilot_spp {
            return end;
        }
        end.min((first + 1).next_power_of_two()).min(self.pilot_spp)
    }

    fn warmup(&self, first: u32) -> Warmup {
        let end = if self.pilot_spp == 0 { first } else { first.min(self.pilot_spp) };
        Warmup::new(0..end, true)
    }

    fn prepare(&self, _: &Ctx, _: u32, _: bool, _: &mut Work) -> Prepared<()> {
        Prepared::only(())
    }

    fn render_tile(&self, ctx: &Ctx, _: &(), tile: Tile, first: u32, count: u32) -> TileResult {
        let (width, height) = (ctx.scene.film.width, ctx.scene.film.height);
        let roulette = self.tau.as_deref().map(|tau| RouletteMap { tau, width, height });
        let conn = Connector { scene: ctx.scene, heuristic: self.heuristic, counts: &Counts::Bdpt, roulette };
        let mut scratch = Scratch::default();
        sample_tile(ctx, tile, first, count, |pos, rng, sink, counters| {
            self.bdpt.sample(&conn, pos, rng, &mut scratch, sink, counters);
            true
        })
    }

    fn finish(&mut self, _: &Ctx, _: (), iterations: Range<u32>, results: &[TileResult]) {
        if !self.in_pilot(iterations.start) {
            return;
        }
        add_results(&mut self.pilot, &[], 0, results);
        let end = iterations.end;
        if self.pilot_spp == 0 || end.is_power_of_two() || end == self.pilot_spp {
            let fraction = self.fraction;
            self.tau = Some(self.pilot.develop().iter().map(|c| luminance(*c).max(0.0) * fraction).collect());
        }
    }
}

impl Integrator for EorrOptions {
    const BIDIRECTIONAL: bool = true;

    fn render(&self, scene: &Scene, opts: &RenderOptions, iterations: Iterations) -> Rendered {
        use crate::error::Error;
        if self.pilot_spp == 0 && iterations.as_ref().is_some_and(|r| r.start > 0) {
            return Err(Error::Usage(
                "EORR's running-mean thresholds (--eorr-pilot-spp 0) depend on every earlier pass: render \
                 them in one process, or give the pilot a sample count"
                    .into(),
            ));
        }
        if !(self.fraction >= 0.0 && self.fraction.is_finite()) {
            return Err(Error::Usage(format!("--eorr-fraction must be a non-negative number, got {}", self.fraction)));
        }
        let method = Eorr::new(Bdpt::for_scene(scene, false), self.heuristic, self.fraction, self.pilot_spp, scene);
        crate::integrator::render_loop::run(scene, opts, method, true, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
        Some(&mut self.heuristic)
    }
}
