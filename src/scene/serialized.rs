//! Mitsuba's `.serialized` meshes (versions 3 and 4 of the format, as Mitsuba 0.5/0.6 wrote
//! them and Mitsuba 3 reads them): one or more shapes, each a little-endian header (format
//! `0x041C`, version) followed by a zlib stream holding the flags, the shape's name (version
//! 4), the vertex and triangle counts, the positions, the optional normals, texture
//! coordinates and colours in single or double precision, and the triangles' `u32`
//! indices; the file ends with the offset of every shape (`u64`, `u32` in version 3) and
//! their count (`u32`). `shape_index` picks a shape. Colours are read past; face normals
//! (flag `0x0010`) drop the vertex normals.

use crate::error::{Error, Result};
use crate::scene::mesh::TriangleMesh;
use flate2::read::ZlibDecoder;
use glam::{Vec2, Vec3};
use std::io::Read;
use std::path::Path;

const FORMAT: u16 = 0x041C;
const HAS_NORMALS: u32 = 0x0001;
const HAS_TEXCOORDS: u32 = 0x0002;
const HAS_COLORS: u32 = 0x0008;
const FACE_NORMALS: u32 = 0x0010;
const DOUBLE_PRECISION: u32 = 0x2000;

/// The largest expansion of DEFLATE: what a shape's counts may promise from the compressed
/// bytes that follow its header (a corrupt count must not allocate beyond what the file can
/// hold).
const MAX_EXPANSION: u64 = 1032;

/// Loads shape `shape_index` of the `.serialized` file at `path`.
pub fn load_serialized(path: &Path, shape_index: u32) -> Result<TriangleMesh> {
    let bytes = std::fs::read(path).map_err(|e| Error::in_file(path, format!("cannot read: {e}")))?;
    serialized_from_bytes(&bytes, shape_index, path)
}

/// Reads shape `shape_index` of `.serialized` data as if read from `path` (errors name it).
pub fn serialized_from_bytes(bytes: &[u8], shape_index: u32, path: &Path) -> Result<TriangleMesh> {
    let fail = |msg: String| Error::in_file(path, msg);
    let version = header(bytes, 0).map_err(fail)?;
    let offset = if shape_index == 0 { 0 } else { shape_offset(bytes, version, shape_index).map_err(fail)? };
    if offset != 0 && header(bytes, offset).map_err(fail)? != version {
        return Err(fail(format!("shape {shape_index} has another version than the file's first")));
    }
    let compressed = &bytes[offset + 4..];
    let mesh = read_shape(compressed, version).map_err(|e| fail(format!("shape {shape_index}: {e}")))?;
    mesh.validate(path)?;
    Ok(mesh)
}

/// The format version of the header at `at`.
fn header(bytes: &[u8], at: usize) -> std::result::Result<u16, String> {
    let h = bytes.get(at..at + 4).ok_or("the file ends inside a shape's header")?;
    let (format, version) = (u16::from_le_bytes([h[0], h[1]]), u16::from_le_bytes([h[2], h[3]]));
    if format != FORMAT {
        return Err(format!("not a Mitsuba serialized mesh (format 0x{format:04x} where 0x041c was expected)"));
    }
    if version != 3 && version != 4 {
        return Err(format!("serialized mesh version {version} (versions 3 and 4 are read)"));
    }
    Ok(version)
}

/// Where shape `index` starts, from the dictionary at the end of the file.
fn shape_offset(bytes: &[u8], version: u16, index: u32) -> std::result::Result<usize, String> {
    let n = bytes.len();
    let word = |at: usize, len: usize| -> std::result::Result<u64, String> {
        let b = bytes.get(at..at + len).ok_or("the file is too short for its dictionary of shapes")?;
        Ok(b.iter().rev().fold(0u64, |v, &x| (v << 8) | x as u64))
    };
    let count = word(n.checked_sub(4).ok_or("the file has no dictionary of shapes")?, 4)?;
    if index as u64 >= count {
        return Err(format!(
            "shape_index {index} is past the file's {count} shape{}",
            if count == 1 { "" } else { "s" }
        ));
    }
    let size = if version == 4 { 8 } else { 4 };
    let at = (count - index as u64) as usize * size + 4;
    let offset = word(n.checked_sub(at).ok_or("the file is too short for its dictionary of shapes")?, size)?;
    if offset >= n as u64 {
        return Err(format!("shape {index} starts at byte {offset}, past the end of the file"));
    }
    Ok(offset as usize)
}

/// Little-endian reads from the shape's decompressed stream.
struct Stream<'a> {
    inner: ZlibDecoder<&'a [u8]>,
}

