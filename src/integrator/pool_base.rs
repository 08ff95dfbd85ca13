//! The base of the integrators that connect camera vertices to a light pool shared by every
//! pixel of an iteration (contract §5): LVC ([`crate::integrator::lvc`]), PCBPT and SPCBPT
//! embed a [`PoolBase`], which does in the render loop what they share, and add what is
//! their own — strategy counts, a
//! [`PoolSelection`](crate::integrator::bidir::pool::PoolSelection), what they build over each pool (PCBPT's
//! cache, SPCBPT's subspaces), and for PCBPT and SPCBPT a budget:
//! - `begin`: a pilot pool measures `V̄`, fixes the light paths per iteration `M` and checks
//!   the pool's memory ([`PoolBase::pilot`]);
//! - `prepare`: the iteration's pool, its light tracing splatting when the render keeps the
//!   iteration, through the budget where there is one ([`PoolBase::trace`]);
//! - `render_tile`: the camera pass, BDPT's `s = 0` and `s = 1` strategies and `N` draws of
//!   the selection per camera vertex ([`PoolBase::sampler`]);
//! - `finish`: the pool's size and the draws of the iterations the render keeps
//!   ([`PoolBase::finish`]), which the integrator's statistics report ([`PoolStats`]).

use crate::error::Error;
use crate::integrator::bidir::bdpt::{Bdpt, Connector, Scratch};
use crate::integrator::bidir::mis::{Counts, Heuristic, StrategyCounts};
use crate::integrator::bidir::pool::{
    LightPool, PILOT_ITERATION, PoolCounters, PoolPass, PoolSampler, check_pool_memory,
};
use crate::integrator::budget::{Budget, Operations, TracedPool};
use crate::integrator::render_loop::{Ctx, Work};
use serde::Serialize;
use std::ops::Range;
use std::time::Instant;

/// What the pool integrators share in the render loop.
pub struct PoolBase {
    /// The walks and the strategies of the camera pass.
    pub bdpt: Bdpt,
    pub heuristic: Heuristic,
    /// Memory limit of the pool, in MiB.
    pub max_pool_mb: usize,
    /// Light paths per iteration (`M`): the option's until the pilot fixes it.
    pub light_paths: usize,
    pub stats: PoolStats,
}

/// A pool integrator's statistics of its pools.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PoolStats {
    /// Light paths and connectible vertices of the last pool.
    pub size: Option<(usize, usize)>,
    /// The draws of the camera passes of the iterations the render keeps.
    pub draws: PoolCounters,
}

impl PoolStats {
    /// The summary's line on the pools.
    pub fn line(&self) -> Option<String> {
        let (paths, vertices) = self.size?;
        let d = &self.draws;
        Some(format!(
            "  light pool: {paths} paths with {vertices} connectible vertices (the last iteration's); {} camera \
             vertices drew, {} repeated draws merged, {} shadow rays",
            d.lookups, d.draws_merged, d.shadow_rays
        ))
    }
}

impl PoolBase {
    pub fn new(bdpt: Bdpt, heuristic: Heuristic, max_pool_mb: usize, light_paths: usize) -> PoolBase {
        PoolBase { bdpt, heuristic, max_pool_mb, light_paths, stats: PoolStats::default() }
    }

    /// Traces the pilot pool of [`PoolBase::light_paths`] paths and fixes `M` from it: enough
    /// paths for about `target` pool vertices ([`light_paths_for`]; 0 keeps the option's);
    /// fails when the pool of `M` paths would need more memory than its limit.
    pub(crate) fn pilot(&mut self, ctx: &Ctx, target: usize) -> Result<LightPool, Error> {
        let (scene, m) = (ctx.scene, self.light_paths);
        let (pilot, _, _) = LightPool::trace::<Counts>(scene, &self.bdpt.limits, m, ctx.seed, PILOT_ITERATION, None);
        let pixels = scene.film.width as usize * scene.film.height as usize;
        let m = light_paths_for(m, target, pilot.mean_vertices(), pixels);
        check_pool_memory(m, &pilot, self.max_pool_mb, "--light-paths")?;
        self.light_paths = m;
        Ok(pilot)
    }

