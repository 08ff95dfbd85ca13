//! Light-vertex-cache BDPT (Davidovic et al. 2014; contract §5): `M` light subpaths per
//! iteration in a pool, light tracing (`t = 1`) from all of them, and `N` connections per
//! camera vertex to pool vertices chosen uniformly — PCBPT without its cached PMFs: the
//! pool integrators' base ([`crate::integrator::pool_base`]) with uniform selection and its
//! counts.

use crate::error::Error;
use crate::film::Tile;
use crate::integrator::bidir::Vertex;
use crate::integrator::bidir::bdpt::{Bdpt, Connector};
use crate::integrator::bidir::mis::{FullPath, Heuristic, StrategyCounts};
use crate::integrator::bidir::pool::{LightPool, PoolCounters, PoolSelection};
use crate::integrator::pool_base::{PoolBase, PoolStats};
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Warmup, Work, sample_tile};
use crate::integrator::run::RunOptions;
use crate::integrator::run::{Integrator, Iterations, Rendered};
use crate::integrator::stats::{Details, IntegratorStats, RenderStats};
use crate::sampling::Random;
use crate::scene::Scene;
use serde::Serialize;
use std::ops::Range;

/// Options of light-vertex-cache BDPT (`--integrator lvc`).
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct LvcOptions {
    /// MIS heuristic.
    #[arg(long, value_enum, default_value_t = Heuristic::default())]
    pub heuristic: Heuristic,
    /// Light paths per iteration (0 = one per pixel).
    #[arg(long = "light-paths", alias = "lvc-light-paths", default_value_t = LvcOptions::default().light_paths)]
    pub light_paths: usize,
    /// Connections to pool vertices per camera vertex.
    #[arg(long = "connections", alias = "lvc-connections", default_value_t = LvcOptions::default().connections)]
    pub connections: u32,
    /// Memory limit of the light pool, in MiB: settings whose pool would need more are refused.
    #[arg(long = "max-pool-mb", default_value_t = LvcOptions::default().max_pool_mb)]
    pub max_pool_mb: usize,
}

impl Default for LvcOptions {
    fn default() -> LvcOptions {
        LvcOptions { heuristic: Heuristic::default(), light_paths: 0, connections: 1, max_pool_mb: 4096 }
    }
}

/// LVC's strategy counts: light tracing from `M` paths over `W·H` pixels
/// (`light_trace = M / (W·H)`) and `N` uniform pool connections per camera vertex
/// (`connect = N / V̄`, V̄ the mean number of pool vertices per light path).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LvcCounts {
    pub light_trace: f32,
    pub connect: f32,
}

impl StrategyCounts for LvcCounts {
    #[inline]
    fn count(&self, _: &FullPath, s: usize, t: usize) -> f32 {
        match (s, t) {
            (_, 1) => self.light_trace,
            (0 | 1, _) => 1.0,
            _ => self.connect,
        }
    }
}

/// Uniform selection over the pool's `v` vertices (LVC): each draw weighs `V / (N M)`.
struct Uniform {
    v: usize,
    scale: f32,
}

impl PoolSelection for Uniform {
    type Lookup = ();

    fn lookup(&self, _z: &Vertex) {}

    #[inline]
    fn draw<R: Random>(&self, _: &(), _k: u32, _n: u32, rng: &mut R) -> Option<(usize, f32)> {
        Some((((rng.next_1d() * self.v as f32) as usize).min(self.v - 1), self.scale))
    }
}

/// LVC in the render loop, on the pool integrators' base: BDPT's `s = 0` and `s = 1`
/// strategies per camera vertex and `N` connections to uniformly chosen pool vertices,
/// `F = (1/N) Σ w C(v, z) V / M`. One pool per iteration; the strategy counts use `V̄` of
/// the previous iteration's pool (of the pilot pool before the first), so a chunk that
/// starts at iteration `A` re-traces pool `A - 1`.
pub struct LvcRender {
    pub base: PoolBase,
    /// Connections per camera vertex (`N`).
    pub connections: u32,
    vbar: f32,
}

impl LvcRender {
    pub fn new(base: PoolBase, connections: u32) -> LvcRender {
        LvcRender { base, connections, vbar: 0.0 }
    }

    fn counts(&self, scene: &Scene) -> LvcCounts {
        let pixels = scene.film.width as f32 * scene.film.height as f32;
        LvcCounts {
            light_trace: self.base.light_paths as f32 / pixels,
            connect: if self.vbar > 0.0 { self.connections as f32 / self.vbar } else { 0.0 },
        }
    }
}

impl Iterative for LvcRender {
    type Pass = LightPool;
    type TileData = PoolCounters;

    fn begin(&mut self, ctx: &Ctx) -> Result<(), Error> {
        self.vbar = self.base.pilot(ctx, 0)?.mean_vertices();
        Ok(())
    }

    fn pass_end(&self, first: u32, _: u32) -> u32 {
        first + 1
    }

    fn warmup(&self, first: u32) -> Warmup {
        Warmup::new(first.saturating_sub(1)..first, false)
    }

    fn prepare(&self, ctx: &Ctx, first: u32, keep: bool, work: &mut Work) -> Prepared<LightPool> {
        let counts = self.counts(ctx.scene);
        let conn = Connector::new(ctx.scene, self.base.heuristic, &counts);
        let traced = self.base.trace(ctx, &conn, None, first, keep, work);
        Prepared { pass: traced.pool, splats: traced.splats, counters: traced.counters, splat_paths: None }
    }

    fn render_tile(&self, ctx: &Ctx, pool: &LightPool, tile: Tile, first: u32, count: u32) -> TileResult<PoolCounters> {
        let counts = self.counts(ctx.scene);
        let conn = Connector::new(ctx.scene, self.base.heuristic, &counts);
        let v = pool.connectible.len();
        let select = Uniform { v, scale: v as f32 / (pool.paths.max(1) as f32 * self.connections as f32) };
        let mut sampler = self.base.sampler(&conn, pool, self.connections, &select);
        let result = sample_tile(ctx, tile, first, count, |pos, rng, sink, counters| {
            sampler.sample(pos, rng, sink, counters);
            true
        });
        result.map(|()| sampler.draws)
    }

    fn finish(&mut self, ctx: &Ctx, pool: LightPool, iterations: Range<u32>, results: &[TileResult<PoolCounters>]) {
        self.vbar = pool.mean_vertices();
        self.base.finish(ctx, &pool, &iterations, results.iter().map(|r| &r.data));
    }

    fn details(&self) -> Details {
        Details::of(LvcStats { pool: self.base.stats })
    }
}

/// LVC's statistics: its pools.
#[derive(Clone, Debug, Serialize)]
pub struct LvcStats {
    pub pool: PoolStats,
}

impl IntegratorStats for LvcStats {
    fn lines(&self, _: &RenderStats) -> Vec<String> {
        self.pool.line().into_iter().collect()
    }
}

impl Integrator for LvcOptions {
    const BIDIRECTIONAL: bool = true;
    const MEDIA: bool = true;

    fn render(&self, scene: &Scene, opts: &RunOptions, iterations: Iterations) -> Rendered {
        if self.connections == 0 {
            return Err(Error::Usage("--connections must be at least 1".into()));
        }
        let pixels = scene.film.width as usize * scene.film.height as usize;
        let m = if self.light_paths == 0 { pixels } else { self.light_paths };
        let base = PoolBase::new(Bdpt::for_scene(scene, false), self.heuristic, self.max_pool_mb, m);
        let method = LvcRender::new(base, self.connections);
        crate::integrator::render_loop::run(scene, opts, method, true, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
        Some(&mut self.heuristic)
    }
}
