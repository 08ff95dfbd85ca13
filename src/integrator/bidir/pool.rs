//! Light pools shared by every pixel of an iteration (contract §5), and the camera pass of
//! the integrators that connect to them (LVC, PCBPT, SPCBPT): BDPT's `s = 0` and `s = 1`
//! strategies at every camera vertex and connections to pool vertices that a
//! [`PoolSelection`] picks.

use crate::error::Error;
use crate::film::Splat;
use crate::integrator::bidir::bdpt::{Bdpt, Connector, Scratch};
use crate::integrator::bidir::mis::StrategyCounts;
use crate::integrator::bidir::walk::{WalkLimits, camera_subpath, light_subpath};
use crate::integrator::bidir::{Delivery, Sink, Vertex};
use crate::integrator::stats::Counters;
use crate::math::Rgb;
use crate::sampling::{Random, Sampler};
use crate::scene::Scene;
use glam::Vec2;
use rayon::prelude::*;
use serde::Serialize;

/// Camera depths the concentration of pool draws is measured for: `z_1 .. z_15` each, deeper
/// vertices together.
pub const CONCENTRATION_DEPTHS: usize = 16;

/// The entry of a concentration measured, or a count looked up, for camera vertex `z_{t-1}`.
#[inline]
pub fn concentration_depth(t: usize) -> usize {
    (t - 2).min(CONCENTRATION_DEPTHS - 1)
}

/// What a camera pass counts of its pool draws.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PoolCounters {
    /// Camera vertices that drew pool connections.
    pub lookups: u64,
    /// Draws of a camera vertex that repeated an earlier draw of it and were merged into
    /// that connection (its weight counts both).
    pub draws_merged: u64,
    /// Shadow rays of pool connections.
    pub shadow_rays: u64,
    /// Draws whose connection was traced and found unoccluded, by the depth of the camera
    /// vertex ([`concentration_depth`]).
    pub hits: [u64; CONCENTRATION_DEPTHS],
    /// Sum over those draws of `1 / (V · PMF)`, the inverse of their selection probability
    /// relative to uniform selection (1 for uniform draws), by the same depths.
    pub hits_inverse_concentration: [f64; CONCENTRATION_DEPTHS],
}

impl PoolCounters {
    /// The harmonic mean of `V · PMF` over the unoccluded draws, over all depths and per
    /// camera depth (a depth without such draws gets the overall one); `None` without any.
    pub fn concentration(&self) -> Option<(f64, [f64; CONCENTRATION_DEPTHS])> {
        let hits: u64 = self.hits.iter().sum();
        let inverse: f64 = self.hits_inverse_concentration.iter().sum();
        if hits == 0 || inverse <= 0.0 {
            return None;
        }
        let all = hits as f64 / inverse;
        let mut by_depth = [all; CONCENTRATION_DEPTHS];
        for (k, c) in by_depth.iter_mut().enumerate() {
            if self.hits[k] > 0 && self.hits_inverse_concentration[k] > 0.0 {
                *c = self.hits[k] as f64 / self.hits_inverse_concentration[k];
            }
        }
        Some((all, by_depth))
    }
}

impl std::ops::AddAssign for PoolCounters {
    fn add_assign(&mut self, o: PoolCounters) {
        self.lookups += o.lookups;
        self.draws_merged += o.draws_merged;
        self.shadow_rays += o.shadow_rays;
        for k in 0..CONCENTRATION_DEPTHS {
            self.hits[k] += o.hits[k];
            self.hits_inverse_concentration[k] += o.hits_inverse_concentration[k];
        }
    }
}

/// Key word that separates pool random streams from camera-sample streams.
const POOL_STREAM: u64 = 0x706f_6f6c;

/// One chunk of a pool being traced: its vertices, path lengths, splats and counters.
type Chunk = (Vec<Vertex>, Vec<u32>, Vec<Splat>, Counters);

/// The light subpaths of one iteration in one flat array.
#[derive(Default)]
pub struct LightPool {
    /// Every vertex of every path, path after path.
    pub vertices: Vec<Vertex>,
    /// For each vertex, where its path starts in `vertices`.
    pub path_start: Vec<u32>,
    /// Where each path starts in `vertices`, in the order traced, and the end of the last.
    pub offsets: Vec<u32>,
    /// The vertices pool connections draw from: connectible surface vertices after the
    /// emitter (`y_1, y_2, …`; `y_0` is left to next-event estimation).
    pub connectible: Vec<u32>,
    /// Number of light subpaths traced (`M`).
    pub paths: usize,
}

