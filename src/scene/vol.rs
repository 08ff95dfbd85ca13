//! Mitsuba's binary volume grids (`.vol`, version 3, as Mitsuba 0.6 and Mitsuba 3 read
//! them): the bytes `VOL` and the version 3, the encoding (`i32`, 1 = `f32`; the other
//! encodings are refused), the resolution along x, y and z and the channel count (`i32`
//! each), the data's bounding box (six `f32`: min x y z, max x y z), then the values,
//! little-endian, x fastest and channels interleaved:
//! `data[((z * yres + y) * xres + x) * channels + c]`.

use crate::error::{Error, Result};
use glam::Vec3;
use std::path::Path;

const HEADER: usize = 48;

/// A grid as a `.vol` file holds it.
#[derive(Clone, Debug, PartialEq)]
pub struct VolFile {
    /// Cells along x, y and z.
    pub res: [usize; 3],
    pub channels: usize,
    /// The data's bounding box (in the volume's own space).
    pub bbox: (Vec3, Vec3),
    /// `res[0] * res[1] * res[2] * channels` values, x fastest, channels interleaved.
    pub data: Vec<f32>,
}

/// Reads the `.vol` file at `path`.
pub fn load_vol(path: &Path) -> Result<VolFile> {
    let bytes = std::fs::read(path).map_err(|e| Error::in_file(path, format!("cannot read: {e}")))?;
    vol_from_bytes(&bytes).map_err(|msg| Error::in_file(path, msg))
}

/// Reads `.vol` data; the error says what is wrong with it.
pub fn vol_from_bytes(bytes: &[u8]) -> std::result::Result<VolFile, String> {
    if bytes.len() < HEADER {
        return Err(format!("the file ends inside the {HEADER}-byte header of a volume grid ({} bytes)", bytes.len()));
    }
    if &bytes[..3] != b"VOL" {
        return Err("not a Mitsuba volume grid (the file does not start with \"VOL\")".into());
    }
    if bytes[3] != 3 {
        return Err(format!("volume grid version {} (version 3 is read)", bytes[3]));
    }
    let int = |i: usize| i32::from_le_bytes(bytes[4 + 4 * i..8 + 4 * i].try_into().unwrap());
    let float = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let encoding = int(0);
    if encoding != 1 {
        return Err(format!("volume grid encoding {encoding} (only 1, 32-bit floats, is read)"));
    }
    let mut res = [0usize; 3];
    for (axis, r) in res.iter_mut().enumerate() {
        let n = int(1 + axis);
        if n < 1 {
            return Err(format!("volume grid resolution {n} along {} (must be at least 1)", ["x", "y", "z"][axis]));
        }
        *r = n as usize;
    }
    let channels = int(4);
    if !(1..=3).contains(&channels) || channels == 2 {
        return Err(format!("a volume grid with {channels} channels (1 or 3 are read)"));
    }
    let channels = channels as usize;
    let min = Vec3::new(float(24), float(28), float(32));
    let max = Vec3::new(float(36), float(40), float(44));
    if !(min.is_finite() && max.is_finite() && max.cmpgt(min).all()) {
        return Err(format!("volume grid bounding box {min} – {max} is empty or not finite"));
    }
    let count = res.iter().try_fold(channels, |n, &r| n.checked_mul(r));
    let body = &bytes[HEADER..];
    let expected = count.and_then(|n| n.checked_mul(4));
    if expected != Some(body.len()) {
        let cells = format!("{} × {} × {} cells of {channels} channel(s)", res[0], res[1], res[2]);
        return Err(match expected {
            Some(e) if e > body.len() => {
                format!("the file is truncated: {cells} need {e} bytes of data, it has {}", body.len())
            }
            Some(e) => format!("{} bytes past the {e} bytes of data that {cells} need", body.len() - e),
            None => format!("{cells} is more than can be addressed"),
        });
    }
    let data = body.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    Ok(VolFile { res, channels, bbox: (min, max), data })
}

/// The `.vol` bytes of a grid (the tests and the scripts that make grids write them).
pub fn vol_to_bytes(vol: &VolFile) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER + 4 * vol.data.len());
    out.extend_from_slice(b"VOL\x03");
    for n in [1, vol.res[0] as i32, vol.res[1] as i32, vol.res[2] as i32, vol.channels as i32] {
        out.extend_from_slice(&n.to_le_bytes());
    }
    for v in vol.bbox.0.to_array().into_iter().chain(vol.bbox.1.to_array()).chain(vol.data.iter().copied()) {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> VolFile {
        VolFile { res: [3, 2, 1], channels: 1, bbox: (Vec3::ZERO, Vec3::ONE), data: vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0] }
    }

    #[test]
    fn a_grid_reads_back_as_written() {
        assert_eq!(vol_from_bytes(&vol_to_bytes(&grid())).unwrap(), grid());
    }

    #[test]
    fn corrupt_grids_are_refused_with_the_reason() {
        let good = vol_to_bytes(&grid());
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..good.len() - 4].to_vec(), "truncated"),
            (good[..20].to_vec(), "header"),
            ([b"VOX".as_slice(), &good[3..]].concat(), "does not start with \"VOL\""),
            ([b"VOL\x02".as_slice(), &good[4..]].concat(), "version 2"),
            ([&good[..4], &2i32.to_le_bytes(), &good[8..]].concat(), "encoding 2"),
            ([&good[..8], &(-3i32).to_le_bytes(), &good[12..]].concat(), "resolution -3 along x"),
            ([&good[..20], &2i32.to_le_bytes(), &good[24..]].concat(), "2 channels"),
            ([good.as_slice(), &[0, 0, 0, 0]].concat(), "4 bytes past"),
            ([&good[..36], &(-1f32).to_le_bytes(), &good[40..]].concat(), "bounding box"),
        ];
        for (bytes, wanted) in cases {
            let err = vol_from_bytes(&bytes).unwrap_err();
            assert!(err.contains(wanted), "{err:?} lacks {wanted:?}");
        }
    }

    #[test]
    fn huge_resolutions_do_not_allocate() {
        let mut bytes = vol_to_bytes(&grid());
        for axis in 0..3 {
            bytes[8 + 4 * axis..12 + 4 * axis].copy_from_slice(&i32::MAX.to_le_bytes());
        }
        assert!(vol_from_bytes(&bytes).unwrap_err().contains("cells"));
    }
}
