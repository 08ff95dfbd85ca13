//! Mitsuba 0.6's `hair` shape: strands of straight segments of one radius, read from a
//! `.mitshair` file, in the ASCII format (a vertex `x y z` per line; an empty line, or a
//! line starting with `#`, starts a new strand) or the binary one (the 11 bytes
//! `BINARY_HAIR`, a little-endian `u32` vertex count, then the vertices as little-endian
//! `f32` triples, where an infinite value before a vertex starts a new strand).
//!
//! [`Hair::build`] prepares strands as Mitsuba 0.6 does: in world space (`to_world`, which
//! must scale uniformly, scales the radius too), repeated vertices dropped, and a vertex
//! whose segment turns by less than `angle_threshold` degrees from the one before merged
//! into the next (the previous vertex is replaced by the new one); `reduction` drops that
//! fraction of the strands at random (seeded, so a scene loads the same every time) and
//! widens the rest by `1 / (1 - reduction)`. Mitsuba 0.6 intersects each segment as a
//! cylinder whose ends are cut by the planes bisecting the angle with its neighbours; the
//! renderer traces Embree's round linear curves instead ([`crate::accel::curve`]): the same
//! cylinders, with the joints filled by spheres rather than mitred, and round strand ends.

use crate::accel::Geometry;
use crate::accel::curve::{LEFT, RIGHT, closest_on_segment};
use crate::error::{Error, Result};
use crate::math::{Frame, Transform};
use crate::sampling::Sampler;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::path::Path;

/// The header that marks the binary format.
const BINARY_HEADER: &[u8; 11] = b"BINARY_HAIR";

/// Strands as read from a file: all vertices in order, and where each strand starts.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Strands {
    pub vertices: Vec<Vec3>,
    /// Index in `vertices` of each strand's first vertex, increasing.
    pub starts: Vec<usize>,
}

impl Strands {
    /// The vertices of each strand.
    pub fn iter(&self) -> impl Iterator<Item = &[Vec3]> {
        let ends = self.starts.iter().skip(1).copied().chain(std::iter::once(self.vertices.len()));
        self.starts.iter().zip(ends).map(|(&s, e)| &self.vertices[s..e])
    }

    fn push(&mut self, p: Vec3, new_strand: bool) {
        if new_strand || self.starts.is_empty() {
            self.starts.push(self.vertices.len());
        }
        self.vertices.push(p);
    }
}

/// Reads the `.mitshair` file at `path`.
pub fn read_hair(path: &Path) -> Result<Strands> {
    let bytes = std::fs::read(path).map_err(|e| Error::in_file(path, format!("cannot read the hair file: {e}")))?;
    hair_from_bytes(&bytes, path)
}

/// Reads `.mitshair` data as if read from `path` (errors name it, and the line in the ASCII
/// format).
pub fn hair_from_bytes(bytes: &[u8], path: &Path) -> Result<Strands> {
    match bytes.strip_prefix(BINARY_HEADER) {
        Some(rest) => read_binary(rest).map_err(|e| Error::in_file(path, e)),
        None => read_ascii(bytes, path),
    }
}

/// The strands in the ASCII format (what [`hair_from_bytes`] reads back).
pub fn hair_to_ascii(strands: &Strands) -> String {
    let mut out = String::new();
    for (i, strand) in strands.iter().enumerate() {
        if i > 0 {
            out.push('\n');
        }
        for p in strand {
            out += &format!("{} {} {}\n", p.x, p.y, p.z);
        }
    }
    out
}

/// The strands in the binary format (an infinity before each strand but the first).
pub fn hair_to_binary(strands: &Strands) -> Vec<u8> {
    let mut out = BINARY_HEADER.to_vec();
    out.extend_from_slice(&(strands.vertices.len() as u32).to_le_bytes());
    for (i, strand) in strands.iter().enumerate() {
        if i > 0 {
            out.extend_from_slice(&f32::INFINITY.to_le_bytes());
        }
        for w in strand.iter().flat_map(|p| p.to_array()) {
            out.extend_from_slice(&w.to_le_bytes());
        }
    }
    out
}