/// What a pool's light tracing records of each splat besides the splat, for its
/// integrator (the budget's efficiency estimate records the splat's MIS shares): each splat's
/// path comes through [`SplatRecorder::observe`] right before the splat.
pub trait SplatRecorder: Sync {
    /// What is kept of a path until its splat.
    type Pending: Copy + Default;
    /// What is kept of a splat.
    type Record: Send;
    fn observe<C: StrategyCounts>(&self, delivery: &Delivery<'_, C>) -> Self::Pending;
    fn record(&self, pending: Self::Pending, pos: Vec2, value: Rgb) -> Self::Record;
}

/// Records nothing.
pub struct NoRecords;

impl SplatRecorder for NoRecords {
    type Pending = ();
    type Record = ();
    fn observe<C: StrategyCounts>(&self, _: &Delivery<'_, C>) {}
    fn record(&self, _: (), _: Vec2, _: Rgb) {}
}

/// Collects splats (pool light tracing has no pixel of its own), and with a recorder each
/// splat's record.
struct SplatSink<'a, R: SplatRecorder> {
    splats: &'a mut Vec<Splat>,
    layers: bool,
    recorder: Option<(&'a R, &'a mut Vec<R::Record>)>,
    pending: R::Pending,
}

impl<R: SplatRecorder> Sink for SplatSink<'_, R> {
    fn add(&mut self, _s: usize, _t: usize, _value: Rgb) {
        unreachable!("light paths only splat");
    }

    #[inline]
    fn splat(&mut self, s: usize, t: usize, pos: Vec2, value: Rgb) {
        self.splats.push(Splat::of_strategy(s, t, pos, value, self.layers));
        if let Some((recorder, out)) = self.recorder.as_mut() {
            out.push(recorder.record(self.pending, pos, value));
        }
    }

    fn observes(&self) -> bool {
        self.recorder.is_some()
    }

    fn observe<C: StrategyCounts>(&mut self, delivery: &Delivery<'_, C>) {
        if let Some((recorder, _)) = &self.recorder {
            self.pending = recorder.observe(delivery);
        }
    }
}

/// How many light paths an iteration traces, and what each does: paths `0..pool_paths`
/// form the pool that connections draw from, paths `0..splat_paths` are light traced
/// (`t = 1`). Path `i` is the same path whatever the plan (its random stream is keyed by `i`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PoolPlan {
    pub pool_paths: usize,
    pub splat_paths: usize,
}

impl PoolPlan {
    /// `m` paths that both form the pool and splat.
    pub fn both(m: usize) -> PoolPlan {
        PoolPlan { pool_paths: m, splat_paths: m }
    }

    pub fn traced(&self) -> usize {
        self.pool_paths.max(self.splat_paths)
    }
}

impl LightPool {
    /// Traces `paths` light subpaths for iteration `iteration`, splatting their `t = 1`
    /// strategies through `splat` when given. Work is split into fixed chunks and joined
    /// in order, so the pool and the splats do not depend on the number of threads.
    pub fn trace<C: StrategyCounts + Sync>(
        scene: &Scene,
        limits: &WalkLimits,
        paths: usize,
        seed: u64,
        iteration: u64,
        splat: Option<(&Connector<C>, &Bdpt, bool)>,
    ) -> (LightPool, Vec<Splat>, Counters) {
        let (pool, splats, counters, _) =
            LightPool::trace_plan::<C, NoRecords>(scene, limits, PoolPlan::both(paths), seed, iteration, splat, None);
        (pool, splats, counters)
    }

    /// [`LightPool::trace`] by a [`PoolPlan`]; with a `recorder`, also each splat's record,
    /// in the splats' order.
    pub fn trace_plan<C: StrategyCounts + Sync, R: SplatRecorder>(
        scene: &Scene,
        limits: &WalkLimits,
        plan: PoolPlan,
        seed: u64,
        iteration: u64,
        splat: Option<(&Connector<C>, &Bdpt, bool)>,
        recorder: Option<&R>,
    ) -> (LightPool, Vec<Splat>, Counters, Vec<R::Record>) {
        const CHUNK: usize = 256;
        let paths = plan.traced();
        let chunks: Vec<(Chunk, Vec<R::Record>)> = (0..paths.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| {
                let mut verts = Vec::new();
                let mut lens = Vec::new();
                let mut splats = Vec::new();
                let mut records = Vec::new();
                let mut counters = Counters::default();
                let mut path = Vec::new();
                for i in c * CHUNK..((c + 1) * CHUNK).min(paths) {
                    let mut rng = Sampler::new(&[seed, POOL_STREAM, iteration, i as u64]);
                    light_subpath(scene, limits, &mut rng, &mut path, &mut counters);
                    counters.light_paths += 1;
                    if let Some((conn, bdpt, layers)) = splat.filter(|_| i < plan.splat_paths) {
                        let recorder = recorder.map(|r| (r, &mut records));
                        let mut sink =
                            SplatSink { splats: &mut splats, layers, recorder, pending: R::Pending::default() };
                        for s in 1..=path.len() {
                            if bdpt.allowed(s, 1) {
                                conn.to_camera(&path[..s], &mut rng, &mut sink, &mut counters);
                            }
                        }
                    }
                    if i < plan.pool_paths {
                        lens.push(path.len() as u32);
                        verts.extend_from_slice(&path);
                    }
                }
                ((verts, lens, splats, counters), records)
            })
            .collect();
        let mut pool = LightPool { paths: plan.pool_paths, ..Default::default() };
        let mut splats = Vec::new();
        let mut all_records = Vec::new();
        let mut counters = Counters::default();
        for ((verts, lens, sp, c), sh) in chunks {
            all_records.extend(sh);
            let mut k = 0usize;
            for len in lens {
                let start = pool.vertices.len() as u32;
                pool.offsets.push(start);
                for (depth, v) in verts[k..k + len as usize].iter().enumerate() {
                    let index = pool.vertices.len() as u32;
                    if depth >= 1 && v.scatters() && v.is_connectible() {
                        pool.connectible.push(index);
                    }
                    pool.vertices.push(*v);
                    pool.path_start.push(start);
                }
                k += len as usize;
            }
            splats.extend(sp);
            counters += c;
        }
        pool.offsets.push(pool.vertices.len() as u32);
        (pool, splats, counters, all_records)
    }

