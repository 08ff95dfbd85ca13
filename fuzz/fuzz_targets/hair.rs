//! The `.mitshair` reader and Mitsuba 0.6's strand preparation: any bytes give strands whose
//! segments join distinct, finite vertices, or an error naming the file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcbpt::math::Transform;
use pcbpt::scene::hair::{Hair, HairParams, hair_from_bytes};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz-input.mitshair");
    let strands = match hair_from_bytes(data, path) {
        Ok(s) => s,
        Err(e) => {
            assert!(e.to_string().contains("fuzz-input.mitshair"), "{e}");
            return;
        }
    };
    assert!(strands.starts.windows(2).all(|w| w[0] < w[1]));
    assert!(strands.starts.last().is_none_or(|&s| s < strands.vertices.len()));
    for reduction in [0.0, 0.5] {
        let params = HairParams { reduction, ..HairParams::default() };
        if let Ok(hair) = Hair::build(&strands, &Transform::default(), params) {
            assert_eq!(hair.flags.len(), hair.segments.len());
            for i in 0..hair.segments.len() {
                let (a, b) = hair.segment(i);
                assert!(a.is_finite() && b.is_finite() && a != b);
            }
        }
    }
});
