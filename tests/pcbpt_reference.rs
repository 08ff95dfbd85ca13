//! PCBPT against the Mitsuba 3 path-tracer references on cornell-ply, veach-mis and
//! veach-ajar, for each MIS option, each distance term of the interpolation and each way of
//! inverting the blended PMF, with the
//! same verdict as the other bidirectional integrators (`tests/bidir_reference.rs`): two
//! seeds averaged, image mean within 0.5%, relMSE within 1.3× of what noise explains.
//!
//! The `veach-ajar` cases of `uniform` render 2 × 512 spp: the image means of single
//! 128-spp renders (160×90) spread by 0.72% (56 seeds: 1.0010 ± 0.0010 against the
//! reference, where BDPT gives 1.0008 ± 0.0003 and the path tracer 1.0011 ± 0.0003), so
//! two of them leave the 0.5% check no margin; four times the samples halve that spread.
//!
//! `--pc-mis harmonic` (the default) weighs the pool connections of each camera depth by how
//! much the previous iteration's draws that reached a vertex were concentrated (the harmonic
//! mean of `V · PMF` over them); its measurement is checked against uniform selection, where it
//! is exactly one. Its two `veach-ajar` cases are ignored for the same reason as resampling's
//! below, with a wider spread: giving the shared pool's connections more weight makes more of
//! the error common to many pixels, so single 128-spp image means (160×90) spread by about
//! ±1.8% (seeds 3–8 with M = 1000: 1.0236, 1.0031, 1.0113, 1.0182, 0.9720, 0.9912; `uniform` on
//! the same seeds ±1.1%). With these seeds they gave 0.9965 and 0.9981 with M = 1000, 1.0039
//! and 1.0047 with M = 500 and a uniform blend of 0.5, and 1.0050 and 1.0056 with the present
//! defaults (M = 500, blend 0.75; the printed case just outside 0.5%; measured before the walks
//! took their densities between vertex positions, which raised BDPT's mean there by 0.2%): the
//! same spread moving with every option. Its mean is checked instead, for each distance term,
//! on 40 same-seed pairs against `uniform` (`harmonic_*keeps_the_veach_ajar_mean_*`; earlier
//! studies: 1.0007 ± 0.0008 on 60 pairs at 80×45 and 0.9988 ± 0.0019 on 60 pairs at 160×90);
//! its `cornell-ply` and `veach-mis` cases run here. `--pc-mis correlated` (harmonic's counts
//! corrected for the correlation of the connections that share a camera vertex) is checked
//! the same way: reference cases on `cornell-ply`, `veach-mis` and `staircase2`, and same-seed
//! pairs against `uniform` on `veach-ajar`.
//!
//! The two `veach-ajar` cases of `--pc-mis resampling` are ignored: that estimator's heavy
//! tail spreads the image means of single 128-spp renders (160×90) by about ±1%, so the mean
//! of two cannot be held to 0.5% with a safe margin (with the defaults of 3 neighbours,
//! N = 4, M = 1000 and these seeds both passed, at 1.0041 and 1.0045; with 6 neighbours and
//! N = 3 one missed at 1.0052; a different CPU's intersection rounding can move one
//! firefly). Its mean was measured instead on 180 same-seed pairs against `uniform` (whose
//! own veach-ajar cases run here): resampling/uniform 1.0006 ± 0.0009
//! (BENCHMARKS.md, `scripts/paired_means.py`). The check stays runnable with `-- --ignored`.

mod common;

use common::*;
use pcbpt::image_io::Image;
use pcbpt::integrator::budget::{BudgetMode, BudgetOptions};
use pcbpt::integrator::pcbpt::{DistanceTerm, PcMis, PcOptions, PcSampling};
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::Scene;

fn render(scene: &Scene, spp: u32, opts: &PcOptions, seed: u64) -> Image {
    let mut o = RenderOptions::new(IntegratorKind::Pcbpt, Budget::Spp(spp));
    o.seed = seed;
    o.method.pcbpt_mut().pc = opts.clone();
    image(integrator::render(scene, &o).unwrap())
}

fn check(case: &Case, spp: u32, mis: PcMis, distance_term: DistanceTerm, sampling: PcSampling) {
    let opts = PcOptions {
        mis,
        distance_term,
        sampling,
        budget: BudgetOptions { mode: BudgetMode::Off, ..BudgetOptions::default() },
        ..PcOptions::default()
    };
    let scene = case.scene();
    let a = render(&scene, spp, &opts, 1);
    let b = render(&scene, spp, &opts, 2);
    case.check(&a, &b, &format!("PCBPT {mis:?} {distance_term:?} {sampling:?}, 2 × {spp} spp"));
}