    /// The light subpath `y_0..y_{s-1}` that ends at connectible vertex `k`.
    #[inline]
    pub fn prefix(&self, k: usize) -> &[Vertex] {
        let g = self.connectible[k] as usize;
        &self.vertices[self.path_start[g] as usize..=g]
    }

    /// Light path `i`, `y_0..`, as traced.
    #[inline]
    pub fn path(&self, i: usize) -> &[Vertex] {
        &self.vertices[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// Connectible vertices per light path (`V / M`).
    pub fn mean_vertices(&self) -> f32 {
        if self.paths == 0 { 0.0 } else { self.connectible.len() as f32 / self.paths as f32 }
    }
}

/// How a pool integrator picks the pool vertices a camera vertex connects to.
pub trait PoolSelection {
    /// What the draws of one camera vertex share.
    type Lookup;
    fn lookup(&self, z: &Vertex) -> Self::Lookup;
    /// Labels the camera subpath's vertices before their strategies are weighed
    /// ([`Vertex::label`]); nothing by default.
    fn label(&self, _camera: &mut [Vertex]) {}
    /// Draw `k` of `n` for a camera vertex: a connectible pool index and the factor
    /// `1 / (N M P)` of its contribution, or `None` when the draw is wasted.
    fn draw<R: Random>(&self, lookup: &Self::Lookup, k: u32, n: u32, rng: &mut R) -> Option<(usize, f32)>;
    /// All `n` draws of a camera vertex, in order, each passed to `out` unless wasted.
    fn draw_all<R: Random>(&self, lookup: &Self::Lookup, n: u32, rng: &mut R, out: impl FnMut(usize, f32)) {
        draw_one_by_one(self, lookup, n, rng, out)
    }
}

/// [`PoolSelection::draw_all`] by `n` calls of [`PoolSelection::draw`].
pub fn draw_one_by_one<P: PoolSelection + ?Sized, R: Random>(
    select: &P,
    lookup: &P::Lookup,
    n: u32,
    rng: &mut R,
    mut out: impl FnMut(usize, f32),
) {
    for k in 0..n {
        if let Some((i, scale)) = select.draw(lookup, k, n, rng) {
            out(i, scale);
        }
    }
}

/// A [`PoolPass`] with its selection and scratch, as one camera sample at a time, counting
/// its draws.
pub(crate) struct PoolSampler<'a, C, P> {
    pub pass: PoolPass<'a, C>,
    pub select: &'a P,
    pub scratch: Scratch,
    pub draws: PoolCounters,
}

impl<C: StrategyCounts, P: PoolSelection> PoolSampler<'_, C, P> {
    /// The camera sample at film position `pos`.
    #[inline]
    pub fn sample<R: Random>(&mut self, pos: Vec2, rng: &mut R, sink: &mut impl Sink, counters: &mut Counters) {
        self.pass.sample(self.select, pos, rng, &mut self.scratch, sink, counters, &mut self.draws);
    }
}

/// The camera pass of the pool integrators: per camera sample, BDPT's `s = 0` and `s = 1`
/// strategies at every camera vertex and `connections` connections to pool vertices chosen
/// by a [`PoolSelection`].
pub struct PoolPass<'a, C> {
    pub bdpt: &'a Bdpt,
    pub connections: u32,
    pub conn: &'a Connector<'a, C>,
    pub pool: &'a LightPool,
}

