//! PCBPT's and SPCBPT's efficiency-aware budgets (`--budget auto`): on `veach-ajar`, whose
//! pool error is common to the image, PCBPT with a budget against PCBPT without one on
//! same-seed pairs; the horizon a short render plans for; the margin that keeps the measured
//! plan, and with it the image of the render without a budget, bit for bit; SPCBPT's
//! measurement during training. Their checks against the references are rows of
//! `tests/reference.rs`.

mod common;

use common::*;
use pcbpt::image_io::Image;
use pcbpt::integrator::budget::{BudgetMode, BudgetModel};
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::Scene;

/// A render with the budget `budget` and the realized model (the default); prints the plan.
fn render(scene: &Scene, kind: IntegratorKind, spp: u32, budget: BudgetMode, seed: u64) -> Image {
    let mut o = RenderOptions::new(kind, Budget::Spp(spp));
    o.run.seed = seed;
    o.method.budget_mut().mode = budget;
    o.method.budget_mut().model = BudgetModel::Realized;
    let out = integrator::render(scene, &o).unwrap();
    if let Some(b) = budget_of(&out.stats) {
        println!("{kind:?} seed {seed}: plan {:?}, measured with {:?}", b.chosen, b.measured_with);
    }
    image(out)
}

/// `veach-ajar` at `resx` × `resy` with unlimited depth, on Embree.
fn veach_ajar(resx: &str, resy: &str) -> Scene {
    load(
        &root().join(VEACH_AJAR.scene),
        &[("resx", resx), ("resy", resy), ("max_depth", "-1")],
        pcbpt::accel::Backend::Embree,
    )
}

/// PCBPT with a budget against PCBPT without one on 12 same-seed pairs of `veach-ajar`
/// renders (80×45, unlimited depth, 48 spp), which share their pools: the ratio of their
/// image means is free of most of the pool's common error. A plan that lost a strategy's
/// share would move it by far more than the 1% allowed.
#[test]
fn pcbpt_budget_keeps_the_veach_ajar_mean_on_same_seed_pairs() {
    let scene = veach_ajar("80", "45");
    let pcbpt = IntegratorKind::Pcbpt;
    let ratios: Vec<f64> = (1000..1012)
        .map(|seed| {
            render(&scene, pcbpt, 48, BudgetMode::Auto, seed).mean()
                / render(&scene, pcbpt, 48, BudgetMode::Off, seed).mean()
        })
        .collect();
    let (ratio, se) = mean_and_standard_error(&ratios);
    println!("veach-ajar 80×45, 12 pairs × 48 spp: PCBPT with a budget / without = {ratio:.5} ± {se:.5}");
    assert!(se < 0.004, "pairs too noisy to judge the mean: ± {se}");
    assert!((ratio - 1.0).abs() < 0.01, "PCBPT with a budget / without = {ratio} ± {se}");
}

/// A short render still plans for at least 256 samples per pixel: the floor of the moments
/// treats each rare sample as a region of its own, and planned for 8 samples per pixel it
/// made path tracing look best on `veach-ajar`, whose light the connections carry (at 8
/// spp the path tracer misses most of it). With the default horizon the plan keeps its
/// connections.
#[test]
fn short_renders_plan_for_the_default_horizon_and_keep_veach_ajars_connections() {
    use pcbpt::integrator::budget::DEFAULT_HORIZON;
    let scene = veach_ajar("160", "90");
    let mut o = RenderOptions::new(IntegratorKind::Pcbpt, Budget::Spp(8));
    o.run.seed = 1;
    o.method.budget_mut().mode = BudgetMode::Auto;
    let out = integrator::render(&scene, &o).unwrap();
    let b = budget_of(&out.stats).cloned().expect("a budget's statistics");
    println!("veach-ajar 160×90, 8 spp: plan {:?}, planned for {} spp", b.chosen, b.horizon);
    assert_eq!(b.horizon, DEFAULT_HORIZON);
    assert!(b.chosen.is_some_and(|p| p.connections > 0), "plan {:?}", b.chosen);
}

