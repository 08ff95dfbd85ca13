//! Triangle meshes: loading OBJ (`tobj`) files (PLY files in [`super::ply`]), and the
//! tessellated forms of Mitsuba's `rectangle`, `cube` and `disk` shapes.

use crate::error::{Error, Result};
use crate::math::Transform;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::path::Path;

pub use super::ply::{load_ply, load_ply_with_progress, ply_from_bytes};

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

    /// Smooth vertex normals for a mesh that has none, as Mitsuba (0.6 and 3) computes them
    /// for a mesh loaded without normals: at each vertex, the sum of the unit normals of the
    /// triangles around it, each weighted by the triangle's angle at the vertex (Thürmer
    /// and Wüthrich 1998), normalised. A vertex of degenerate triangles only (which no ray
    /// hits) gets `+z`.
    pub fn compute_vertex_normals(&mut self) {
        let mut sums = vec![Vec3::ZERO; self.positions.len()];
        for t in &self.indices {
            let p = t.map(|k| self.positions[k as usize]);
            let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            if n == Vec3::ZERO {
                continue;
            }
            for i in 0..3 {
                let d0 = (p[(i + 1) % 3] - p[i]).normalize_or_zero();
                let d1 = (p[(i + 2) % 3] - p[i]).normalize_or_zero();
                let angle = d0.dot(d1).clamp(-1.0, 1.0).acos();
                if angle.is_finite() {
                    sums[t[i] as usize] += n * angle;
                }
            }
        }
        self.normals = Some(sums.into_iter().map(|s| s.try_normalize().unwrap_or(Vec3::Z)).collect());
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
    fn vertex_normals_weigh_faces_by_their_angle() {
        // A flat fan: every normal is the plane's.
        let mut flat = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(-1.0, 0.2, 0.0)],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        };
        flat.compute_vertex_normals();
        assert!(flat.normals.as_ref().unwrap().iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
        // The corner of a cube (three faces, two triangles each, shared vertices): the corner's
        // normal is the diagonal only with angle weights (face (x=0) meets the corner with
        // two triangles, 45° + 45°; the others with one of 90°) — area or plain averaging
        // would tilt it.
        let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let mut corner = TriangleMesh {
            positions: vec![p(0., 0., 0.), p(1., 0., 0.), p(0., 1., 0.), p(0., 0., 1.), p(0., 1., 1.)],
            // z = 0 face (normal -z), y = 0 face (normal -y), x = 0 face in two triangles (normal -x).
            indices: vec![[0, 2, 1], [0, 1, 3], [0, 3, 4], [0, 4, 2]],
            ..Default::default()
        };
        corner.compute_vertex_normals();
        let n0 = corner.normals.as_ref().unwrap()[0];
        assert!((n0 - Vec3::splat(-1.0).normalize()).length() < 1e-5, "{n0}");
        // A vertex of a degenerate triangle alone gets +z.
        let mut degenerate = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, 2.0 * Vec3::X],
            indices: vec![[0, 1, 2]],
            ..Default::default()
        };
        degenerate.compute_vertex_normals();
        assert_eq!(degenerate.normals.unwrap(), vec![Vec3::Z; 3]);
    }

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
