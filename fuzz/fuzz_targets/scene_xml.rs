//! Mitsuba XML scene loading, end to end: parsing, `$default` substitution, `<include>`,
//! plugin instantiation with the meshes and textures of `scenes/`, and the accelerator.
//! Any input must give a scene or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcbpt::scene::{LoadOptions, Scene};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    // Relative file names resolve against `scenes/`, so the seeds reach real meshes.
    let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/fuzz-input.xml"));
    if let Err(e) = Scene::load_str(text, path, &LoadOptions::default()) {
        assert!(!e.to_string().is_empty());
    }
});
