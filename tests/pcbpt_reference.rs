//! PCBPT's MIS counts on `veach-ajar`, where single renders cannot hold the image mean to
//! 0.5% (the ignored `veach-ajar` rows of `tests/reference.rs`, whose other rows check PCBPT
//! against the references): `harmonic` (the default) for each distance term, and `correlated`
//! (harmonic's counts corrected for the correlation of the connections that share a camera
//! vertex), against `uniform` on same-seed pairs. And the measurement `harmonic` weighs the
//! pool connections of each camera depth by: how much the previous iteration's draws that
//! reached a vertex were concentrated (the harmonic mean of `V · PMF` over them), exactly one
//! under uniform selection.

mod common;

use common::*;
use pcbpt::image_io::Image;
use pcbpt::integrator::budget::{BudgetMode, BudgetOptions};
use pcbpt::integrator::lvc::LvcStats;
use pcbpt::integrator::pcbpt::{DistanceTerm, PcMis, PcOptions, PcbptStats};
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::Scene;

fn render(scene: &Scene, spp: u32, opts: &PcOptions, seed: u64) -> Image {
    let mut o = RenderOptions::new(IntegratorKind::Pcbpt, Budget::Spp(spp));
    o.run.seed = seed;
    o.method.pcbpt_mut().pc = opts.clone();
    image(integrator::render(scene, &o).unwrap())
}

/// Image means of same-seed pairs on `veach-ajar` (80×45, unlimited depth): option sets `a`
/// and `b` trace the same paths when they differ only in MIS weights, so the ratio of the two
/// means isolates what the weights do to the image mean, free of the pool-correlated spread
/// that single renders have there. Returns the mean ratio `b / a` and its standard error.
fn paired_mean_ratio(a: &PcOptions, b: &PcOptions, spp: u32, seeds: std::ops::Range<u64>) -> (f64, f64) {
    let scene = load(
        &root().join(VEACH_AJAR.scene),
        &[("resx", "80"), ("resy", "45"), ("max_depth", "-1")],
        pcbpt::accel::Backend::Embree,
    );
    let mean = |opts: &PcOptions, seed: u64| render(&scene, spp, opts, seed).mean();
    let ratios: Vec<f64> = seeds.map(|seed| mean(b, seed) / mean(a, seed)).collect();
    let n = ratios.len() as f64;
    let avg = ratios.iter().sum::<f64>() / n;
    let var = ratios.iter().map(|r| (r - avg) * (r - avg)).sum::<f64>() / (n - 1.0);
    (avg, (var / n).sqrt())
}

/// `mis` (`harmonic`, the default, or `correlated`) on `veach-ajar`, where single renders
/// cannot hold the mean to 0.5%: against `uniform` with the same distance term (whose own
/// `veach-ajar` rows check the reference), on 40 same-seed pairs.
/// A weight that lost or gained a strategy's share would move the ratio by far more than the
/// 0.5% allowed.
fn check_pairs(distance_term: DistanceTerm, mis: PcMis) {
    let uniform = PcOptions {
        mis: PcMis::Uniform,
        distance_term,
        budget: BudgetOptions { mode: BudgetMode::Off, ..BudgetOptions::default() },
        ..PcOptions::default()
    };
    let other = PcOptions { mis, ..uniform.clone() };
    let (ratio, se) = paired_mean_ratio(&uniform, &other, 64, 1000..1040);
    println!("veach-ajar 80×45, {distance_term:?}, 40 pairs × 64 spp: {mis:?} / uniform = {ratio:.5} ± {se:.5}");
    assert!(se < 0.002, "{distance_term:?}: pairs too noisy to judge the mean: ± {se}");
    assert!((ratio - 1.0).abs() < 0.005, "{distance_term:?}: {mis:?} / uniform = {ratio} ± {se}");
}

/// `--pc-mis correlated` on `veach-ajar`, where single renders cannot hold the mean to 0.5%
/// either (its counts are `harmonic`'s, corrected).
#[test]
fn correlated_keeps_the_veach_ajar_mean_on_same_seed_pairs() {
    check_pairs(DistanceTerm::Falloff, PcMis::Correlated);
}

#[test]
fn harmonic_keeps_the_veach_ajar_mean_on_same_seed_pairs() {
    check_pairs(DistanceTerm::Falloff, PcMis::Harmonic);
}

#[test]
fn harmonic_printed_keeps_the_veach_ajar_mean_on_same_seed_pairs() {
    check_pairs(DistanceTerm::Printed, PcMis::Harmonic);
}

/// The harmonic mean of `V · PMF` over the unoccluded pool connections, overall and by
/// camera depth, which `--pc-mis harmonic` takes from one iteration into the next.
fn concentration(kind: IntegratorKind, spp: u32) -> (f64, [f64; integrator::CONCENTRATION_DEPTHS]) {
    let scene = VEACH_AJAR.scene();
    let mut o = RenderOptions::new(kind, Budget::Spp(spp));
    o.run.seed = 5;
    let details = integrator::render(&scene, &o).unwrap().stats.details;
    let pool = match kind {
        IntegratorKind::Lvc => details.get::<LvcStats>().unwrap().pool,
        _ => details.get::<PcbptStats>().unwrap().pool,
    };
    let d = pool.draws;
    let hits: u64 = d.hits.iter().sum();
    assert!(hits > 1000 && d.hits[0] > 100, "{kind:?}: {:?} unoccluded pool connections", d.hits);
    d.concentration().unwrap()
}

#[test]
fn harmonic_counts_measure_how_much_the_cache_concentrates_the_connections_that_reach() {
    // Uniform selection (light-vertex-cache BDPT) draws every vertex with P = 1/V, at every
    // depth.
    let (lvc, by_depth) = concentration(IntegratorKind::Lvc, 4);
    assert!((lvc - 1.0).abs() < 1e-5, "LVC: {lvc}");
    assert!(by_depth.iter().all(|c| (c - 1.0).abs() < 1e-5), "LVC: {by_depth:?}");
    // Behind veach-ajar's door most of the pool is hidden from the camera's room; the cache's
    // PMFs send the draws that reach a vertex to the few it can see, most sharply from the
    // first hit, whose records are the densest and nearest.
    let (pc, by_depth) = concentration(IntegratorKind::Pcbpt, 4);
    assert!(pc > 2.0, "PCBPT: {pc}");
    assert!(by_depth[0] > pc && by_depth[0] > by_depth[2], "PCBPT: {by_depth:?}");
}