impl<C: StrategyCounts> PoolPass<'_, C> {
    #[allow(clippy::too_many_arguments)]
    pub fn sample<R: Random, P: PoolSelection>(
        &self,
        select: &P,
        pos: Vec2,
        rng: &mut R,
        scratch: &mut Scratch,
        sink: &mut impl Sink,
        counters: &mut Counters,
        draws: &mut PoolCounters,
    ) {
        let (conn, bdpt) = (self.conn, self.bdpt);
        camera_subpath(conn.scene, pos, &bdpt.limits, rng, &mut scratch.camera, counters);
        select.label(&mut scratch.camera);
        let camera = &scratch.camera;
        // A draw's factor is `1 / (N M P)`; `1 / (V P)` is its factor over this one's.
        let uniform_scale =
            self.pool.connectible.len() as f64 / (self.connections as f64 * self.pool.paths.max(1) as f64);
        for t in 2..=camera.len() {
            if bdpt.allowed(0, t) {
                conn.emission(&camera[..t], sink);
            }
            if bdpt.allowed(1, t) {
                conn.next_event(&camera[..t], pos, rng, sink, counters);
            }
            if self.connections == 0 || self.pool.connectible.is_empty() || !camera[t - 1].is_connectible() {
                continue;
            }
            draws.lookups += 1;
            let lookup = select.lookup(&camera[t - 1]);
            // Draws that repeat an earlier one (a peaked PMF and stratified draws) make the
            // same connection: it is evaluated and traced once with the factors summed.
            scratch.draws.clear();
            let drawn = &mut scratch.draws;
            select.draw_all(&lookup, self.connections, rng, |i, scale| match drawn.iter_mut().find(|d| d.0 == i) {
                Some(d) => {
                    d.1 += scale;
                    d.2 += 1;
                    draws.draws_merged += 1;
                }
                None => drawn.push((i, scale, 1)),
            });
            // The drawn pool vertices lie anywhere in the pool: their reads are started
            // together here rather than one connection after another.
            let mut touched = 0.0f32;
            for &(i, _, _) in &scratch.draws {
                let y = &self.pool.vertices[self.pool.connectible[i] as usize];
                touched += y.p.x + y.pdf_rev + y.beta.x;
            }
            std::hint::black_box(touched);
            let shadow_before = counters.shadow_rays;
            for &(i, scale, repeats) in &scratch.draws {
                let light = self.pool.prefix(i);
                if bdpt.allowed(light.len(), t) && conn.connect(light, &camera[..t], scale, pos, rng, sink, counters) {
                    let k = concentration_depth(t);
                    draws.hits[k] += repeats as u64;
                    draws.hits_inverse_concentration[k] += scale as f64 / uniform_scale;
                }
            }
            draws.shadow_rays += counters.shadow_rays - shadow_before;
        }
    }
}
/// The concentration `κ` by camera depth of a camera pass's unoccluded pool draws
/// ([`PoolCounters::concentration`], its tiles' `draws` summed in tile order); `None`
/// without any.
pub(crate) fn pass_concentration<'a>(
    draws: impl IntoIterator<Item = &'a PoolCounters>,
) -> Option<[f32; CONCENTRATION_DEPTHS]> {
    let mut sum = PoolCounters::default();
    for d in draws {
        sum += *d;
    }
    sum.concentration().map(|(_, by_depth)| by_depth.map(|c| c as f32))
}

/// Key of the pilot pool that measures `V̄` before the first iteration.
pub(crate) const PILOT_ITERATION: u64 = u64::MAX;

/// Bytes a light pool spends per vertex (the vertex and its path-start index).
fn pool_vertex_bytes() -> usize {
    std::mem::size_of::<Vertex>() + std::mem::size_of::<u32>() * 2
}

/// Checks that a pool of `m` light paths fits `max_pool_mb`, from the vertices per path of
/// the pilot pool `pilot`, with a margin; `option` is the option that sets `m`.
pub(crate) fn check_pool_memory(m: usize, pilot: &LightPool, max_pool_mb: usize, option: &str) -> Result<(), Error> {
    const MIB: f64 = 1024.0 * 1024.0;
    let per_path = pilot.vertices.len() as f64 / pilot.paths.max(1) as f64;
    let mb = 1.5 * m as f64 * per_path.max(1.0) * pool_vertex_bytes() as f64 / MIB;
    if mb > max_pool_mb as f64 {
        return Err(Error::Usage(format!(
            "the light pool of {m} paths ({per_path:.1} vertices per path) needs about {mb:.0} MiB, over the limit of \
             {max_pool_mb} MiB (--max-pool-mb); use fewer light paths ({option}) or raise the limit"
        )));
    }
    Ok(())
}
