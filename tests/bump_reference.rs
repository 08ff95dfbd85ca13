//! Bump and normal mapping (`scenes/bumpmap/`): BDPT against the path tracer on the bump
//! map, and Mitsuba 0.6's `scale` texture around the height. Their renders against the
//! Mitsuba 3 references, with and without the perturbation, are rows of `tests/reference.rs`.

mod common;

use common::*;
use pcbpt::integrator::IntegratorKind;

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
