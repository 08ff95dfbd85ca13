//! Mitsuba 0.5/0.6 scenes as published (Bitterli's exports): the version upgrade and its
//! parameters, film properties that mean nothing here and properties no plugin reads (one
//! warning naming each, as Mitsuba 0.6 gave them; in a Mitsuba 3 file an error), Mitsuba 0.6's `extEta` of conductors and mip-mapped bitmap filters, references to
//! ids nested in other objects, a file's integrator when the command line picks another, and
//! the film size replaced by `--resolution`.

mod common;

use common::root;
use glam::{Vec2, Vec3};
use pcbpt::bsdf::fresnel::fresnel_conductor;
use pcbpt::bsdf::{BsdfModel, TransportMode};
use pcbpt::error::Result;
use pcbpt::scene::{LoadOptions, Scene, parse_resolution};
use pcbpt::texture::{FilterType, Texture};

/// Loads scene text as if it were `scenes/materials/legacy.xml` (its textures resolve there).
fn load(text: &str, options: &LoadOptions) -> Result<Scene> {
    Scene::load_str(text, &root().join("scenes/materials/legacy.xml"), options)
}

/// A small version-`version` scene: a camera looking at an emitting rectangle, with `film`
/// inside the film block and `body` in the scene.
fn scene(version: &str, film: &str, body: &str) -> String {
    format!(
        r#"<scene version="{version}">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="toWorld"><lookAt origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sampleCount" value="3"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="16"/>
            <integer name="height" value="12"/>
{film}
        </film>
    </sensor>
{body}
    <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>
"#
    )
}

fn opts() -> LoadOptions {
    LoadOptions::default()
}

