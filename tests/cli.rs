//! The command line: bad scenes give a clear error naming the file and line, a non-zero
//! exit and no output file, never a panic; good renders write their image and statistics;
//! `compare` reports the metrics.

mod common;

use common::root;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn pcbpt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pcbpt")).args(args).output().expect("runs the binary")
}

/// A minimal valid scene around `body`, written to `dir/name`.
fn scene(dir: &Path, name: &str, body: &str) -> PathBuf {
    let xml = format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
{body}
</scene>
"#
    );
    let p = dir.join(name);
    std::fs::write(&p, xml).unwrap();
    p
}

const LIGHT: &str =
    r#"    <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>"#;

/// Runs a render that must fail; returns its stderr.
fn fails(scene: &Path, expect: &[&str]) -> String {
    let out_path = scene.with_extension("exr");
    let out = pcbpt(&["render", scene.to_str().unwrap(), "-o", out_path.to_str().unwrap(), "--spp", "1", "--quiet"]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{} rendered: {err}", scene.display());
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        err.contains(&scene.file_name().unwrap().to_string_lossy().into_owned())
            || expect.iter().any(|e| e.ends_with(".ply") || e.ends_with(".obj")),
        "error does not name the file: {err}"
    );
    for e in expect {
        assert!(err.contains(e), "expected {e:?} in: {err}");
    }
    assert!(!out_path.exists(), "an output file was written");
    err
}

#[test]
fn loader_errors_name_file_and_line() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    // A missing mesh: the scene file and the line of the filename property.
    let s = scene(
        dir,
        "missing_mesh.xml",
        &format!("{LIGHT}\n    <shape type=\"ply\"><string name=\"filename\" value=\"nowhere.ply\"/></shape>"),
    );
    fails(&s, &["missing_mesh.xml:7:", "nowhere.ply", "does not exist"]);
    // An unknown plugin.
    let s = scene(dir, "unknown_plugin.xml", &format!("{LIGHT}\n    <bsdf type=\"velvet\" id=\"v\"/>"));
    fails(&s, &["unknown_plugin.xml:7:", "unknown bsdf plugin \"velvet\""]);
    // An unused property.
    let s = scene(
        dir,
        "unused.xml",
        &format!("{LIGHT}\n    <bsdf type=\"diffuse\" id=\"d\"><float name=\"roughness\" value=\"0.1\"/></bsdf>"),
    );
    fails(&s, &["unused.xml:7:", "unused property \"roughness\""]);
    // A malformed number.
    let s = scene(
        dir,
        "number.xml",
        &format!(
            "{LIGHT}\n    <bsdf type=\"diffuse\" id=\"d\"><rgb name=\"reflectance\" value=\"0.5, 0.x, 0.5\"/></bsdf>"
        ),
    );
    fails(&s, &["number.xml:7:", "\"0.x\" is not a number"]);
    // Not well-formed XML.
    let s = dir.join("broken.xml");
    std::fs::write(&s, "<scene version=\"3.0.0\">\n  <shape type=\"cube\">\n</scene>\n").unwrap();
    fails(&s, &["broken.xml:3:", "malformed XML"]);
    // An undefined parameter, a reference to a missing id, a duplicate id.
    let s = scene(
        dir,
        "param.xml",
        &format!("{LIGHT}\n    <shape type=\"cube\"><float name=\"x\" value=\"$nope\"/></shape>"),
    );
    fails(&s, &["param.xml:7:", "undefined parameter \"$nope\""]);
    let s = scene(dir, "ref.xml", &format!("{LIGHT}\n    <shape type=\"cube\"><ref id=\"ghost\"/></shape>"));
    fails(&s, &["ref.xml:7:", "undefined id \"ghost\""]);
    let s = scene(
        dir,
        "dup.xml",
        &format!("{LIGHT}\n    <bsdf type=\"diffuse\" id=\"a\"/>\n    <bsdf type=\"diffuse\" id=\"a\"/>"),
    );
    fails(&s, &["dup.xml:8:", "duplicate id \"a\""]);
    // A mesh file that is not a mesh.
    std::fs::write(dir.join("garbage.ply"), b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n\xff\xfe")
        .unwrap();
    let s = scene(
        dir,
        "garbage.xml",
        &format!("{LIGHT}\n    <shape type=\"ply\"><string name=\"filename\" value=\"garbage.ply\"/></shape>"),
    );
    fails(&s, &["garbage.xml:7:", "garbage.ply"]);
    // A field of view out of range, and a scene with no light.
    let s = dir.join("fov.xml");
    std::fs::write(&s, format!("<scene version=\"3.0.0\">\n<sensor type=\"perspective\"><float name=\"fov\" value=\"180\"/></sensor>\n{LIGHT}\n</scene>\n")).unwrap();
    fails(&s, &["fov.xml:2:", "field of view"]);
    let s = scene(dir, "dark.xml", "    <shape type=\"cube\"/>");
    fails(&s, &["dark.xml:1:", "no emitters"]);
}

