//! The fuzz targets' checks (`fuzz/fuzz_targets/`) on a stable toolchain: every seed and
//! every input a fuzzer once crashed on (`fuzz/regressions/<target>/`) loads or fails with
//! an error naming the file, never a panic. A regression input `X` has its expected error
//! (a substring, or `ok` for a successful load) in `X.expect`.

mod common;

use common::root;
use pcbpt::math::Transform;
use pcbpt::scene::hair::{Hair, HairParams, hair_from_bytes};
use pcbpt::scene::mesh::{TriangleMesh, obj_from_bytes, ply_from_bytes};
use pcbpt::scene::serialized::serialized_from_bytes;
use pcbpt::scene::vol::vol_from_bytes;
use pcbpt::scene::{LoadOptions, Scene};
use pcbpt::{Error, Result};
use std::path::{Path, PathBuf};

fn inputs(dir: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join(dir))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_none_or(|e| e != "expect"))
        .collect();
    v.sort();
    v
}

/// What the scene_xml target does: load the text as `scenes/fuzz-input.xml`.
fn scene(data: &[u8]) -> Result<()> {
    let Ok(text) = std::str::from_utf8(data) else { return Ok(()) };
    Scene::load_str(text, &root().join("scenes/fuzz-input.xml"), &LoadOptions::default()).map(|_| ())
}

/// What the obj and ply targets check of a mesh they load.
fn mesh(loaded: Result<TriangleMesh>, path: &Path) -> Result<()> {
    let mesh = loaded?;
    mesh.validate(path).unwrap();
    let area: f32 = (0..mesh.indices.len()).map(|i| mesh.triangle_area(i)).sum();
    assert!(mesh.degenerate_count() <= mesh.indices.len() && !area.is_nan(), "{}", path.display());
    Ok(())
}

/// What the hair target checks: the strands, and the segments Mitsuba 0.6's preparation
/// makes of them (with and without `reduction`), join distinct, finite vertices.
fn hair(data: &[u8], path: &Path) -> Result<()> {
    let strands = hair_from_bytes(data, path)?;
    assert!(strands.starts.windows(2).all(|w| w[0] < w[1]));
    assert!(strands.starts.last().is_none_or(|&s| s < strands.vertices.len()));
    let mut built = Err(Error::in_file(path, "not built"));
    for reduction in [0.5, 0.0] {
        let params = HairParams { reduction, ..HairParams::default() };
        built = Hair::build(&strands, &Transform::default(), params).map_err(|e| Error::in_file(path, e));
        if let Ok(h) = &built {
            assert_eq!(h.flags.len(), h.segments.len());
            assert!((0..h.segments.len()).all(|i| {
                let (a, b) = h.segment(i);
                a.is_finite() && b.is_finite() && a != b
            }));
        }
    }
    built.map(|_| ())
}

/// What the vol target checks: the values fill the resolution and channels (one or three)
/// within a finite, non-empty box.
fn vol(data: &[u8], path: &Path) -> Result<()> {
    let vol = vol_from_bytes(data).map_err(|e| Error::in_file(path, e))?;
    assert!(vol.channels == 1 || vol.channels == 3);
    assert_eq!(vol.data.len(), vol.res.iter().product::<usize>() * vol.channels);
    assert!(vol.bbox.0.is_finite() && vol.bbox.1.is_finite() && vol.bbox.1.cmpgt(vol.bbox.0).all());
    Ok(())
}

fn run(target: &str, input: &Path) -> Result<()> {
    let data = std::fs::read(input).unwrap();
    let name = Path::new(match target {
        "obj" => "fuzz-input.obj",
        "serialized" => "fuzz-input.serialized",
        "hair" => "fuzz-input.mitshair",
        "vol" => "fuzz-input.vol",
        _ => "fuzz-input.ply",
    });
    let r = match target {
        "scene_xml" => return scene(&data),
        "obj" => mesh(obj_from_bytes(&data, name), name),
        "hair" => hair(&data, name),
        "vol" => vol(&data, name),
        // Shape 1 as well, as the target reads it (through the dictionary at the end).
        "serialized" => match serialized_from_bytes(&data, 1, name) {
            Err(e) if !e.to_string().contains(name.to_str().unwrap()) => panic!("{}: {e}", input.display()),
            _ => mesh(serialized_from_bytes(&data, 0, name), name),
        },
        _ => mesh(ply_from_bytes(&data, name), name),
    };
    if let Err(e) = &r {
        assert!(e.to_string().contains(name.to_str().unwrap()), "{}: {e}", input.display());
    }
    r
}

#[test]
fn seeds_load_or_fail_cleanly() {
    for target in ["scene_xml", "obj", "ply", "serialized", "hair", "vol"] {
        let seeds = inputs(&format!("fuzz/seeds/{target}"));
        assert!(seeds.len() >= 10, "{target}: {} seeds", seeds.len());
        let loaded = seeds.iter().filter(|s| run(target, s).is_ok()).count();
        // The seeds are the project's scenes and meshes plus the bad-input catalogue:
        // the good ones must load.
        assert!(loaded >= 5, "{target}: only {loaded} of {} seeds load", seeds.len());
    }
}

#[test]
fn fuzz_regressions_give_their_errors() {
    let mut count = 0;
    for target in ["scene_xml", "obj", "ply", "serialized", "hair", "vol"] {
        // A target that never crashed has no regression folder (git keeps no empty folders).
        if !root().join("fuzz/regressions").join(target).is_dir() {
            continue;
        }
        for input in inputs(&format!("fuzz/regressions/{target}")) {
            let expect = std::fs::read_to_string(
                input.with_extension(format!("{}.expect", input.extension().and_then(|e| e.to_str()).unwrap_or(""))),
            )
            .unwrap_or_else(|_| panic!("{} has no .expect file", input.display()));
            let expect = expect.trim();
            match run(target, &input) {
                Ok(()) => assert_eq!(expect, "ok", "{} loaded", input.display()),
                Err(e) => assert!(e.to_string().contains(expect), "{}: {e}", input.display()),
            }
            count += 1;
        }
    }
    assert!(count >= 1);
}