fn read_binary(bytes: &[u8]) -> std::result::Result<Strands, String> {
    let count = bytes.get(..4).ok_or("the binary hair file ends before its vertex count")?;
    let count = u32::from_le_bytes([count[0], count[1], count[2], count[3]]) as usize;
    let mut words = bytes[4..].chunks_exact(4).map(|w| f32::from_le_bytes([w[0], w[1], w[2], w[3]]));
    // Each vertex takes at least 12 bytes: a count the file cannot hold allocates nothing.
    if count > (bytes.len() - 4) / 12 {
        return Err(format!(
            "the binary hair file promises {count} vertices but holds at most {}",
            (bytes.len() - 4) / 12
        ));
    }
    let mut strands = Strands { vertices: Vec::with_capacity(count), starts: Vec::new() };
    let truncated = |read: usize| format!("the binary hair file ends after {read} of its {count} vertices");
    let mut new_strand = true;
    while strands.vertices.len() < count {
        let read = strands.vertices.len();
        let mut x = words.next().ok_or_else(|| truncated(read))?;
        if x.is_infinite() {
            new_strand = true;
            x = words.next().ok_or_else(|| truncated(read))?;
        }
        let y = words.next().ok_or_else(|| truncated(read))?;
        let z = words.next().ok_or_else(|| truncated(read))?;
        let p = Vec3::new(x, y, z);
        if !p.is_finite() {
            return Err(format!("vertex {read} of the binary hair file is not finite ({x}, {y}, {z})"));
        }
        strands.push(p, new_strand);
        new_strand = false;
    }
    Ok(strands)
}

fn read_ascii(bytes: &[u8], path: &Path) -> Result<Strands> {
    let mut strands = Strands::default();
    let mut new_strand = true;
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let at = |msg: String| {
            let mut loc = crate::error::Location::file(path);
            loc.line = Some(i as u32 + 1);
            Error::input(&loc, msg)
        };
        let line =
            std::str::from_utf8(line).map_err(|_| at("the hair file is neither ASCII nor binary hair".into()))?;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            new_strand = true;
            continue;
        }
        let numbers: Vec<f32> = line.split_whitespace().map_while(|w| w.parse().ok()).collect();
        if numbers.len() != 3 || line.split_whitespace().count() != 3 {
            let shown: String = line.chars().take(60).collect();
            return Err(at(format!("expected a hair vertex \"x y z\" (three numbers), found \"{shown}\"")));
        }
        let p = Vec3::new(numbers[0], numbers[1], numbers[2]);
        if !p.is_finite() {
            return Err(at(format!("the hair vertex {p} is not finite")));
        }
        strands.push(p, new_strand);
        new_strand = false;
    }
    Ok(strands)
}

/// The parameters of a `hair` shape, as the scene gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HairParams {
    /// Radius in object space (`radius`, default 0.025).
    pub radius: f32,
    /// Segments turning by less than this many degrees are merged (`angle_threshold`,
    /// default 1).
    pub angle_threshold: f32,
    /// The fraction of strands dropped (`reduction`, in `[0, 1)`, default 0).
    pub reduction: f32,
}

impl Default for HairParams {
    fn default() -> Self {
        HairParams { radius: 0.025, angle_threshold: 1.0, reduction: 0.0 }
    }
}

/// A render-ready hair shape: world-space vertices and the segments between them.
#[derive(Clone, Debug)]
pub struct Hair {
    pub vertices: Vec<Vec3>,
    /// The first vertex of each segment (the second is the next one).
    pub segments: Vec<u32>,
    /// Embree's curve flags of each segment ([`LEFT`], [`RIGHT`]).
    pub flags: Vec<u8>,
    /// World-space radius.
    pub radius: f32,
    /// The texture coordinate `u` (the fraction of its strand's length) at each segment's
    /// start, and its growth along the segment.
    u_range: Vec<Vec2>,
    /// The number of strands with at least one segment.
    pub strands: usize,
}

impl Hair {
    /// Prepares `strands` for rendering (see the module documentation). Errors are plain
    /// messages, for the caller to place.
    pub fn build(strands: &Strands, to_world: &Transform, params: HairParams) -> std::result::Result<Hair, String> {
        let HairParams { radius, angle_threshold, reduction } = params;
        if !(radius.is_finite() && radius > 0.0) {
            return Err(format!("the hair radius must be positive, got {radius}"));
        }
        if !(angle_threshold.is_finite() && angle_threshold >= 0.0) {
            return Err(format!("angle_threshold must be a non-negative number of degrees, got {angle_threshold}"));
        }
        if !(0.0..1.0).contains(&reduction) {
            return Err(format!("reduction must lie in [0, 1), got {reduction}"));
        }
        let axes = [Vec3::X, Vec3::Y, Vec3::Z].map(|a| to_world.vector(a).length());
        if (axes[0] - axes[1]).abs() > 1e-4 * axes[0] || (axes[0] - axes[2]).abs() > 1e-4 * axes[0] {
            return Err("a hair shape's to_world must scale uniformly".into());
        }
        let radius = radius * axes[2] / (1.0 - reduction);
        let cos_threshold = angle_threshold.to_radians().cos();
        let mut hair = Hair {
            vertices: Vec::with_capacity(strands.vertices.len()),
            segments: Vec::new(),
            flags: Vec::new(),
            radius,
            u_range: Vec::new(),
            strands: 0,
        };
        let mut keep = Sampler::new(&[0x6a17]);
        for strand in strands.iter() {
            if reduction > 0.0 && keep.next_1d() < reduction {
                continue;
            }
            let merged = merge(strand.iter().map(|p| to_world.point(*p)), cos_threshold);
            hair.add_strand(&merged);
        }
        if hair.segments.is_empty() {
            return Err("the hair file has no segments (no strand has two distinct vertices)".into());
        }
        if let Some(p) = hair.vertices.iter().find(|p| p.abs().max_element() > super::mesh::MAX_COORDINATE) {
            return Err(format!("after to_world, the hair vertex {p} lies beyond ±{:e}", super::mesh::MAX_COORDINATE));
        }
        Ok(hair)
    }

