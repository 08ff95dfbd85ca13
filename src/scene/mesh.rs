//! Triangle meshes: loading OBJ (`tobj`) and PLY (`ply-rs-bw`) files, and the tessellated
//! forms of Mitsuba's `rectangle`, `cube` and `disk` shapes.

use crate::error::{Error, Result};
use crate::math::Transform;
use glam::{Vec2, Vec3};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Addable, BeginList, ElementDef, Encoding, Property, PropertyAccess, PropertyAccessResult};
use std::f32::consts::PI;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// A triangle mesh in world space.
#[derive(Clone, Debug, Default)]
pub struct TriangleMesh {
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (absent with `face_normals`).
    pub normals: Option<Vec<Vec3>>,
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<[u32; 3]>,
}

impl TriangleMesh {
    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        self.indices[i].map(|k| self.positions[k as usize])
    }

    /// Unit geometric normal of triangle `i` (`(p1 - p0) × (p2 - p0)`; zero when degenerate).
    pub fn triangle_normal(&self, i: usize) -> Vec3 {
        let [a, b, c] = self.triangle(i);
        (b - a).cross(c - a).normalize_or_zero()
    }

    pub fn triangle_area(&self, i: usize) -> f32 {
        let [a, b, c] = self.triangle(i);
        0.5 * (b - a).cross(c - a).length()
    }

    /// Applies `to_world` to positions and normals.
    pub fn transform(&mut self, t: &Transform) {
        for p in &mut self.positions {
            *p = t.point(*p);
        }
        if let Some(ns) = &mut self.normals {
            for n in ns {
                *n = t.normal(*n).normalize_or_zero();
            }
        }
    }

    /// Reverses the winding of every triangle (flips geometric normals).
    pub fn reverse_winding(&mut self) {
        for t in &mut self.indices {
            t.swap(1, 2);
        }
    }

    /// Number of triangles with zero area or non-finite vertices.
    pub fn degenerate_count(&self) -> usize {
        (0..self.indices.len())
            .filter(|&i| {
                let a = self.triangle_area(i);
                a.is_nan() || a <= 0.0
            })
            .count()
    }

    /// The first vertex that is not finite or lies beyond ±[`MAX_COORDINATE`].
    pub fn position_out_of_range(&self) -> Option<usize> {
        self.positions.iter().position(|p| !(p.is_finite() && p.abs().max_element() <= MAX_COORDINATE))
    }

    /// Checks what every loaded mesh guarantees: triangles, indices in range, finite
    /// positions, one normal and one uv per vertex where present (errors name `file`).
    pub fn validate(&self, file: &Path) -> Result<()> {
        if self.indices.is_empty() {
            return Err(Error::in_file(file, "the mesh has no triangles"));
        }
        let n = self.positions.len();
        if let Some((i, t)) = self.indices.iter().enumerate().find(|(_, t)| t.iter().any(|&k| k as usize >= n)) {
            return Err(Error::in_file(
                file,
                format!(
                    "face {i} references vertex {} but the mesh has {n} vertices",
                    t.iter().max().copied().unwrap_or(0)
                ),
            ));
        }
        if let Some(i) = self.position_out_of_range() {
            return Err(Error::in_file(file, out_of_range_message(i, self.positions[i])));
        }
        if let Some(ns) = &self.normals
            && ns.len() != n
        {
            return Err(Error::in_file(file, format!("{} normals for {n} vertices", ns.len())));
        }
        if let Some(uv) = &self.uvs
            && uv.len() != n
        {
            return Err(Error::in_file(file, format!("{} texture coordinates for {n} vertices", uv.len())));
        }
        Ok(())
    }
}

/// The largest vertex coordinate accepted: edge vectors and their cross products (the
/// triangle areas light sampling needs) stay finite in single precision below it.
pub const MAX_COORDINATE: f32 = 1e16;

