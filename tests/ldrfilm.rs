//! Mitsuba 0.5/0.6's `ldrfilm` and the rest of what Bitterli's scene files ask for on their
//! first lines: the tonemapper against Mitsuba 0.6's own PNGs of the same samples, the film
//! read from a scene and written as a tonemapped PNG, Mitsuba's other samplers, the path
//! tracer's `strictNormals`, and properties no plugin reads (a warning in a 0.x file, an
//! error in a Mitsuba 3 one).

mod common;

use common::root;
use pcbpt::image_io::tonemap::{Ldr, Tonemap, Transfer};
use pcbpt::image_io::{self, Image};
use pcbpt::sampling::SamplerKind;
use pcbpt::scene::{LoadOptions, Scene};
use std::process::Command;

/// The largest difference, in 8-bit code values, between `ldr` applied to Mitsuba 0.6's
/// `hdrfilm` render and its `ldrfilm` PNG `png` of the same samples.
fn largest_difference(ldr: &Ldr, png: &str) -> i32 {
    let exr = image_io::read_exr(&root().join("tests/data/veach-ajar_mitsuba06_160x90_4spp_hdrfilm.exr")).unwrap();
    let want = image::open(root().join("tests/data").join(png)).unwrap().to_rgb8();
    assert_eq!((want.width(), want.height()), (exr.width, exr.height));
    let got = ldr.encode8(&exr);
    got.iter().zip(want.as_raw()).map(|(a, b)| (*a as i32 - *b as i32).abs()).max().unwrap()
}

const SRGB_PNG: &str = "veach-ajar_mitsuba06_160x90_4spp_ldrfilm-srgb-exposure1.png";
const REINHARD_PNG: &str = "veach-ajar_mitsuba06_160x90_4spp_ldrfilm-reinhard-key0.3-burn0.2-gamma2.2.png";

#[test]
fn the_tonemapper_gives_mitsuba_06s_pngs_within_one_code_value() {
    let srgb = Ldr { tonemap: Tonemap::Exposure(1.0), transfer: Transfer::Srgb };
    assert!(largest_difference(&srgb, SRGB_PNG) <= 1, "sRGB, exposure 1: {}", largest_difference(&srgb, SRGB_PNG));
    let reinhard = Ldr { tonemap: Tonemap::Reinhard { key: 0.3, burn: 0.2 }, transfer: Transfer::Gamma(2.2) };
    let d = largest_difference(&reinhard, REINHARD_PNG);
    assert!(d <= 1, "Reinhard, key 0.3, burn 0.2, gamma 2.2: {d}");
    // Negative controls: half a stop off, a key 10% off, the sRGB curve for gamma 2.2. (The
    // burn barely shows here: the light seen through the door gap sets the white point far
    // above the rest of the image.)
    for (wrong, png) in [
        (Ldr { tonemap: Tonemap::Exposure(0.5), ..srgb }, SRGB_PNG),
        (Ldr { tonemap: Tonemap::Reinhard { key: 0.27, burn: 0.2 }, ..reinhard }, REINHARD_PNG),
        (Ldr { transfer: Transfer::Srgb, ..reinhard }, REINHARD_PNG),
    ] {
        assert!(largest_difference(&wrong, png) > 1, "{wrong:?} matched {png}");
    }
}

/// veach-ajar's Mitsuba 0.6 file with its film replaced by `film`.
fn ajar_06(film: &str) -> String {
    let text = std::fs::read_to_string(root().join("scenes/veach-ajar/scene_v0.6.xml")).unwrap();
    let start = text.find("<film").unwrap();
    let end = text.find("</film>").unwrap() + "</film>".len();
    format!("{}{film}{}", &text[..start], &text[end..])
}

const LDR_FILM: &str = r#"<film type="ldrfilm">
            <integer name="width" value="$resx"/>
            <integer name="height" value="$resy"/>
            <string name="fileFormat" value="png"/>
            <string name="pixelFormat" value="rgb"/>
            <string name="tonemapMethod" value="reinhard"/>
            <float name="key" value="0.3"/>
            <float name="burn" value="0.2"/>
            <float name="gamma" value="2.2"/>
            <boolean name="banner" value="false"/>
            <rfilter type="tent"/>
        </film>"#;

