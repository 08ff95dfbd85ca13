//! Ctrl-C (SIGINT) and SIGTERM stop a render after the pass in flight, save the image of the
//! samples done so far atomically, report it, and exit with status 130.
#![cfg(unix)]

mod common;

use common::root;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn interrupt_with(signal: &str) {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("partial.exr");
    let scene = root().join("scenes/cornell-box/scene.xml");
    let child = Command::new(env!("CARGO_BIN_EXE_pcbpt"))
        .args([
            "render",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-D",
            "resx=64",
            "-D",
            "resy=64",
            // A time budget renders passes of one sample per pixel (a few milliseconds each
            // here), so passes complete before the signal even on a loaded machine; a sample
            // budget this large would render passes of 256 spp, over 3 s each on one thread.
            "--time",
            "600",
            "--threads",
            "1",
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Let it load the scene and render a few passes, with room for a loaded machine.
    std::thread::sleep(Duration::from_millis(3000));
    let status = Command::new("kill").args([signal, &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let start = Instant::now();
    let output = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{err}");
    assert!(start.elapsed() < Duration::from_secs(30), "the render did not stop promptly");
    assert!(err.contains("interrupted") && !err.contains("panicked"), "{err}");
    let img = pcbpt::image_io::read_exr(&out).expect("the partial image is a valid EXR");
    assert_eq!((img.width, img.height), (64, 64));
    assert!(img.mean() > 0.0, "{err}");
    let names: Vec<_> = std::fs::read_dir(d.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), 1, "temporary files left behind: {names:?}");
}

#[test]
fn sigint_saves_the_partial_image() {
    interrupt_with("-INT");
}

#[test]
fn sigterm_saves_the_partial_image() {
    interrupt_with("-TERM");
}
