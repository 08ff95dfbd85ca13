//! The bidirectional integrators (light tracing, BDPT, EORR, LVC) against the Mitsuba 3
//! path-tracer references, and the per-strategy images.
//!
//! Each check averages two renders with different seeds and requires the image mean within
//! 0.5% and the relMSE within 1.3× of what noise explains: half the two renders' noise plus
//! the reference's own noise. The references are path-traced, so their noise is the path
//! tracer's at the reference sample count, measured with our path tracer (same estimator):
//! cornell-ply 5.09e-3 at 64 spp → 8.0e-5 at 4096; veach-mis 2.82e-3 at 64 spp → 2.2e-5 at
//! 8192; veach-ajar 0.29 at 256 spp → 4.5e-3 at 16384.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::image_io::Image;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::Scene;

struct Case {
    name: &'static str,
    scene: &'static str,
    defines: &'static [(&'static str, &'static str)],
    reference: &'static str,
    ref_noise: f64,
    /// Pixels brighter than this in the reference are left out of the mean (tiny emitters).
    mean_cutoff: Option<f32>,
}

const CORNELL_PLY: Case = Case {
    name: "cornell-ply",
    scene: "scenes/cornell-ply/cornell_mi.xml",
    defines: &[],
    reference: "cornell-ply_mitsuba3-path_4096spp_maxdepth8_box.exr",
    ref_noise: 8.0e-5,
    mean_cutoff: None,
};

const VEACH_MIS: Case = Case {
    name: "veach-mis",
    scene: "scenes/veach-mis/scene.xml",
    defines: &[("resx", "192"), ("resy", "108")],
    reference: "veach-mis.exr",
    ref_noise: 2.2e-5,
    mean_cutoff: Some(100.0),
};

const VEACH_AJAR: Case = Case {
    name: "veach-ajar",
    scene: "scenes/veach-ajar/scene.xml",
    defines: &[("resx", "160"), ("resy", "90"), ("max_depth", "-1")],
    reference: "veach-ajar.exr",
    ref_noise: 4.5e-3,
    mean_cutoff: None,
};

fn scene(case: &Case) -> Scene {
    load(&root().join(case.scene), case.defines, Backend::Embree)
}

fn check(case: &Case, kind: IntegratorKind, spp: u32) {
    let scene = scene(case);
    let reference = reference(case.reference);
    let a = image(render(&scene, kind, spp, 1, 0));
    let b = image(render(&scene, kind, spp, 2, 0));
    let (mut v, avg) = Verdict::averaged(&reference, &a, &b, case.ref_noise);
    if let Some(cutoff) = case.mean_cutoff {
        v = v.excluding_emitters(&reference, &avg, cutoff);
    }
    v.check(&format!("{}, {kind:?}, 2 × {spp} spp", case.name), 0.005, 1.3).unwrap();
}

#[test]
fn lighttrace_cornell_ply() {
    check(&CORNELL_PLY, IntegratorKind::Lighttrace, 32);
}

#[test]
fn bdpt_cornell_ply() {
    check(&CORNELL_PLY, IntegratorKind::Bdpt, 16);
}

#[test]
fn eorr_cornell_ply() {
    check(&CORNELL_PLY, IntegratorKind::Eorr, 16);
}

#[test]
fn lvc_cornell_ply() {
    check(&CORNELL_PLY, IntegratorKind::Lvc, 16);
}

#[test]
fn lighttrace_veach_mis() {
    check(&VEACH_MIS, IntegratorKind::Lighttrace, 256);
}

#[test]
fn bdpt_veach_mis() {
    check(&VEACH_MIS, IntegratorKind::Bdpt, 32);
}

#[test]
fn eorr_veach_mis() {
    check(&VEACH_MIS, IntegratorKind::Eorr, 32);
}

#[test]
fn lvc_veach_mis() {
    check(&VEACH_MIS, IntegratorKind::Lvc, 32);
}

#[test]
fn lighttrace_veach_ajar() {
    check(&VEACH_AJAR, IntegratorKind::Lighttrace, 1024);
}

#[test]
fn bdpt_veach_ajar() {
    check(&VEACH_AJAR, IntegratorKind::Bdpt, 128);
}

#[test]
fn eorr_veach_ajar() {
    check(&VEACH_AJAR, IntegratorKind::Eorr, 128);
}

#[test]
fn lvc_veach_ajar() {
    check(&VEACH_AJAR, IntegratorKind::Lvc, 128);
}

fn render_layers(scene: &Scene, kind: IntegratorKind, spp: u32, seed: u64) -> integrator::RenderOutput {
    let mut o = RenderOptions::new(kind, Budget::Spp(spp));
    o.seed = seed;
    o.strategy_images = true;
    integrator::render(scene, &o).unwrap()
}

#[test]
fn strategy_images_sum_to_the_image_and_a_missing_strategy_is_caught() {
    let scene = scene(&CORNELL_PLY);
    let reference = reference(CORNELL_PLY.reference);
    for kind in [IntegratorKind::Bdpt, IntegratorKind::Lvc, IntegratorKind::Lighttrace] {
        let out = render_layers(&scene, kind, 4, 7);
        assert!(!out.strategy_images.is_empty());
        for (i, p) in out.image.iter().enumerate() {
            let sum = out.strategy_images.iter().fold(glam::Vec3::ZERO, |acc, (_, img)| acc + img[i]);
            assert!(
                (sum - *p).abs().max_element() <= 1e-4 * (1.0 + p.max_element()),
                "{kind:?} pixel {i}: {sum} vs {p}"
            );
        }
    }
    // Negative control: without the weighted `(s=1, t=2)` image (direct light by NEE), an
    // otherwise converged BDPT image fails the check, as any wrong weight would.
    let a = render_layers(&scene, IntegratorKind::Bdpt, 16, 1);
    let b = render_layers(&scene, IntegratorKind::Bdpt, 16, 2);
    let drop = |out: &integrator::RenderOutput| {
        let (_, layer) = out.strategy_images.iter().find(|(n, _)| n == "s1_t2").unwrap();
        Image::new(out.width, out.height, out.image.iter().zip(layer).map(|(p, l)| *p - *l).collect())
    };
    let (full, _) = Verdict::averaged(
        &reference,
        &Image::new(a.width, a.height, a.image.clone()),
        &Image::new(b.width, b.height, b.image.clone()),
        CORNELL_PLY.ref_noise,
    );
    full.check("cornell-ply, BDPT", 0.005, 1.3).unwrap();
    let (v, _) = Verdict::averaged(&reference, &drop(&a), &drop(&b), CORNELL_PLY.ref_noise);
    assert!(v.check("cornell-ply, BDPT without s1_t2", 0.005, 1.3).is_err(), "a missing strategy went unnoticed");
}