#[test]
fn a_scenes_ldrfilm_is_read_and_its_png_tonemapped() {
    let dir = tempfile::tempdir().unwrap();
    let scene = root().join("scenes/veach-ajar").join(format!("ldrfilm-test-{}.xml", std::process::id()));
    std::fs::write(&scene, ajar_06(LDR_FILM)).unwrap();
    let loaded = Scene::load(&scene, &LoadOptions::default());
    let render = |out: &std::path::Path| {
        Command::new(env!("CARGO_BIN_EXE_pcbpt"))
            .current_dir(dir.path())
            .args(["render", scene.to_str().unwrap(), "-D", "resx=32", "-D", "resy=18", "--spp", "2", "--quiet"])
            .args(["-o", out.to_str().unwrap()])
            .output()
            .unwrap()
    };
    let (png, exr) = (dir.path().join("a.png"), dir.path().join("a.exr"));
    let (a, b) = (render(&png), render(&exr));
    let _ = std::fs::remove_file(&scene);
    let loaded = loaded.unwrap();
    let want = Ldr { tonemap: Tonemap::Reinhard { key: 0.3, burn: 0.2 }, transfer: Transfer::Gamma(2.2) };
    assert_eq!(loaded.film.ldr, Some(want));
    assert!(a.status.success() && b.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    // The PNG is the EXR (the same samples) tonemapped by the film.
    let linear = image_io::read_exr(&exr).unwrap();
    let written = image::open(&png).unwrap().to_rgb8();
    assert_eq!(written.as_raw(), &want.encode8(&linear));
    // It is not the plain sRGB encoding of the same image.
    assert_ne!(written.as_raw(), &Ldr::default().encode8(&linear));
}

#[test]
fn an_ldrfilm_renders_to_a_png_by_default() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("box.xml");
    std::fs::write(
        &scene,
        r#"<scene version="0.6.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="toWorld"><lookAt origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="ldrfilm"><integer name="width" value="8"/><integer name="height" value="6"/>
            <float name="exposure" value="-1"/><boolean name="banner" value="false"/></film>
    </sensor>
    <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>"#,
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_pcbpt"))
        .current_dir(dir.path())
        .args(["render", "box.xml", "--spp", "1", "--quiet"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let png = image::open(dir.path().join("box.png")).unwrap().to_rgb8();
    // Radiance 1 at −1 stop: sRGB(0.5) = 188 where the camera sees the light.
    assert!(png.pixels().any(|p| p.0 == [188, 188, 188]), "{:?}", png.pixels().next());
}

/// A small scene of version `version` with `sampler`, `integrator` and `extra` in it.
fn small(version: &str, sampler: &str, integrator: &str, extra: &str) -> String {
    format!(
        r#"<scene version="{version}">
    {integrator}
    <sensor type="perspective"><float name="fov" value="40"/>{extra}
        <transform name="toWorld"><lookAt origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        {sampler}
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>
    </sensor>
    <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>"#
    )
}

fn load(text: &str) -> pcbpt::error::Result<Scene> {
    Scene::load_str(text, &root().join("scenes/materials/test.xml"), &LoadOptions::default())
}

#[test]
fn mitsubas_samplers_are_read_for_their_sample_count_and_rendered_with_sobol() {
    let sampler = |plugin: &str| {
        format!(
            r#"<sampler type="{plugin}"><integer name="sampleCount" value="9"/><integer name="scramble" value="-1"/></sampler>"#
        )
    };
    let s = load(&small("0.6.0", &sampler("sobol"), "", "")).unwrap();
    assert_eq!((s.sampler.spp, s.sampler.kind), (9, SamplerKind::Sobol));
    assert!(s.stats.warnings.is_empty(), "{:?}", s.stats.warnings);
    for plugin in ["stratified", "ldsampler", "halton", "hammersley", "multijitter", "orthogonal"] {
        let s = load(&small("0.6.0", &sampler(plugin), "", "")).unwrap_or_else(|e| panic!("{plugin}: {e}"));
        assert_eq!((s.sampler.spp, s.sampler.kind), (9, SamplerKind::Sobol), "{plugin}");
        assert_eq!(s.stats.warnings.len(), 1, "{plugin}: {:?}", s.stats.warnings);
        assert!(s.stats.warnings[0].contains(&format!("\"{plugin}\" sampler")), "{:?}", s.stats.warnings);
    }
    let s = load(&small("0.6.0", r#"<sampler type="independent"/>"#, "", "")).unwrap();
    assert_eq!(s.sampler.kind, SamplerKind::Independent);
    let e = load(&small("0.6.0", r#"<sampler type="sobbol"/>"#, "", "")).err().unwrap().to_string();
    assert!(e.contains("unknown sampler plugin \"sobbol\"") && e.contains("sobol") && e.contains("test.xml:"), "{e}");
}

#[test]
fn the_sobol_sampler_is_the_path_tracers() {
    let box_scene = root().join("scenes/cornell-box/scene.xml");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_pcbpt"))
            .args(["render", box_scene.to_str().unwrap(), "-D", "resx=16", "-D", "resy=16", "--spp", "4", "--quiet"])
            .args(args)
            .output()
            .unwrap()
    };
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (a, b) = (out("sobol.exr"), out("independent.exr"));
    assert!(run(&["--sampler", "sobol", "-o", &a]).status.success());
    assert!(run(&["--sampler", "independent", "-o", &b]).status.success());
    let (a, b) =
        (image_io::read_exr(std::path::Path::new(&a)).unwrap(), image_io::read_exr(std::path::Path::new(&b)).unwrap());
    assert_ne!(a.pixels, b.pixels, "the sampler changes the samples");
    // Asked for under another integrator, it is an error naming the option.
    let o = run(&["--sampler", "sobol", "--integrator", "bdpt", "-o", &out("bdpt.exr")]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(1) && e.contains("--sampler sobol") && e.contains("bdpt"), "{e}");
}

/// The line of `text` that holds `needle`, counting from 1.
fn line_of(text: &str, needle: &str) -> usize {
    text[..text.find(needle).unwrap()].matches('\n').count() + 1
}

/// A small shape with the material `bsdf`, so that the material is read.
fn with_material(bsdf: &str) -> String {
    format!(r#"<shape type="sphere"><float name="radius" value="0.1"/>{bsdf}</shape>"#)
}

#[test]
fn properties_no_plugin_reads_are_warnings_in_a_06_file_and_errors_in_a_mitsuba_3_file() {
    // Bitterli's files: focusDistance on a pinhole, alpha on a smooth conductor, strictNormals
    // on BDPT — Mitsuba 0.6 warned of each and rendered.
    let extra = r#"<float name="focusDistance" value="3"/>"#;
    let integrator = format!(
        "<integrator type=\"bdpt\"><boolean name=\"strictNormals\" value=\"true\"/></integrator>\n    {}",
        with_material(r#"<bsdf type="conductor"><float name="alpha" value="0.1"/></bsdf>"#)
    );
    let text = small("0.6.0", "", &integrator, extra);
    let s = load(&text).unwrap();
    let w = s.stats.warnings.join("\n");
    for (name, needle) in [("focus_distance", "focusDistance"), ("strict_normals", "strictNormals"), ("alpha", "alpha")]
    {
        let at = format!("test.xml:{}:", line_of(&text, needle));
        assert!(w.contains(&format!("\"{name}\"")) && w.contains(&at), "{name} at {at}: {w}");
    }
    assert!(!s.integrator.strict_normals, "BDPT does not read strictNormals");
    let v3 = small("3.0.0", "", "", r#"<float name="focus_distance" value="3"/>"#)
        .replace("toWorld", "to_world")
        .replace("lookAt", "lookat");
    let e = load(&v3).err().expect("an unused property of a Mitsuba 3 file is an error").to_string();
    let at = format!("test.xml:{}:", line_of(&v3, "focus_distance"));
    assert!(e.contains("unused property \"focus_distance\"") && e.contains(&at), "{e}");
}

#[test]
fn a_negative_conductor_eta_or_k_of_a_06_file_is_its_magnitude() {
    let bsdf = |eta: &str, k: &str| {
        with_material(&format!(
            r#"<bsdf type="conductor"><rgb name="eta" value="{eta}"/><rgb name="k" value="{k}"/></bsdf>"#
        ))
    };
    let same = load(&small("0.6.0", "", &bsdf("0.2, 0.9, 1.1", "3, 2, 1"), "")).unwrap();
    assert!(same.stats.warnings.iter().all(|w| !w.contains("negative channel")), "{:?}", same.stats.warnings);
    // living-room-2's fitted k has a negative red channel.
    for (eta, k, name) in [("-0.2, 0.9, 1.1", "3, 2, 1", "eta"), ("0.2, 0.9, 1.1", "-3, 2, 1", "k")] {
        let s = load(&small("0.6.0", "", &bsdf(eta, k), "")).unwrap();
        assert!(
            s.stats.warnings.iter().any(|w| w.contains(&format!("{name} ")) && w.contains("negative channel")),
            "{:?}",
            s.stats.warnings
        );
        assert_eq!(format!("{:?}", s.bsdfs), format!("{:?}", same.bsdfs));
        let v3 = small("3.0.0", "", &bsdf(eta, k), "").replace("toWorld", "to_world").replace("lookAt", "lookat");
        let e = load(&v3).err().expect("a negative eta or k in a Mitsuba 3 file is an error").to_string();
        assert!(e.contains(&format!("\"{name}\" must be finite and non-negative")), "{e}");
    }
}

/// A diffuse quad in the `z = 0` plane whose vertex normals lean 73° towards `+x`, seen from
/// above, and a light below the plane on the `+x` side: directions to the light lie below the
/// geometric surface but above the shading one.
const LEANING_NORMALS_OBJ: &str =
    "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvn 1 0 0.3\nf 1//1 2//1 3//1\nf 1//1 3//1 4//1\n";

fn leaning_normals_scene(dir: &std::path::Path, strict: bool) -> String {
    std::fs::write(dir.join("quad.obj"), LEANING_NORMALS_OBJ).unwrap();
    format!(
        r#"<scene version="0.6.0">
    <integrator type="path"><integer name="maxDepth" value="3"/><boolean name="strictNormals" value="{strict}"/></integrator>
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="toWorld"><lookAt origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
    </sensor>
    <shape type="obj"><string name="filename" value="quad.obj"/><bsdf type="diffuse"/></shape>
    <shape type="rectangle">
        <transform name="toWorld"><rotate y="1" angle="-90"/><translate x="3" y="0" z="-1"/></transform>
        <emitter type="area"><rgb name="radiance" value="5"/></emitter>
    </shape>
</scene>"#
    )
}

#[test]
fn strict_normals_end_paths_where_the_normals_disagree() {
    let dir = tempfile::tempdir().unwrap();
    let render = |strict: bool| {
        let path = dir.path().join(format!("quad-{strict}.xml"));
        std::fs::write(&path, leaning_normals_scene(dir.path(), strict)).unwrap();
        let scene = common::load(&path, &[], pcbpt::accel::Backend::Embree);
        assert_eq!(scene.integrator.strict_normals, strict);
        common::image(common::render(&scene, pcbpt::integrator::IntegratorKind::Path, 4, 1, 0))
    };
    let sum = |i: &Image| i.pixels.iter().map(|p| (p.x + p.y + p.z) as f64).sum::<f64>();
    let (loose, strict) = (render(false), render(true));
    // Without strict normals the light leaks through the quad along its shading normals.
    assert!(sum(&loose) > 0.0, "the light below the quad reaches it along the shading normals");
    assert_eq!(sum(&strict), 0.0, "with strict normals nothing from below the surface counts");
    // Where the two normals agree (flat shading) strict normals change nothing.
    let box_defines = [("resx", "32"), ("resy", "32")];
    let flat = |strict: bool| {
        let mut scene =
            common::load(&root().join("scenes/cornell-box/scene.xml"), &box_defines, pcbpt::accel::Backend::Embree);
        scene.integrator.strict_normals = strict;
        common::image(common::render(&scene, pcbpt::integrator::IntegratorKind::Path, 4, 1, 0))
    };
    assert_eq!(flat(false).pixels, flat(true).pixels, "flat shading: the normals agree everywhere");
}
