//! Hair segments as both backends trace them: Embree's round linear curve
//! (`RTC_GEOMETRY_TYPE_ROUND_LINEAR_CURVE`) of constant radius, and the same shape
//! intersected here for the obvhs backend.
//!
//! A strand is a polyline of vertices; each segment between two consecutive vertices is a
//! cylinder of radius `r` cut by the planes through its end vertices perpendicular to its
//! axis, and the joints are filled by spheres of radius `r` at the vertices (the start and
//! end vertices of a strand get a sphere too): the strand is the volume a sphere sweeps
//! along the polyline. Embree splits that surface between the segments by constructive
//! solid geometry, and so does [`intersect_round_segment`]: segment `i` owns its cylinder
//! minus what lies inside the capped cylinders of its neighbours, the half of the sphere at
//! its end vertex beyond its end plane and before the next segment's start plane, and, when
//! it starts a strand, the half of the sphere at its start vertex behind its start plane.
//! Which neighbours a segment has is given per segment by Embree's curve flags
//! ([`LEFT`], [`RIGHT`]).

use super::Ray;
use glam::{DVec3, Vec3};

/// `RTC_CURVE_FLAG_NEIGHBOR_LEFT`: the segment continues the one before it (whose first
/// vertex is the one before the segment's).
pub const LEFT: u8 = 1;
/// `RTC_CURVE_FLAG_NEIGHBOR_RIGHT`: the segment is continued by the one after it.
pub const RIGHT: u8 = 2;

/// Whether `q` lies strictly inside the cylinder of radius `r` from `a` to `b`, capped by the
/// planes through `a` and `b` perpendicular to its axis.
fn inside_capped_cylinder(q: DVec3, a: DVec3, b: DVec3, r: f64) -> bool {
    let axis = b - a;
    let l2 = axis.length_squared();
    let rel = q - a;
    let y = rel.dot(axis);
    y > 0.0 && y < l2 && rel.length_squared() * l2 - y * y < l2 * r * r
}

/// The two roots `t0 <= t1` of the ray's intersection with the sphere at `c` of radius `r`.
fn sphere_roots(o: DVec3, d: DVec3, c: DVec3, r: f64) -> Option<(f64, f64)> {
    let rel = o - c;
    let dd = d.length_squared();
    let b = rel.dot(d);
    let h2 = b * b - dd * (rel.length_squared() - r * r);
    if h2 < 0.0 {
        return None;
    }
    let h = h2.sqrt();
    Some(((-b - h) / dd, (-b + h) / dd))
}

