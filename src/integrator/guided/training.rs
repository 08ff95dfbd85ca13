//! The guided path tracer's training: passes of 1, 2, 4, … samples per pixel over the whole
//! image, each sampling from the tree the passes before it built while its paths record
//! into the next one ([`train`]).
//!
//! With a sample count `N` the training passes are the longest doubling sequence that fits
//! in half of it: `2^k - 1 ≤ N / 2` samples per pixel in `k` passes ([`doubling_passes`]),
//! so that the final pass, which the image is made of alone, has at least half of the
//! samples. With a time budget, passes double while the next one (predicted to take twice
//! the last) ends within half the budget.
//!
//! Training iterations draw their random numbers from streams keyed by their own seed (the
//! render's, mixed with a constant), pixel and training iteration, apart from the final
//! pass's. Each tile keeps its records in a list with their pixels; the lists are put in
//! pixel order (each pixel's records in the order its paths made them) and added to the
//! tree in that order, so the tree depends neither on the number of threads nor on the
//! tiles' size. A pass is cut into parts of at most [`PART_SAMPLES`] camera samples per
//! part so the lists stay small.

use crate::film::Tile;
use crate::integrator::guided::mixture::Guided;
use crate::integrator::guided::sdtree::{FractionRecord, Record, Refinement, SdTree};
use crate::integrator::path::PathTracer;
use crate::integrator::render_loop::{Ctx, sample_tile_with};
use crate::integrator::stats::Counters;
use crate::sampling::sobol::SobolSampler;
use crate::sampling::{PixelSampler, Sampler, SamplerKind};
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// The most camera samples whose records are held at once.
pub const PART_SAMPLES: u64 = 1 << 18;

/// The seed of the training iterations' random streams, from the render's.
pub fn training_seed(seed: u64) -> u64 {
    seed ^ 0x6775_6964_6564_7472
}

/// The samples per pixel of the training passes of a render of `total`: 1, 2, 4, … as long
/// as their sum stays within half of `total`.
pub fn doubling_passes(total: u32) -> Vec<u32> {
    let mut passes = Vec::new();
    let mut sum = 0u64;
    let mut next = 1u64;
    while 2 * (sum + next) <= total as u64 {
        passes.push(next as u32);
        sum += next;
        next *= 2;
    }
    passes
}

/// What [`train`] needs besides the tree.
pub struct Training<'a> {
    pub pt: &'a PathTracer,
    pub bsdf_fraction: f32,
    pub refinement: Refinement,
    pub tiles: &'a [Tile],
    pub stop: Option<Arc<AtomicBool>>,
    /// When the render started (for a time budget).
    pub start: Instant,
}

/// What the training did.
#[derive(Clone, Copy, Debug, Default)]
pub struct Trained {
    pub passes: u32,
    /// Samples per pixel over all passes.
    pub spp: u32,
    pub counters: Counters,
    pub seconds: f64,
}

/// Trains `tree` over the whole image in passes of `passes` samples per pixel (or, with
/// `seconds`, doubling passes while time remains), with random numbers from the path
/// tracer's sampler; stops early when the stop flag is set.
pub(crate) fn train(ctx: &Ctx, t: &Training, tree: &mut SdTree, passes: &[u32], seconds: Option<f64>) -> Trained {
    match t.pt.sampler {
        SamplerKind::Independent => train_with::<Sampler>(ctx, t, tree, passes, seconds),
        SamplerKind::Sobol => train_with::<SobolSampler>(ctx, t, tree, passes, seconds),
    }
}

