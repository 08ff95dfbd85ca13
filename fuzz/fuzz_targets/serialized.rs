//! The `.serialized` mesh reader: any bytes, as shape 0 or 1, give a valid triangle mesh or
//! an error naming the file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcbpt::scene::serialized::serialized_from_bytes;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz-input.serialized");
    for index in [0, 1] {
        match serialized_from_bytes(data, index, path) {
            Ok(mesh) => {
                mesh.validate(path).unwrap();
                let area: f32 = (0..mesh.indices.len()).map(|i| mesh.triangle_area(i)).sum();
                assert!(mesh.degenerate_count() <= mesh.indices.len() && !area.is_nan());
            }
            Err(e) => assert!(e.to_string().contains("fuzz-input.serialized"), "{e}"),
        }
    }
});
