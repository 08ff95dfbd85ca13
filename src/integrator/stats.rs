//! What a render counts and reports: the work counters every tile sums, the phases' times,
//! the statistics of a finished render, and the interface through which an integrator adds
//! its own ([`IntegratorStats`]: serialized into `--stats` JSON, printed in the summary).

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
}

impl Counters {
    /// Every ray traced: camera, extension and shadow rays.
    #[inline]
    pub fn rays(&self) -> u64 {
        self.camera_rays + self.extension_rays + self.shadow_rays
    }

    /// Runs `trace`, a walk from the camera that counts every ray it traces as an extension
    /// ray, and counts its first ray as the camera ray instead (none when it traced none).
    #[inline]
    pub fn camera_path<T>(&mut self, trace: impl FnOnce(&mut Counters) -> T) -> T {
        let before = self.extension_rays;
        let out = trace(self);
        if self.extension_rays > before {
            self.extension_rays -= 1;
            self.camera_rays += 1;
        }
        out
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
    /// The integrator's name (filled by the registry's dispatch).
    pub integrator: &'static str,
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
    /// The integrator's options (filled by the registry's dispatch).
    pub options: serde_json::Value,
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
    /// The render's own estimate of its relMSE against the true image, from two half-images
    /// ([`crate::integrator::noise`]), when it kept them (the variance AOV, the noise
    /// threshold).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relmse_estimate: Option<f64>,
    /// With a noise threshold: whether the estimate fell below it (or the budget ran out
    /// first).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise_threshold_reached: Option<bool>,
}

impl RenderStats {
    /// The statistics every render loop reports; the rest start empty.
    pub(crate) fn new(
        scene: &Scene,
        threads: usize,
        counters: Counters,
        seconds: f64,
        spp: u32,
        invalid_samples: u64,
        interrupted: bool,
    ) -> RenderStats {
        let mut stats = RenderStats {
            integrator: "",
            backend: scene.accel.backend().to_string(),
            threads,
            width: scene.film.width,
            height: scene.film.height,
            spp,
            passes: 1,
            seconds,
            samples_per_second: 0.0,
            rays_per_second: 0.0,
            counters,
            phases: PhaseTimes::default(),
            shadow_rays: PhaseRays::default(),
            options: serde_json::Value::Null,
            details: Details::default(),
            invalid_samples,
            interrupted,
            iterations: None,
            relmse_estimate: None,
            noise_threshold_reached: None,
        };
        stats.set_rates();
        stats
    }

    /// Samples and rays per second from the counters and the seconds.
    pub(crate) fn set_rates(&mut self) {
        self.samples_per_second = self.counters.samples as f64 / self.seconds.max(1e-9);
        self.rays_per_second = self.counters.rays() as f64 / self.seconds.max(1e-9);
    }
}