/// `--pc-budget-margin`: on `veach-mis` (96×54) PCBPT's budget predicts light tracing
/// without connections about 1.7 times as efficient as its measured plan, and the path
/// tracer's plan less efficient than that plan. With a margin just above the best
/// candidate's predicted gain the measured plan stays, and the render is then the one
/// without a budget bit for bit (the measurement only reads the samples); just below it,
/// that candidate is taken.
#[test]
fn a_gain_within_the_margin_keeps_the_measured_plan_and_its_image() {
    let scene =
        load_at(&root().join(VEACH_MIS.scene), VEACH_MIS.defines, Some((96, 54)), pcbpt::accel::Backend::Embree);
    let run = |budget: BudgetMode, margin: f32| {
        let mut o = RenderOptions::new(IntegratorKind::Pcbpt, Budget::Spp(6));
        o.run.seed = 2;
        o.method.budget_mut().mode = budget;
        o.method.budget_mut().margin = margin;
        integrator::render(&scene, &o).unwrap()
    };
    let free = budget_of(&run(BudgetMode::Auto, 1.0).stats).cloned().expect("a budget's statistics");
    let (best, gain, measured) = (free.best.unwrap(), free.best_gain, free.measured_with.unwrap());
    println!("veach-mis 96×54: measured with {measured:?}, best {best:?} at {gain:.3}×");
    assert!(best != measured && !best.path_tracing());
    assert!(gain > 1.2, "the best candidate's predicted gain {gain}");
    assert_eq!(free.chosen, Some(best));

    let below = budget_of(&run(BudgetMode::Auto, (gain * 0.99) as f32).stats).cloned().unwrap();
    assert_eq!(below.chosen, Some(best));
    assert!((below.predicted_gain - gain).abs() < 1e-9 * gain);

    let above = run(BudgetMode::Auto, (gain * 1.01) as f32);
    let b = budget_of(&above.stats).cloned().unwrap();
    assert_eq!((b.chosen, b.predicted_gain, b.best), (Some(measured), 1.0, Some(best)));
    let off = run(BudgetMode::Off, 1.1);
    let bits =
        |o: &integrator::RenderOutput| o.image.iter().flat_map(|c| c.to_array()).map(f32::to_bits).collect::<Vec<_>>();
    assert!(bits(&above) == bits(&off), "the kept plan's image differs from the render without a budget");
}

/// SPCBPT's budget measures its last two training iterations by default: the choice is
/// made once `Γ` is trained (after four iterations, not six), the measurement changes no
/// training sample (a kept plan renders the image of the render without a budget, measured
/// during training or after it), and `--sp-budget-in-training false` measures after training.
#[test]
fn spcbpt_measures_its_last_training_iterations() {
    let scene =
        load_at(&root().join(VEACH_MIS.scene), VEACH_MIS.defines, Some((96, 54)), pcbpt::accel::Backend::Embree);
    let run = |spp: u32, budget: BudgetMode, in_training: bool| {
        let mut o = RenderOptions::new(IntegratorKind::Spcbpt, Budget::Spp(spp));
        o.run.seed = 2;
        o.method.budget_mut().mode = budget;
        // A margin no prediction reaches keeps the measured plan.
        o.method.budget_mut().margin = 1e9;
        o.method.spcbpt_mut().sp.budget_in_training = in_training;
        integrator::render(&scene, &o).unwrap()
    };
    let training = pcbpt::integrator::spcbpt::SpOptions::default().training_iterations;
    assert_eq!(training, 4);
    let chosen = |spp: u32, in_training: bool| budget_of(&run(spp, BudgetMode::Auto, in_training).stats).is_some();
    assert!(chosen(training, true), "no choice after the training iterations");
    assert!(!chosen(training - 1, true), "a choice before the last training iteration");
    assert!(!chosen(training, false) && chosen(training + 2, false));
    let bits =
        |o: &integrator::RenderOutput| o.image.iter().flat_map(|c| c.to_array()).map(f32::to_bits).collect::<Vec<_>>();
    let off = bits(&run(8, BudgetMode::Off, true));
    for in_training in [true, false] {
        let kept = run(8, BudgetMode::Auto, in_training);
        let b = budget_of(&kept.stats).cloned().expect("a budget's statistics");
        assert_eq!(b.chosen, b.measured_with);
        assert!(bits(&kept) == off, "measured in training: {in_training}; the kept plan's image differs");
    }
}