impl Stream<'_> {
    fn bytes<const N: usize>(&mut self) -> std::result::Result<[u8; N], String> {
        let mut b = [0u8; N];
        self.inner.read_exact(&mut b).map_err(truncated)?;
        Ok(b)
    }

    fn u32(&mut self) -> std::result::Result<u32, String> {
        self.bytes::<4>().map(u32::from_le_bytes)
    }

    fn u64(&mut self) -> std::result::Result<u64, String> {
        self.bytes::<8>().map(u64::from_le_bytes)
    }

    /// `count` numbers in single or double precision.
    fn reals(&mut self, count: usize, double: bool) -> std::result::Result<Vec<f32>, String> {
        let width = if double { 8 } else { 4 };
        let mut raw = vec![0u8; count * width];
        self.inner.read_exact(&mut raw).map_err(truncated)?;
        Ok(if double {
            raw.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32).collect()
        } else {
            raw.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()
        })
    }
}

fn truncated(e: std::io::Error) -> String {
    match e.kind() {
        std::io::ErrorKind::UnexpectedEof => "the compressed data ends before the shape does".into(),
        _ => format!("corrupt compressed data ({e})"),
    }
}

/// The shape in the zlib stream `compressed` of format `version`.
fn read_shape(compressed: &[u8], version: u16) -> std::result::Result<TriangleMesh, String> {
    let mut s = Stream { inner: ZlibDecoder::new(compressed) };
    let flags = s.u32()?;
    if version == 4 {
        // The shape's name, NUL-terminated.
        let mut len = 0usize;
        while s.bytes::<1>()?[0] != 0 {
            len += 1;
            if len > 1 << 16 {
                return Err("the shape's name runs past 65536 bytes".into());
            }
        }
    }
    let (vertices, triangles) = (s.u64()?, s.u64()?);
    let double = flags & DOUBLE_PRECISION != 0;
    let real = if double { 8 } else { 4 };
    let per_vertex = real
        * (3 + 3 * u64::from(flags & HAS_NORMALS != 0)
            + 2 * u64::from(flags & HAS_TEXCOORDS != 0)
            + 3 * u64::from(flags & HAS_COLORS != 0));
    let promised = vertices.saturating_mul(per_vertex).saturating_add(triangles.saturating_mul(12));
    if vertices > u32::MAX as u64 || promised > MAX_EXPANSION.saturating_mul(compressed.len() as u64) + 1024 {
        return Err(format!(
            "{vertices} vertices and {triangles} triangles are more than its {} compressed bytes can hold",
            compressed.len()
        ));
    }
    let (nv, nt) = (vertices as usize, triangles as usize);
    let vec3 = |v: Vec<f32>| -> Vec<Vec3> { v.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect() };
    let positions = vec3(s.reals(3 * nv, double)?);
    let normals = if flags & HAS_NORMALS != 0 { Some(vec3(s.reals(3 * nv, double)?)) } else { None };
    let uvs = if flags & HAS_TEXCOORDS != 0 {
        Some(s.reals(2 * nv, double)?.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])).collect())
    } else {
        None
    };
    if flags & HAS_COLORS != 0 {
        s.reals(3 * nv, double)?;
    }
    let mut raw = vec![0u8; 12 * nt];
    s.inner.read_exact(&mut raw).map_err(truncated)?;
    let indices = raw
        .chunks_exact(12)
        .map(|t| [0, 4, 8].map(|k| u32::from_le_bytes(t[k..k + 4].try_into().expect("4 bytes"))))
        .collect();
    let normals = normals
        .filter(|_| flags & FACE_NORMALS == 0)
        .map(|ns: Vec<Vec3>| ns.into_iter().map(|n| n.normalize_or_zero()).collect());
    Ok(TriangleMesh { positions, normals, uvs, indices })
}

