//! MEMLT (path-space Metropolis with the bidirectional mutation and the lens, caustic and
//! manifold perturbations): where its chains put a caustic's light, its direct-light pass
//! under a time budget, its determinism, the options it refuses, its bootstrap's share of a
//! time budget and its longest stay (its reference checks are rows of `tests/reference.rs`).
//!
//! Two renders with different seeds (independent chains and bootstraps) are averaged; the
//! image mean must agree within 1% and the relMSE stay within 1.3× of what the two renders'
//! noise and the reference's own noise explain.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::integrator::memlt::MemltDetails;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions, RenderOutput};
use pcbpt::scene::Scene;

fn memlt(scene: &Scene, spp: u32, seed: u64, direct_samples: i32) -> RenderOutput {
    memlt_with(scene, spp, seed, &|o| o.method.memlt_mut().direct_samples = direct_samples)
}

fn memlt_with(scene: &Scene, spp: u32, seed: u64, set: &dyn Fn(&mut RenderOptions)) -> RenderOutput {
    render_with(scene, IntegratorKind::Memlt, spp, seed, 2, set)
}

#[test]
fn memlt_glass_caustic() {
    // A glass ball's caustic seen directly (the caustic perturbation's paths), the floor
    // through the ball (the lens perturbation's) and the caustic through the ball (the
    // manifold perturbation's), at 160×90, the direct light in the chains.
    // This checks where the chains put the light: each render is scaled to the reference's
    // mean first. The mean itself is the normalisation `b` from BDPT's bootstrap, whose
    // error here (about ±1% at 10⁶ samples: the caustic seen through the ball, and the
    // light's highlight on it, are paths only the camera walk finds) and the reference's
    // own are not what this test is about (the bootstrap's `b` is checked against the path
    // densities in `src/integrator/memlt/tests.rs`).
    let scene =
        load(&root().join("scenes/glass-caustic/scene.xml"), &[("resx", "160"), ("resy", "90")], Backend::Embree);
    let reference = reference("glass-caustic.exr");
    let mean = |i: &pcbpt::image_io::Image| i.pixels.iter().map(|p| (p.x + p.y + p.z) as f64).sum::<f64>();
    let scaled = |seed| {
        let out = memlt(&scene, 128, seed, -1);
        // The manifold perturbation moves the paths the others cannot (the caustic seen
        // through the ball): its walks must mostly converge and return.
        let s = out.stats.details.get::<MemltDetails>().unwrap().memlt.clone();
        let manifold = s.mutators.iter().find(|m| m.mutator == pcbpt::integrator::memlt::Mutator::Manifold).unwrap();
        let w = s.manifold_walks;
        assert!(manifold.acceptance > 0.2, "manifold perturbation accepted {}", manifold.acceptance);
        assert!(w.tried > 1000 && w.converged * 4 > w.tried && w.irreversible * 4 < w.converged, "walks: {w:?}");
        let i = image(out);
        let k = (mean(&reference) / mean(&i)) as f32;
        pcbpt::image_io::Image::new(i.width, i.height, i.pixels.iter().map(|p| *p * k).collect())
    };
    let (a, b) = (scaled(1), scaled(2));
    let (v, _) = Verdict::averaged(&reference, &a, &b, 1.25e-3);
    v.check("glass-caustic, MEMLT, 2 × 128 spp, scaled to the reference's mean", 0.01, 1.3).unwrap();
}

#[test]
fn memlt_is_deterministic_for_a_seed_whatever_the_thread_count() {
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "48"), ("resy", "40")], Backend::Embree);
    let run = |seed, threads| {
        let mut o = RenderOptions::new(IntegratorKind::Memlt, Budget::Spp(4));
        o.run.seed = seed;
        o.run.threads = threads;
        o.method.chain_mut().bootstrap = 5000;
        integrator::render(&scene, &o).unwrap()
    };
    let bits = |o: &RenderOutput| o.image.iter().map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
    let a = run(7, 2);
    assert_eq!(bits(&a), bits(&run(7, 2)), "same seed and threads, different image");
    // The chains (64) run the same mutations whichever thread runs them.
    assert_eq!(bits(&a), bits(&run(7, 1)), "one thread against two, different image");
    assert_eq!(bits(&a), bits(&run(7, 3)), "three threads against two, different image");
    assert_ne!(bits(&a), bits(&run(8, 2)), "the seed must change the image");
    let s = &a.stats.details.get::<MemltDetails>().unwrap().memlt;
    assert_eq!(s.chains, 64);
    assert_eq!(s.mutations, 4 * 48 * 40);
    assert_eq!(s.mutators.iter().map(|m| m.proposed).sum::<u64>(), s.mutations);
}

#[test]
fn memlt_balances_its_direct_light_under_a_time_budget() {
    // Under a time budget the direct-light pass goes on for its share of the time. The
    // sun-lit room is lit mostly directly: the pass takes samples beyond the two passes of
    // 16 that measure its noise, and the image still matches the reference.
    let scene = SUNLIT_ROOM.scene();
    let timed = |o: &mut RenderOptions| o.run.budget = Budget::Time(6.0);
    let (a, b) = (memlt_with(&scene, 0, 1, &timed), memlt_with(&scene, 0, 2, &timed));
    for out in [&a, &b] {
        let s = &out.stats.details.get::<MemltDetails>().unwrap().memlt;
        let d = s.direct_balance.expect("the balance measured both parts");
        assert!(d.direct_noise > 0.0 && d.chain_noise > 0.0, "{d:?}");
        assert!(d.extra_samples > 0 && s.direct_samples == 32 + d.extra_samples, "{} samples, {d:?}", s.direct_samples);
    }
    SUNLIT_ROOM.check(&image(a), &image(b), "MEMLT, 2 × 6 s, the direct light balanced");
    // Without the balance, or with a budget of mutations, the pass takes its 16 samples.
    let off = |o: &mut RenderOptions| {
        o.run.budget = Budget::Time(1.0);
        o.method.memlt_mut().direct_balance = false;
    };
    for out in [memlt_with(&scene, 0, 1, &off), memlt(&scene, 1, 1, 16)] {
        let s = &out.stats.details.get::<MemltDetails>().unwrap().memlt;
        assert!(s.direct_samples == 16 && s.direct_balance.is_none(), "{} samples", s.direct_samples);
    }
}

