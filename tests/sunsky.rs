//! The `sunsky`, `sun` and `sky` emitters: a diffuse ground and block under Mitsuba 3's sun
//! and sky rendered by the path tracer and BDPT against Mitsuba 3's reference
//! (`tests/data/sunsky.exr`, `scripts/make_references.py sunsky`); the plugins and
//! parameters as the loader reads them (Mitsuba 3's names, Mitsuba 0.6's upgraded, and
//! Mitsuba 0.6's own sun in a file of version 0.x; its renders against Mitsuba 0.6's are
//! rows of `tests/reference.rs`).

mod common;

use common::*;
use glam::Vec3;
use pcbpt::integrator::IntegratorKind;
use pcbpt::light::Light;
use pcbpt::scene::{LoadOptions, Scene};
use std::path::Path;

fn load(version: &str, emitter: &str) -> Result<Scene, String> {
    let text = format!(
        r#"<scene version="{version}">
<sensor type="perspective"><float name="fov" value="40"/><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
{emitter}
</scene>"#
    );
    Scene::load_str(&text, Path::new("sky.xml"), &LoadOptions::default()).map_err(|e| e.to_string())
}

fn kinds(scene: &Scene) -> Vec<&'static str> {
    scene
        .lights
        .iter()
        .map(|l| match l {
            Light::Sky(_) => "sky",
            Light::Sun(_) => "sun",
            _ => "other",
        })
        .collect()
}

#[test]
fn ground_under_sun_and_sky_matches_mitsuba3_with_path_and_bdpt() {
    let scene = load_at(&root().join("scenes/sunsky/scene.xml"), &[], None, pcbpt::accel::Backend::Embree);
    let reference = reference("sunsky.exr");
    // The path tracer: the reference is the same estimator at 4096 spp.
    let spp = 128;
    let a = image(render(&scene, IntegratorKind::Path, spp, 1, 2));
    let b = image(render(&scene, IntegratorKind::Path, spp, 2, 2));
    let v = Verdict::new(&reference, &a, &b, spp, 4096);
    v.check("sunsky, path", 0.005, 1.3).unwrap();
    // Negative control: without the light between the ground and the block (direct light
    // only) the same check fails.
    let mut direct_only = load_at(&root().join("scenes/sunsky/scene.xml"), &[], None, pcbpt::accel::Backend::Embree);
    direct_only.integrator.max_depth = 2;
    let direct = image(render(&direct_only, IntegratorKind::Path, spp, 1, 2));
    let w = Verdict::new(&reference, &direct, &b, spp, 4096);
    assert!(w.check("sunsky, path, direct light only", 0.005, 1.3).is_err());
    // BDPT against the reference's noise (the path tracer's at 4096 spp).
    let ref_noise = v.noise * spp as f64 / 4096.0;
    let a = image(render(&scene, IntegratorKind::Bdpt, 32, 3, 2));
    let b = image(render(&scene, IntegratorKind::Bdpt, 32, 4, 2));
    let (v, _) = Verdict::averaged(&reference, &a, &b, ref_noise);
    v.check("sunsky, bdpt", 0.005, 1.3).unwrap();
}