fn err(r: Result<Scene>) -> String {
    match r {
        Ok(_) => panic!("the scene loaded"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn version_05_names_are_upgraded_like_version_06() {
    let body = r#"
    <integrator type="path"><integer name="maxDepth" value="5"/><integer name="rrDepth" value="4"/></integrator>
    <bsdf type="diffuse" id="d"><rgb name="diffuseReflectance" value="0.25"/></bsdf>
    <bsdf type="dielectric" id="g"><float name="intIOR" value="1.5"/><float name="extIOR" value="1"/></bsdf>
    <shape type="cube"><transform name="toWorld"><translate x="3"/></transform><ref id="d"/></shape>
    <shape type="cube"><transform name="toWorld"><translate x="-3"/></transform><ref id="g"/></shape>"#;
    for version in ["0.5.0", "0.6.0"] {
        let s = load(&scene(version, "", body), &opts()).unwrap_or_else(|e| panic!("{version}: {e}"));
        assert_eq!((s.sampler.spp, s.integrator.max_depth, s.integrator.rr_depth), (3, 5, 4), "{version}");
        assert_eq!((s.film.width, s.film.height), (16, 12));
        // Mitsuba 3's upgrade renames a diffuse BSDF's `diffuseReflectance` to `reflectance`.
        assert_eq!(
            s.bsdfs[0].model,
            BsdfModel::Diffuse { reflectance: Texture::Constant(Vec3::splat(0.25)) },
            "{version}"
        );
        assert!(matches!(s.bsdfs[1].model, BsdfModel::Dielectric { eta, .. } if eta == 1.5), "{version}");
        assert!(s.stats.warnings.is_empty(), "{version}: {:?}", s.stats.warnings);
    }
    // A version-3 file is not upgraded: `lookAt` is not a transform, `toWorld` not a property.
    let e = err(load(&scene("3.0.0", "", body), &opts()));
    assert!(e.contains("legacy.xml:4:") && e.contains("unknown transform operation <lookAt>"), "{e}");
    let e = err(load(&scene("3.0.0", "", body).replace("lookAt", "lookat"), &opts()));
    assert!(e.contains("legacy.xml:5:") && e.contains("unused property \"sampleCount\""), "{e}");
}

#[test]
fn a_camel_case_default_matches_its_reference() {
    // The issue's input: both spellings are upgraded alike, so `$photonCount` finds
    // `<default name="photonCount">`.
    let text = r#"<scene version="0.6.0">
    <default name="photonCount" value="4"/>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <sampler type="independent"><integer name="sampleCount" value="$photonCount"/></sampler>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>"#;
    let s = load(text, &opts()).unwrap();
    assert_eq!(s.sampler.spp, 4);
    assert!(s.stats.warnings.is_empty(), "{:?}", s.stats.warnings);
    // `-D` overrides it in either spelling, and neither is "not declared".
    for name in ["photonCount", "photon_count"] {
        let o = LoadOptions { overrides: vec![(name.into(), "9".into())], ..opts() };
        let s = load(text, &o).unwrap();
        assert_eq!(s.sampler.spp, 9, "-D {name}");
        assert!(s.stats.warnings.is_empty(), "-D {name}: {:?}", s.stats.warnings);
    }
    // The snake_case reference finds the camelCase default too (the upgraded name).
    let s = load(&text.replace("$photonCount", "$photon_count"), &opts()).unwrap();
    assert_eq!(s.sampler.spp, 4);
    // In a version-3 file names are taken as written.
    let e = err(load(
        &text.replace("0.6.0", "3.0.0").replace("sampleCount", "sample_count").replace("$photonCount", "$photon_count"),
        &opts(),
    ));
    assert!(e.contains("legacy.xml:5:") && e.contains("undefined parameter \"$photon_count\""), "{e}");
}

/// Bitterli's film block (staircase2, living-room), with Mitsuba 0.6's `gamma` added.
const LEGACY_FILM: &str = r#"            <string name="fileFormat" value="openexr"/>
            <string name="pixelFormat" value="rgb"/>
            <boolean name="banner" value="false"/>
            <float name="gamma" value="2.2"/>
            <rfilter name="rfilter" type="tent"/>
            <boolean name="high_quality_edges" value="true"/>"#;

#[test]
fn legacy_film_properties_are_accepted_with_one_warning_and_a_misspelt_one_is_named_there_too() {
    let s = load(&scene("0.5.0", LEGACY_FILM, ""), &opts()).unwrap();
    assert_eq!(s.stats.warnings.len(), 1, "{:?}", s.stats.warnings);
    let w = &s.stats.warnings[0];
    for name in ["\"high_quality_edges\"", "\"file_format\"", "\"pixel_format\"", "\"banner\"", "\"gamma\""] {
        assert!(w.contains(name), "{name} not named in: {w}");
    }
    assert!(
        w.contains("\"file_format\" of film \"hdrfilm\" (") && w.contains("legacy.xml:9:13)"),
        "the first at its line: {w}"
    );
    assert_eq!((s.film.width, s.film.height), (16, 12));
    // A misspelt or unknown property of the same film is named in the warning, at its line,
    // as Mitsuba 0.6 warned of properties no plugin read; in a Mitsuba 3 file it is an error.
    for (from, to, name) in [
        ("high_quality_edges", "high_quality_edge", "high_quality_edge"),
        ("\"banner\"", "\"bannner\"", "bannner"),
        ("pixelFormat", "pixelFormats", "pixel_formats"),
    ] {
        let s = load(&scene("0.5.0", &LEGACY_FILM.replace(from, to), ""), &opts()).unwrap();
        let w = s.stats.warnings.join("\n");
        assert!(w.contains(&format!("\"{name}\"")) && w.contains("legacy.xml:1"), "{to}: {w}");
    }
    // Mitsuba 3's own output-format values that agree with what is written: no warning.
    let v3 = scene(
        "3.0.0",
        "<string name=\"file_format\" value=\"openexr\"/><string name=\"pixel_format\" value=\"rgb\"/>",
        "",
    )
    .replace("toWorld", "to_world")
    .replace("sampleCount", "sample_count")
    .replace("lookAt", "lookat");
    let s = load(&v3, &opts()).unwrap();
    assert!(s.stats.warnings.is_empty(), "{:?}", s.stats.warnings);
    let e = err(load(&v3.replace("</film>", "<boolean name=\"bannner\" value=\"false\"/></film>"), &opts()));
    assert!(e.contains("unused property \"bannner\"") && e.contains("legacy.xml:"), "{e}");
    // One that asks for something else means nothing here either: the warning.
    let s = load(&v3.replace("\"rgb\"", "\"luminance\""), &opts()).unwrap();
    assert!(s.stats.warnings.len() == 1 && s.stats.warnings[0].contains("\"pixel_format\""), "{:?}", s.stats.warnings);
}

/// Normal-incidence reflectance of a conductor, per channel.
fn normal_reflectance(eta: Vec3, k: Vec3) -> Vec3 {
    let f = |n: f32, k: f32| ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
    Vec3::new(f(eta.x, k.x), f(eta.y, k.y), f(eta.z, k.z))
}

#[test]
fn ext_eta_of_conductors_divides_eta_and_k_as_mitsuba_06_did() {
    let (eta, k) = (Vec3::new(0.2, 0.92, 1.1), Vec3::new(3.9, 2.45, 2.2));
    let conductor = |plugin: &str, ext: &str| {
        format!(
            r#"<bsdf type="{plugin}" id="m"><rgb name="eta" value="{}, {}, {}"/><rgb name="k" value="{}, {}, {}"/>{ext}</bsdf>"#,
            eta.x, eta.y, eta.z, k.x, k.y, k.z
        )
    };
    let wo = Vec3::Z;
    let reflect = |s: &Scene, wo: Vec3| {
        s.bsdfs[0].sample(wo, Vec2::ZERO, 0.5, Vec2::splat(0.5), TransportMode::Radiance).unwrap().weight
    };
    let plain = load(&scene("0.6.0", "", &conductor("conductor", "")), &opts()).unwrap();
    let r0 = reflect(&plain, wo);
    assert!((r0 - normal_reflectance(eta, k)).abs().max_element() < 1e-5, "{r0}");
    for (ext, value) in
        [("<float name=\"extEta\" value=\"1.5\"/>", 1.5f32), ("<string name=\"extEta\" value=\"water\"/>", 1.333)]
    {
        let s = load(&scene("0.6.0", "", &conductor("conductor", ext)), &opts()).unwrap();
        assert!(s.stats.warnings.is_empty());
        let BsdfModel::Conductor { eta: e, k: kk, .. } = s.bsdfs[0].model else { panic!("not a conductor") };
        assert!((e - eta / value).abs().max_element() < 1e-6 && (kk - k / value).abs().max_element() < 1e-6);
        // The reflectance at normal incidence is that of eta / extEta, k / extEta, and it
        // differs from the one without the exterior medium by much more than rounding.
        let r = reflect(&s, wo);
        let expected = normal_reflectance(eta / value, k / value);
        assert!((r - expected).abs().max_element() < 1e-5, "{ext}: {r} against {expected}");
        assert!((r - r0).abs().max_element() > 0.01, "{ext}: {r} against {r0}");
        // At 60° as the Fresnel equations give for the divided indices.
        let w60 = Vec3::new(60f32.to_radians().sin(), 0.0, 0.5);
        let r60 = reflect(&s, w60);
        let f60 = fresnel_conductor(0.5, eta / value, k / value);
        assert!((r60 - f60).abs().max_element() < 1e-5, "{ext}: {r60} against {f60}");
    }
    // The rough conductor alike: the same values as the indices divided by hand.
    let s = load(&scene("0.6.0", "", &conductor("roughconductor", "<float name=\"extEta\" value=\"1.5\"/>")), &opts())
        .unwrap();
    let BsdfModel::RoughConductor { eta: e, k: kk, .. } = s.bsdfs[0].model.clone() else { panic!() };
    assert!((e - eta / 1.5).abs().max_element() < 1e-6 && (kk - k / 1.5).abs().max_element() < 1e-6);
    let wi = Vec3::new(-0.3, 0.1, 0.95).normalize();
    let f = s.bsdfs[0].eval(Vec3::new(0.2, 0.0, 0.98).normalize(), wi, Vec2::ZERO, TransportMode::Radiance);
    let plain = load(&scene("0.6.0", "", &conductor("roughconductor", "")), &opts()).unwrap();
    let f0 = plain.bsdfs[0].eval(Vec3::new(0.2, 0.0, 0.98).normalize(), wi, Vec2::ZERO, TransportMode::Radiance);
    assert!((f - f0).abs().max_element() > 0.01 * f0.max_element(), "{f} against {f0}");
    // Not a number or a known medium: an error at its line.
    let e =
        err(load(&scene("0.6.0", "", &conductor("conductor", "<string name=\"extEta\" value=\"vacuumm\"/>")), &opts()));
    assert!(e.contains("legacy.xml:12:") && e.contains("unknown index of refraction \"vacuumm\""), "{e}");
}

fn bitmap(filter: &str) -> String {
    format!(
        r#"<texture name="reflectance" type="bitmap"><string name="filename" value="textures/tiles.png"/><string name="filterType" value="{filter}"/></texture>"#
    )
}

#[test]
fn mip_mapped_bitmap_filters_are_bilinear_lookups_with_one_warning() {
    let body = format!(
        r#"<bsdf type="diffuse" id="a">{}</bsdf>
    <bsdf type="diffuse" id="b">{}</bsdf>
    <bsdf type="diffuse" id="c">{}</bsdf>"#,
        bitmap("trilinear"),
        bitmap("ewa"),
        bitmap("nearest")
    );
    let s = load(&scene("0.6.0", "", &body), &opts()).unwrap();
    let filters: Vec<FilterType> = s.bsdfs[..3]
        .iter()
        .map(|b| match &b.model {
            BsdfModel::Diffuse { reflectance: Texture::Bitmap { bitmap, .. } } => bitmap.filter,
            m => panic!("{m:?}"),
        })
        .collect();
    assert_eq!(filters, [FilterType::Bilinear, FilterType::Bilinear, FilterType::Nearest]);
    assert_eq!(s.stats.warnings.len(), 1, "{:?}", s.stats.warnings);
    let w = &s.stats.warnings[0];
    assert!(w.contains("\"trilinear\"") && w.contains("legacy.xml:12:") && w.contains("1 more"), "{w}");
    let e =
        err(load(&scene("0.6.0", "", &format!("<bsdf type=\"diffuse\" id=\"a\">{}</bsdf>", bitmap("bogus"))), &opts()));
    assert!(e.contains("legacy.xml:12:") && e.contains("unknown filter_type \"bogus\""), "{e}");
}

/// A mask's opacity given as a colour (Bitterli's kitchen: `<spectrum name="opacity"
/// value="0.612066"/>`): a grey one is its value, without a warning; a coloured one counts by
/// its luminance, with a warning naming the line; out of range stays an error.
#[test]
fn a_mask_opacity_given_as_a_colour_counts_by_its_luminance() {
    let mask = |opacity: &str| format!(r#"<bsdf type="mask" id="m">{opacity}<bsdf type="diffuse"/></bsdf>"#);
    let opacity_of = |s: &Scene| match s.bsdfs[0].opacity.as_deref() {
        Some(pcbpt::texture::Opacity::Constant(a)) => *a,
        o => panic!("{o:?}"),
    };
    for (version, prop) in [
        ("0.5.0", r#"<spectrum name="opacity" value="0.612066"/>"#),
        ("0.6.0", r#"<rgb name="opacity" value="0.25"/>"#),
    ] {
        let s = load(&scene(version, "", &mask(prop)), &opts()).unwrap();
        let expect = if version == "0.5.0" { 0.612066 } else { 0.25 };
        assert_eq!(opacity_of(&s), expect, "{version}");
        assert!(s.stats.warnings.is_empty(), "{:?}", s.stats.warnings);
    }
    let s = load(&scene("0.6.0", "", &mask(r#"<rgb name="opacity" value="0.2, 0.5, 0.8"/>"#)), &opts()).unwrap();
    let a = opacity_of(&s);
    assert!((a - pcbpt::math::luminance(Vec3::new(0.2, 0.5, 0.8))).abs() < 1e-6, "{a}");
    assert_eq!(s.stats.warnings.len(), 1, "{:?}", s.stats.warnings);
    let w = &s.stats.warnings[0];
    assert!(w.contains("legacy.xml:12:") && w.contains("coloured") && w.contains("luminance"), "{w}");
    let e = err(load(&scene("0.6.0", "", &mask(r#"<rgb name="opacity" value="1.5, 1.5, 1.5"/>"#)), &opts()));
    assert!(e.contains("legacy.xml:12:") && e.contains("between 0 and 1, got 1.5"), "{e}");
    let e = err(load(&scene("0.6.0", "", &mask(r#"<string name="opacity" value="half"/>"#)), &opts()));
    assert!(e.contains("legacy.xml:12:") && e.contains("expected rgb"), "{e}");
}

#[test]
fn ids_nested_in_other_objects_can_be_referenced() {
    let body = r#"
    <bsdf type="twosided" id="outer">
        <bsdf type="diffuse" id="inner">
            <texture name="reflectance" type="checkerboard" id="checks"><rgb name="color0" value="0.1"/></texture>
        </bsdf>
    </bsdf>
    <shape type="cube"><transform name="to_world"><translate x="3"/></transform><ref id="inner"/></shape>
    <shape type="cube"><transform name="to_world"><translate x="-3"/></transform><ref id="outer"/></shape>
    <shape type="cube"><transform name="to_world"><translate y="3"/></transform>
        <bsdf type="roughconductor"><ref name="alpha" id="checks"/></bsdf>
    </shape>"#;
    let text = scene("3.0.0", "", body)
        .replace("toWorld", "to_world")
        .replace("sampleCount", "sample_count")
        .replace("lookAt", "lookat");
    let s = load(&text, &opts()).unwrap();
    let shape_bsdf = |i: usize| &s.bsdfs[s.shapes[i].bsdf];
    // The nested diffuse on its own is one-sided; the twosided around it is two-sided.
    assert!(matches!(shape_bsdf(0).model, BsdfModel::Diffuse { .. }) && !shape_bsdf(0).two_sided);
    assert!(matches!(shape_bsdf(1).model, BsdfModel::Diffuse { .. }) && shape_bsdf(1).two_sided);
    assert_eq!(shape_bsdf(0).model, shape_bsdf(1).model);
    // The checkerboard nested in the diffuse serves as another BSDF's roughness.
    assert!(matches!(shape_bsdf(2).model, BsdfModel::RoughConductor { .. }));
    // A reference that makes an object contain itself is an error, not a stack overflow.
    for cycle in [
        r#"<bsdf type="twosided" id="a"><ref id="a"/></bsdf>"#,
        r#"<bsdf type="twosided" id="a"><bsdf type="twosided" id="b"><ref id="a"/></bsdf></bsdf>"#,
    ] {
        let e = err(load(&scene("0.6.0", "", cycle), &opts()));
        assert!(
            e.contains("legacy.xml:12:") && e.contains("reference to id \"a\"") && e.contains("contain itself"),
            "{e}"
        );
    }
}

const SPPM: &str = r#"<integrator type="sppm">
        <integer name="maxDepth" value="7"/>
        <integer name="photonCount" value="250000"/>
        <float name="initialRadius" value="0"/>
    </integrator>"#;

#[test]
fn a_file_integrator_this_renderer_lacks_is_an_error_unless_the_command_line_picks_one() {
    let e = err(load(&scene("0.5.0", "", SPPM), &opts()));
    assert!(
        e.contains("legacy.xml:12:") && e.contains("unknown integrator plugin \"sppm\"") && e.contains("--integrator"),
        "{e}"
    );
    let picked = LoadOptions { integrator_override: Some("--integrator bdpt".into()), ..opts() };
    let s = load(&scene("0.5.0", "", SPPM), &picked).unwrap();
    assert_eq!(s.integrator.max_depth, 7, "the file's max_depth applies");
    assert_eq!(s.stats.warnings.len(), 1, "{:?}", s.stats.warnings);
    let w = &s.stats.warnings[0];
    for part in
        ["legacy.xml:12:", "\"sppm\"", "--integrator bdpt", "max_depth", "\"photon_count\" (", "\"initial_radius\""]
    {
        assert!(w.contains(part), "{part:?} not in: {w}");
    }
    // Properties only another integrator reads, on a type this renderer has: named, with
    // their lines, in the warning, as Mitsuba 0.6 warned of them.
    let path = SPPM.replace("sppm", "path");
    let s = load(&scene("0.5.0", "", &path), &opts()).unwrap();
    let w = s.stats.warnings.join("\n");
    assert!(w.contains("\"photon_count\"") && w.contains("legacy.xml:14:"), "{w}");
    let s = load(&scene("0.5.0", "", &path), &picked).unwrap();
    assert_eq!((s.integrator.max_depth, s.stats.warnings.len()), (7, 1), "{:?}", s.stats.warnings);
    assert!(s.stats.warnings[0].contains("\"photon_count\"") && !s.stats.warnings[0].contains("lacks"));
    // What applies is still checked.
    let e = err(load(&scene("0.5.0", "", &SPPM.replace("\"7\"", "\"-7\"")), &picked));
    assert!(e.contains("legacy.xml:13:") && e.contains("max_depth must be"), "{e}");
    // A file with nothing to ignore gives no warning.
    let s = load(
        &scene("0.5.0", "", r#"<integrator type="path"><integer name="maxDepth" value="3"/></integrator>"#),
        &picked,
    )
    .unwrap();
    assert!(s.stats.warnings.is_empty() && s.integrator.max_depth == 3, "{:?}", s.stats.warnings);
}

#[test]
fn resolution_replaces_the_film_size() {
    assert_eq!(parse_resolution("320x180"), Ok((320, 180)));
    assert_eq!(parse_resolution("64×36"), Ok((64, 36)));
    assert_eq!(parse_resolution(" 8X6 "), Ok((8, 6)));
    for bad in ["320", "x180", "0x10", "10x0", "-3x4", "abc", "70000x2", "3x4x5"] {
        assert!(parse_resolution(bad).is_err(), "{bad}");
    }
    let o = LoadOptions { resolution: Some((40, 30)), ..opts() };
    let s = load(&scene("0.5.0", LEGACY_FILM, ""), &o).unwrap();
    assert_eq!((s.film.width, s.film.height), (40, 30));
    let film_size = |s: &Scene| (s.film.width, s.film.height);
    // Without a film block (Mitsuba's default 768×576) too.
    let no_film = r#"<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="40"/></sensor>
        <shape type="rectangle"><emitter type="area"/></shape></scene>"#;
    assert_eq!(film_size(&load(no_film, &opts()).unwrap()), (768, 576));
    assert_eq!(film_size(&load(no_film, &o).unwrap()), (40, 30));
    let too_big = LoadOptions { resolution: Some((65536, 65536)), ..opts() };
    let e = err(load(no_film, &too_big));
    assert!(e.contains("--resolution 65536x65536"), "{e}");
}

#[test]
fn staircase2_loads_unchanged() {
    let path = root().join("scenes/staircase2/scene.xml");
    // As published: Mitsuba 0.5 names, the film's options for Mitsuba 0.5.
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.contains("<scene version=\"0.5.0\" >") && text.contains("high_quality_edges") && text.contains("maxDepth")
    );
    let s = Scene::load(&path, &LoadOptions::default()).unwrap();
    assert_eq!((s.film.width, s.film.height, s.sampler.spp), (1280, 720, 256));
    assert_eq!((s.integrator.plugin.as_str(), s.integrator.max_depth), ("path", 65));
    assert_eq!(s.lights.len(), 13);
    exporters_film_options_ignored_once(&s);
    // The rest are the exporter's zero-area triangles, counted per shape.
    assert!(
        s.stats.warnings.iter().all(|w| w.contains("ignored") || w.contains("degenerate")),
        "{:?}",
        s.stats.warnings
    );
}

/// One warning names the film options of Bitterli's Mitsuba 0.5 exports that mean nothing
/// here.
fn exporters_film_options_ignored_once(s: &Scene) {
    let ignored: Vec<&String> = s.stats.warnings.iter().filter(|w| w.contains("ignored")).collect();
    assert_eq!(ignored.len(), 1, "{:?}", s.stats.warnings);
    for name in ["high_quality_edges", "file_format", "pixel_format", "banner"] {
        assert!(ignored[0].contains(name), "{name}: {}", ignored[0]);
    }
}

#[test]
fn living_room_loads_unchanged() {
    let path = root().join("scenes/living-room/scene.xml");
    // As published: Mitsuba 0.5 names, the film's options for Mitsuba 0.5, and the leaves
    // cut out by a mask whose opacity is leaf.png (RGBA: its alpha).
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.contains("<scene version=\"0.5.0\" >")
            && text.contains("high_quality_edges")
            && text.contains("<bsdf type=\"mask\" id=\"Leaves\" >")
            && text.contains("textures/leaf.png")
    );
    let s = Scene::load(&path, &LoadOptions::default()).unwrap();
    assert_eq!((s.film.width, s.film.height), (1280, 720));
    assert_eq!((s.integrator.plugin.as_str(), s.integrator.max_depth), ("path", 65));
    assert_eq!((s.lights.len(), s.infinite_lights.len()), (1, 1));
    // One BSDF has the leaves' cut-out, read from the alpha channel: opaque and clear
    // texels both, with the nested two-sided diffuse model.
    let masked: Vec<_> = s.bsdfs.iter().filter(|b| b.opacity.is_some()).collect();
    assert_eq!(masked.len(), 1);
    assert!(masked[0].two_sided);
    let Some(pcbpt::texture::Opacity::Alpha { bitmap, .. }) = masked[0].opacity.as_deref() else {
        panic!("the leaves' opacity is not leaf.png's alpha: {:?}", masked[0].opacity.is_some())
    };
    assert!(bitmap.texels.contains(&0.0) && bitmap.texels.contains(&1.0));
    let leaves = s.shapes.iter().filter(|sh| s.bsdfs[sh.bsdf].opacity.is_some()).count();
    assert!(leaves > 0);
    exporters_film_options_ignored_once(&s);
    assert!(
        s.stats.warnings.iter().all(|w| w.contains("ignored") || w.contains("degenerate")),
        "{:?}",
        s.stats.warnings
    );
}
