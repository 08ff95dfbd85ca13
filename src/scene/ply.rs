//! PLY meshes (`ply-rs-bw`): ASCII or binary files read element by element from a stream
//! (a file is never held in memory whole), each vertex and face into a fixed record.

use super::mesh::TriangleMesh;
use crate::error::{Error, Result};
use glam::{Vec2, Vec3};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Addable, BeginList, ElementDef, Encoding, Property, PropertyAccess, PropertyAccessResult};
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// Loads a PLY file (ASCII or binary of either endianness): `vertex` with `x y z`,
/// optional `nx ny nz` and `u v` (or `s t`, `texture_u texture_v`); `face` with a
/// `vertex_indices` (or `vertex_index`) list, polygons fanned into triangles.
pub fn load_ply(path: &Path) -> Result<TriangleMesh> {
    load_ply_with_progress(path, &mut |_| {})
}

/// [`load_ply`], streaming the file (it is never held in memory whole) and calling
/// `progress` with the bytes read so far, about once per MiB.
pub fn load_ply_with_progress(path: &Path, progress: &mut dyn FnMut(u64)) -> Result<TriangleMesh> {
    let file = File::open(path).map_err(|e| Error::in_file(path, format!("cannot open PLY file: {e}")))?;
    let size = file.metadata().map_err(|e| Error::in_file(path, format!("cannot open PLY file: {e}")))?.len();
    read_ply(BufReader::with_capacity(1 << 20, CountingReader { inner: file, read: 0, progress }), size, path)
}

/// Parses PLY data as if read from `path` (messages name it).
pub fn ply_from_bytes(bytes: &[u8], path: &Path) -> Result<TriangleMesh> {
    read_ply(std::io::Cursor::new(bytes), bytes.len() as u64, path)
}

/// A reader that reports the bytes it has passed on.
struct CountingReader<'a, R> {
    inner: R,
    read: u64,
    progress: &'a mut dyn FnMut(u64),
}

impl<R: Read> Read for CountingReader<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.read += n as u64;
        (self.progress)(self.read);
        Ok(n)
    }
}

/// Vertex properties read from a PLY file, in [`PlyVertex`] slot order.
const VERTEX_PROPERTIES: [&str; 14] =
    ["x", "y", "z", "nx", "ny", "nz", "u", "v", "s", "t", "texture_u", "texture_v", "texture_s", "texture_t"];

/// One PLY vertex: the numeric properties of [`VERTEX_PROPERTIES`], with a bit per slot set.
#[derive(Default)]
struct PlyVertex {
    values: [f32; 14],
    set: u16,
}

impl PropertyAccess for PlyVertex {
    fn new() -> Self {
        PlyVertex::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let slot = match name {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            "nx" => 3,
            "ny" => 4,
            "nz" => 5,
            "u" => 6,
            "v" => 7,
            "s" => 8,
            "t" => 9,
            "texture_u" => 10,
            "texture_v" => 11,
            "texture_s" => 12,
            "texture_t" => 13,
            _ => return PropertyAccessResult::Ignored,
        };
        if let Some(x) = property.to_f32_lossy() {
            self.values[slot] = x;
            self.set |= 1 << slot;
        }
        PropertyAccessResult::Set
    }
}

/// One PLY face: its `vertex_indices` list, however it is typed.
#[derive(Default)]
struct PlyFace {
    ints: Vec<i32>,
    uints: Vec<u32>,
    other: Vec<i64>,
    list: FaceList,
}

/// Which field of a [`PlyFace`] holds its list.
#[derive(Clone, Copy, Default, PartialEq)]
enum FaceList {
    #[default]
    Missing,
    Int,
    UInt,
    Other,
    NotIntegers,
}

impl PlyFace {
    fn len(&self) -> usize {
        match self.list {
            FaceList::Int => self.ints.len(),
            FaceList::UInt => self.uints.len(),
            _ => self.other.len(),
        }
    }

    fn indices(&self) -> Box<dyn Iterator<Item = i64> + '_> {
        match self.list {
            FaceList::Int => Box::new(self.ints.iter().map(|&k| k as i64)),
            FaceList::UInt => Box::new(self.uints.iter().map(|&k| k as i64)),
            _ => Box::new(self.other.iter().copied()),
        }
    }
}