    /// Appends one strand's vertices and its segments (none for fewer than two vertices).
    fn add_strand(&mut self, strand: &[Vec3]) {
        if strand.len() < 2 {
            return;
        }
        let first = self.vertices.len() as u32;
        self.vertices.extend_from_slice(strand);
        let lengths: Vec<f32> = strand.windows(2).map(|w| (w[1] - w[0]).length()).collect();
        // Positive even where the lengths underflow.
        let total = lengths.iter().sum::<f32>().max(f32::MIN_POSITIVE);
        let mut along = 0.0;
        let last = lengths.len() - 1;
        for (i, len) in lengths.iter().enumerate() {
            self.segments.push(first + i as u32);
            self.flags.push(if i > 0 { LEFT } else { 0 } | if i < last { RIGHT } else { 0 });
            self.u_range.push(Vec2::new(along / total, len / total));
            along += len;
        }
        self.strands += 1;
    }

    /// The geometry the accelerator is built from.
    pub fn accel_geometry(&self) -> Geometry<'_> {
        Geometry::Curves { vertices: &self.vertices, segments: &self.segments, flags: &self.flags, radius: self.radius }
    }

    /// Bytes held by the vertex and segment arrays.
    pub fn memory_bytes(&self) -> usize {
        self.vertices.capacity() * size_of::<Vec3>()
            + self.segments.capacity() * size_of::<u32>()
            + self.flags.capacity()
            + self.u_range.capacity() * size_of::<Vec2>()
    }

    /// The end vertices of segment `i`.
    #[inline]
    pub fn segment(&self, i: usize) -> (Vec3, Vec3) {
        let k = self.segments[i] as usize;
        (self.vertices[k], self.vertices[k + 1])
    }

    /// The lateral area of the segments' cylinders.
    pub fn area(&self) -> f32 {
        let length: f64 = (0..self.segments.len())
            .map(|i| {
                let (a, b) = self.segment(i);
                (b - a).length() as f64
            })
            .sum();
        (2.0 * std::f64::consts::PI * self.radius as f64 * length) as f32
    }

    /// Where a hit at `p` on segment `i` lies: the point on the surface, its outward unit
    /// normal (from the closest point of the segment's axis: perpendicular to the axis on the
    /// cylinder, from the vertex on a joint's or an end's sphere), the shading frame (`s`
    /// along the strand) and the texture coordinates: `u` the fraction of the strand's
    /// length, `v` the angle around the axis over 2π.
    pub fn surface_point(&self, i: usize, p: Vec3) -> (Vec3, Vec3, Frame, Vec2) {
        let (a, b) = self.segment(i);
        let axis = (b - a).normalize_or(Vec3::X);
        let (c, s) = closest_on_segment(p, a, b);
        let around = Frame::from_normal(axis);
        let mut n = (p - c).normalize_or_zero();
        if n == Vec3::ZERO {
            n = around.s;
        }
        let tangent = (axis - n * n.dot(axis)).normalize_or(around.s);
        let frame = Frame { s: tangent, t: n.cross(tangent), n };
        let mut phi = n.dot(around.t).atan2(n.dot(around.s));
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let range = self.u_range[i];
        let uv = Vec2::new(range.x + range.y * s, phi / (2.0 * PI));
        (c + n * self.radius, n, frame, uv)
    }

    /// `(dp/du, dp/dv)` at a point with outward normal `n` on segment `i`, in the
    /// parameterisation of [`Hair::surface_point`] (a cylinder's).
    pub fn tangents(&self, i: usize, n: Vec3) -> (Vec3, Vec3) {
        let (a, b) = self.segment(i);
        let range = self.u_range[i];
        let dp_du = if range.y > 0.0 { (b - a) / range.y } else { b - a };
        let axis = (b - a).normalize_or(Vec3::X);
        (dp_du, axis.cross(n) * (2.0 * PI * self.radius))
    }
}