/// Writes `meshes` as a version-4 `.serialized` file (single precision, positions, and the
/// normals and texture coordinates each mesh has): the format's other half, for tests and
/// tools.
pub fn write_serialized(meshes: &[&TriangleMesh]) -> Vec<u8> {
    use flate2::Compression;
    use flate2::write::ZlibEncoder;
    use std::io::Write;
    let mut out = Vec::new();
    let mut offsets = Vec::new();
    for m in meshes {
        offsets.push(out.len() as u64);
        out.extend_from_slice(&FORMAT.to_le_bytes());
        out.extend_from_slice(&4u16.to_le_bytes());
        let flags = 0x1000
            | if m.normals.is_some() { HAS_NORMALS } else { 0 }
            | if m.uvs.is_some() { HAS_TEXCOORDS } else { 0 };
        let mut z = ZlibEncoder::new(Vec::new(), Compression::default());
        let mut put = |b: &[u8]| z.write_all(b).expect("writing to memory");
        put(&flags.to_le_bytes());
        put(b"mesh\0");
        put(&(m.positions.len() as u64).to_le_bytes());
        put(&(m.indices.len() as u64).to_le_bytes());
        let mut floats = |v: &[f32]| v.iter().for_each(|x| put(&x.to_le_bytes()));
        floats(&m.positions.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>());
        if let Some(ns) = &m.normals {
            floats(&ns.iter().flat_map(|n| n.to_array()).collect::<Vec<_>>());
        }
        if let Some(uv) = &m.uvs {
            floats(&uv.iter().flat_map(|t| t.to_array()).collect::<Vec<_>>());
        }
        for t in &m.indices {
            t.iter().for_each(|k| put(&k.to_le_bytes()));
        }
        out.extend(z.finish().expect("writing to memory"));
    }
    for o in &offsets {
        out.extend_from_slice(&o.to_le_bytes());
    }
    out.extend_from_slice(&(meshes.len() as u32).to_le_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::mesh;

    fn path() -> &'static Path {
        Path::new("test.serialized")
    }

    #[test]
    fn meshes_written_are_read_back_by_index() {
        let (quad, cube) = (mesh::rectangle(), mesh::cube());
        let bytes = write_serialized(&[&quad, &cube]);
        for (i, want) in [(0, &quad), (1, &cube)] {
            let got = serialized_from_bytes(&bytes, i, path()).unwrap();
            assert_eq!((&got.positions, &got.indices, &got.uvs), (&want.positions, &want.indices, &want.uvs));
            assert_eq!(got.normals.is_some(), want.normals.is_some());
        }
        let e = serialized_from_bytes(&bytes, 2, path()).unwrap_err().to_string();
        assert!(e.contains("test.serialized") && e.contains("shape_index 2 is past the file's 2 shapes"), "{e}");
    }

    #[test]
    fn double_precision_face_normals_and_colours_as_mitsuba_writes_them() {
        use flate2::Compression;
        use flate2::write::ZlibEncoder;
        use std::io::Write;
        // Version 3 (no name), double precision, normals and colours, face normals on.
        let flags: u32 = DOUBLE_PRECISION | HAS_NORMALS | HAS_COLORS | FACE_NORMALS;
        let mut z = ZlibEncoder::new(Vec::new(), Compression::default());
        z.write_all(&flags.to_le_bytes()).unwrap();
        z.write_all(&3u64.to_le_bytes()).unwrap();
        z.write_all(&1u64.to_le_bytes()).unwrap();
        for v in [0.0f64, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
            z.write_all(&v.to_le_bytes()).unwrap();
        }
        for _ in 0..6 {
            for v in [0.0f64, 0.0, 1.0] {
                z.write_all(&v.to_le_bytes()).unwrap();
            }
        }
        for k in [0u32, 1, 2] {
            z.write_all(&k.to_le_bytes()).unwrap();
        }
        let mut bytes = vec![0x1C, 0x04, 3, 0];
        bytes.extend(z.finish().unwrap());
        bytes.extend_from_slice(&0u32.to_le_bytes());
        bytes.extend_from_slice(&1u32.to_le_bytes());
        let m = serialized_from_bytes(&bytes, 0, path()).unwrap();
        assert_eq!(m.positions, vec![Vec3::ZERO, Vec3::X, Vec3::Y]);
        assert_eq!(m.indices, vec![[0, 1, 2]]);
        assert!(m.normals.is_none(), "face normals drop the vertex normals");
    }

    #[test]
    fn bad_files_are_errors_naming_the_file() {
        let quad = mesh::rectangle();
        let good = write_serialized(&[&quad]);
        let mut wrong_format = good.clone();
        wrong_format[0] = 0;
        let mut wrong_version = good.clone();
        wrong_version[2] = 9;
        // The zlib header's check bits.
        let mut corrupt = good.clone();
        corrupt[5] ^= 0xff;
        let bad_index = write_serialized(&[&mesh::TriangleMesh { indices: vec![[0, 1, 7]], ..quad.clone() }]);
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..2].to_vec(), "ends inside a shape's header"),
            (wrong_format, "not a Mitsuba serialized mesh"),
            (wrong_version, "version 9"),
            (good[..good.len() / 2].to_vec(), "shape 0:"),
            (corrupt, "shape 0:"),
            (bad_index, "references vertex 7"),
        ];
        for (bytes, want) in cases {
            let e = serialized_from_bytes(&bytes, 0, path()).unwrap_err().to_string();
            assert!(e.contains("test.serialized") && e.contains(want), "{want}: {e}");
        }
        // A count the compressed bytes cannot hold is refused before anything is allocated.
        use flate2::write::ZlibEncoder;
        use std::io::Write;
        let mut z = ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&0x1000u32.to_le_bytes()).unwrap();
        z.write_all(b"\0").unwrap();
        z.write_all(&(1u64 << 31).to_le_bytes()).unwrap();
        z.write_all(&1u64.to_le_bytes()).unwrap();
        let mut huge = vec![0x1C, 0x04, 4, 0];
        huge.extend(z.finish().unwrap());
        huge.extend_from_slice(&0u64.to_le_bytes());
        huge.extend_from_slice(&1u32.to_le_bytes());
        let e = serialized_from_bytes(&huge, 0, path()).unwrap_err().to_string();
        assert!(e.contains("more than its"), "{e}");
    }
}
