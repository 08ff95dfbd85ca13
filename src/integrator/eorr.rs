//! BDPT with efficiency-optimised Russian roulette on connections (EORR, contract §4): a
//! connection whose MIS-weighted contribution (luminance) falls below a per-pixel threshold
//! `τ = fraction × (the pixel's mean luminance)` is traced with probability `c / τ` and
//! divided by it: a [`ConnectionPolicy`] of the bidirectional core ([`Roulette`]). The
//! render loop keeps between iterations the pixel means the thresholds come from.
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
use crate::integrator::bidir::bdpt::{Bdpt, ConnectionPolicy, Connector};
use crate::integrator::bidir::mis::{Counts, Heuristic};
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Warmup, Work, add_results};
use crate::integrator::run::RunOptions;
use crate::integrator::run::{Integrator, Iterations, Rendered};
use crate::integrator::stats::{Details, IntegratorStats, RenderStats};
use crate::math::{Rgb, luminance};
use crate::sampling::Random;
use crate::scene::Scene;
use glam::Vec2;
use serde::Serialize;
use std::cell::Cell;
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
    /// Trace each tile's samples as a wavefront, their walks bounce by bounce and their
    /// connections together, with batched ray queries (false: one sample at a time; the
    /// same image). Scenes with media are traced one sample at a time either way.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub wavefront: bool,
}

impl Default for EorrOptions {
    fn default() -> EorrOptions {
        EorrOptions { heuristic: Heuristic::default(), fraction: 0.1, pilot_spp: 16, wavefront: true }
    }
}

/// EORR's roulette on connections, per pixel: a connection whose weighted contribution
/// (luminance) falls below the pixel's threshold `τ` is traced with probability `c / τ` and
/// divided by it. Without thresholds (the first sample of every pixel) every connection is
/// traced.
pub struct Roulette<'a> {
    /// `τ` per pixel, row by row.
    pub tau: Option<&'a [f32]>,
    pub width: u32,
    pub height: u32,
    /// Connections left untraced.
    pub skipped: Cell<u64>,
}

impl Roulette<'_> {
    #[inline]
    fn tau_at(tau: &[f32], width: u32, height: u32, pos: Vec2) -> f32 {
        let x = (pos.x.max(0.0) as u32).min(width - 1);
        let y = (pos.y.max(0.0) as u32).min(height - 1);
        tau[(y * width + x) as usize]
    }
}

impl ConnectionPolicy for Roulette<'_> {
    #[inline]
    fn judges(&self) -> bool {
        self.tau.is_some()
    }

    #[inline]
    fn keep<R: Random>(&self, c: Rgb, pos: Vec2, rng: &mut R) -> Option<f32> {
        let Some(tau) = self.tau else { return Some(1.0) };
        let tau = Roulette::tau_at(tau, self.width, self.height, pos);
        let y = luminance(c).abs();
        if y >= tau || tau <= 0.0 {
            return Some(1.0);
        }
        let p = y / tau;
        if rng.next_1d() < p {
            Some(1.0 / p)
        } else {
            self.skipped.set(self.skipped.get() + 1);
            None
        }
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
    /// Connections the roulette left untraced in the iterations the render keeps.
    skipped: u64,
    /// Trace the tiles as a wavefront ([`crate::integrator::bidir::wavefront`]) in scenes
    /// without media.
    pub wavefront: bool,
}

impl Eorr {
    pub fn new(bdpt: Bdpt, heuristic: Heuristic, fraction: f32, pilot_spp: u32, scene: &Scene) -> Eorr {
        let pilot = Film::new(scene.film.width, scene.film.height, scene.film.filter);
        Eorr { bdpt, heuristic, fraction, pilot_spp, pilot, tau: None, skipped: 0, wavefront: false }
    }

    fn in_pilot(&self, iteration: u32) -> bool {
        self.pilot_spp == 0 || iteration < self.pilot_spp
    }
}

impl Iterative for Eorr {
    type Pass = ();
    /// Connections the tile's roulette left untraced.
    type TileData = u64;

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

    fn render_tile(&self, ctx: &Ctx, _: &(), tile: Tile, first: u32, count: u32) -> TileResult<u64> {
        let (width, height) = (ctx.scene.film.width, ctx.scene.film.height);
        let policy = Roulette { tau: self.tau.as_deref(), width, height, skipped: Cell::new(0) };
        let conn =
            Connector { scene: ctx.scene, heuristic: self.heuristic, counts: &Counts::Bdpt, policy, guide: None };
        let result = self.bdpt.render_tile(ctx, &conn, tile, first, count, self.wavefront);
        result.map(|()| conn.policy.skipped.get())
    }

    fn finish(&mut self, ctx: &Ctx, _: (), iterations: Range<u32>, results: &[TileResult<u64>]) {
        if iterations.start >= ctx.start {
            self.skipped += results.iter().map(|r| r.data).sum::<u64>();
        }
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

    fn details(&self) -> Details {
        Details::of(EorrStats { connections_skipped: self.skipped })
    }
}

/// EORR's statistics.
#[derive(Clone, Debug, Serialize)]
pub struct EorrStats {
    /// Connections left untraced by the roulette.
    pub connections_skipped: u64,
}

impl IntegratorStats for EorrStats {
    fn lines(&self, _: &RenderStats) -> Vec<String> {
        vec![format!("  EORR: {} connections left untraced by the roulette", self.connections_skipped)]
    }
}

impl Integrator for EorrOptions {
    const BIDIRECTIONAL: bool = true;
    const MEDIA: bool = true;

    fn render(&self, scene: &Scene, opts: &RunOptions, iterations: Iterations) -> Rendered {
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
        let mut method = Eorr::new(Bdpt::for_scene(scene, false), self.heuristic, self.fraction, self.pilot_spp, scene);
        method.wavefront = self.wavefront;
        crate::integrator::render_loop::run(scene, opts, method, true, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
        Some(&mut self.heuristic)
    }
}