/// The error message for a vertex rejected by [`TriangleMesh::position_out_of_range`].
pub fn out_of_range_message(i: usize, p: Vec3) -> String {
    if p.is_finite() {
        format!("vertex {i} at {p} lies beyond ±{MAX_COORDINATE:e}, the range of single-precision geometry")
    } else {
        format!("vertex {i} is not finite ({p})")
    }
}

/// Loads a Wavefront OBJ file (all its objects merged into one mesh).
pub fn load_obj(path: &Path) -> Result<TriangleMesh> {
    let bytes = std::fs::read(path).map_err(|e| Error::in_file(path, format!("cannot load OBJ: {e}")))?;
    obj_from_bytes(&bytes, path)
}

/// Parses OBJ text as if read from `path` (messages name it). Material libraries are
/// not read: materials come from the scene file.
pub fn obj_from_bytes(bytes: &[u8], path: &Path) -> Result<TriangleMesh> {
    let opts = tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true };
    let (models, _materials) =
        tobj::load_obj_buf(&mut std::io::Cursor::new(bytes), &opts, |_| Err(tobj::LoadError::OpenFileFailed))
            .map_err(|e| Error::in_file(path, format!("cannot load OBJ: {e}")))?;
    let mut mesh = TriangleMesh::default();
    let all_normals = models.iter().all(|m| !m.mesh.normals.is_empty());
    let all_uvs = models.iter().all(|m| !m.mesh.texcoords.is_empty());
    let (mut normals, mut uvs) = (Vec::new(), Vec::new());
    for m in &models {
        let base = mesh.positions.len() as u32;
        let mm = &m.mesh;
        mesh.positions.extend(mm.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])));
        if all_normals {
            normals.extend(mm.normals.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2]).normalize_or_zero()));
        }
        if all_uvs {
            uvs.extend(mm.texcoords.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])));
        }
        if mm.indices.len() % 3 != 0 {
            return Err(Error::in_file(path, format!("object \"{}\" has an incomplete triangle", m.name)));
        }
        mesh.indices.extend(mm.indices.chunks_exact(3).map(|c| [base + c[0], base + c[1], base + c[2]]));
    }
    if all_normals && !normals.is_empty() {
        mesh.normals = Some(normals);
    }
    if all_uvs && !uvs.is_empty() {
        mesh.uvs = Some(uvs);
    }
    mesh.validate(path)?;
    Ok(mesh)
}

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

/// Mitsuba's `rectangle`: `[-1,1]²` in the z = 0 plane, normal +z, uv `[0,1]²`.
pub fn rectangle() -> TriangleMesh {
    TriangleMesh {
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        normals: Some(vec![Vec3::Z; 4]),
        uvs: Some(vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)]),
        indices: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// Mitsuba's `cube`: `[-1,1]³`, outward normals, 24 vertices (flat faces).
pub fn cube() -> TriangleMesh {
    let mut m = TriangleMesh { normals: Some(Vec::new()), uvs: Some(Vec::new()), ..Default::default() };
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            let (u, v) = {
                let mut u = Vec3::ZERO;
                let mut v = Vec3::ZERO;
                u[(axis + 1) % 3] = 1.0;
                v[(axis + 2) % 3] = 1.0;
                (u, v)
            };
            let base = m.positions.len() as u32;
            for (a, b) in [(-1.0f32, -1.0f32), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                m.positions.push(n + u * a + v * b);
                if let Some(x) = m.normals.as_mut() {
                    x.push(n)
                }
                if let Some(x) = m.uvs.as_mut() {
                    x.push(Vec2::new((a + 1.0) * 0.5, (b + 1.0) * 0.5))
                }
            }
            // u × v = n for sign +1; reverse the winding for the negative face.
            if sign > 0.0 {
                m.indices.extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
            } else {
                m.indices.extend([[base, base + 2, base + 1], [base, base + 3, base + 2]]);
            }
        }
    }
    m
}