/// The first hit of the ray within `[tmin, tmax]` on the part of a strand that segment
/// `p0`–`p1` owns (see the module documentation), with its neighbours' far vertices `left`
/// (the vertex before `p0`) and `right` (the one after `p1`) where they exist. Returns the
/// distance and the position along the segment (Embree's `u`: the projection of the hit on
/// the axis, 0 at `p0` and 1 at `p1`; 0 and 1 on the spheres).
///
/// Computed in double precision. As Embree does, it takes the nearest entry into the
/// segment's part when that lies within the ray's range, else the farthest exit; and a ray
/// that misses the segment's infinite cylinder (or runs parallel to its axis) misses the
/// segment.
pub fn intersect_round_segment(
    ray: &Ray,
    p0: Vec3,
    p1: Vec3,
    left: Option<Vec3>,
    right: Option<Vec3>,
    r: f32,
) -> Option<(f32, f32)> {
    let (o, d) = (ray.o.as_dvec3(), ray.d.as_dvec3());
    let (a, b, r) = (p0.as_dvec3(), p1.as_dvec3(), r as f64);
    let (left, right) = (left.map(Vec3::as_dvec3), right.map(Vec3::as_dvec3));
    let axis = b - a;
    let l2 = axis.length_squared();
    let dd = d.length_squared();
    if l2 == 0.0 || dd == 0.0 {
        return None;
    }
    // The infinite cylinder: |(h - a) × axis|² = r² |axis|² with h = o + t d.
    let rel = o - a;
    let (rel_axis, d_axis) = (rel.dot(axis), d.dot(axis));
    let qa = l2 * dd - d_axis * d_axis;
    let qb = 2.0 * (l2 * rel.dot(d) - d_axis * rel_axis);
    let qc = l2 * rel.length_squared() - rel_axis * rel_axis - r * r * l2;
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 || qa <= 1e-12 * l2 * dd {
        return None;
    }
    let y = |t: f64| rel_axis + t * d_axis;
    let at = |t: f64| o + d * t;
    let owned_by_cylinder = |t: f64| {
        let (yt, h) = (y(t), at(t));
        yt > 0.0
            && yt <= l2
            && !left.is_some_and(|l| inside_capped_cylinder(h, l, a, r))
            && !right.is_some_and(|n| inside_capped_cylinder(h, b, n, r))
    };
    let q = disc.sqrt();
    let (front, back) = ((-qb - q) / (2.0 * qa), (-qb + q) / (2.0 * qa));
    // (distance, u) of the nearest entry and the farthest exit.
    let mut lower = (f64::INFINITY, 0.0);
    let mut upper = (f64::NEG_INFINITY, 0.0);
    let mut offer = |t: f64, u: f64, entry: bool| {
        if entry && t < lower.0 {
            lower = (t, u);
        } else if !entry && t > upper.0 {
            upper = (t, u);
        }
    };
    if owned_by_cylinder(front) {
        offer(front, (y(front) / l2).clamp(0.0, 1.0), true);
    }
    if owned_by_cylinder(back) {
        offer(back, (y(back) / l2).clamp(0.0, 1.0), false);
    }
    if let Some((t0, t1)) = sphere_roots(o, d, b, r) {
        let owned = |t: f64| y(t) > l2 && right.is_none_or(|n| (at(t) - b).dot(n - b) <= 0.0);
        if owned(t0) {
            offer(t0, 1.0, true);
        }
        if owned(t1) {
            offer(t1, 1.0, false);
        }
    }
    if left.is_none()
        && let Some((t0, t1)) = sphere_roots(o, d, a, r)
    {
        if y(t0) < 0.0 {
            offer(t0, 0.0, true);
        }
        if y(t1) < 0.0 {
            offer(t1, 0.0, false);
        }
    }
    let (tmin, tmax) = (ray.tmin as f64, ray.tmax as f64);
    let in_range = |t: f64| t.is_finite() && t >= tmin && t <= tmax;
    let (t, u) = if in_range(lower.0) {
        lower
    } else if in_range(upper.0) {
        upper
    } else {
        return None;
    };
    Some((t as f32, u as f32))
}

/// The point of segment `p0`–`p1` closest to `p`, and its parameter in `[0, 1]`.
pub fn closest_on_segment(p: Vec3, p0: Vec3, p1: Vec3) -> (Vec3, f32) {
    let axis = p1 - p0;
    let l2 = axis.length_squared();
    let s = if l2 > 0.0 { ((p - p0).dot(axis) / l2).clamp(0.0, 1.0) } else { 0.0 };
    (p0 + axis * s, s)
}

#[cfg(test)]
mod tests {
    use super::*;

    const R: f32 = 0.25;

