//! What a render counts and reports: the work counters every tile sums, the phases' times,
//! the statistics of a finished render, and the interface through which an integrator adds
//! its own ([`IntegratorStats`]: serialized into `--stats` JSON, printed in the summary).

use crate::integrator::bidir::pool::CONCENTRATION_DEPTHS;
use crate::integrator::{IntegratorKind, Method, RenderOptions};
use crate::scene::Scene;
use serde::Serialize;
use std::any::Any;
use std::fmt::Debug;
use std::ops::Range;
use std::sync::Arc;

/// An integrator's own statistics: their JSON (an object whose fields join the render's
/// `--stats` object) and their lines in the render's summary.
pub trait IntegratorStats: AsJson + Any + Debug + Send + Sync {
    /// The summary's lines on these statistics (`render` is the whole render's).
    fn lines(&self, render: &RenderStats) -> Vec<String>;
}

/// A value's JSON object, for [`IntegratorStats`] (every `Serialize` type has it).
pub trait AsJson {
    fn as_json(&self) -> serde_json::Value;
}

impl<T: Serialize> AsJson for T {
    fn as_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or(serde_json::Value::Null)
    }
}

/// The integrator's statistics of a render, if it keeps any.
#[derive(Clone, Debug, Default)]
pub struct Details(Option<Arc<dyn IntegratorStats>>);

impl Details {
    pub fn of(stats: impl IntegratorStats) -> Details {
        Details(Some(Arc::new(stats)))
    }

    /// The statistics as their own type `T`, if they are a `T`.
    pub fn get<T: IntegratorStats>(&self) -> Option<&T> {
        let any: &dyn Any = self.0.as_deref()?;
        any.downcast_ref()
    }

    /// The summary's lines on them.
    pub fn lines(&self, render: &RenderStats) -> Vec<String> {
        self.0.as_ref().map(|s| s.lines(render)).unwrap_or_default()
    }
}

impl Serialize for Details {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = s.serialize_map(None)?;
        if let Some(serde_json::Value::Object(fields)) = self.0.as_ref().map(|d| d.as_json()) {
            for (k, v) in &fields {
                map.serialize_entry(k, v)?;
            }
        }
        map.end()
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
    /// Pool draws of a camera vertex that repeated an earlier draw of it and were merged
    /// into that connection (its weight counts both).
    pub draws_merged: u64,
    /// Pool draws whose connection was traced and found unoccluded, by the depth of the
    /// camera vertex (`[t - 2]` for `z_{t-1}`, deeper ones in the last entry).
    pub pool_hits: [u64; CONCENTRATION_DEPTHS],
    /// Sum over those draws of `1 / (V · PMF)`, the inverse of their selection probability
    /// relative to uniform selection (1 for uniform draws), by the same depths.
    pub pool_hits_inverse_concentration: [f64; CONCENTRATION_DEPTHS],
    /// Shadow rays of pool connections (of `shadow_rays`).
    pub pool_shadow_rays: u64,
    /// Camera vertices that drew pool connections.
    pub pool_lookups: u64,
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
        self.draws_merged += o.draws_merged;
        self.pool_shadow_rays += o.pool_shadow_rays;
        self.pool_lookups += o.pool_lookups;
        for k in 0..CONCENTRATION_DEPTHS {
            self.pool_hits[k] += o.pool_hits[k];
            self.pool_hits_inverse_concentration[k] += o.pool_hits_inverse_concentration[k];
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
    /// Re-running the iterations before a chunk's first one that its state comes from.
    pub warmup: f64,
}

/// Shadow rays traced in each phase of the render loop.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PhaseRays {
    pub light_pool: u64,
    pub cache: u64,
    pub camera_pass: u64,
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
    /// The integrator's options.
    pub options: Method,
    /// The integrator's own statistics (their fields join these in the JSON).
    #[serde(flatten)]
    pub details: Details,
    /// Samples dropped because they were NaN or infinite.
    pub invalid_samples: u64,
    /// The render stopped early (interrupted).
    pub interrupted: bool,
    /// The iterations rendered (samples per pixel, or mutations per pixel for the Markov
    /// chains), when known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iterations: Option<Range<u32>>,
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
            integrator: opts.integrator(),
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
            options: opts.method.clone(),
            details: Details::default(),
            invalid_samples,
            interrupted,
            iterations: None,
        }
    }
}
