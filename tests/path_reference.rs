//! The path tracer against Mitsuba 3 references (tests/data, settings beside each EXR),
//! with negative controls showing the checks catch a missing bounce.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::integrator::IntegratorKind;

#[test]
fn cornell_ply_matches_mitsuba() {
    let scene = load(&root().join("scenes/cornell-ply/cornell_mi.xml"), &[], Backend::Embree);
    let reference = reference("cornell-ply_mitsuba3-path_4096spp_maxdepth8_box.exr");
    let a = image(render(&scene, IntegratorKind::Path, 64, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, 64, 2, 0));
    Verdict::new(&reference, &a, &b, 64, 4096).check("cornell-ply, path, 64 spp", 0.005, 1.3).unwrap();
}

#[test]
fn cornell_ply_missing_bounce_is_caught() {
    // Negative control: one bounce fewer than the reference must fail the same check.
    let mut scene = load(&root().join("scenes/cornell-ply/cornell_mi.xml"), &[], Backend::Embree);
    scene.integrator.max_depth = 7;
    let reference = reference("cornell-ply_mitsuba3-path_4096spp_maxdepth8_box.exr");
    let a = image(render(&scene, IntegratorKind::Path, 64, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, 64, 2, 0));
    let v = Verdict::new(&reference, &a, &b, 64, 4096);
    assert!(v.check("cornell-ply, path, max_depth 7", 0.005, 1.3).is_err(), "a missing bounce went unnoticed");
}

#[test]
fn cornell_box_matches_mitsuba() {
    let scene = load(
        &root().join("scenes/cornell-box/scene.xml"),
        &[("resx", "128"), ("resy", "128"), ("max_depth", "30")],
        Backend::Embree,
    );
    let reference = reference("cornell-box.exr");
    let a = image(render(&scene, IntegratorKind::Path, 128, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, 128, 2, 0));
    Verdict::new(&reference, &a, &b, 128, 8192).check("cornell-box, path, 128 spp", 0.005, 1.3).unwrap();
}

#[test]
fn veach_mis_matches_mitsuba() {
    let scene = load(&root().join("scenes/veach-mis/scene.xml"), &[("resx", "192"), ("resy", "108")], Backend::Embree);
    let reference = reference("veach-mis.exr");
    let a = image(render(&scene, IntegratorKind::Path, 128, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, 128, 2, 0));
    // The smallest light (radius 0.05, radiance 3040) is seen directly by a handful of pixels.
    let v = Verdict::new(&reference, &a, &b, 128, 8192).excluding_emitters(&reference, &a, 100.0);
    v.check("veach-mis, path, 128 spp", 0.005, 1.3).unwrap();
}

#[test]
fn veach_ajar_matches_mitsuba() {
    let scene = load(
        &root().join("scenes/veach-ajar/scene.xml"),
        &[("resx", "160"), ("resy", "90"), ("max_depth", "-1")],
        Backend::Embree,
    );
    let reference = reference("veach-ajar.exr");
    let a = image(render(&scene, IntegratorKind::Path, 1024, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, 1024, 2, 0));
    Verdict::new(&reference, &a, &b, 1024, 16384).check("veach-ajar, path, 1024 spp", 0.005, 1.3).unwrap();
}

#[test]
fn materials_scene_matches_mitsuba() {
    let scene = load(&root().join("scenes/materials/scene.xml"), &[("resx", "160"), ("resy", "120")], Backend::Embree);
    let reference = reference("materials.exr");
    let a = image(render(&scene, IntegratorKind::Path, 128, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, 128, 2, 0));
    Verdict::new(&reference, &a, &b, 128, 4096).check("materials, path, 128 spp", 0.005, 1.3).unwrap();
}

#[test]
fn sunlit_room_matches_mitsuba() {
    // Lit by `sunsky` alone, through a window: the sun patch on the floor lights the room.
    let case = &SUNLIT_ROOM;
    let scene = case.scene();
    let a = image(render(&scene, IntegratorKind::Path, 32, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, 32, 2, 0));
    case.check(&a, &b, "path, 2 × 32 spp");
}

#[test]
fn staircase2_matches_mitsuba() {
    // Bitterli's Mitsuba 0.5 export as published, at 320×180 (`--resolution`), its own
    // max_depth 65: glass, glossy floors, 13 area lights on disks and rectangles. The
    // reference has 1024 spp; the verdict counts its noise (the same estimator's).
    let case = &STAIRCASE2;
    let scene = case.scene();
    let reference = reference(case.reference);
    let a = image(render(&scene, IntegratorKind::Path, 128, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, 128, 2, 0));
    Verdict::new(&reference, &a, &b, 128, 1024).check("staircase2, path, 128 spp", case.mean_tol, 1.3).unwrap();
}

#[test]
fn living_room_matches_mitsuba() {
    // Bitterli's "The Grey & White Room" as published, at 320×180, its own max_depth 65:
    // an envmap through the windows, rough plastic, the potted plants' leaves cut out by
    // leaf.png's alpha (the reference got the same alpha). The verdict counts the
    // reference's noise (the same estimator's, at 1024 spp).
    let case = &LIVING_ROOM;
    let scene = case.scene();
    let reference = reference(case.reference);
    let a = image(render(&scene, IntegratorKind::Path, 48, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, 48, 2, 0));
    Verdict::new(&reference, &a, &b, 48, 1024).check("living-room, path, 48 spp", case.mean_tol, 1.3).unwrap();
}
