//! The cost model of a budget ([`super`]): the operations an iteration counts and their
//! prices, from which the cost of an iteration under another plan is predicted.

use crate::integrator::budget::{Plan, PoolTile};
use crate::integrator::render_loop::TileResult;
use serde::Serialize;

/// Relative cost of the operations an iteration counts, in extension rays (a closest-hit
/// ray and the vertex built at its hit), fitted once to PCBPT's camera pass timed at several
/// connection counts per camera vertex (the timings are in `docs/results/budget.md`): a
/// traced connection (its draw, both BSDFs, the shadow ray and the MIS weight), a lookup
/// (the search a camera vertex's draws need), next-event shadow rays priced like
/// connections, and a cache entry (a record's target and shadow ray for one pool vertex).
///
/// SPCBPT's connection costs more (its draw samples a light subspace from `Γ` by a guide
/// table into the row's running sum, and a vertex within it from the subspace's alias
/// table), and its counts that follow the path's subspaces make every connection's weight
/// dearer still, so its connections are priced by their MIS counts ([`SPCBPT_PRICES`] for
/// counts that do not follow them, [`SPCBPT_SUBSPACE_PRICES`], [`SPCBPT_RESAMPLING_PRICES`]),
/// each from its camera pass's time per added connection against PCBPT's
/// (`docs/results/spcbpt.md`).
#[derive(Clone, Copy, Debug)]
pub struct Prices {
    /// A shadow ray of next-event estimation or light tracing.
    pub shadow: f64,
    /// A traced pool connection.
    pub connection: f64,
    pub lookup: f64,
    pub cache_entry: f64,
    /// The path tracer's camera pass over the bidirectional one's without connections (the
    /// plan without connections or light tracing renders with the path tracer).
    pub path_tracer: f64,
}

/// PCBPT's prices.
pub const PRICES: Prices = Prices { shadow: 1.15, connection: 1.15, lookup: 0.58, cache_entry: 1.0, path_tracer: 0.82 };

/// SPCBPT's prices: PCBPT's, with its dearer connections.
pub const SPCBPT_PRICES: Prices = Prices { connection: 1.29, ..PRICES };

/// SPCBPT's prices with `--sp-mis subspace`.
pub const SPCBPT_SUBSPACE_PRICES: Prices = Prices { connection: 1.63, ..PRICES };

/// SPCBPT's prices with `--sp-mis resampling`.
pub const SPCBPT_RESAMPLING_PRICES: Prices = Prices { connection: 2.17, ..PRICES };

/// Operations one iteration performed, summed over the measured iterations.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Operations {
    /// Camera and extension rays of the camera pass.
    pub camera_rays: u64,
    /// Shadow rays of the camera pass other than pool connections (next-event estimation).
    pub camera_shadow: u64,
    /// Shadow rays of pool connections.
    pub pool_shadow: u64,
    /// Camera vertices that drew connections.
    pub lookups: u64,
    /// Rays of the light paths.
    pub light_rays: u64,
    /// Shadow rays of light tracing.
    pub splat_shadow: u64,
    /// Cache entries built for the pool (PCBPT's records × pool vertices; 0 for SPCBPT).
    pub cache_entries: u64,
}

impl std::ops::AddAssign for Operations {
    fn add_assign(&mut self, o: Operations) {
        self.camera_rays += o.camera_rays;
        self.camera_shadow += o.camera_shadow;
        self.pool_shadow += o.pool_shadow;
        self.lookups += o.lookups;
        self.light_rays += o.light_rays;
        self.splat_shadow += o.splat_shadow;
        self.cache_entries += o.cache_entries;
    }
}

impl Operations {
    /// These operations with those of a camera pass's tiles added.
    pub(crate) fn with_camera_pass<L>(mut self, results: &[TileResult<PoolTile<L>>]) -> Operations {
        for r in results {
            let (c, d) = (&r.counters, &r.data.draws);
            self.camera_rays += c.camera_rays + c.extension_rays;
            self.camera_shadow += c.shadow_rays - d.shadow_rays;
            self.pool_shadow += d.shadow_rays;
            self.lookups += d.lookups;
        }
        self
    }

    /// The cost of an iteration under `to`, in extension rays, from these operations made
    /// under `from`.
    pub fn cost(&self, from: &Plan, to: &Plan, prices: &Prices) -> f64 {
        let ratio = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
        let mut c = self.camera_rays as f64 + prices.shadow * self.camera_shadow as f64;
        if to.path_tracing() {
            return c * prices.path_tracer;
        }
        if to.connections > 0 {
            c += prices.connection * self.pool_shadow as f64 * to.connections as f64 / from.connections.max(1) as f64;
            c += prices.cache_entry * self.cache_entries as f64 + prices.lookup * self.lookups as f64;
        }
        c += self.light_rays as f64 * ratio(to.traced(), from.traced());
        c += prices.shadow * self.splat_shadow as f64 * ratio(to.splat_paths, from.splat_paths);
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn costs_scale_each_part_with_what_the_plan_changes() {
        let from = Plan { connections: 4, pool_paths: 500, splat_paths: 500 };
        let ops = Operations {
            camera_rays: 1000,
            camera_shadow: 500,
            pool_shadow: 2000,
            lookups: 0,
            light_rays: 100,
            splat_shadow: 50,
            cache_entries: 300,
        };
        let p = Prices { shadow: 0.5, connection: 0.75, lookup: 0.0, cache_entry: 0.25, path_tracer: 0.8 };
        assert_eq!(ops.cost(&from, &from, &p), 1000.0 + 250.0 + 1500.0 + 75.0 + 100.0 + 25.0);
        let pt = Plan { connections: 0, pool_paths: 0, splat_paths: 0 };
        assert_eq!(ops.cost(&from, &pt, &p), 1000.0);
        let more = Plan { connections: 8, pool_paths: 500, splat_paths: 2000 };
        assert_eq!(ops.cost(&from, &more, &p), 1250.0 + 3000.0 + 75.0 + 400.0 + 100.0);
    }
}