#[test]
fn memlt_refuses_options_that_leave_no_chain() {
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "16"), ("resy", "16")], Backend::Embree);
    let mut o = RenderOptions::new(IntegratorKind::Memlt, Budget::Spp(1));
    o.method.memlt_mut().bidirectional_mutation = false;
    o.method.memlt_mut().lens_perturbation = false;
    o.method.memlt_mut().caustic_perturbation = false;
    o.method.memlt_mut().multichain_perturbation = false;
    o.method.memlt_mut().light_hit_perturbation = false;
    o.method.memlt_mut().manifold_perturbation = false;
    let e = integrator::render(&scene, &o).err().expect("no mutation must be refused").to_string();
    assert!(e.contains("at least one mutation"), "{e}");
    let mut o = RenderOptions::new(IntegratorKind::Memlt, Budget::Spp(1));
    o.method.memlt_mut().lambda = 0.0;
    let e = integrator::render(&scene, &o).err().expect("λ = 0 must be refused").to_string();
    assert!(e.contains("--lambda"), "{e}");
    let mut o = RenderOptions::new(IntegratorKind::Memlt, Budget::Spp(1));
    o.method.memlt_mut().theta_diff = -1.0;
    let e = integrator::render(&scene, &o).err().expect("a negative θ_diff must be refused").to_string();
    assert!(e.contains("--theta-diff"), "{e}");
    let mut o = RenderOptions::new(IntegratorKind::Memlt, Budget::Time(1.0));
    o.method.memlt_mut().bootstrap_fraction = 1.0;
    let e = integrator::render(&scene, &o).err().expect("the whole time on the bootstrap must be refused").to_string();
    assert!(e.contains("--bootstrap-fraction"), "{e}");
    for kind in [IntegratorKind::Memlt, IntegratorKind::Pssmlt] {
        let mut o = RenderOptions::new(kind, Budget::Spp(1));
        o.method.chain_mut().chains = 0;
        let e = integrator::render(&scene, &o).err().expect("no chain must be refused").to_string();
        assert!(e.contains("--chains"), "{kind:?}: {e}");
    }
}

#[test]
fn memlt_bootstrap_takes_its_share_of_a_time_budget() {
    // With a time budget the bootstrap goes on in batches until its fraction of the time
    // has passed: more than one batch of a small `--bootstrap` in a quarter of a second.
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "16"), ("resy", "16")], Backend::Embree);
    let mut o = RenderOptions::new(IntegratorKind::Memlt, Budget::Time(1.0));
    o.method.chain_mut().bootstrap = 1000;
    o.method.memlt_mut().bootstrap_fraction = 0.25;
    o.run.threads = 2;
    let out = integrator::render(&scene, &o).unwrap();
    let s = &out.stats.details.get::<MemltDetails>().unwrap().memlt;
    assert!(s.bootstrap_samples > 1000 && s.bootstrap_samples.is_multiple_of(1000), "{} samples", s.bootstrap_samples);
    assert!(s.bootstrap_seconds >= 0.25 && s.normalisation > 0.0, "{} s", s.bootstrap_seconds);
    // Two-stage Metropolis' first stage has the first half of that time, in batches too.
    assert!(*o.method.two_stage_mut());
    let n = s.first_stage_samples;
    assert!(n > 1000 && n.is_multiple_of(1000), "{n} first-stage samples");
}

#[test]
fn memlt_reports_a_chain_that_never_leaves_its_pixel() {
    // One chain, the direct light in it, and only the multi-chain perturbation, which no
    // path of this diffuse box suits (it needs a specular vertex between rough ones): the
    // chain keeps its start path, every mutation splats it into one pixel, and that
    // pixel's light is all the stay's.
    let scene = CORNELL_PLY.scene();
    let mut o = RenderOptions::new(IntegratorKind::Memlt, Budget::Spp(4));
    o.run.seed = 3;
    o.run.threads = 2;
    o.method.memlt_mut().direct_samples = -1;
    o.method.chain_mut().chains = 1;
    o.method.memlt_mut().bidirectional_mutation = false;
    o.method.memlt_mut().lens_perturbation = false;
    o.method.memlt_mut().caustic_perturbation = false;
    o.method.memlt_mut().manifold_perturbation = false;
    o.method.memlt_mut().light_hit_perturbation = false;
    o.method.memlt_mut().independent_mutation = Some(false);
    let out = integrator::render(&scene, &o).unwrap();
    let stay = out.stats.details.get::<MemltDetails>().unwrap().memlt.longest_stay.unwrap();
    assert_eq!(stay.mutations, out.width as u64 * out.height as u64 * 4);
    assert!((stay.share - 1.0).abs() < 1e-3, "share {}", stay.share);
    assert!(stay.dominates());
    // With the usual mutations no stay is that long in so short a render.
    let mut o = RenderOptions::new(IntegratorKind::Memlt, Budget::Spp(4));
    o.run.seed = 3;
    o.run.threads = 2;
    let out = integrator::render(&scene, &o).unwrap();
    let stay = out.stats.details.get::<MemltDetails>().unwrap().memlt.longest_stay.unwrap();
    assert!(!stay.dominates(), "{stay:?}");
}
