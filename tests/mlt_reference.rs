//! PSSMLT (over BDPT) against the Mitsuba 3 references, and its determinism.
//!
//! Two renders with different seeds (independent chains) are averaged; the image mean must
//! agree within 1% and the relMSE stay within 1.3× of what the two renders' noise and the
//! reference's own noise explain (see `tests/bidir_reference.rs` for the reference noise).

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::integrator::pssmlt::PssmltStats;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions, RenderOutput};
use pcbpt::scene::Scene;

fn check(scene: &Scene, reference_name: &str, ref_noise: f64, spp: u32, what: &str) {
    let reference = reference(reference_name);
    let a = image(render(scene, IntegratorKind::Pssmlt, spp, 1, 2));
    let b = image(render(scene, IntegratorKind::Pssmlt, spp, 2, 2));
    let (v, _) = Verdict::averaged(&reference, &a, &b, ref_noise);
    v.check(what, 0.01, 1.3).unwrap();
}

#[test]
fn pssmlt_cornell_ply() {
    let scene = load(&root().join("scenes/cornell-ply/cornell_mi.xml"), &[], Backend::Embree);
    check(&scene, "cornell-ply_mitsuba3-path_4096spp_maxdepth8_box.exr", 8.0e-5, 16, "cornell-ply, PSSMLT, 2 × 16 spp");
}

fn veach_ajar() -> Scene {
    load(
        &root().join("scenes/veach-ajar/scene.xml"),
        &[("resx", "160"), ("resy", "90"), ("max_depth", "-1")],
        Backend::Embree,
    )
}

#[test]
fn pssmlt_veach_ajar() {
    check(&veach_ajar(), "veach-ajar.exr", 4.5e-3, 64, "veach-ajar, PSSMLT, 2 × 64 spp");
}

#[test]
fn pssmlt_veach_ajar_two_stage() {
    // Two-stage Metropolis (MEMLT's default): the chains' target luminance over a first
    // stage's map, the image scaled to the bootstrap's mean luminance.
    let scene = veach_ajar();
    let reference = reference("veach-ajar.exr");
    let run = |seed| {
        let out = render_with(&scene, IntegratorKind::Pssmlt, 64, seed, 2, &|o| *o.method.two_stage_mut() = true);
        assert!(out.stats.details.get::<PssmltStats>().unwrap().mlt.first_stage_samples > 0);
        image(out)
    };
    let (v, _) = Verdict::averaged(&reference, &run(1), &run(2), 4.5e-3);
    v.check("veach-ajar, PSSMLT in two stages, 2 × 64 spp", 0.01, 1.3).unwrap();
}

#[test]
fn pssmlt_staircase2() {
    // Bitterli's Mitsuba 0.5 export as published, at 320×180 (`--resolution`).
    let scene = STAIRCASE2.scene();
    check(&scene, STAIRCASE2.reference, STAIRCASE2.ref_noise, 16, "staircase2, PSSMLT, 2 × 16 spp");
}

#[test]
fn pssmlt_sunlit_room() {
    // Sky and sun through a window (whole-image mean: the sky seen through it counts).
    let scene = SUNLIT_ROOM.scene();
    check(&scene, SUNLIT_ROOM.reference, SUNLIT_ROOM.ref_noise, 16, "sunlit-room, PSSMLT, 2 × 16 spp");
}

#[test]
fn pssmlt_living_room() {
    // Bitterli's "The Grey & White Room" as published, at 320×180: the envmap through the
    // windows, the leaves' cut-outs.
    let scene = LIVING_ROOM.scene();
    check(&scene, LIVING_ROOM.reference, LIVING_ROOM.ref_noise, 32, "living-room, PSSMLT, 2 × 32 spp");
}

#[test]
fn pssmlt_is_deterministic_for_a_seed_whatever_the_thread_count() {
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "48"), ("resy", "40")], Backend::Embree);
    let run = |seed, threads, base| {
        let mut o = RenderOptions::new(IntegratorKind::Pssmlt, Budget::Spp(4));
        o.seed = seed;
        o.threads = threads;
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
    o.seed = 4;
    o.threads = 2;
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