#[test]
fn sun_and_sky_are_the_halves_of_sunsky() {
    let dir = r#"<vector name="sun_direction" x="0.2" y="0.3" z="0.8"/>"#;
    let both = load("3.0.0", &format!(r#"<emitter type="sunsky">{dir}</emitter>"#)).unwrap();
    let sun = load("3.0.0", &format!(r#"<emitter type="sun">{dir}</emitter>"#)).unwrap();
    let sky = load("3.0.0", &format!(r#"<emitter type="sky">{dir}</emitter>"#)).unwrap();
    assert_eq!((kinds(&both), kinds(&sun), kinds(&sky)), (vec!["sky", "sun"], vec!["sun"], vec!["sky"]));
    let towards_sun = Vec3::new(0.2, 0.3, 0.8).normalize();
    for d in [towards_sun, Vec3::new(-0.3, 0.1, 0.5).normalize()] {
        let sum = |s: &Scene| s.lights.iter().map(|l| l.eval_infinite(d)).sum::<Vec3>();
        assert_eq!(sum(&both), sum(&sun) + sum(&sky), "towards {d}");
    }
    // The sun gets most of the light selection on a clear day, the sky a fair share.
    let p_sun = both.light_sampler.pmf(1);
    eprintln!("the sun is chosen with probability {p_sun}");
    assert!((0.5..0.95).contains(&p_sun), "the sun is chosen with probability {p_sun}");
    // A zero scale leaves its half out.
    let off = load("3.0.0", &format!(r#"<emitter type="sunsky">{dir}<float name="sky_scale" value="0"/></emitter>"#));
    assert_eq!(kinds(&off.unwrap()), vec!["sun"]);
}

#[test]
fn a_sun_below_the_horizon_is_a_warning_and_a_black_sky() {
    let area = r#"<shape type="rectangle"><emitter type="area"/></shape>"#;
    let night = r#"<emitter type="sunsky"><float name="hour" value="2"/></emitter>"#;
    let scene = load("3.0.0", &format!("{night}{area}")).unwrap();
    assert_eq!(kinds(&scene), vec!["other"]);
    let w = scene.stats.warnings.join("\n");
    assert!(w.contains("sky.xml:3") && w.contains("the sun is below the horizon"), "{w}");
    // With nothing else to light it, the scene is refused as black.
    let e = load("3.0.0", night).err().unwrap();
    assert!(e.contains("no emitters"), "{e}");
}

#[test]
fn mitsuba_06_names_and_frame() {
    // Mitsuba 0.6: camelCase names, +y up, `sunRadiusScale` scales the 0.5358° disk,
    // `resolution` of its baked image is named as ignored.
    let legacy = r#"<emitter type="sunsky"><vector name="sunDirection" x="0.3" y="0.8" z="0.2"/>
        <float name="sunScale" value="2"/><float name="skyScale" value="0.5"/>
        <float name="sunRadiusScale" value="4"/><integer name="resolution" value="256"/></emitter>"#;
    let modern = r#"<emitter type="sunsky"><vector name="sun_direction" x="0.3" y="0.8" z="0.2"/>
        <float name="sun_scale" value="2"/><float name="sky_scale" value="0.5"/><float name="albedo" value="0.2"/>
        <float name="sun_aperture" value="2.1432"/>
        <transform name="to_world"><rotate x="1" angle="-90"/></transform></emitter>"#;
    let old = load("0.6.0", legacy).unwrap();
    let new = load("3.0.0", modern).unwrap();
    let w = old.stats.warnings.join("\n");
    assert!(w.contains("resolution"), "{w}");
    // The sky's horizon is y = 0 in both (Mitsuba 0.6's default ground albedo, 0.2, given
    // to the Mitsuba 3 file); the sun the same disk, with Mitsuba 0.6's radiance: the
    // Preetham sun at this zenith angle and the default turbidity, scaled by `sunScale`
    // and spread over a disk of 4 times the radius.
    let sun = Vec3::new(0.3, 0.8, 0.2).normalize();
    let zenith = sun.y.acos();
    let radius = pcbpt::light::sun06::ANGULAR_RADIUS;
    let spread = (1.0 - radius.cos()) / (1.0 - (4.0 * radius).cos());
    let expected_sun = pcbpt::light::sun06::radiance(zenith, 3.0) * 2.0 * spread;
    for d in
        [sun, Vec3::new(0.5, 0.2, -0.6).normalize(), Vec3::new(0.1, 0.6, 0.7).normalize(), Vec3::new(0.5, -0.1, 0.3)]
    {
        let d = d.normalize();
        let (a, b) = (old.lights[0].eval_infinite(d), new.lights[0].eval_infinite(d));
        assert!((a - b).abs().max_element() <= 1e-4 * b.max_element().max(1e-3), "sky towards {d}: {a} against {b}");
        let (pa, pb) = (old.lights[1].pdf_infinite(d), new.lights[1].pdf_infinite(d));
        assert!((pa - pb).abs() <= 1e-3 * pb, "the sun's density towards {d}: {pa} against {pb}");
        let l = old.lights[1].eval_infinite(d);
        let want = if d == sun { expected_sun } else { Vec3::ZERO };
        assert!(
            (l - want).abs().max_element() <= 1e-4 * want.max_element().max(1e-3),
            "sun towards {d}: {l} against {want}"
        );
    }
    // A Mitsuba 0.6 name in a Mitsuba 3 file is unused.
    let e = load("3.0.0", r#"<emitter type="sunsky"><float name="sunScale" value="2"/></emitter>"#).err().unwrap();
    assert!(e.contains("unused property \"sunScale\""), "{e}");
}

/// Mitsuba 0.6's sun keeps its power whatever `sunRadiusScale` makes of its size, and a
/// `sunRadiusScale` of 0 makes it a directional light of that irradiance; a Mitsuba 0.6
/// sky's ground albedo defaults to 0.2 (Mitsuba 3's to 0.3).
#[test]
fn mitsuba_06_sun_keeps_its_power_and_a_zero_radius_is_directional() {
    let sun = |radius_scale: &str| {
        let e = format!(
            r#"<emitter type="sun"><vector name="sunDirection" x="-0.4" y="0.6" z="0.69"/><float name="turbidity" value="4"/>
            <float name="scale" value="5"/><float name="sunRadiusScale" value="{radius_scale}"/></emitter>"#
        );
        let scene = load("0.6.0", &e).unwrap();
        assert_eq!(scene.lights.len(), 1);
        match &scene.lights[0] {
            Light::Sun(s) => s.irradiance(),
            Light::Directional { direction, irradiance } => {
                assert!((*direction + Vec3::new(-0.4, 0.6, 0.69).normalize()).length() < 1e-6, "{direction}");
                *irradiance
            }
            other => panic!("not a sun: {other:?}"),
        }
    };
    let zenith = Vec3::new(-0.4, 0.6, 0.69).normalize().y.acos();
    let expected = pcbpt::light::sun06::irradiance(zenith, 4.0) * 5.0;
    for scale in ["1", "3", "0"] {
        let e = sun(scale);
        assert!(
            (e - expected).abs().max_element() <= 2e-3 * expected.max_element(),
            "sunRadiusScale {scale}: {e} against {expected}"
        );
    }
    let e = load("0.6.0", r#"<emitter type="sun"><float name="sunRadiusScale" value="-1"/></emitter>"#).err().unwrap();
    assert!(e.contains("sunRadiusScale"), "{e}");
    let sky = |albedo: &str| {
        let e =
            format!(r#"<emitter type="sky"><vector name="sunDirection" x="0.3" y="0.3" z="0.9"/>{albedo}</emitter>"#);
        load("0.6.0", &e).unwrap().lights[0].eval_infinite(Vec3::new(0.2, 0.1, 0.5).normalize())
    };
    let (default, explicit, brighter) =
        (sky(""), sky(r#"<float name="albedo" value="0.2"/>"#), sky(r#"<float name="albedo" value="0.3"/>"#));
    assert_eq!(default, explicit);
    assert!(brighter.y > default.y, "{brighter} against {default}");
}

#[test]
fn every_integrator_converges_to_mitsuba3_under_sun_and_sky() {
    use pcbpt::integrator::pcbpt::PcMis;
    use pcbpt::integrator::{Budget, RenderOptions};
    let scene = load_at(&root().join("scenes/sunsky/scene.xml"), &[], None, pcbpt::accel::Backend::Embree);
    let reference = reference("sunsky.exr");
    let options = |kind: IntegratorKind, spp: u32| {
        let mut o = RenderOptions::new(kind, Budget::Spp(spp));
        o.run.seed = 11;
        o.run.threads = 2;
        o
    };
    let mut methods = vec![
        ("lighttrace", options(IntegratorKind::Lighttrace, 64)),
        ("eorr", options(IntegratorKind::Eorr, 32)),
        ("lvc", options(IntegratorKind::Lvc, 32)),
    ];
    // Each MIS option with the connections it weighs (no budget), and the defaults (a budget).
    for mis in [PcMis::Harmonic, PcMis::Uniform, PcMis::Resampling, PcMis::Correlated] {
        let mut o = options(IntegratorKind::Pcbpt, 16);
        o.method.pcbpt_mut().pc.mis = mis;
        o.method.budget_mut().mode = pcbpt::integrator::budget::BudgetMode::Off;
        methods.push(("pcbpt", o));
        let mut o = options(IntegratorKind::Spcbpt, 16);
        o.method.spcbpt_mut().sp.mis = mis;
        o.method.budget_mut().mode = pcbpt::integrator::budget::BudgetMode::Off;
        methods.push(("spcbpt", o));
    }
    methods.push(("pcbpt, defaults", options(IntegratorKind::Pcbpt, 16)));
    methods.push(("spcbpt, defaults", options(IntegratorKind::Spcbpt, 16)));
    let mut o = options(IntegratorKind::Pssmlt, 32);
    o.method.chain_mut().bootstrap = 20_000;
    methods.push(("pssmlt", o));
    let mean = |img: &pcbpt::image_io::Image| img.pixels.iter().map(|p| (p.x + p.y + p.z) as f64).sum::<f64>();
    let mut failures = Vec::new();
    for (name, mut o) in methods {
        let img = image(pcbpt::integrator::render(&scene, &o).unwrap());
        let ratio = mean(&img) / mean(&reference);
        let name = match name {
            "pcbpt" => format!("pcbpt {:?}", o.method.pcbpt_mut().pc.mis),
            "spcbpt" => format!("spcbpt {:?}", o.method.spcbpt_mut().sp.mis),
            _ => name.to_string(),
        };
        eprintln!("sunsky, {name}: mean ratio {ratio:.4}");
        if (ratio - 1.0).abs() > 0.01 {
            failures.push(format!("{name}: mean ratio {ratio:.4}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("; "));
}