/// Mitsuba 0.6's preparation of one strand: repeated vertices dropped, and a vertex whose
/// segment turns by less than the threshold (`cos_threshold`, the cosine of the angle) from
/// the segment before replaced by the next vertex.
fn merge(strand: impl Iterator<Item = Vec3>, cos_threshold: f32) -> Vec<Vec3> {
    let mut out: Vec<Vec3> = Vec::new();
    let mut tangent = Vec3::ZERO;
    let mut last = Vec3::ZERO;
    for p in strand {
        if out.is_empty() {
            out.push(p);
        } else if p != last {
            let next = (p - last).normalize();
            if tangent == Vec3::ZERO {
                out.push(p);
                tangent = next;
            } else if next.dot(tangent) > cos_threshold {
                let n = out.len();
                out[n - 1] = p;
                tangent = (p - out[n - 2]).normalize();
            } else {
                out.push(p);
                tangent = next;
            }
        }
        last = p;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Mat4;

    fn strands(text: &str) -> Result<Strands> {
        hair_from_bytes(text.as_bytes(), Path::new("test.mitshair"))
    }

    fn binary(count: u32, words: &[f32]) -> Vec<u8> {
        let mut b = BINARY_HEADER.to_vec();
        b.extend_from_slice(&count.to_le_bytes());
        for w in words {
            b.extend_from_slice(&w.to_le_bytes());
        }
        b
    }

    #[test]
    fn ascii_and_binary_give_the_same_strands() {
        let text = "0 0 0\n1 0 0\n2 0.5 0\n\n# another\n5 5 5\r\n6 5 5\n";
        let a = strands(text).unwrap();
        assert_eq!(a.starts, vec![0, 3]);
        assert_eq!(a.vertices[2], Vec3::new(2.0, 0.5, 0.0));
        let inf = f32::INFINITY;
        let words = [0., 0., 0., 1., 0., 0., 2., 0.5, 0., inf, 5., 5., 5., 6., 5., 5.];
        let b = hair_from_bytes(&binary(5, &words), Path::new("b.mitshair")).unwrap();
        assert_eq!(a, b);
        assert_eq!(hair_to_binary(&a), binary(5, &words));
        assert_eq!(strands(&hair_to_ascii(&a)).unwrap(), a);
    }

    #[test]
    fn bad_files_name_the_file_and_line() {
        let e = strands("0 0 0\n1 0 0\n1 x 2\n").unwrap_err().to_string();
        assert!(e.starts_with("test.mitshair:3:") && e.contains("\"1 x 2\""), "{e}");
        let e = strands("0 0 0 4\n").unwrap_err().to_string();
        assert!(e.starts_with("test.mitshair:1:"), "{e}");
        let e = strands("0 0 0\n0 nan 1\n").unwrap_err().to_string();
        assert!(e.starts_with("test.mitshair:2:") && e.contains("not finite"), "{e}");
        let truncated = binary(3, &[0., 0., 0., 1., 0., 0., 2.]);
        let e = hair_from_bytes(&truncated, Path::new("t.mitshair")).unwrap_err().to_string();
        assert!(e.starts_with("t.mitshair:") && e.contains("promises 3 vertices"), "{e}");
        let cut = binary(3, &[0., 0., 0., f32::INFINITY, 1., 0., 0., 2., 0.]);
        let e = hair_from_bytes(&cut, Path::new("t.mitshair")).unwrap_err().to_string();
        assert!(e.contains("ends after 2 of its 3 vertices"), "{e}");
        let e = hair_from_bytes(b"BINARY_HAIR\x01", Path::new("t.mitshair")).unwrap_err().to_string();
        assert!(e.contains("before its vertex count"), "{e}");
        let e = hair_from_bytes(&binary(1, &[0., f32::NAN, 0.]), Path::new("t.mitshair")).unwrap_err().to_string();
        assert!(e.contains("vertex 0") && e.contains("not finite"), "{e}");
        let e = read_hair(Path::new("/nonexistent/h.mitshair")).unwrap_err().to_string();
        assert!(e.starts_with("/nonexistent/h.mitshair:") && e.contains("cannot read"), "{e}");
    }

    #[test]
    fn nearly_straight_vertices_merge_as_in_mitsuba() {
        // A strand bending by 0.5° at vertex 1 and 30° at vertex 2, with a repeated vertex.
        let bend = |deg: f32| Vec3::new(deg.to_radians().cos(), deg.to_radians().sin(), 0.0);
        let p1 = Vec3::X;
        let p2 = p1 + bend(0.5);
        let p3 = p2 + bend(30.5);
        let s = Strands { vertices: vec![Vec3::ZERO, p1, p1, p2, p3], starts: vec![0] };
        let h = Hair::build(&s, &Transform::default(), HairParams::default()).unwrap();
        assert_eq!(h.vertices, vec![Vec3::ZERO, p2, p3]);
        assert_eq!(h.flags, vec![RIGHT, LEFT]);
        // With a threshold of 0.25°, nothing merges (the repeated vertex still goes).
        let fine = HairParams { angle_threshold: 0.25, ..HairParams::default() };
        assert_eq!(Hair::build(&s, &Transform::default(), fine).unwrap().vertices.len(), 4);
    }

    #[test]
    fn parameters_are_checked() {
        let s = strands("0 0 0\n1 0 0\n").unwrap();
        let id = Transform::default();
        for (params, needle) in [
            (HairParams { radius: 0.0, ..HairParams::default() }, "radius must be positive"),
            (HairParams { radius: -1.0, ..HairParams::default() }, "radius must be positive"),
            (HairParams { reduction: 1.0, ..HairParams::default() }, "reduction"),
            (HairParams { angle_threshold: f32::NAN, ..HairParams::default() }, "angle_threshold"),
        ] {
            let e = Hair::build(&s, &id, params).unwrap_err();
            assert!(e.contains(needle), "{e}");
        }
        let squash = Transform::new(Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0)));
        assert!(Hair::build(&s, &squash, HairParams::default()).unwrap_err().contains("uniformly"));
        let single = strands("0 0 0\n\n1 1 1\n").unwrap();
        assert!(Hair::build(&single, &id, HairParams::default()).unwrap_err().contains("no segments"));
        // A uniform scale scales the radius.
        let h = Hair::build(&s, &Transform::new(Mat4::from_scale(Vec3::splat(2.0))), HairParams::default()).unwrap();
        assert!((h.radius - 0.05).abs() < 1e-7);
    }

    #[test]
    fn reduction_drops_strands_and_widens_the_rest() {
        let text: String = (0..1000).map(|i| format!("{i} 0 0\n{i} 1 0\n\n")).collect();
        let s = strands(&text).unwrap();
        let params = HairParams { reduction: 0.75, ..HairParams::default() };
        let h = Hair::build(&s, &Transform::default(), params).unwrap();
        assert!((200..300).contains(&h.strands), "{} strands kept", h.strands);
        assert!((h.radius - 0.1).abs() < 1e-6);
        let again = Hair::build(&s, &Transform::default(), params).unwrap();
        assert_eq!(h.vertices, again.vertices);
    }

    #[test]
    fn surface_points_lie_on_the_cylinder() {
        let s = strands("0 0 0\n2 0 0\n2 2 0\n").unwrap();
        let h = Hair::build(&s, &Transform::default(), HairParams { radius: 0.1, ..HairParams::default() }).unwrap();
        let (p, n, frame, uv) = h.surface_point(0, Vec3::new(0.5, 0.0, 0.1001));
        assert!((p - Vec3::new(0.5, 0.0, 0.1)).length() < 1e-6 && (n - Vec3::Z).length() < 1e-6);
        assert!((frame.s - Vec3::X).length() < 1e-6 && (frame.n - n).length() < 1e-6);
        assert!((uv.x - 0.125).abs() < 1e-6, "{uv}");
        let (p, n, _, uv) = h.surface_point(1, Vec3::new(2.1, 1.0, 0.0));
        assert!((p - Vec3::new(2.1, 1.0, 0.0)).length() < 1e-6 && (n - Vec3::X).length() < 1e-6);
        assert!((uv.x - 0.75).abs() < 1e-6, "{uv}");
        // v turns once around the axis; dp/dv is the derivative of p in it.
        let (_, n0, _, uv0) = h.surface_point(0, Vec3::new(1.0, 0.1, 0.0));
        let (dp_du, dp_dv) = h.tangents(0, n0);
        assert!((dp_du - Vec3::new(4.0, 0.0, 0.0)).length() < 1e-5);
        let step = 1e-3;
        let (_, _, _, uv1) = h.surface_point(0, Vec3::new(1.0, 0.1, 0.0) + dp_dv * step);
        assert!((uv1.y - uv0.y - step).abs() < 1e-5, "{uv0} {uv1}");
        assert!((dp_dv.length() - 2.0 * PI * 0.1).abs() < 1e-5);
    }
}