/// The name [`PlyFace`] reads its list from (a `vertex_index` list is renamed to it).
const FACE_LIST: &str = "vertex_indices";

impl PropertyAccess for PlyFace {
    fn new() -> Self {
        PlyFace::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        if name != FACE_LIST {
            return PropertyAccessResult::Ignored;
        }
        let widen = |v: &mut Vec<i64>, it: &mut dyn Iterator<Item = i64>| v.extend(it);
        self.list = FaceList::Other;
        match property {
            Property::ListChar(l) => widen(&mut self.other, &mut l.iter().map(|&x| x as i64)),
            Property::ListUChar(l) => widen(&mut self.other, &mut l.iter().map(|&x| x as i64)),
            Property::ListShort(l) => widen(&mut self.other, &mut l.iter().map(|&x| x as i64)),
            Property::ListUShort(l) => widen(&mut self.other, &mut l.iter().map(|&x| x as i64)),
            Property::ListInt(l) => widen(&mut self.other, &mut l.iter().map(|&x| x as i64)),
            Property::ListUInt(l) => widen(&mut self.other, &mut l.iter().map(|&x| x as i64)),
            _ => self.list = FaceList::NotIntegers,
        }
        PropertyAccessResult::Set
    }

    fn begin_list_int(&mut self, name: &str, _len: usize) -> BeginList<'_, i32> {
        if name != FACE_LIST {
            return BeginList::UseSetter;
        }
        self.list = FaceList::Int;
        BeginList::Fill(&mut self.ints)
    }

    fn begin_list_uint(&mut self, name: &str, _len: usize) -> BeginList<'_, u32> {
        if name != FACE_LIST {
            return BeginList::UseSetter;
        }
        self.list = FaceList::UInt;
        BeginList::Fill(&mut self.uints)
    }
}

/// An element read and dropped (PLY elements other than `vertex` and `face`).
struct PlySkip;

impl PropertyAccess for PlySkip {
    fn new() -> Self {
        PlySkip
    }
}

/// Reads the elements of `def` one at a time, handing each to `each` with its index.
fn read_elements<E: PropertyAccess, R: BufRead>(
    reader: &mut Reader<R>,
    encoding: Encoding,
    def: &ElementDef,
    path: &Path,
    mut each: impl FnMut(usize, E) -> Result<()>,
) -> Result<()> {
    let parser = Parser::<E>::new();
    let mut line = String::new();
    for i in 0..def.count {
        let element = match encoding {
            Encoding::BinaryLittleEndian => parser.read_little_endian_element(reader.get_mut(), def),
            Encoding::BinaryBigEndian => parser.read_big_endian_element(reader.get_mut(), def),
            Encoding::Ascii => {
                line.clear();
                match reader.get_mut().read_line(&mut line) {
                    Ok(0) => {
                        Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "unexpected end of file").into())
                    }
                    Ok(_) => parser.read_ascii_element(&line, def),
                    Err(e) => Err(e.into()),
                }
            }
        };
        let element = element
            .map_err(|e| Error::in_file(path, format!("cannot parse PLY: {} {i} of {}: {e}", def.name, def.count)))?;
        each(i, element)?;
    }
    Ok(())
}

