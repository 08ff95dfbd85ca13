//! Comparing the closest hits two traversals report for one ray (two backends, two BVH
//! layouts, single rays against streams, one instruction set against another).
//!
//! Which of two primitives at the same distance a traversal reports is arbitrary: it
//! depends on the BVH, and on the instruction set Embree picked on the CPU at hand. Such a
//! pair is accepted, uncounted, only when each primitive is shown to contain the other's
//! hit point (coplanar faces such as a box standing on the floor, a shared edge). What is
//! left, a ray through an edge that one triangle test counts and the other does not, or a
//! ray that starts on a surface, is an edge tie that the tests cap.

use glam::Vec3;
use pcbpt::accel::{Accel, Geometry, Hit, Ray};

/// How close to an edge (in barycentric units) a hit must be to count as an edge tie.
pub const EDGE: f32 = 1e-4;

/// How two hits of one ray compare.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HitMatch {
    /// Both miss, or the same primitive at the same distance.
    Same,
    /// Two primitives at the same distance, each verified to contain the other's point.
    Coincident,
    /// One hit (or both) lies at an edge, or the ray starts on a surface.
    EdgeTie,
    /// Anything else: a real disagreement.
    Differ,
}

pub fn near_edge(h: &Hit, geometry: &[Geometry<'_>]) -> bool {
    match geometry[h.geom as usize] {
        Geometry::Triangles { .. } => h.u.min(h.v).min(1.0 - h.u - h.v) < EDGE,
        // A curve's hits are compared by their own test (`tests/hair.rs`).
        Geometry::Sphere { .. } | Geometry::Curves { .. } => false,
    }
}

/// Whether the point `p` lies on primitive `h` (on a triangle's plane and within its edges,
/// up to `eps` of the scene size), so that two primitives hit at the same distance are
/// genuinely both there.
pub fn lies_on(h: &Hit, p: Vec3, geometry: &[Geometry<'_>], eps: f32) -> bool {
    match geometry[h.geom as usize] {
        Geometry::Triangles { positions, indices } => {
            let [a, b, c] = indices[h.prim as usize].map(|k| positions[k as usize]);
            let n = (b - a).cross(c - a);
            let area2 = n.length_squared();
            if area2 == 0.0 {
                return false;
            }
            let n = n / area2.sqrt();
            if n.dot(p - a).abs() > eps {
                return false;
            }
            // Barycentric coordinates of the projection, each at least -eps (relative).
            let q = p - n * n.dot(p - a);
            let w1 = (q - a).cross(c - a).dot(n) / area2.sqrt();
            let w2 = (b - a).cross(q - a).dot(n) / area2.sqrt();
            let tol = 1e-3;
            w1 >= -tol && w2 >= -tol && w1 + w2 <= 1.0 + tol
        }
        Geometry::Sphere { center, radius } => ((p - center).length() - radius).abs() <= eps,
        Geometry::Curves { vertices, segments, radius, .. } => {
            let k = segments[h.prim as usize] as usize;
            let (c, _) = pcbpt::accel::curve::closest_on_segment(p, vertices[k], vertices[k + 1]);
            ((p - c).length() - radius).abs() <= eps
        }
    }
}

/// Compares the hits `a` and `b` of ray `r`. Distances agree within `t_tol` relative (at
/// least 1 scene unit's worth); `grazing` is the distance under which a ray counts as
/// starting on a surface (and the tolerance of [`lies_on`]).
pub fn compare_hits(
    r: &Ray,
    a: Option<Hit>,
    b: Option<Hit>,
    geometry: &[Geometry<'_>],
    grazing: f32,
    t_tol: f32,
) -> HitMatch {
    let close = |x: &Hit, y: &Hit| (x.t - y.t).abs() <= t_tol * x.t.max(1.0);
    match (a, b) {
        (None, None) => HitMatch::Same,
        (Some(x), Some(y)) if (x.geom, x.prim) == (y.geom, y.prim) => {
            if close(&x, &y) {
                HitMatch::Same
            } else {
                HitMatch::Differ
            }
        }
        (Some(x), Some(y))
            if close(&x, &y)
                && lies_on(&x, r.at(y.t), geometry, grazing)
                && lies_on(&y, r.at(x.t), geometry, grazing) =>
        {
            HitMatch::Coincident
        }
        // One traversal counted a triangle's edge (or a surface the ray starts on) that the
        // other passed through to a farther surface: the nearer hit is the tie.
        (Some(x), Some(y)) => {
            let near = if x.t <= y.t { x } else { y };
            if near_edge(&near, geometry) || near.t < grazing { HitMatch::EdgeTie } else { HitMatch::Differ }
        }
        (Some(x), None) | (None, Some(x)) if near_edge(&x, geometry) || x.t < grazing => HitMatch::EdgeTie,
        _ => HitMatch::Differ,
    }
}

/// Tallies of [`HitMatch`] over a set of rays.
#[derive(Clone, Copy, Debug, Default)]
pub struct Tally {
    pub rays: usize,
    pub hits: usize,
    pub coincident: usize,
    pub edge_ties: usize,
    pub occlusion_ties: usize,
}

impl Tally {
    /// Counts one comparison; panics with the ray on a real disagreement.
    pub fn add(&mut self, what: &str, i: usize, r: &Ray, m: HitMatch, a: Option<Hit>, b: Option<Hit>) {
        match m {
            HitMatch::Same => self.hits += usize::from(a.is_some()),
            HitMatch::Coincident => self.coincident += 1,
            HitMatch::EdgeTie => self.edge_ties += 1,
            HitMatch::Differ => panic!("{what}, ray {i} {r:?}: {a:?} against {b:?}"),
        }
    }

    /// The ties the tests cap: edge ties of hits and of occlusion.
    pub fn capped(&self) -> usize {
        self.edge_ties + self.occlusion_ties
    }
}

/// Whether two traversals `a` and `b` that disagree on whether segment `seg` is occluded do
/// so by a tie: the blocking hit (either's, looked for a little past the segment's end) is at
/// an edge, at the segment's end, or on a surface the segment starts on.
pub fn occlusion_tie(a: &Accel, b: &Accel, seg: &Ray, geometry: &[Geometry<'_>], grazing: f32) -> bool {
    let longer = Ray { tmax: seg.tmax * 1.001, ..*seg };
    match a.intersect(&longer).or(b.intersect(&longer)) {
        Some(h) => near_edge(&h, geometry) || h.t < grazing || (h.t - seg.tmax).abs() <= 1e-3 * seg.tmax,
        None => false,
    }
}