    /// Traces the pool of iteration `first`, its light tracing splatting through `conn` when
    /// the render keeps the iteration (`keep`), by the budget's plan where there is one, and
    /// adds its time and shadow rays to `work`.
    pub(crate) fn trace<C: StrategyCounts + Sync>(
        &self,
        ctx: &Ctx,
        conn: &Connector<C>,
        budget: Option<&Budget>,
        first: u32,
        keep: bool,
        work: &mut Work,
    ) -> TracedPool {
        let t = Instant::now();
        let traced = match budget {
            Some(budget) => budget.trace_pool(ctx, conn, &self.bdpt, first, keep, self.light_paths),
            None => {
                let splat = keep.then_some((conn, &self.bdpt, ctx.layers));
                let (limits, m) = (&self.bdpt.limits, self.light_paths);
                let (pool, splats, counters) = LightPool::trace(ctx.scene, limits, m, ctx.seed, first as u64, splat);
                let splat_paths = counters.light_paths;
                let operations = Operations::default();
                TracedPool { pool, splats, counters, splat_shares: Vec::new(), operations, splat_paths }
            }
        };
        work.phases.light_pool += t.elapsed().as_secs_f64();
        work.shadow.light_pool += traced.counters.shadow_rays;
        traced
    }

    /// The camera pass over `pool`: `connections` draws of `select` per camera vertex.
    pub(crate) fn sampler<'a, C, P>(
        &'a self,
        conn: &'a Connector<'a, C>,
        pool: &'a LightPool,
        connections: u32,
        select: &'a P,
    ) -> PoolSampler<'a, C, P> {
        let pass = PoolPass { bdpt: &self.bdpt, connections, conn, pool };
        PoolSampler { pass, select, scratch: Scratch::default(), draws: PoolCounters::default() }
    }

    /// After the pass over `pool` of `iterations`: keeps the pool's size and, when the render
    /// keeps the iterations, the tiles' `draws`.
    pub(crate) fn finish<'a>(
        &mut self,
        ctx: &Ctx,
        pool: &LightPool,
        iterations: &Range<u32>,
        draws: impl IntoIterator<Item = &'a PoolCounters>,
    ) {
        self.stats.size = Some((pool.paths, pool.connectible.len()));
        if iterations.start >= ctx.start {
            for d in draws {
                self.stats.draws += *d;
            }
        }
    }
}

/// Light paths per iteration: at least `floor`, and enough for about `target` pool vertices
/// at `vbar` vertices per path, but no more than one per pixel (beyond that the pool would
/// cost more than BDPT's light subpaths). A `target` of 0, or a pilot with no vertices,
/// keeps `floor`.
pub fn light_paths_for(floor: usize, target: usize, vbar: f32, pixels: usize) -> usize {
    if target == 0 || vbar.is_nan() || vbar <= 0.0 {
        return floor;
    }
    let want = (target as f64 / vbar as f64).ceil() as usize;
    floor.max(want.min(pixels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_paths_reach_the_pool_target_between_the_floor_and_one_per_pixel() {
        // veach-ajar's 4.4 vertices per path: the floor already gives 2 000.
        assert_eq!(light_paths_for(500, 2000, 4.4, 57_600), 500);
        // sunlit-room's 0.62 (most paths from the sky miss the room): 3 226 paths.
        assert_eq!(light_paths_for(500, 2000, 0.62, 57_600), 3226);
        // At most one per pixel; a target of 0 or an empty pilot keeps the floor.
        assert_eq!(light_paths_for(500, 2000, 0.01, 57_600), 57_600);
        assert_eq!(light_paths_for(500, 0, 0.62, 57_600), 500);
        assert_eq!(light_paths_for(500, 2000, 0.0, 57_600), 500);
        assert_eq!(light_paths_for(500, 2000, f32::NAN, 57_600), 500);
        // The floor wins over the pixel cap.
        assert_eq!(light_paths_for(500, 2000, 0.01, 100), 500);
    }
}
