//! Mitsuba 0.6's `ward` BSDF in whole scenes (written as Mitsuba 0.6 files, with its
//! camelCase names): without a specular reflectance it renders the image a `diffuse` BSDF
//! renders, and a glossy Ward sphere under a small light renders to the same mean with the
//! path tracer and BDPT, and its direct light to the same mean with the path tracer (whose
//! BSDF samples are weighted by the Ward pdf) and light tracing (which never uses it). Its
//! Mitsuba 0.6 properties load as 0.6 reads them.

mod common;

use common::*;
use glam::Vec3;
use pcbpt::accel::Backend;
use pcbpt::bsdf::BsdfModel;
use pcbpt::bsdf::ward::{WardAlpha, WardVariant};
use pcbpt::image_io::Image;
use pcbpt::integrator::IntegratorKind;
use pcbpt::scene::Scene;
use pcbpt::texture::Texture;

/// A sphere with `bsdf`, on a grey floor where `floor`, lit by a square light of half-width
/// `light` above and to the side.
fn scene_with(bsdf: &str, max_depth: i32, floor: bool, light: f32) -> (tempfile::TempDir, Scene) {
    let floor = if floor {
        r#"<shape type="rectangle">
        <transform name="toWorld"><scale value="4"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
    </shape>"#
    } else {
        ""
    };
    let xml = format!(
        r#"<scene version="0.6.0">
    <integrator type="path"><integer name="maxDepth" value="{max_depth}"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="32"/>
        <transform name="toWorld"><lookAt origin="0, -4, 2.2" target="0, 0, 0.7" up="0, 0, 1"/></transform>
        <sampler type="independent"><integer name="sampleCount" value="16"/></sampler>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/><rfilter type="box"/></film>
    </sensor>
    <shape type="sphere"><point name="center" x="0" y="0" z="0.8"/><float name="radius" value="0.8"/>{bsdf}</shape>
    {floor}
    <shape type="rectangle">
        <transform name="toWorld"><scale value="{light}"/><rotate x="1" angle="180"/><translate x="1.2" y="-1.5" z="2.6"/></transform>
        <emitter type="area"><rgb name="radiance" value="{radiance}"/></emitter>
    </shape>
</scene>"#,
        radiance = 2.7 / (light * light)
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ward.xml");
    std::fs::write(&path, xml).unwrap();
    let scene = load(&path, &[], Backend::Embree);
    (dir, scene)
}

/// [`scene_with`] with the floor and a light of half-width 0.3.
fn scene(bsdf: &str, max_depth: i32) -> (tempfile::TempDir, Scene) {
    scene_with(bsdf, max_depth, true, 0.3)
}

const GLOSSY: &str = r#"<bsdf type="ward">
        <string name="variant" value="balanced"/>
        <float name="alphaU" value="0.08"/><float name="alphaV" value="0.25"/>
        <spectrum name="specularReflectance" value="0.7"/>
        <rgb name="diffuseReflectance" value="0.1, 0.2, 0.25"/>
    </bsdf>"#;

/// Pixels equal to within float rounding (relative 1e-4).
fn same_image(a: &Image, b: &Image) -> bool {
    a.pixels.iter().zip(&b.pixels).all(|(p, q)| (*p - *q).abs().max_element() <= 1e-4 * p.max_element().max(1e-3))
}

#[test]
fn ward_without_specular_reflectance_renders_the_diffuse_image() {
    // Same seed, same random numbers: a Ward BSDF (each variant, anisotropic) whose
    // specular reflectance is 0 never samples its glossy lobe and adds nothing from it.
    let (_d, diffuse) = scene(r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.4, 0.2"/></bsdf>"#, 3);
    for kind in [IntegratorKind::Path, IntegratorKind::Bdpt] {
        let reference = image(render(&diffuse, kind, 8, 11, 0));
        assert!(reference.mean() > 0.05, "{kind:?}: {}", reference.mean());
        for variant in ["ward", "ward-duer", "balanced"] {
            let (_w, ward) = scene(
                &format!(
                    r#"<bsdf type="ward"><string name="variant" value="{variant}"/>
                    <float name="alphaU" value="0.1"/><float name="alphaV" value="0.3"/>
                    <spectrum name="specularReflectance" value="0"/><rgb name="diffuseReflectance" value="0.6, 0.4, 0.2"/></bsdf>"#
                ),
                3,
            );
            let img = image(render(&ward, kind, 8, 11, 0));
            assert!(same_image(&reference, &img), "{kind:?}, {variant}: the images differ");
        }
        // Negative control: a reflectance 1% off is told apart.
        let (_o, other) =
            scene(r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.606, 0.404, 0.202"/></bsdf>"#, 3);
        assert!(!same_image(&reference, &image(render(&other, kind, 8, 11, 0))), "{kind:?}");
    }
}

/// The mean of `kind`'s image over `seeds` independent renders, and its standard error.
fn mean_of_renders(scene: &Scene, kind: IntegratorKind, spp: u32, seeds: u64) -> (f64, f64) {
    let means: Vec<f64> = (0..seeds).map(|s| image(render(scene, kind, spp, 100 + s, 0)).mean()).collect();
    mean_and_standard_error(&means)
}

/// Whether two means lie within four standard errors of their difference, their renders
/// converged enough (standard error below 0.5%) for that to mean something.
fn agree(what: &str, (a, sa): (f64, f64), (b, sb): (f64, f64)) -> Result<(), String> {
    let se = (sa * sa + sb * sb).sqrt();
    eprintln!("{what}: {a:.5} ± {sa:.5} against {b:.5} ± {sb:.5} ({:.2} standard errors)", (a - b).abs() / se);
    if (a - b).abs() >= 4.0 * se {
        return Err(format!("{what}: {a} ± {sa} against {b} ± {sb}"));
    }
    if se >= 0.005 * a {
        return Err(format!("{what}: standard error {se} of {a}"));
    }
    Ok(())
}

#[test]
fn glossy_ward_sphere_renders_the_same_with_path_tracing_and_bdpt() {
    let (_d, s) = scene(GLOSSY, 5);
    let pt = mean_of_renders(&s, IntegratorKind::Path, 512, 8);
    let bdpt = mean_of_renders(&s, IntegratorKind::Bdpt, 256, 8);
    agree("ward sphere, path against bdpt", pt, bdpt).unwrap();
}

#[test]
fn direct_light_on_a_glossy_ward_sphere_matches_light_tracing() {
    // The sphere alone (no floor), lit directly. Light tracing connects each light path's
    // first hit to the camera with the BSDF's value alone; the path tracer and BDPT weight
    // their BSDF samples by the Ward pdf (and MIS by both densities): a density that is not
    // the sampler's would bias them.
    let (_d, s) = scene_with(GLOSSY, 2, false, 0.6);
    let pt = mean_of_renders(&s, IntegratorKind::Path, 512, 8);
    let bdpt = mean_of_renders(&s, IntegratorKind::Bdpt, 256, 8);
    let lt = mean_of_renders(&s, IntegratorKind::Lighttrace, 4096, 8);
    let checks = [
        agree("ward sphere direct light, path against light tracing", pt, lt),
        agree("ward sphere direct light, bdpt against light tracing", bdpt, lt),
        agree("ward sphere direct light, path against bdpt", pt, bdpt),
    ];
    let failed: Vec<String> = checks.into_iter().filter_map(Result::err).collect();
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

#[test]
fn mitsuba_06_properties_load_as_06_reads_them() {
    // Defaults; `alphaU` overriding `alpha`; a textured roughness; the variant in any case;
    // reflectances summing past 1 scaled (with a warning) unless energy conservation is off.
    let text = r#"<scene version="0.6.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <bsdf type="ward" id="defaults"/>
    <bsdf type="ward" id="duer"><string name="variant" value="Ward-Duer"/><float name="alpha" value="0.2"/><float name="alphaU" value="0.05"/></bsdf>
    <bsdf type="ward" id="textured">
        <texture type="checkerboard" name="alphaV"><rgb name="color0" value="0.1"/><rgb name="color1" value="0.4"/></texture>
        <rgb name="specularReflectance" value="0.5"/><rgb name="diffuseReflectance" value="0.7, 0.2, 0.2"/>
    </bsdf>
    <bsdf type="ward" id="kept"><boolean name="ensureEnergyConservation" value="false"/>
        <spectrum name="specularReflectance" value="0.5"/><spectrum name="diffuseReflectance" value="0.7"/></bsdf>
    <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>"#;
    let dir = tempfile::tempdir().unwrap();
    let s =
        Scene::load_str(text, &dir.path().join("ward06.xml"), &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    let ward = |i: usize| match &s.bsdfs[i].model {
        BsdfModel::Ward { params, alpha, diffuse_reflectance, specular_reflectance } => {
            (*params, alpha.clone(), diffuse_reflectance.clone(), specular_reflectance.clone())
        }
        m => panic!("bsdf {i} is {m:?}"),
    };
    let c = |v: f32| Texture::Constant(Vec3::splat(v));
    let (p, alpha, d, sp) = ward(0);
    assert_eq!(
        (p.variant, p.scale, alpha, d, sp),
        (WardVariant::Balanced, 1.0, WardAlpha::Fixed { u: 0.1, v: 0.1 }, c(0.5), c(0.2))
    );
    assert!((p.specular_sampling_weight - 0.2 / 0.7).abs() < 1e-6, "{}", p.specular_sampling_weight);
    let (p, alpha, ..) = ward(1);
    assert_eq!((p.variant, alpha), (WardVariant::WardDuer, WardAlpha::Fixed { u: 0.05, v: 0.2 }));
    let (p, alpha, ..) = ward(2);
    let WardAlpha::Textured { u, v } = alpha else { panic!("{alpha:?}") };
    assert!(u == c(0.1) && matches!(v, Texture::Checkerboard { .. }), "{u:?} {v:?}");
    assert!((p.scale - 0.99 / 1.2).abs() < 1e-6, "{}", p.scale);
    assert_eq!(ward(3).0.scale, 1.0);
    // One warning, for the scaled material, at its line.
    let warned: Vec<&String> = s.stats.warnings.iter().filter(|w| w.contains("ward")).collect();
    assert_eq!(warned.len(), 1, "{:?}", s.stats.warnings);
    assert!(warned[0].contains("ward06.xml:8:") && warned[0].contains("scaled by 0.825"), "{}", warned[0]);
}