fn read_ply<R: BufRead>(inner: R, size: u64, path: &Path) -> Result<TriangleMesh> {
    let parse_error = |e: ply_rs_bw::parser::ParseError| Error::in_file(path, format!("cannot parse PLY: {e}"));
    let mut reader = Reader::new(inner);
    let header = Parser::<PlySkip>::new().read_header(&mut reader).map_err(parse_error)?;
    // Every element takes at least one byte, but one without properties takes none and
    // would be read `count` times from nothing: refuse counts the file cannot hold.
    if let Some(e) = header.elements.values().find(|e| e.count as u64 > size) {
        return Err(Error::in_file(
            path,
            format!("PLY element \"{}\" claims {} entries, more than the file's {size} bytes", e.name, e.count),
        ));
    }
    let vdef =
        header.elements.get("vertex").ok_or_else(|| Error::in_file(path, "PLY file has no \"vertex\" element"))?;
    let fdef = header.elements.get("face").ok_or_else(|| Error::in_file(path, "PLY file has no \"face\" element"))?;
    let has = |k: &str| vdef.properties.contains_key(k);
    let has_normals = has("nx") && has("ny") && has("nz");
    // The uv slot pair of PlyVertex, by the first property pair the file has.
    let uv_slot = [6, 8, 10, 12].into_iter().find(|&k| has(VERTEX_PROPERTIES[k]) && has(VERTEX_PROPERTIES[k + 1]));
    // Faces are read from a `vertex_indices` list, or else a `vertex_index` list renamed.
    let fdef = if fdef.properties.contains_key(FACE_LIST) {
        fdef.clone()
    } else if let Some(p) = fdef.properties.get("vertex_index") {
        let mut renamed = ElementDef::new(fdef.name.clone());
        renamed.count = fdef.count;
        for (k, q) in &fdef.properties {
            let q = if k == "vertex_index" {
                ply_rs_bw::ply::PropertyDef::new(FACE_LIST.to_string(), p.data_type.clone())
            } else {
                q.clone()
            };
            renamed.properties.add(q);
        }
        renamed
    } else if fdef.count > 0 {
        return Err(Error::in_file(path, "face 0 has no vertex_indices list"));
    } else {
        fdef.clone()
    };
    let vertex_count = vdef.count;
    let mut mesh = TriangleMesh::default();
    let (mut normals, mut uvs) = (Vec::new(), Vec::new());
    let hint = |count: usize, bytes: u64| count.min((size / bytes) as usize);
    mesh.positions.reserve_exact(hint(vertex_count, 12));
    if has_normals {
        normals.reserve_exact(hint(vertex_count, 24));
    }
    if uv_slot.is_some() {
        uvs.reserve_exact(hint(vertex_count, 20));
    }
    mesh.indices.reserve_exact(hint(fdef.count, 13));
    for def in header.elements.values() {
        match def.name.as_str() {
            "vertex" => read_elements(&mut reader, header.encoding, def, path, |i, v: PlyVertex| {
                if v.set & 0b111 != 0b111 {
                    return Err(Error::in_file(path, format!("vertex {i} lacks a numeric x, y or z")));
                }
                let x = v.values;
                mesh.positions.push(Vec3::new(x[0], x[1], x[2]));
                if has_normals {
                    normals.push(Vec3::new(x[3], x[4], x[5]).normalize_or_zero());
                }
                if let Some(k) = uv_slot {
                    uvs.push(Vec2::new(x[k], x[k + 1]));
                }
                Ok(())
            })?,
            "face" => read_elements(&mut reader, header.encoding, &fdef, path, |i, f: PlyFace| {
                match f.list {
                    FaceList::Missing => {
                        return Err(Error::in_file(path, format!("face {i} has no vertex_indices list")));
                    }
                    FaceList::NotIntegers => {
                        return Err(Error::in_file(path, format!("face {i}: vertex_indices is not an integer list")));
                    }
                    FaceList::Int | FaceList::UInt | FaceList::Other => {}
                }
                let corners = f.len();
                if corners < 3 {
                    return Err(Error::in_file(path, format!("face {i} has {corners} vertices")));
                }
                let (mut first, mut prev) = (0, 0);
                for (c, k) in f.indices().enumerate() {
                    if k < 0 || k as usize >= vertex_count {
                        return Err(Error::in_file(
                            path,
                            format!("face {i} references vertex {k} but the mesh has {vertex_count} vertices"),
                        ));
                    }
                    let k = k as u32;
                    match c {
                        0 => first = k,
                        1 => {}
                        _ => mesh.indices.push([first, prev, k]),
                    }
                    prev = k;
                }
                Ok(())
            })?,
            _ => read_elements(&mut reader, header.encoding, def, path, |_, _: PlySkip| Ok(()))?,
        }
    }
    if has_normals {
        normals.shrink_to_fit();
        mesh.normals = Some(normals);
    }
    if uv_slot.is_some() {
        uvs.shrink_to_fit();
        mesh.uvs = Some(uvs);
    }
    mesh.positions.shrink_to_fit();
    mesh.indices.shrink_to_fit();
    mesh.validate(path)?;
    Ok(mesh)
}
