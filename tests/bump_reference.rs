//! Bump and normal mapping (`scenes/bumpmap/`) against Mitsuba 3 path-tracer references: a
//! plane under a grazing area light, its shading normal perturbed by a bump map
//! (`scene.xml`) or a normal map (`normalmap.xml`), rendered by the path tracer, by light
//! tracing (the adjoint BSDF alone, with its shading-normal correction) and by BDPT. Each
//! check averages two renders with different seeds: image mean within 1% and relMSE within
//! 1.3× of what the renders' noise and the reference's explain. The same scenes without
//! the perturbation must fail that check.

mod common;

use common::*;
use pcbpt::integrator::IntegratorKind;

/// The references carry the path tracer's relMSE noise at their 2048 spp, measured on these
/// scenes: one render's noise at 64 spp (from a pair of seeds) scaled by 64 / 2048, 8.2e-4 →
/// 2.6e-5 with the bump map and 5.7e-4 → 1.8e-5 with the normal map.
const BUMPMAP: Case = Case {
    name: "bumpmap",
    scene: "scenes/bumpmap/scene.xml",
    defines: &[],
    reference: "bumpmap.exr",
    ref_noise: 2.6e-5,
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

const NORMALMAP: Case = Case {
    name: "normalmap",
    scene: "scenes/bumpmap/normalmap.xml",
    defines: &[],
    reference: "normalmap.exr",
    ref_noise: 1.8e-5,
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

fn check(case: &Case, kind: IntegratorKind, spp: u32) {
    let scene = case.scene();
    let a = image(render(&scene, kind, spp, 1, 0));
    let b = image(render(&scene, kind, spp, 2, 0));
    case.check(&a, &b, &format!("{kind:?}, 2 × {spp} spp"));
}

/// The check of [`check`] on the scene loaded with `defines` that remove the perturbation:
/// it must fail.
fn check_fails_without_perturbation(case: &Case, defines: &[(&str, &str)], spp: u32) {
    let scene = load(&root().join(case.scene), defines, pcbpt::accel::Backend::Embree);
    let a = image(render(&scene, IntegratorKind::Path, spp, 1, 0));
    let b = image(render(&scene, IntegratorKind::Path, spp, 2, 0));
    let (v, _) = Verdict::averaged(&reference(case.reference), &a, &b, case.ref_noise);
    let verdict = v.check(&format!("{} without the perturbation", case.name), case.mean_tol, 1.3);
    assert!(verdict.is_err(), "the check cannot tell the perturbation is missing");
}

#[test]
fn bumpmap_path() {
    check(&BUMPMAP, IntegratorKind::Path, 64);
}

#[test]
fn bumpmap_lighttrace() {
    check(&BUMPMAP, IntegratorKind::Lighttrace, 64);
}

#[test]
fn bumpmap_bdpt() {
    check(&BUMPMAP, IntegratorKind::Bdpt, 32);
}

#[test]
fn bumpmap_missing_fails() {
    check_fails_without_perturbation(&BUMPMAP, &[("bump_scale", "0")], 64);
}

#[test]
fn normalmap_path() {
    check(&NORMALMAP, IntegratorKind::Path, 64);
}

#[test]
fn normalmap_lighttrace() {
    check(&NORMALMAP, IntegratorKind::Lighttrace, 64);
}

#[test]
fn normalmap_bdpt() {
    check(&NORMALMAP, IntegratorKind::Bdpt, 32);
}

#[test]
fn normalmap_missing_fails() {
    check_fails_without_perturbation(&NORMALMAP, &[("normals", "textures/flat.png")], 64);
}

#[test]
fn bdpt_and_path_tracer_agree_on_the_bump_map() {
    // The two estimators side by side, with no reference between them: BDPT's MIS over
    // light-tracing, connection and emitter-hit strategies (importance-mode BSDFs with the
    // shading-normal correction) converges to the path tracer's image.
    let scene = BUMPMAP.scene();
    let pa = image(render(&scene, IntegratorKind::Path, 128, 3, 0));
    let pb = image(render(&scene, IntegratorKind::Path, 128, 4, 0));
    let path = pcbpt::image_io::Image::new(
        pa.width,
        pa.height,
        pa.pixels.iter().zip(&pb.pixels).map(|(x, y)| (*x + *y) * 0.5).collect(),
    );
    let a = image(render(&scene, IntegratorKind::Bdpt, 32, 5, 0));
    let b = image(render(&scene, IntegratorKind::Bdpt, 32, 6, 0));
    // The path-traced image carries its own noise: half a 128-spp render's.
    let path_noise = Verdict::new(&path, &pa, &pb, 1, 1).noise / 2.0;
    let (v, _) = Verdict::averaged(&path, &a, &b, path_noise);
    v.check("bumpmap, BDPT against the path tracer", 0.01, 1.3).unwrap();
}

#[test]
fn mitsuba_06_scale_texture_multiplies_the_bump_scale() {
    // Mitsuba 0.6 wrote the height as a `scale` texture around the bitmap; the product of
    // its `scale` and the bumpmap's is the gradient's factor.
    use pcbpt::bsdf::perturb::PerturbKind;
    use pcbpt::scene::{LoadOptions, Scene};
    let scene_with = |version: &str, bsdf: &str| {
        let text = format!(
            r#"<scene version="{version}">
                <sensor type="perspective"><float name="fov" value="40"/></sensor>
                <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
                <shape type="rectangle">{bsdf}</shape>
            </scene>"#
        );
        let path = root().join("scenes/bumpmap/inline.xml");
        Scene::load_str(&text, &path, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
    };
    let bitmap = r#"<texture type="bitmap"><string name="filename" value="textures/height.exr"/></texture>"#;
    let legacy = scene_with(
        "0.6.0",
        &format!(
            r#"<bsdf type="bumpmap"><texture type="scale"><float name="scale" value="2.5"/>{bitmap}</texture>
               <float name="scale" value="2"/><bsdf type="diffuse"/></bsdf>"#
        ),
    );
    let current = scene_with(
        "3.0.0",
        &format!(r#"<bsdf type="bumpmap">{bitmap}<float name="scale" value="5"/><bsdf type="diffuse"/></bsdf>"#),
    );
    let kind = |s: &Scene| s.bsdfs.iter().find_map(|b| b.perturbation.as_ref()).map(|p| p.kind.clone()).unwrap();
    let (a, b) = (kind(&legacy), kind(&current));
    assert!(matches!(a, PerturbKind::Bump { scale, .. } if scale == 5.0), "{a:?}");
    assert_eq!(a, b);
}