macro_rules! cases {
    ($($(#[$attr:meta])* $name:ident: $case:expr, $spp:expr, $mis:ident, $term:ident, $sampling:ident;)*) => {
        $(
            #[test]
            $(#[$attr])*
            fn $name() {
                check(&$case, $spp, PcMis::$mis, DistanceTerm::$term, PcSampling::$sampling);
            }
        )*
    };
}

cases! {
    cornell_ply_uniform_falloff: CORNELL_PLY, 24, Uniform, Falloff, Mixture;
    cornell_ply_uniform_printed: CORNELL_PLY, 24, Uniform, Printed, Mixture;
    cornell_ply_resampling_falloff: CORNELL_PLY, 24, Resampling, Falloff, Mixture;
    cornell_ply_resampling_printed: CORNELL_PLY, 24, Resampling, Printed, Mixture;
    veach_mis_uniform_falloff: VEACH_MIS, 32, Uniform, Falloff, Mixture;
    veach_mis_uniform_printed: VEACH_MIS, 32, Uniform, Printed, Mixture;
    veach_mis_resampling_falloff: VEACH_MIS, 32, Resampling, Falloff, Mixture;
    veach_mis_resampling_printed: VEACH_MIS, 32, Resampling, Printed, Mixture;
    veach_ajar_uniform_falloff: VEACH_AJAR, 512, Uniform, Falloff, Mixture;
    veach_ajar_uniform_printed: VEACH_AJAR, 512, Uniform, Printed, Mixture;
    #[ignore = "resampling MIS on veach-ajar: single 128-spp image means spread by ±1% (heavy tail), too much for a 0.5% check of two renders; unbiased on 180 same-seed pairs (BENCHMARKS.md); run with --ignored"]
    veach_ajar_resampling_falloff: VEACH_AJAR, 128, Resampling, Falloff, Mixture;
    #[ignore = "resampling MIS on veach-ajar: single 128-spp image means spread by ±1% (heavy tail), too much for a 0.5% check of two renders; unbiased on 180 same-seed pairs (BENCHMARKS.md); run with --ignored"]
    veach_ajar_resampling_printed: VEACH_AJAR, 128, Resampling, Printed, Mixture;
    cornell_ply_harmonic_falloff: CORNELL_PLY, 24, Harmonic, Falloff, Mixture;
    cornell_ply_harmonic_printed: CORNELL_PLY, 24, Harmonic, Printed, Mixture;
    veach_mis_harmonic_falloff: VEACH_MIS, 32, Harmonic, Falloff, Mixture;
    veach_mis_harmonic_printed: VEACH_MIS, 32, Harmonic, Printed, Mixture;
    #[ignore = "harmonic MIS on veach-ajar: pool-correlated error spreads single 128-spp image means by about ±1.8%, too much for a 0.5% check of two renders; its mean is checked on same-seed pairs against uniform below; run with --ignored"]
    veach_ajar_harmonic_falloff: VEACH_AJAR, 128, Harmonic, Falloff, Mixture;
    #[ignore = "harmonic MIS on veach-ajar: pool-correlated error spreads single 128-spp image means by about ±1.8%, too much for a 0.5% check of two renders; its mean is checked on same-seed pairs against uniform below; run with --ignored"]
    veach_ajar_harmonic_printed: VEACH_AJAR, 128, Harmonic, Printed, Mixture;
    cornell_ply_uniform_falloff_cmf: CORNELL_PLY, 24, Uniform, Falloff, Cmf;
    veach_mis_uniform_falloff_cmf: VEACH_MIS, 32, Uniform, Falloff, Cmf;
    veach_ajar_uniform_falloff_cmf: VEACH_AJAR, 512, Uniform, Falloff, Cmf;
    staircase2_harmonic_falloff: STAIRCASE2, 32, Harmonic, Falloff, Mixture;
    sunlit_room_harmonic_falloff: SUNLIT_ROOM, 16, Harmonic, Falloff, Mixture;
    sunlit_room_uniform_falloff: SUNLIT_ROOM, 16, Uniform, Falloff, Mixture;
    sunlit_room_resampling_falloff: SUNLIT_ROOM, 8, Resampling, Falloff, Mixture;
    living_room_harmonic_falloff: LIVING_ROOM, 32, Harmonic, Falloff, Mixture;
    living_room_uniform_falloff: LIVING_ROOM, 32, Uniform, Falloff, Mixture;
    living_room_resampling_falloff: LIVING_ROOM, 16, Resampling, Falloff, Mixture;
    staircase2_uniform_falloff: STAIRCASE2, 32, Uniform, Falloff, Mixture;
    staircase2_resampling_falloff: STAIRCASE2, 16, Resampling, Falloff, Mixture;
    cornell_ply_correlated_falloff: CORNELL_PLY, 24, Correlated, Falloff, Mixture;
    veach_mis_correlated_falloff: VEACH_MIS, 32, Correlated, Falloff, Mixture;
    staircase2_correlated_falloff: STAIRCASE2, 32, Correlated, Falloff, Mixture;
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
/// cannot hold the mean to 0.5% (the ignored cases above): against `uniform` with the same
/// distance term (whose own `veach-ajar` cases check the reference), on 40 same-seed pairs.
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
    o.seed = 5;
    let c = integrator::render(&scene, &o).unwrap().stats.counters;
    let hits: u64 = c.pool_hits.iter().sum();
    assert!(hits > 1000 && c.pool_hits[0] > 100, "{kind:?}: {:?} unoccluded pool connections", c.pool_hits);
    c.concentration().unwrap()
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
