//! The path tracer as a wavefront: a tile's camera samples are traced in batches of
//! [`BATCH`] paths, bounce by bounce. Each bounce asks the backend for the closest hits of
//! every live path's ray in one batch query (Embree's stream interface), shades the hits one
//! path at a time with the scalar path tracer's own steps ([`PathTracer::light_at`],
//! [`PathTracer::go_on`]), and answers the bounce's shadow rays in one batch of occlusion
//! queries.
//!
//! Each path draws its random numbers from its own sampler, in the order the scalar path
//! tracer draws them (a shadow ray's answer changes no later draw), and adds its light in the
//! same order, so the two give the same image wherever the batch queries report the hits
//! single queries report.

use super::{BsdfSampling, PathState, PathTracer};
use crate::accel::Ray;
use crate::film::Tile;
use crate::integrator::render_loop::{Bounce, Ctx, TileResult, camera_samples, tile_block};
use crate::integrator::stats::Counters;
use crate::math::Rgb;
use crate::sampling::PixelSampler;
use crate::scene::Scene;
use glam::Vec2;

/// Paths traced together: enough for the batch queries to pay, few enough for the paths'
/// state (about 100 bytes each) to stay in the core's caches.
const BATCH: usize = 2048;

/// A camera sample in flight.
struct Lane<S> {
    sampler: S,
    pos: Vec2,
    path: PathState,
}

/// The batches' buffers, kept from one bounce and one batch to the next.
#[derive(Default)]
struct Queues {
    /// The live paths and their rays.
    bounce: Bounce,
    /// The bounce's shadow rays, the path each belongs to with the light it brings if
    /// nothing blocks it, and the answers.
    shadow: Vec<Ray>,
    pending: Vec<(u32, Rgb)>,
    occluded: Vec<bool>,
}

impl PathTracer {
    /// Iterations `first..first + count` of a tile, traced as a wavefront (a scene without
    /// media).
    pub(super) fn tile_wavefront<S: PixelSampler>(&self, ctx: &Ctx, tile: Tile, first: u32, count: u32) -> TileResult {
        let mut block = tile_block(ctx, tile);
        let mut counters = Counters::default();
        let mut queues = Queues::default();
        let mut lanes: Vec<Lane<S>> = Vec::with_capacity(BATCH);
        let mut samples = camera_samples::<S>(ctx, tile, (first, count), None);
        loop {
            lanes.clear();
            lanes.extend(samples.by_ref().take(BATCH).map(|(sampler, pos)| Lane {
                sampler,
                pos,
                path: PathState::new(ctx.scene.camera.generate_ray(pos)),
            }));
            if lanes.is_empty() {
                break;
            }
            if self.max_depth > 0 {
                self.trace(ctx.scene, &mut lanes, &mut queues, &mut counters);
            }
            for lane in &lanes {
                block.put_layers(lane.pos, lane.path.l, &[]);
            }
            counters.samples += lanes.len() as u64;
        }
        TileResult { block, splats: Vec::new(), counters, data: () }
    }

    /// Traces a batch of paths from their camera rays to their ends.
    fn trace<S: PixelSampler>(&self, scene: &Scene, lanes: &mut [Lane<S>], q: &mut Queues, counters: &mut Counters) {
        let b = &mut q.bounce;
        b.live.clear();
        b.live.extend(0..lanes.len() as u32);
        let mut camera = true;
        while !b.live.is_empty() {
            b.rays.clear();
            b.rays.extend(b.live.iter().map(|&i| lanes[i as usize].path.ray));
            b.intersect(scene, camera, counters);
            camera = false;

            b.next.clear();
            q.shadow.clear();
            q.pending.clear();
            for (k, &i) in b.live.iter().enumerate() {
                let lane = &mut lanes[i as usize];
                let Some(hit) = &b.hits[k] else {
                    self.escaped(scene, &mut lane.path, b.rays[k].d.normalize(), &mut BsdfSampling);
                    continue;
                };
                let si = scene.interaction(&b.rays[k], hit);
                let mut shadow = None;
                let lit = self.light_at(
                    scene,
                    &mut lane.path,
                    &si,
                    &mut lane.sampler,
                    counters,
                    &mut BsdfSampling,
                    |r, _| {
                        shadow = Some(*r);
                        Rgb::ONE
                    },
                );
                let Some(lit) = lit else { continue };
                if let Some(r) = shadow {
                    q.shadow.push(r);
                    q.pending.push((i, lit.direct));
                }
                // The path tracer's own continuation gathers nothing, so the light sample's
                // contribution can wait for the batch's shadow rays.
                if self.go_on(&mut lane.path, &si, &lit, &mut lane.sampler, &mut BsdfSampling) {
                    b.next.push(i);
                }
            }

            scene.accel.occluded_batch(&q.shadow, false, &mut q.occluded);
            for (&(i, direct), &blocked) in q.pending.iter().zip(&q.occluded) {
                if !blocked {
                    lanes[i as usize].path.l += direct;
                }
            }
            std::mem::swap(&mut b.live, &mut b.next);
        }
    }
}
