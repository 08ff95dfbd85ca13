//! The `.vol` volume-grid reader: any bytes give a grid whose values fill its resolution
//! and channels (one or three) within a finite, non-empty box, or an error saying why.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcbpt::scene::vol::vol_from_bytes;

fuzz_target!(|data: &[u8]| {
    match vol_from_bytes(data) {
        Ok(vol) => {
            assert!(vol.channels == 1 || vol.channels == 3);
            assert_eq!(vol.data.len(), vol.res.iter().product::<usize>() * vol.channels);
            let (min, max) = vol.bbox;
            assert!(min.is_finite() && max.is_finite() && max.cmpgt(min).all());
        }
        Err(e) => assert!(!e.is_empty()),
    }
});
