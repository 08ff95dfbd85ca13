//! The OBJ loader: any bytes give a valid triangle mesh or an error naming the file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcbpt::scene::mesh::obj_from_bytes;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz-input.obj");
    match obj_from_bytes(data, path) {
        Ok(mesh) => {
            mesh.validate(path).unwrap();
            let area: f32 = (0..mesh.indices.len()).map(|i| mesh.triangle_area(i)).sum();
            assert!(mesh.degenerate_count() <= mesh.indices.len() && !area.is_nan());
        }
        Err(e) => assert!(e.to_string().contains("fuzz-input.obj"), "{e}"),
    }
});