/// [`train`] with random numbers from `S`.
fn train_with<S: PixelSampler>(
    ctx: &Ctx,
    t: &Training,
    tree: &mut SdTree,
    passes: &[u32],
    seconds: Option<f64>,
) -> Trained {
    let begun = Instant::now();
    let ctx = Ctx { scene: ctx.scene, seed: training_seed(ctx.seed), layers: false, planned_spp: None, start: 0 };
    let mut done = Trained::default();
    let stopped = || t.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst));
    let pixels = ctx.scene.film.width as u64 * ctx.scene.film.height as u64;
    let part = (PART_SAMPLES / pixels.max(1)).clamp(1, u32::MAX as u64) as u32;
    let mut k = 0usize;
    loop {
        let spp = match seconds {
            None => match passes.get(k) {
                Some(&spp) => spp,
                None => break,
            },
            Some(_) => 1u32 << k.min(31),
        };
        let pass_start = Instant::now();
        let mut first = done.spp;
        let end = done.spp + spp;
        while first < end {
            if stopped() {
                return Trained { seconds: begun.elapsed().as_secs_f64(), ..done };
            }
            let count = part.min(end - first);
            let (records, fractions, counters) = pass_part::<S>(&ctx, t, tree, first, count);
            tree.add(&records);
            tree.add_fraction_records(&fractions);
            done.counters += counters;
            first += count;
        }
        tree.finish_pass(spp, &t.refinement);
        done.passes += 1;
        done.spp = end;
        k += 1;
        if let Some(budget) = seconds {
            let last = pass_start.elapsed().as_secs_f64();
            if t.start.elapsed().as_secs_f64() + 2.0 * last > budget {
                break;
            }
        }
    }
    done.seconds = begun.elapsed().as_secs_f64();
    done
}

/// What the tiles of a part of a pass recorded: each record with its pixel.
type TileRecords = (Vec<(u32, Record)>, Vec<(u32, FractionRecord)>, Counters);

/// Training iterations `first..first + count` of every tile: the records and the fraction
/// records, each in pixel order, and the counters summed in tile order.
fn pass_part<S: PixelSampler>(
    ctx: &Ctx,
    t: &Training,
    tree: &SdTree,
    first: u32,
    count: u32,
) -> (Vec<Record>, Vec<FractionRecord>, Counters) {
    let width = ctx.scene.film.width;
    let parts: Vec<TileRecords> = t
        .tiles
        .par_iter()
        .with_max_len(1)
        .map(|&tile| {
            let (mut records, mut fractions) = (Vec::new(), Vec::new());
            let (mut path_records, mut path_fractions) = (Vec::new(), Vec::new());
            let mut cont = Guided::new(tree, t.bsdf_fraction, true);
            let r = sample_tile_with::<S>(ctx, tile, (first, count), None, |pos, sampler, sink, counters| {
                let ray = ctx.scene.camera.generate_ray(pos);
                sink.l = counters.camera_path(|c| t.pt.li_with(ctx.scene, ray, sampler, c, &mut cont));
                cont.take_records(&mut path_records, &mut path_fractions);
                let pixel = pos.y as u32 * width + pos.x as u32;
                records.extend(path_records.drain(..).map(|r| (pixel, r)));
                fractions.extend(path_fractions.drain(..).map(|r| (pixel, r)));
                true
            });
            (records, fractions, r.counters)
        })
        .collect();
    let mut counters = Counters::default();
    let (mut records, mut fractions) = (Vec::new(), Vec::new());
    for (r, f, c) in parts {
        counters += c;
        records.extend(r);
        fractions.extend(f);
    }
    (in_pixel_order(records), in_pixel_order(fractions), counters)
}

/// Records without their pixels, in pixel order; a stable sort keeps each pixel's records in
/// the order its samples made them.
fn in_pixel_order<T>(mut records: Vec<(u32, T)>) -> Vec<T> {
    records.sort_by_key(|&(pixel, _)| pixel);
    records.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn training_takes_doubling_passes_within_half_the_samples() {
        assert_eq!(doubling_passes(0), Vec::<u32>::new());
        assert_eq!(doubling_passes(1), Vec::<u32>::new());
        assert_eq!(doubling_passes(2), vec![1]);
        assert_eq!(doubling_passes(5), vec![1]);
        assert_eq!(doubling_passes(7), vec![1, 2]);
        assert_eq!(doubling_passes(64), vec![1, 2, 4, 8, 16]);
        assert_eq!(doubling_passes(1024), vec![1, 2, 4, 8, 16, 32, 64, 128, 256]);
        for n in 0..2000u32 {
            let sum: u32 = doubling_passes(n).iter().sum();
            assert!(2 * sum <= n && 2 * (2 * sum + 1) > n, "{n}: {sum}");
        }
    }
}