    /// One segment along x from 0 to 2, alone (spheres at both ends).
    fn hit(o: Vec3, d: Vec3) -> Option<(f32, f32)> {
        intersect_round_segment(&Ray::new(o, d), Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0), None, None, R)
    }

    #[test]
    fn a_ray_across_the_axis_hits_the_cylinder_at_its_radius() {
        let (t, u) = hit(Vec3::new(0.5, 3.0, 0.0), Vec3::NEG_Y).unwrap();
        assert!((t - (3.0 - R)).abs() < 1e-6 && (u - 0.25).abs() < 1e-6, "{t} {u}");
        // Oblique, off the axis: the analytic root of the circle in the y-z plane.
        let (o, d) = (Vec3::new(0.2, 2.0, 0.1), Vec3::new(0.3, -1.0, 0.0).normalize());
        let (t, _) = hit(o, d).unwrap();
        let p = o + d * t;
        assert!(((p.y * p.y + p.z * p.z).sqrt() - R).abs() < 1e-5, "{p}");
        let t_circle = (2.0 - (R * R - 0.01f32).sqrt()) / d.y.abs();
        assert!((t - t_circle).abs() < 1e-5, "{t} against {t_circle}");
        // Past the radius it misses.
        assert!(hit(Vec3::new(1.0, 3.0, R * 1.01), Vec3::NEG_Y).is_none());
    }

    #[test]
    fn the_ends_of_a_strand_are_round() {
        // Along the axis: the sphere at the start, then (from inside) the far one.
        assert!(hit(Vec3::new(-3.0, 0.0, 0.0), Vec3::X).is_none(), "a ray along the axis misses, as in Embree");
        let d = Vec3::new(1.0, 0.01, 0.0).normalize();
        let (t, u) = hit(Vec3::new(-3.0, 0.0, 0.0), d).unwrap();
        let p = Vec3::new(-3.0, 0.0, 0.0) + d * t;
        assert!((p.length() - R).abs() < 1e-5 && u == 0.0, "{p} {u}");
        // Beyond the end vertex, within the radius: the end sphere.
        let (t, u) = hit(Vec3::new(2.1, 3.0, 0.0), Vec3::NEG_Y).unwrap();
        let expected = 3.0 - (R * R - 0.01f32).sqrt();
        assert!((t - expected).abs() < 1e-5 && u == 1.0, "{t} {u}");
    }

    #[test]
    fn a_joint_belongs_to_one_segment() {
        // An elbow: (0,0,0) → (1,0,0) → (1,1,0). A ray into the outer corner hits the joint's
        // sphere, owned by the first segment; the second segment does not report it.
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0));
        let d = Vec3::new(-1.0, 1.0, 0.0).normalize();
        let ray = Ray::new(b - d * 3.0, d);
        let first = intersect_round_segment(&ray, a, b, None, Some(c), R).unwrap();
        let p = ray.at(first.0);
        assert!(((p - b).length() - R).abs() < 1e-5 && first.1 == 1.0, "{p}");
        assert!(intersect_round_segment(&ray, b, c, Some(a), None, R).is_none_or(|(t, _)| t > first.0 + 1e-3));
        // The inner side of the elbow: the first segment's cylinder inside the second's is
        // not its surface.
        let inner = Ray::new(Vec3::new(0.9, 0.2, 3.0), Vec3::NEG_Z);
        let h = intersect_round_segment(&inner, a, b, None, Some(c), R);
        assert!(h.is_none(), "{h:?}");
        let (t, _) = intersect_round_segment(&inner, b, c, Some(a), None, R).unwrap();
        assert!((t - (3.0 - (R * R - 0.01f32).sqrt())).abs() < 1e-5, "{t}");
    }

    #[test]
    fn the_range_of_the_ray_is_respected() {
        let o = Vec3::new(0.5, 3.0, 0.0);
        let short = Ray::segment(o, Vec3::NEG_Y, 2.0);
        let ends = Vec3::new(2.0, 0.0, 0.0);
        assert!(intersect_round_segment(&short, Vec3::ZERO, ends, None, None, R).is_none());
        // Starting past the entry: the exit.
        let inside = Ray { tmin: 3.0, ..Ray::new(o, Vec3::NEG_Y) };
        let (t, _) = intersect_round_segment(&inside, Vec3::ZERO, ends, None, None, R).unwrap();
        assert!((t - (3.0 + R)).abs() < 1e-5);
    }
}