#[test]
fn missing_scene_file_is_an_error() {
    let out = pcbpt(&["render", "/nonexistent/scene.xml", "--quiet"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("/nonexistent/scene.xml") && !err.contains("panicked"), "{err}");
}

#[test]
fn render_writes_image_and_stats_and_compare_reads_them() {
    let d = tempfile::tempdir().unwrap();
    let scene = root().join("scenes/cornell-box/scene.xml");
    let exr = d.path().join("cb.exr");
    let png = d.path().join("cb.png");
    let stats = d.path().join("stats.json");
    for (out, extra) in [(&exr, vec!["--stats", stats.to_str().unwrap()]), (&png, vec![])] {
        let mut args = vec![
            "render",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-D",
            "resx=32",
            "-D",
            "resy=24",
            "--spp",
            "4",
            "--threads",
            "2",
        ];
        args.extend(extra);
        let o = pcbpt(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(out.exists());
    }
    let s: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(s["render"]["spp"], 4);
    assert_eq!(s["render"]["width"], 32);
    assert!(s["render"]["counters"]["shadow_rays"].as_u64().unwrap() > 0);
    let err_png = d.path().join("err.png");
    let o =
        pcbpt(&["compare", exr.to_str().unwrap(), exr.to_str().unwrap(), "--error-image", err_png.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && text.contains("relMSE     0.0"), "{text}");
    assert!(err_png.exists());
}

#[test]
fn version_06_scene_renders_like_version_3() {
    // The door-ajar room in Mitsuba 0.6 syntax (camelCase names, `uscale`/`vscale`, the
    // film banner) upgrades to exactly the scene of the version-3 file.
    let doc = pcbpt::scene::xml::parse_file(&root().join("scenes/veach-ajar/scene_v0.6.xml"), &[]).unwrap();
    let names: Vec<&str> = doc.nodes.iter().flat_map(|n| n.props.iter().map(|p| p.name.as_str())).collect();
    assert!(names.contains(&"to_world") && names.contains(&"sample_count") && names.contains(&"to_uv"));
    assert!(!names.iter().any(|n| n.chars().any(|c| c.is_ascii_uppercase())));
    assert_eq!(doc.params.get("max_depth").map(String::as_str), Some("13"));
    let d = tempfile::tempdir().unwrap();
    let mut images = Vec::new();
    for file in ["scene.xml", "scene_v0.6.xml"] {
        let out = d.path().join(format!("{file}.exr"));
        let scene = root().join("scenes/veach-ajar").join(file);
        let o = pcbpt(&[
            "render",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-D",
            "resx=48",
            "-D",
            "resy=27",
            "--spp",
            "4",
            "--seed",
            "9",
            "--quiet",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        images.push(pcbpt::image_io::read_exr(&out).unwrap());
    }
    assert_eq!(images[0], images[1]);
}

#[test]
fn material_parameter_errors() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let cases = [
        (
            "alpha.xml",
            r#"<bsdf type="roughconductor" id="b"><float name="alpha" value="0"/></bsdf>"#,
            "\"alpha\" must be positive",
        ),
        (
            "ior.xml",
            r#"<bsdf type="dielectric" id="b"><string name="int_ior" value="unobtainium"/></bsdf>"#,
            "unknown index of refraction",
        ),
        (
            "neg_ior.xml",
            r#"<bsdf type="dielectric" id="b"><float name="int_ior" value="-1.5"/></bsdf>"#,
            "\"int_ior\" must be positive",
        ),
        (
            "metal.xml",
            r#"<bsdf type="conductor" id="b"><string name="material" value="Xx"/></bsdf>"#,
            "unknown conductor material",
        ),
        (
            "distr.xml",
            r#"<bsdf type="roughconductor" id="b"><string name="distribution" value="phong"/></bsdf>"#,
            "unknown distribution",
        ),
        (
            "texture.xml",
            r#"<bsdf type="diffuse" id="b"><texture type="bitmap" name="reflectance"><string name="filename" value="none.png"/></texture></bsdf>"#,
            "texture file does not exist",
        ),
        (
            "radiance.xml",
            r#"<shape type="cube"><emitter type="area"><rgb name="radiance" value="-1, 0, 0"/></emitter></shape>"#,
            "\"radiance\" must be finite and non-negative",
        ),
    ];
    for (name, body, msg) in cases {
        let s = scene(dir, name, &format!("{LIGHT}\n    {body}"));
        fails(&s, &[&format!("{name}:7:"), msg]);
    }
}

#[test]
fn bdpt_writes_strategy_images_and_bidirectional_statistics() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("bdpt.exr");
    let dir = d.path().join("strategies");
    let stats = d.path().join("stats.json");
    let scene = root().join("scenes/cornell-box/scene.xml");
    let o = pcbpt(&[
        "render",
        scene.to_str().unwrap(),
        "-D",
        "resx=24",
        "-D",
        "resy=20",
        "--integrator",
        "bdpt",
        "--spp",
        "2",
        "--max-depth",
        "4",
        "--heuristic",
        "balance",
        "-o",
        out.to_str().unwrap(),
        "--strategy-images",
        dir.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Paths of up to 4 segments: 2 + 3 + 4 + 5 strategies, plus the longer-path image.
    for name in ["s0_t2", "s1_t1", "s2_t3", "s4_t1", "s0_t5", "longer_than_8"] {
        assert!(dir.join(format!("{name}.exr")).exists(), "{name}.exr missing");
    }
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let r = &json["render"];
    assert_eq!(r["integrator"], "bdpt");
    assert_eq!(r["options"]["heuristic"], "balance");
    for key in ["extension_rays", "shadow_rays", "light_paths", "connections", "connections_occluded"] {
        assert!(r["counters"][key].as_u64().unwrap() > 0, "{key} in {r}");
    }
    assert!(r["phases"]["camera_pass"].as_f64().unwrap() > 0.0);
}

#[test]
fn bidirectional_integrators_render_lights_at_infinity_and_refuse_a_scene_without_light() {
    let d = tempfile::tempdir().unwrap();
    let s = scene(d.path(), "sky.xml", r#"    <emitter type="constant"><rgb name="radiance" value="1"/></emitter>"#);
    let out = d.path().join("sky.exr");
    for integrator in ["bdpt", "lighttrace", "eorr", "lvc", "pcbpt", "pssmlt"] {
        let o = pcbpt(&["render", s.to_str().unwrap(), "--integrator", integrator, "-o", out.to_str().unwrap(), "-q"]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{integrator}: {err}");
        assert!(out.exists());
        std::fs::remove_file(&out).unwrap();
    }
    let dark = scene(d.path(), "dark.xml", "");
    let o = pcbpt(&["render", dark.to_str().unwrap(), "--integrator", "bdpt", "-o", out.to_str().unwrap(), "-q"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("dark.xml") && err.contains("no emitter"), "{err}");
    assert!(!out.exists());
}

#[test]
fn light_pool_over_the_memory_limit_is_refused_before_rendering() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("lvc.exr");
    let scene = root().join("scenes/cornell-box/scene.xml");
    let o = pcbpt(&[
        "render",
        scene.to_str().unwrap(),
        "-D",
        "resx=64",
        "-D",
        "resy=64",
        "--integrator",
        "lvc",
        "--spp",
        "2",
        "--max-pool-mb",
        "1",
        "-o",
        out.to_str().unwrap(),
        "-q",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--max-pool-mb") && err.contains("4096 paths"), "{err}");
    assert!(!err.contains("panicked") && !out.exists());
}

#[test]
fn compare_reports_one_metric_over_a_crop_or_a_mask() {
    let d = tempfile::tempdir().unwrap();
    let (r, t, m) = (d.path().join("r.exr"), d.path().join("t.exr"), d.path().join("mask.png"));
    let px = |v: f32| vec![glam::Vec3::splat(0.5); 8].into_iter().chain(vec![glam::Vec3::splat(v); 8]).collect();
    use pcbpt::image_io::{Image, write};
    // Top half equal, bottom half differs; the mask keeps the top half only.
    write(&r, &Image::new(4, 4, px(0.5))).unwrap();
    write(&t, &Image::new(4, 4, px(0.8))).unwrap();
    write(&m, &Image::new(4, 4, vec![glam::Vec3::ONE; 8].into_iter().chain(vec![glam::Vec3::ZERO; 8]).collect()))
        .unwrap();
    let value = |extra: &[&str]| {
        let mut args = vec!["compare", r.to_str().unwrap(), t.to_str().unwrap()];
        args.extend_from_slice(extra);
        let o = pcbpt(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).trim().parse::<f64>().unwrap()
    };
    assert!(value(&["--metric", "relmse"]) > 0.0);
    assert_eq!(value(&["--metric", "relmse", "--crop", "0,0,4,2"]), 0.0);
    assert_eq!(value(&["--metric", "mse", "--mask", m.to_str().unwrap()]), 0.0);
    assert!(value(&["--metric", "mse", "--crop", "0,2,4,2"]) > 0.08);
    let flip = value(&["--metric", "flip"]);
    assert!(flip > 0.0 && flip < 1.0);
    let o = pcbpt(&["compare", r.to_str().unwrap(), t.to_str().unwrap(), "--crop", "2,2,4,4"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not inside"));
}

#[test]
fn degenerate_triangles_are_counted_with_a_warning_and_the_render_goes_on() {
    let d = tempfile::tempdir().unwrap();
    // Two triangles: one proper, one with all three corners on a line.
    std::fs::write(d.path().join("tri.obj"), "v 0 0 3\nv 1 0 3\nv 0 1 3\nv 2 0 3\nf 1 2 3\nf 1 2 4\n").unwrap();
    let s = scene(
        d.path(),
        "degenerate.xml",
        &format!("{LIGHT}\n    <shape type=\"obj\"><string name=\"filename\" value=\"tri.obj\"/></shape>"),
    );
    let out = d.path().join("degenerate.exr");
    let stats = d.path().join("stats.json");
    let o = pcbpt(&[
        "render",
        s.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--spp",
        "1",
        "--stats",
        stats.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("warning:") && err.contains("1 degenerate (zero-area) triangles"), "{err}");
    assert!(out.exists());
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(json["degenerate_triangles"], 1);
}

#[test]
fn pcbpt_cache_over_the_memory_limit_is_refused_and_bad_options_are_named() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("pc.exr");
    let scene = root().join("scenes/cornell-box/scene.xml");
    let run = |extra: &[&str]| {
        let mut args = vec!["render", scene.to_str().unwrap(), "-D", "resx=64", "-D", "resy=64", "--integrator"];
        // M fixed at --pc-light-paths (no pool-vertex target), so that fewer light paths
        // make a smaller cache.
        args.extend_from_slice(&["pcbpt", "--spp", "2", "-o", out.to_str().unwrap(), "-q", "--pc-pool-vertices", "0"]);
        args.extend_from_slice(extra);
        pcbpt(&args)
    };
    let o = run(&["--pc-cache-stride", "1", "--pc-max-cache-mb", "8"]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--pc-max-cache-mb") && err.contains("20480 records"), "{err}");
    assert!(!err.contains("panicked") && !out.exists());
    // Each smaller cache the message suggests, made alone, fits the limit: the render goes
    // ahead (the raised limit it also names is the needed size rounded up).
    assert!(err.contains("raise the limit to --pc-max-cache-mb 149"), "{err}");
    let mut suggested = 0;
    for flag in ["--pc-cache-stride", "--pc-cache-depth", "--pc-light-paths"] {
        let Some(tail) = err.split(&format!("{flag} ")).nth(1) else { continue };
        let value: String = tail.chars().take_while(char::is_ascii_digit).collect();
        let mut args = vec!["--pc-cache-stride", "1", "--pc-max-cache-mb", "8"];
        match args.iter().position(|a| *a == flag) {
            Some(i) => args[i + 1] = &value,
            None => args.extend_from_slice(&[flag, &value]),
        }
        let o = run(&args);
        assert!(o.status.success(), "{flag} {value}: {}", String::from_utf8_lossy(&o.stderr));
        std::fs::remove_file(&out).unwrap();
        suggested += 1;
    }
    assert!(suggested >= 2, "{err}");
    for (flag, value) in [
        ("--pc-uniform-blend", "0"),
        ("--budget-iterations", "1"),
        ("--budget-smoothing", "65"),
        ("--pc-neighbours", "40"),
        // SPCBPT's own counts.
        ("--pc-mis", "subspace"),
        ("--pc-guiding-training", "1.5"),
    ] {
        let o = run(&[flag, value]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains(flag) && !err.contains("panicked") && !out.exists(), "{err}");
    }
}

/// Guided camera walks train with the guided path tracer, which renders no media: a scene
/// with media is refused, naming the option and the file.
#[test]
fn guided_pcbpt_refuses_a_scene_with_media() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("fog.exr");
    let scene = root().join("scenes/fog-caustic/scene.xml");
    let args = ["--integrator", "pcbpt", "--pc-guiding", "true", "--spp", "1", "-o", out.to_str().unwrap()];
    let o = pcbpt(&[&["render", scene.to_str().unwrap(), "-D", "resx=16", "-D", "resy=16"], &args[..]].concat());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--pc-guiding") && err.contains("fog-caustic"), "{err}");
    assert!(!err.contains("panicked") && !out.exists(), "{err}");
}

#[test]
fn pcbpt_reports_its_phases_cache_and_shadow_rays() {
    let d = tempfile::tempdir().unwrap();
    let (out, stats) = (d.path().join("pc.exr"), d.path().join("pc.json"));
    let scene = root().join("scenes/cornell-box/scene.xml");
    let o = pcbpt(&[
        "render",
        scene.to_str().unwrap(),
        "-D",
        "resx=64",
        "-D",
        "resy=48",
        "--integrator",
        "pcbpt",
        "--pc-cache-stride",
        "16",
        "--spp",
        "3",
        "-o",
        out.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("PCBPT cache:") && err.contains("cache "), "{err}");
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let r = &json["render"];
    let cache = &r["cache"];
    assert!(cache["records"].as_u64().unwrap() > 0 && cache["pool_vertices"].as_u64().unwrap() > 0, "{cache}");
    assert!(cache["megabytes"].as_f64().unwrap() > 0.0);
    for phase in ["light_pool", "cache", "camera_pass"] {
        assert!(r["shadow_rays"][phase].as_u64().unwrap() > 0, "no shadow rays in {phase}: {r}");
        assert!(r["phases"][phase].as_f64().unwrap() > 0.0, "no time in {phase}: {r}");
    }
    assert_eq!(r["options"]["pool"]["light_paths"].as_u64(), Some(500));
}

#[test]
fn embree_configuration_is_passed_through_and_checked() {
    let d = tempfile::tempdir().unwrap();
    let scene = root().join("scenes/cornell-box/scene.xml");
    let out = d.path().join("cb.exr");
    let run = |config: &str, env: &str| {
        Command::new(env!("CARGO_BIN_EXE_pcbpt"))
            .args(["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "-D", "resx=16", "-D", "resy=16"])
            .args(["--spp", "1", "--quiet", "--embree-config", config])
            .env("PCBPT_EMBREE_CONFIG", env)
            .output()
            .expect("runs the binary")
    };
    // Embree prints the instruction sets of its kernels with verbose=1: SSE4.2 at most.
    let o = run("max_isa=sse4.2,verbose=1", "");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let targets = text.lines().find(|l| l.trim_start().starts_with("Targets") && l.contains("(supported)"));
    let targets = targets.unwrap_or_else(|| panic!("no target line in Embree's report: {text}"));
    assert!(targets.contains("SSE4.2") && !targets.contains("AVX"), "{targets}");
    assert!(out.exists());
    for (config, env, expect) in [
        ("max_isa=avx3", "", "unknown instruction set `max_isa=avx3`"),
        ("max_isa", "", "--embree-config: `max_isa` is not a `key=value` pair"),
        ("", "threads", "PCBPT_EMBREE_CONFIG: `threads` is not a `key=value` pair"),
    ] {
        let o = run(config, env);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains(expect) && !err.contains("panicked"), "expected {expect:?} in: {err}");
    }
}

#[test]
fn chunks_render_and_merge_from_the_command_line_and_bad_parts_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path(), "s.xml", LIGHT);
    let sp = s.to_str().unwrap();
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let run = |args: &[&str]| {
        let o = pcbpt(args);
        (o.status.success(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let base = ["render", sp, "--integrator", "bdpt", "--spp", "5", "--seed", "4", "--quiet"];
    let whole = out("whole.exr");
    assert!(run(&[&base[..], &["-o", &whole]].concat()).0);
    for i in 0..2 {
        let part = out(&format!("p{i}.exr"));
        let (ok, err) = run(&[&base[..], &["--chunk", &format!("{i}/2"), "-o", &part]].concat());
        assert!(ok, "{err}");
    }
    let merged = out("merged.exr");
    let (ok, err) = run(&["merge", &out("p1.exr"), &out("p0.exr"), "-o", &merged, "--quiet"]);
    assert!(ok, "{err}");
    assert!(std::fs::read(&whole).unwrap() == std::fs::read(&merged).unwrap(), "the merge is the one-process file");
    // A missing chunk, a plain image, an empty or out-of-range chunk, a chunk with a time
    // budget: errors that say what is wrong, and no output.
    let x = out("x.exr");
    let (ok, err) = run(&["merge", &out("p0.exr"), "-o", &x]);
    assert!(!ok && err.contains("missing 2..5") && err.contains("--partial"), "{err}");
    let (ok, err) = run(&["merge", &out("p0.exr"), &whole, "-o", &x]);
    assert!(!ok && err.contains("whole.exr") && err.contains("not a partial render"), "{err}");
    let (ok, err) = run(&[&base[..], &["--chunk", "2/2", "-o", &x]].concat());
    assert!(!ok && err.contains("--chunk 2/2"), "{err}");
    let (ok, err) = run(&[&base[..], &["--chunk", "0/9", "-o", &x]].concat());
    assert!(!ok && err.contains("empty"), "{err}");
    let (ok, err) = run(&["render", sp, "--time", "1", "--chunk", "0/2", "-o", &x, "--quiet"]);
    assert!(!ok && err.contains("--time"), "{err}");
    let (ok, err) = run(&[&base[..], &["--chunk", "0/2", "-o", &out("x.png")]].concat());
    assert!(!ok && err.contains("EXR"), "{err}");
    assert!(!dir.path().join("x.exr").exists() && !dir.path().join("x.png").exists());
}

#[test]
fn a_mitsuba_05_scene_renders_unchanged_at_another_resolution() {
    // staircase2 fixes its film at 1280×720 in the XML; --resolution replaces it.
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("staircase2.exr");
    let scene = root().join("scenes/staircase2/scene.xml");
    let o =
        pcbpt(&["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "--spp", "1", "--resolution", "32x18"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let img = pcbpt::image_io::read_exr(&out).unwrap();
    assert_eq!((img.width, img.height), (32, 18));
    assert!(img.mean() > 0.0);
    // One warning names the film's Mitsuba 0.5 options it ignores.
    let ignored: Vec<&str> = err.lines().filter(|l| l.starts_with("warning: ignored")).collect();
    assert_eq!(ignored.len(), 1, "{err}");
    for name in ["high_quality_edges", "file_format", "pixel_format", "banner", "scene.xml:22:"] {
        assert!(ignored[0].contains(name), "{name}: {err}");
    }
    assert!(err.contains("32×18"), "{err}");
    // A malformed or empty resolution is a usage error naming the option.
    for bad in ["0x18", "32by18", "32x"] {
        let o =
            pcbpt(&["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "--resolution", bad, "--quiet"]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains("--resolution") && !err.contains("panicked"), "{bad}: {err}");
    }
}

#[test]
fn a_file_integrator_this_renderer_lacks_needs_one_from_the_command_line() {
    let d = tempfile::tempdir().unwrap();
    // A light and a box it lights, seen from in front; `INTEGRATOR` is replaced below.
    let text = r#"<scene version="0.5.0">
    INTEGRATOR
    <sensor type="perspective">
        <float name="fov" value="60"/>
        <transform name="toWorld"><lookAt origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="12"/></film>
    </sensor>
    <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
    <shape type="cube"><transform name="toWorld"><scale value="0.4"/><translate x="1" z="1"/></transform></shape>
</scene>
"#;
    let write = |name: &str, integrator: &str| {
        let p = d.path().join(name);
        std::fs::write(&p, text.replace("INTEGRATOR", integrator)).unwrap();
        p
    };
    let sppm = write(
        "sppm.xml",
        "<integrator type=\"sppm\">\n        <integer name=\"maxDepth\" value=\"3\"/>\n        <integer name=\"photonCount\" value=\"100000\"/>\n    </integrator>",
    );
    fails(&sppm, &["sppm.xml:2:", "unknown integrator plugin \"sppm\"", "--integrator"]);
    let render = |scene: &Path, out: &str| {
        let out = d.path().join(out);
        let o = pcbpt(&[
            "render",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--spp",
            "2",
            "--seed",
            "5",
            "--integrator",
            "bdpt",
        ]);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        (pcbpt::image_io::read_exr(&out).unwrap(), err)
    };
    let (image, err) = render(&sppm, "sppm.exr");
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning:")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    for part in
        ["sppm.xml:2:", "\"sppm\"", "--integrator bdpt", "its max_depth applies", "\"photon_count\" (", "sppm.xml:4:"]
    {
        assert!(warnings[0].contains(part), "{part:?}: {err}");
    }
    // The file's max_depth applies to the integrator picked: the image of a file that asks
    // for it plainly, and not that of another depth.
    let depth = |d: u32| format!("<integrator type=\"path\"><integer name=\"maxDepth\" value=\"{d}\"/></integrator>");
    let (same, err) = render(&write("path3.xml", &depth(3)), "path3.exr");
    assert!(!err.contains("warning:"), "{err}");
    assert_eq!(image, same);
    let (other, _) = render(&write("path1.xml", &depth(1)), "path1.exr");
    assert_ne!(image, other);
}

#[test]
fn an_option_of_another_integrator_is_an_error_naming_the_integrators_that_read_it() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("x.exr");
    let scene = root().join("scenes/cornell-box/scene.xml");
    let s = scene.to_str().unwrap();
    let o = out.to_str().unwrap();
    for (args, says) in [
        (
            vec!["--integrator", "bdpt", "--pc-connections", "8"],
            "--pc-connections is an option of pcbpt, spcbpt, not of bdpt",
        ),
        (vec!["--integrator=lvc", "--sp-uniform=0.5"], "--sp-uniform is an option of spcbpt, not of lvc"),
        (
            vec!["--integrator", "memlt", "--large-step-prob", "0.5"],
            "--large-step-prob is an option of pssmlt, not of memlt",
        ),
        // Without --integrator, the scene's integrator (the path tracer) decides.
        (vec!["--eorr-fraction", "0.2"], "--eorr-fraction is an option of eorr, not of path (the scene's integrator"),
    ] {
        let r = pcbpt(&[&["render", s, "--spp", "1", "-D", "resx=8", "-D", "resy=8", "-o", o][..], &args[..]].concat());
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says) && !err.contains("panicked") && !out.exists(), "{args:?}: {err}");
    }
    // The integrator's own options are taken, under their new and their old names.
    for args in
        [vec!["--integrator", "pcbpt", "--connections", "2"], vec!["--integrator", "pcbpt", "--pc-connections", "2"]]
    {
        let r = pcbpt(
            &[&["render", s, "--spp", "1", "-D", "resx=8", "-D", "resy=8", "--quiet", "-o", o][..], &args[..]].concat(),
        );
        assert!(r.status.success(), "{args:?}: {}", String::from_utf8_lossy(&r.stderr));
        std::fs::remove_file(&out).unwrap();
    }
}

#[test]
fn integrator_help_lists_that_integrators_options_only() {
    let help = |kind: &str| {
        let r = pcbpt(&["render", "--integrator", kind, "--help"]);
        assert!(r.status.success());
        String::from_utf8_lossy(&r.stdout).into_owned()
    };
    let bdpt = help("bdpt");
    assert!(bdpt.contains("Options of bdpt") && bdpt.contains("--heuristic") && bdpt.contains("--spp"), "{bdpt}");
    assert!(!bdpt.contains("--pc-cache-stride") && !bdpt.contains("--budget"), "{bdpt}");
    let pcbpt_help = help("pcbpt");
    assert!(pcbpt_help.contains("--pc-cache-stride") && pcbpt_help.contains("--budget-margin"), "{pcbpt_help}");
    assert!(!pcbpt_help.contains("--sp-uniform") && !pcbpt_help.contains("--lambda"), "{pcbpt_help}");
    let path = help("path");
    assert!(!path.contains("--heuristic") && path.contains("--max-depth"), "{path}");
    // Without an integrator, the help names where each one's options are listed.
    let r = pcbpt(&["render", "--help"]);
    let all = String::from_utf8_lossy(&r.stdout);
    assert!(all.contains("--integrator NAME --help") && !all.contains("--pc-cache-stride"), "{all}");
}

/// docs/cli.md is what `pcbpt cli-reference` prints from the options' own documentation:
/// this fails when an option changes and the file is not regenerated
/// (`cargo run --release -- cli-reference > docs/cli.md`).
#[test]
fn the_command_line_reference_is_current() {
    let r = pcbpt(&["cli-reference"]);
    assert!(r.status.success());
    let generated = String::from_utf8(r.stdout).unwrap();
    let file = std::fs::read_to_string(root().join("docs/cli.md")).unwrap();
    assert!(generated.contains("`--pc-cache-stride`") && generated.contains("### `--integrator memlt`"));
    assert!(
        generated == file,
        "docs/cli.md is stale: regenerate it with `cargo run --release -- cli-reference > docs/cli.md`"
    );
}

/// Where standard error is not a terminal (here a pipe, as in a Slurm log), progress comes
/// as plain lines, one per `--log-interval` at most (from the Markov chains' rounds as from the
/// render loop's passes), and none with `--quiet`; a negative interval is refused by name.
#[test]
fn progress_in_a_log_is_lines_not_a_bar() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path(), "log.xml", LIGHT);
    let out_path = dir.path().join("log.exr");
    let run = |extra: &[&str]| {
        let mut args = vec!["render", s.to_str().unwrap(), "-o", out_path.to_str().unwrap(), "--spp", "16"];
        args.extend_from_slice(extra);
        let out = pcbpt(&args);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let lines = |err: &str| err.lines().filter(|l| l.starts_with('[') && l.contains(" of 16 spp (")).count();
    let every_pass = run(&["--log-interval", "0"]);
    assert!(lines(&every_pass) >= 1, "{every_pass}");
    assert!(!every_pass.contains('\r') && !every_pass.contains('\u{1b}'), "control codes in a log: {every_pass:?}");
    assert!(every_pass.contains("8×8: 16 of 16 spp (100%)"), "{every_pass}");
    assert_eq!(lines(&run(&["--log-interval", "3600"])), 0);
    assert_eq!(run(&["--log-interval", "0", "--quiet"]), "");
    // The Markov chains' rounds too (mutations per pixel).
    let cornell = root().join("scenes/cornell-ply/cornell_mi.xml");
    for chains in ["pssmlt", "memlt"] {
        let out = pcbpt(&[
            "render",
            cornell.to_str().unwrap(),
            "-o",
            out_path.to_str().unwrap(),
            "--spp",
            "16",
            "--resolution",
            "8x8",
            "--log-interval",
            "0",
            "--integrator",
            chains,
        ]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let log = String::from_utf8_lossy(&out.stderr);
        assert!(log.contains("8×8: 16 of 16 spp (100%)"), "{chains}: {log}");
        assert!(!log.contains('\r') && !log.contains('\u{1b}'), "{chains}: control codes in a log: {log:?}");
    }
    let bad = pcbpt(&["render", s.to_str().unwrap(), "--log-interval=-1"]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("--log-interval") && err.contains("non-negative"), "{err}");
}

/// A reader that stops reading (`pcbpt compare … | head`) ends the output quietly: no
/// panic, no error, exit status 0.
#[test]
fn output_into_a_closed_pipe_ends_quietly() {
    let image = root().join("tests/data/sunlit-room.exr");
    let image = image.to_str().unwrap();
    for args in [&["cli-reference"][..], &["compare", image, image][..]] {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let o = Command::new(env!("CARGO_BIN_EXE_pcbpt")).args(args).stdout(writer).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success() && err.is_empty(), "{args:?}: {:?} {err}", o.status);
    }
}
