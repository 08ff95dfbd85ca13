//! Benedikt Bitterli's scenes as he publishes them (Mitsuba 0.5 files, unchanged): every
//! scene found loads and renders one sample per pixel with every integrator, or stops with
//! the error that names what it lacks — a file that is not there, or a feature this
//! renderer does not have ([`LACKS`]); a scene with participating media renders with the
//! integrators that have them (all of them today), and any other refuses it. A file
//! integrator this renderer lacks
//! (`sppm`) is refused with the hint to pick one, and the scene is then loaded with the path
//! tracer picked (`volpath` is the path tracer).
//!
//! The scenes are read from `scenes/bitterli/` (the four small ones whose files are all
//! there) and, when `PCBPT_BITTERLI` names a folder holding more of the 32 scene folders (as
//! unpacked from Bitterli's site), from there as well. The test prints one line per scene,
//! the table of `docs/results/mitsuba06.md`.

mod common;

use clap::ValueEnum;
use common::*;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::{LoadOptions, Scene};
use std::path::{Path, PathBuf};

/// The 32 scenes of the collection.
const SCENES: [&str; 32] = [
    "bathroom",
    "bathroom2",
    "bedroom",
    "car",
    "car2",
    "classroom",
    "coffee",
    "cornell-box",
    "curly-hair",
    "dining-room",
    "dragon",
    "furball",
    "glass-of-water",
    "hair-curl",
    "house",
    "kitchen",
    "lamp",
    "living-room",
    "living-room-2",
    "living-room-3",
    "material-testball",
    "spaceship",
    "staircase",
    "staircase2",
    "straight-hair",
    "teapot",
    "teapot-full",
    "veach-ajar",
    "veach-bidir",
    "veach-mis",
    "volumetric-caustic",
    "water-caustic",
];

/// What this renderer lacks that a scene needs, as the error that names it says. A scene
/// whose files are all there must stop on this error and nothing else; every other scene
/// whose files are there must render. Nothing, since media and hair.
const LACKS: &[(&str, &str)] = &[];

/// The folders to read scenes from.
fn folders() -> Vec<PathBuf> {
    let mut f = vec![root().join("scenes/bitterli")];
    if let Some(dir) = std::env::var_os("PCBPT_BITTERLI") {
        f.push(PathBuf::from(dir));
    }
    f
}

/// The scenes whose only shapes beside built-in ones are `hair` shapes: each renders, or stops
/// at its `.mitshair` file, which must then be the one that is missing (the public copies of
/// the collection leave these files out: they are 4 MiB or more).
const HAIR: [&str; 4] = ["curly-hair", "furball", "hair-curl", "straight-hair"];

/// How loading a scene went.
enum Outcome {
    Rendered,
    /// The error names a file that is indeed not there.
    MissingFile(String),
    /// The error is the one [`LACKS`] expects.
    Lacks(String),
}

/// Loads `scene` at a small size (with `integrator` picked, if any).
fn load(scene: &Path, integrator: Option<IntegratorKind>) -> Result<Scene, String> {
    let options = LoadOptions {
        resolution: Some((16, 9)),
        integrator_override: integrator.map(|k| k.name().to_string()),
        ..Default::default()
    };
    Scene::load(scene, &options).map_err(|e| e.to_string())
}

/// The file an error says does not exist, if it says so (the loader's "mesh file PATH does
/// not exist" and "PATH: texture file does not exist").
fn missing_file(error: &str) -> Option<PathBuf> {
    let after_location = error.split_once(".xml:")?.1.splitn(3, ':').nth(2)?.trim_start();
    let what = after_location.strip_suffix(" does not exist")?;
    let path = match what.rsplit_once(": ") {
        Some((path, _kind)) => path,
        None => what.rsplit(' ').next()?,
    };
    Some(PathBuf::from(path))
}

/// One sample per pixel with every integrator: a finite, non-negative image. A scene with
/// participating media renders with the integrators that have them, and the others refuse
/// it naming the path tracer.
fn render_all(name: &str, scene: &Scene) {
    for kind in IntegratorKind::value_variants() {
        let mut o = RenderOptions::new(*kind, Budget::Spp(1));
        o.run.threads = 2;
        let out = integrator::render(scene, &o);
        if scene.volumetric && !o.method.renders_media() {
            let e = out.err().unwrap_or_else(|| panic!("{name} with {}: media rendered", kind.name()));
            assert!(e.to_string().contains("--integrator path"), "{name} with {}: {e}", kind.name());
            continue;
        }
        let out = out.unwrap_or_else(|e| panic!("{name} with {}: {e}", kind.name()));
        assert_eq!(out.image.len(), 16 * 9);
        assert!(
            out.image.iter().all(|p| p.is_finite() && p.min_element() >= 0.0),
            "{name} with {}: a pixel is negative or not finite",
            kind.name()
        );
    }
}

/// Loads `name` from `dir` as published, then renders it or checks why it cannot be.
fn check(dir: &Path, name: &str) -> Outcome {
    let file = dir.join(name).join("scene.xml");
    let scene = match load(&file, None) {
        Err(e) if e.contains("unknown integrator plugin") => {
            assert!(e.contains("--integrator"), "{name}: the refusal gives no hint: {e}");
            load(&file, Some(IntegratorKind::Path))
        }
        other => other,
    };
    match scene {
        Ok(scene) => {
            let lacks = LACKS.iter().find(|(n, _)| *n == name);
            assert!(lacks.is_none(), "{name} loads, but LACKS says it needs: {}", lacks.unwrap().1);
            render_all(name, &scene);
            Outcome::Rendered
        }
        Err(e) => {
            assert!(e.contains("scene.xml:"), "{name}: the error names no line of the scene: {e}");
            if let Some(path) = missing_file(&e) {
                assert!(!path.exists(), "{name}: {} exists, yet: {e}", path.display());
                if HAIR.contains(&name) {
                    assert!(
                        e.contains("hair file") && path.extension().is_some_and(|x| x == "mitshair"),
                        "{name} stops at another file than its hair: {e}"
                    );
                }
                return Outcome::MissingFile(e);
            }
            match LACKS.iter().find(|(n, _)| *n == name) {
                Some((_, needle)) if e.contains(needle) => Outcome::Lacks(e),
                _ => panic!("{name} fails to load: {e}"),
            }
        }
    }
}

#[test]
fn bitterlis_scenes_load_as_published_and_render_with_every_integrator() {
    let mut checked = 0;
    for dir in folders() {
        for name in SCENES {
            if !dir.join(name).join("scene.xml").is_file() {
                continue;
            }
            let line = match check(&dir, name) {
                Outcome::Rendered => "loads; renders with every integrator".to_string(),
                Outcome::MissingFile(e) => format!("stops at a missing file: {e}"),
                Outcome::Lacks(e) => format!("lacks a feature: {e}"),
            };
            println!("| {name} | {} | {line} |", dir.display());
            checked += 1;
        }
    }
    // The four shipped scenes at least.
    assert!(checked >= 4, "only {checked} scenes found");
}

/// The error-parsing helper finds the file in the loader's messages.
#[test]
fn missing_files_are_read_from_the_messages() {
    let mesh = "a/scene.xml:226:3: mesh file a/models/Mesh044.obj does not exist";
    assert_eq!(missing_file(mesh), Some(PathBuf::from("a/models/Mesh044.obj")));
    let texture = "a/scene.xml:34:6: a/textures/rug.png: texture file does not exist";
    assert_eq!(missing_file(texture), Some(PathBuf::from("a/textures/rug.png")));
    assert_eq!(missing_file("a/scene.xml:3:1: unknown bsdf plugin \"coating\""), None);
}