/// Mitsuba's `disk`: the unit disk in z = 0, normal +z, as a fan of `segments` triangles
/// (the relative area error is `1 - sin(2π/n) n / 2π`, 1e-4 for 256 segments).
pub fn disk(segments: u32) -> TriangleMesh {
    let mut m = TriangleMesh {
        positions: vec![Vec3::ZERO],
        normals: Some(vec![Vec3::Z]),
        uvs: Some(vec![Vec2::new(0.5, 0.5)]),
        indices: Vec::new(),
    };
    for i in 0..segments {
        let phi = 2.0 * PI * i as f32 / segments as f32;
        let p = Vec3::new(phi.cos(), phi.sin(), 0.0);
        m.positions.push(p);
        if let Some(x) = m.normals.as_mut() {
            x.push(Vec3::Z)
        }
        if let Some(x) = m.uvs.as_mut() {
            x.push(Vec2::new(0.5 + 0.5 * p.x, 0.5 + 0.5 * p.y))
        }
        let a = 1 + i;
        let b = 1 + (i + 1) % segments;
        m.indices.push([0, a, b]);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cube_normals_point_outwards() {
        let c = cube();
        for i in 0..c.indices.len() {
            let [a, b, d] = c.triangle(i);
            let ng = (b - a).cross(d - a).normalize();
            let centre = (a + b + d) / 3.0;
            assert!(ng.dot(centre) > 0.0, "triangle {i}");
            assert!((c.triangle_area(i) - 2.0).abs() < 1e-5);
        }
    }

    /// A binary PLY: a quad as one `vertex_index` face of uints, after an element the
    /// reader skips, with `s t` texture coordinates.
    fn quad_ply() -> Vec<u8> {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement tag 2\nproperty list uchar float values\n\
            element vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float s\n\
            property float t\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n"
            .to_vec();
        for n in [1u8, 2] {
            b.push(n);
            (0..n).for_each(|_| b.extend(9.5f32.to_le_bytes()));
        }
        for (x, y) in [(0.0f32, 0.0f32), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            for v in [x, y, 0.0, x * 0.5, y] {
                b.extend(v.to_le_bytes());
            }
        }
        b.push(4);
        (0..4u32).for_each(|k| b.extend(k.to_le_bytes()));
        b
    }

    #[test]
    fn binary_ply_polygons_are_fanned_and_streamed_like_bytes() {
        let bytes = quad_ply();
        let m = ply_from_bytes(&bytes, Path::new("quad.ply")).unwrap();
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.uvs.as_ref().unwrap()[2], Vec2::new(0.5, 1.0));
        assert!(m.normals.is_none());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("quad.ply");
        std::fs::write(&path, &bytes).unwrap();
        let mut last = 0;
        let streamed = load_ply_with_progress(&path, &mut |n| last = n).unwrap();
        assert_eq!(last, bytes.len() as u64);
        assert_eq!((streamed.positions, streamed.indices, streamed.uvs), (m.positions, m.indices, m.uvs));
    }

    #[test]
    fn bad_ply_faces_are_named() {
        let mut bytes = quad_ply();
        let n = bytes.len();
        bytes[n - 4..].copy_from_slice(&7u32.to_le_bytes());
        let e = ply_from_bytes(&bytes, Path::new("quad.ply")).unwrap_err().to_string();
        assert!(e.contains("quad.ply") && e.contains("face 0 references vertex 7"), "{e}");
        let e = ply_from_bytes(&bytes[..n - 2], Path::new("quad.ply")).unwrap_err().to_string();
        assert!(e.contains("quad.ply") && e.contains("face 0 of 1"), "{e}");
    }

    #[test]
    fn rectangle_and_disk_face_plus_z() {
        for m in [rectangle(), disk(64)] {
            for i in 0..m.indices.len() {
                let [a, b, d] = m.triangle(i);
                assert!((b - a).cross(d - a).z > 0.0);
            }
        }
        let area: f32 = (0..256).map(|i| disk(256).triangle_area(i)).sum();
        assert!((area / PI - 1.0).abs() < 2e-4);
    }
}
