//! BDPT's per-sample estimator ([`Bdpt::sample`]) as a wavefront: a tile's camera samples
//! are taken [`BATCH`] at a time. Their camera walks advance bounce by bounce, each bounce's
//! rays answered in one batch query (Embree's stream interface), then their light walks the
//! same way; then every strategy of every sample is evaluated, and the shadow rays of all
//! their connections are answered in one batch of occlusion queries; last, each sample's
//! visible strategies are weighted and delivered, sample by sample.
//!
//! Each sample draws its random numbers from its own sampler, in the order
//! [`Bdpt::sample`] draws them (no draw depends on a shadow ray's answer), and delivers its
//! contributions in the same order, so the two give the same image wherever the batch
//! queries report the hits single queries report. The MIS weights stay scalar: they are
//! computed at delivery, for the visible connections only, as one sample at a time does.

use crate::accel::Ray;
use crate::film::{ImageBlock, Tile};
use crate::integrator::bidir::bdpt::{Bdpt, ConnectionPolicy, Connector};
use crate::integrator::bidir::mis::StrategyCounts;
use crate::integrator::bidir::walk::{Walk, camera_start, light_start, shadow_segment};
use crate::integrator::bidir::{Connection, Sink, Vertex};
use crate::integrator::render_loop::{Bounce, Ctx, PixelSink, TileResult, camera_samples, tile_block};
use crate::integrator::stats::Counters;
use crate::math::Rgb;
use crate::sampling::{Random, Sampler};
use crate::scene::Scene;
use glam::Vec2;
use std::slice::from_ref;

/// Samples traced together: enough for the batch queries to pay (about ten shadow rays and
/// eight walk rays a sample), few enough for their subpaths to stay in the core's caches.
const BATCH: usize = 256;

/// A camera sample in flight: its sampler, its film position, its two subpaths and the walk
/// that is growing one of them.
struct Lane {
    sampler: Sampler,
    pos: Vec2,
    camera: Vec<Vertex>,
    light: Vec<Vertex>,
    walk: Option<Walk>,
}

/// A strategy of a sample, evaluated: an emitter the camera subpath ends on, or a
/// connection waiting for its shadow ray's answer (answered in the order of the strategies)
/// with its unweighted contribution `c` and what [`Connector::judge`] decided.
enum Strategy {
    /// `s = 0`: the camera subpath's first `t` vertices end on an emitter.
    Emission {
        t: usize,
    },
    Connected {
        ends: Ends,
        conn: Connection,
        c: Rgb,
        weight: Option<f32>,
    },
}

/// The subpaths a connection joins.
#[derive(Clone, Copy)]
enum Ends {
    /// `s = 1`: the light sample `y0` (an index into [`Queues::light_samples`]) seen from
    /// the camera subpath's `t`-th vertex.
    NextEvent { t: usize, y0: usize },
    /// `t = 1`: the light subpath's first `s` vertices seen by the camera at `raster`.
    ToCamera { s: usize, raster: Vec2 },
    /// `s, t >= 2`.
    Connect { s: usize, t: usize },
}

/// The batches' buffers, kept from one batch to the next.
#[derive(Default)]
struct Queues {
    /// The walks under way and their rays.
    bounce: Bounce,
    /// Every lane's strategies, lane after lane, and where each lane's end.
    strategies: Vec<Strategy>,
    ends: Vec<usize>,
    light_samples: Vec<Vertex>,
    /// The connections' shadow rays, in the order of the strategies, and their answers.
    shadow: Vec<Ray>,
    occluded: Vec<bool>,
}

