//! The bad-input catalogue: every `tests/bad_scenes/*.xml` must fail to render with exit
//! status 1, a message naming the scene file and line (the `:line:` in its `.expect` file)
//! and containing each `|`-separated fragment there, no panic, and no output image.

mod common;

use std::process::Command;

#[test]
fn every_bad_scene_gives_a_clear_error() {
    let dir = common::root().join("tests/bad_scenes");
    let out_dir = tempfile::tempdir().unwrap();
    let mut cases: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "xml"))
        .collect();
    cases.sort();
    assert!(cases.len() >= 30, "the catalogue has {} cases", cases.len());
    let mut failures = Vec::new();
    for scene in &cases {
        let name = scene.file_name().unwrap().to_string_lossy().into_owned();
        let expect = std::fs::read_to_string(scene.with_extension("expect"))
            .unwrap_or_else(|_| panic!("{name} has no .expect file"));
        let out = out_dir.path().join(format!("{name}.exr"));
        let o = Command::new(env!("CARGO_BIN_EXE_pcbpt"))
            .args(["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "--spp", "1", "--quiet"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        let mut problems = Vec::new();
        if o.status.code() != Some(1) {
            problems.push(format!("exit status {:?}", o.status.code()));
        }
        if err.contains("panicked") {
            problems.push("panicked".into());
        }
        if !err.contains(&format!("{name}:")) {
            problems.push("the message does not name the scene file".into());
        }
        for fragment in expect.trim().split('|') {
            let wanted = if fragment.starts_with(':') { format!("{name}{fragment}") } else { fragment.to_string() };
            if !err.contains(&wanted) {
                problems.push(format!("missing {wanted:?}"));
            }
        }
        if out.exists() {
            problems.push("an output file was written".into());
        }
        if !problems.is_empty() {
            failures.push(format!("{name}: {} — stderr: {}", problems.join(", "), err.trim()));
        }
    }
    assert!(failures.is_empty(), "{} of {} cases failed:\n{}", failures.len(), cases.len(), failures.join("\n"));
}
