//! SPCBPT's MIS counts on `veach-ajar`, where every pixel connects to the same pool, whose
//! error is common to the whole image: single renders cannot hold the image mean to 0.5%
//! there, so `uniform` is checked against the reference with 2 × 512 spp (a row of
//! `tests/reference.rs`, with SPCBPT's other reference checks), and `harmonic`, `resampling`
//! and `subspace` against `uniform` here, on same-seed pairs, which share their pools and
//! camera subpaths.

mod common;

use common::*;
use pcbpt::image_io::Image;
use pcbpt::integrator::pcbpt::PcMis;
use pcbpt::integrator::spcbpt::SpOptions;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::Scene;

fn render(scene: &Scene, spp: u32, opts: &SpOptions, seed: u64) -> Image {
    let mut o = RenderOptions::new(IntegratorKind::Spcbpt, Budget::Spp(spp));
    o.run.seed = seed;
    o.method.spcbpt_mut().sp = opts.clone();
    // The subspace connections themselves, without a budget.
    o.method.budget_mut().mode = pcbpt::integrator::budget::BudgetMode::Off;
    image(integrator::render(scene, &o).unwrap())
}

/// `mis` against `uniform` on 30 same-seed pairs of `veach-ajar` renders (80×45, unlimited
/// depth, 64 spp): the ratio of their image means isolates what the counts (and the matrix
/// trained with their weights) do to the mean, mostly free of the pool's common error. A weight
/// that lost or gained a strategy's share would move it by far more than the 0.5% allowed.
fn check_pairs(mis: PcMis) {
    let scene = load(
        &root().join(VEACH_AJAR.scene),
        &[("resx", "80"), ("resy", "45"), ("max_depth", "-1")],
        pcbpt::accel::Backend::Embree,
    );
    let uniform = SpOptions { mis: PcMis::Uniform, ..SpOptions::default() };
    let other = SpOptions { mis, ..SpOptions::default() };
    let ratios: Vec<f64> = (1000..1030)
        .map(|seed| render(&scene, 64, &other, seed).mean() / render(&scene, 64, &uniform, seed).mean())
        .collect();
    let (ratio, se) = mean_and_standard_error(&ratios);
    println!("veach-ajar 80×45, 30 pairs × 64 spp: SPCBPT {mis:?} / uniform = {ratio:.5} ± {se:.5}");
    // The pairs share less than PCBPT's (tests/pcbpt_reference.rs): the two counts weigh the
    // training connections differently, so their matrices, and their draws, part after the
    // first iteration (with 128 × 256 subspaces, 40 pairs gave 0.99773 ± 0.00207 for
    // harmonic, 0.99934 ± 0.00264 for resampling).
    assert!(se < 0.003, "pairs too noisy to judge the mean: ± {se}");
    assert!((ratio - 1.0).abs() < 0.005, "SPCBPT {mis:?} / uniform = {ratio} ± {se}");
}

#[test]
fn harmonic_keeps_the_veach_ajar_mean_on_same_seed_pairs() {
    check_pairs(PcMis::Harmonic);
}

#[test]
fn resampling_keeps_the_veach_ajar_mean_on_same_seed_pairs() {
    check_pairs(PcMis::Resampling);
}

#[test]
fn subspace_keeps_the_veach_ajar_mean_on_same_seed_pairs() {
    check_pairs(PcMis::Subspace);
}