impl Bdpt {
    /// Iterations `first..first + count` of a tile of BDPT (not light tracing alone), its
    /// strategies evaluated by `conn`, traced as a wavefront (a scene without media).
    pub(super) fn tile_wavefront<C: StrategyCounts, P: ConnectionPolicy>(
        &self,
        ctx: &Ctx,
        conn: &Connector<C, P>,
        tile: Tile,
        first: u32,
        count: u32,
    ) -> TileResult {
        debug_assert!(!self.light_only && !ctx.scene.volumetric);
        let scene = ctx.scene;
        let mut block = tile_block(ctx, tile);
        let mut counters = Counters::default();
        let mut splats = Vec::new();
        let mut q = Queues::default();
        let mut lanes: Vec<Lane> = Vec::with_capacity(BATCH);
        let mut samples = camera_samples::<Sampler>(ctx, tile, (first, count), None);
        loop {
            let mut n = 0;
            for (sampler, pos) in samples.by_ref().take(BATCH) {
                if n == lanes.len() {
                    lanes.push(Lane { sampler, pos, camera: Vec::new(), light: Vec::new(), walk: None });
                } else {
                    (lanes[n].sampler, lanes[n].pos) = (sampler, pos);
                }
                n += 1;
            }
            if n == 0 {
                break;
            }
            let lanes = &mut lanes[..n];
            for lane in lanes.iter_mut() {
                lane.walk = camera_start(scene, lane.pos, &self.limits, &mut lane.camera);
            }
            self.walk(scene, lanes, true, &mut q, &mut counters);
            for lane in lanes.iter_mut() {
                lane.sampler.start_stream(1);
                lane.walk = light_start(scene, &self.limits, &mut lane.sampler, &mut lane.light);
            }
            counters.light_paths += n as u64;
            self.walk(scene, lanes, false, &mut q, &mut counters);
            self.evaluate(conn, lanes, &mut q, &mut counters);
            scene.accel.occluded_batch(&q.shadow, false, &mut q.occluded);
            deliver_batch(conn, lanes, &q, &mut PixelSink::new(ctx.layers, &mut splats), &mut block, &mut counters);
            counters.samples += n as u64;
        }
        TileResult { block, splats, counters, data: () }
    }

    /// Runs the lanes' walks (camera walks, the first bounce's rays counted as camera rays,
    /// or light walks) to their ends, each bounce's rays in one batch query.
    fn walk(&self, scene: &Scene, lanes: &mut [Lane], camera: bool, q: &mut Queues, counters: &mut Counters) {
        let b = &mut q.bounce;
        b.live.clear();
        b.live.extend(0..lanes.len() as u32);
        let mut first = camera;
        loop {
            // The walks still under way, and their rays.
            b.next.clear();
            b.rays.clear();
            for &i in &b.live {
                if let Some(walk) = &lanes[i as usize].walk {
                    b.next.push(i);
                    b.rays.push(walk.ray);
                }
            }
            std::mem::swap(&mut b.live, &mut b.next);
            if b.live.is_empty() {
                break;
            }
            b.intersect(scene, first, counters);
            first = false;
            for (k, &i) in b.live.iter().enumerate() {
                let lane = &mut lanes[i as usize];
                let si = b.hits[k].as_ref().map(|hit| scene.interaction(&b.rays[k], hit));
                let path = if camera { &mut lane.camera } else { &mut lane.light };
                let Some(walk) = lane.walk.as_mut() else { continue };
                if !walk.step(scene, si, &self.limits, &mut lane.sampler, path) {
                    lane.walk = None;
                }
            }
        }
    }

