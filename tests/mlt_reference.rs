//! PSSMLT (over BDPT) in two stages against the Mitsuba 3 reference, its determinism and
//! its longest stay (its other reference checks are rows of `tests/reference.rs`).
//!
//! Two renders with different seeds (independent chains) are averaged; the image mean must
//! agree within 1% and the relMSE stay within 1.3× of what the two renders' noise and the
//! reference's own noise explain.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::integrator::pssmlt::PssmltStats;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions, RenderOutput};

#[test]
fn pssmlt_veach_ajar_two_stage() {
    // Two-stage Metropolis (MEMLT's default): the chains' target luminance over a first
    // stage's map, the image scaled to the bootstrap's mean luminance.
    let scene = VEACH_AJAR.scene();
    let reference = reference(VEACH_AJAR.reference);
    let run = |seed| {
        let out = render_with(&scene, IntegratorKind::Pssmlt, 64, seed, 2, &|o| *o.method.two_stage_mut() = true);
        assert!(out.stats.details.get::<PssmltStats>().unwrap().mlt.first_stage_samples > 0);
        image(out)
    };
    let (v, _) = Verdict::averaged(&reference, &run(1), &run(2), VEACH_AJAR.noise());
    v.check("veach-ajar, PSSMLT in two stages, 2 × 64 spp", 0.01, 1.3).unwrap();
}

#[test]
fn pssmlt_is_deterministic_for_a_seed_whatever_the_thread_count() {
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "48"), ("resy", "40")], Backend::Embree);
    let run = |seed, threads, base| {
        let mut o = RenderOptions::new(IntegratorKind::Pssmlt, Budget::Spp(4));
        o.run.seed = seed;
        o.run.threads = threads;
        o.method.chain_mut().bootstrap = 5000;
        o.method.pssmlt_mut().base = base;
        integrator::render(&scene, &o).unwrap()
    };
    use pcbpt::integrator::metropolis::MltBase;
    for base in [MltBase::Bdpt, MltBase::Path] {
        let a = run(7, 2, base);
        let bits = |o: &RenderOutput| o.image.iter().map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&run(7, 2, base)), "{base:?}: same seed, different image");
        // The chains (64) run the same mutations whichever thread runs them.
        assert_eq!(bits(&a), bits(&run(7, 1, base)), "{base:?}: one thread against two, different image");
        assert_eq!(bits(&a), bits(&run(7, 3, base)), "{base:?}: three threads against two, different image");
        let c = run(8, 2, base);
        assert_ne!(a.image, c.image, "{base:?}: the seed must change the image");
        let m = a.stats.details.get::<PssmltStats>().unwrap().mlt;
        assert_eq!(m.mutations, 4 * 48 * 40);
        assert!(m.small_acceptance > 0.0 && m.small_acceptance <= 1.0 && m.large_acceptance > 0.0);
    }
}

#[test]
fn pssmlt_measures_its_longest_stay_against_the_image() {
    // A one-pixel film: every state of the one chain lies in it, so the longest stay is the
    // whole render and carries all of the pixel's light (the image's luminance is `b`, and
    // every mutation splats `b`).
    let path = root().join("scenes/cornell-ply/cornell_mi.xml");
    let scene = load_at(&path, &[], Some((1, 1)), Backend::Embree);
    let mut o = RenderOptions::new(IntegratorKind::Pssmlt, Budget::Spp(3000));
    o.run.seed = 4;
    o.run.threads = 2;
    o.method.chain_mut().chains = 1;
    let out = integrator::render(&scene, &o).unwrap();
    let stay = out.stats.details.get::<PssmltStats>().unwrap().mlt.longest_stay.unwrap();
    assert_eq!(stay.mutations, 3000);
    assert_eq!(stay.pixel, [0, 0]);
    assert!((stay.share - 1.0).abs() < 1e-3, "share {}", stay.share);
    assert!(stay.dominates());
    // At the full film no stay of a short render carries that much.
    let scene = load(&path, &[], Backend::Embree);
    let out = render(&scene, IntegratorKind::Pssmlt, 4, 4, 2);
    let stay = out.stats.details.get::<PssmltStats>().unwrap().mlt.longest_stay.unwrap();
    assert!(!stay.dominates(), "{stay:?}");
}