    /// Evaluates every strategy of every lane, in [`Bdpt::sample`]'s order, drawing each
    /// lane's numbers from its sampler: the strategies and the connections' shadow rays
    /// go to `q`.
    fn evaluate<C: StrategyCounts, P: ConnectionPolicy>(
        &self,
        conn: &Connector<C, P>,
        lanes: &mut [Lane],
        q: &mut Queues,
        counters: &mut Counters,
    ) {
        q.strategies.clear();
        q.ends.clear();
        q.light_samples.clear();
        q.shadow.clear();
        let z0 = conn.camera_vertex();
        for lane in lanes.iter_mut() {
            let rng = &mut lane.sampler;
            rng.start_stream(2);
            let (camera, light, pos) = (&lane.camera, &lane.light, lane.pos);
            for t in 1..=camera.len() {
                for s in self.allowed_light_lengths(t, light.len()) {
                    let (z, y) = (&camera[..t], &light[..s]);
                    let (ends, conn_, c, weight, ray) = match (s, t) {
                        (0, _) => {
                            q.strategies.push(Strategy::Emission { t });
                            continue;
                        }
                        (_, 1) => {
                            let Some((raster, c_, c)) = conn.camera_connection(y) else { continue };
                            let Some(weight) = conn.judge(y, from_ref(&z0), &c_, c, raster, rng) else { continue };
                            (Ends::ToCamera { s, raster }, c_, c, weight, shadow_segment(&y[s - 1], &z0).0)
                        }
                        (1, _) => {
                            let Some((y0, c_, c)) = conn.light_sample(z, rng) else { continue };
                            let Some(weight) = conn.judge(from_ref(&y0), z, &c_, c, pos, rng) else { continue };
                            let ray = shadow_segment(&y0, &z[t - 1]).0;
                            q.light_samples.push(y0);
                            (Ends::NextEvent { t, y0: q.light_samples.len() - 1 }, c_, c, weight, ray)
                        }
                        _ => {
                            let Some((c_, c)) = conn.connection(y, z, 1.0) else { continue };
                            let Some(weight) = conn.judge(y, z, &c_, c, pos, rng) else { continue };
                            (Ends::Connect { s, t }, c_, c, weight, shadow_segment(&y[s - 1], &z[t - 1]).0)
                        }
                    };
                    q.strategies.push(Strategy::Connected { ends, conn: conn_, c, weight });
                    q.shadow.push(ray);
                    counters.connections += 1;
                    counters.shadow_rays += 1;
                }
            }
            q.ends.push(q.strategies.len());
        }
    }
}

/// Delivers the strategies of a batch's lanes, lane after lane, each lane's pixel (its
/// radiance and strategy parts) added to `block` when its strategies are in.
fn deliver_batch<C: StrategyCounts, P: ConnectionPolicy>(
    conn: &Connector<C, P>,
    lanes: &[Lane],
    q: &Queues,
    sink: &mut PixelSink,
    block: &mut ImageBlock,
    counters: &mut Counters,
) {
    let mut answers = q.occluded.iter().copied();
    let mut start = 0;
    for (lane, &end) in lanes.iter().zip(&q.ends) {
        sink.clear();
        for strategy in &q.strategies[start..end] {
            deliver(conn, lane, strategy, &q.light_samples, &mut answers, sink, counters);
        }
        sink.put(block, lane.pos);
        start = end;
    }
}

/// Delivers one evaluated strategy of `lane` to its pixel's sink, a connection only when
/// its shadow ray (the next of `answers`) found its ends visible to each other.
fn deliver<C: StrategyCounts, P: ConnectionPolicy>(
    conn: &Connector<C, P>,
    lane: &Lane,
    strategy: &Strategy,
    light_samples: &[Vertex],
    answers: &mut impl Iterator<Item = bool>,
    sink: &mut PixelSink,
    counters: &mut Counters,
) {
    let (camera, light) = (&lane.camera, &lane.light);
    let (ends, c_, c, weight) = match strategy {
        Strategy::Emission { t } => return conn.emission(&camera[..*t], sink),
        Strategy::Connected { ends, conn, c, weight } => (*ends, conn, *c, *weight),
    };
    if answers.next().unwrap_or(true) {
        counters.connections_occluded += 1;
        return;
    }
    match ends {
        Ends::NextEvent { t, y0 } => {
            let y = from_ref(&light_samples[y0]);
            conn.deliver(y, &camera[..t], c_, c, weight, None, sink, |sk, c, w| sk.add(1, t, c * w));
        }
        Ends::ToCamera { s, raster } => {
            let z0 = conn.camera_vertex();
            conn.deliver(&light[..s], from_ref(&z0), c_, c, weight, None, sink, |sk, c, w| {
                sk.splat(s, 1, raster, c * w)
            });
        }
        Ends::Connect { s, t } => {
            let (y, z) = (&light[..s], &camera[..t]);
            conn.deliver(y, z, c_, c, weight, None, sink, |sk, c, w| sk.add_connection(y, z, c, w));
        }
    }
}
