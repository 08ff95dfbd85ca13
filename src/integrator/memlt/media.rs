//! Participating media in the paths of path-space Metropolis: the walks' free flights and
//! null-surface crossings ([`advance`]), and what an edge between two path vertices crosses
//! ([`edge`]): its transmittance, a factor of the path's contribution, and the free-flight
//! factors of the densities with which a walk from either end reaches the other.
//!
//! The chains' acceptance needs the exact density of every proposal, so the walks sample
//! free flights as [`Homogeneous::sample`] does and the densities take
//! [`Homogeneous::densities`]; heterogeneous media, whose delta tracking has no closed-form
//! density, are refused ([`check`]). A walk from `a` reaches a surface vertex `b` by
//! flying past every stretch of the edge (one per medium between null surfaces), and a
//! medium vertex by flying past all but the last and scattering at its end. In area (or
//! volume) measure these factors multiply the solid-angle density and `|cos| / d²` (no
//! cosine at a medium vertex). A medium that only absorbs is never sampled: its flights
//! always pass, and its transmittance stays in the contribution.

use crate::accel::Ray;
use crate::error::Error;
use crate::integrator::bidir::{Vertex, VertexKind};
use crate::integrator::stats::Counters;
use crate::math::{Rgb, offset_origin};
use crate::medium::Homogeneous;
use crate::sampling::Random;
use crate::scene::shape::SurfaceInteraction;
use crate::scene::{MAX_NULL_CROSSINGS, Scene};
use glam::Vec3;

/// Refuses a scene with a heterogeneous medium, naming it and the integrators that render it.
pub fn check(scene: &Scene) -> Result<(), Error> {
    match scene.media.iter().find(|m| m.homogeneous().is_none()) {
        Some(m) => Err(Error::Usage(format!(
            "{}: the medium `{}` is heterogeneous, which --integrator memlt does not render (its acceptance needs \
             the exact density of a free flight); use --integrator path or a bidirectional integrator",
            scene.path.display(),
            m.name
        ))),
        None => Ok(()),
    }
}

/// The coefficients of medium `m` (MEMLT renders homogeneous media alone: [`check`]).
#[inline]
pub fn homogeneous(scene: &Scene, m: u32) -> &Homogeneous {
    scene.media[m as usize].homogeneous().expect("MEMLT renders homogeneous media alone")
}

/// Where a walk's ray ends.
pub enum Stop {
    /// On a surface that scatters (not a null one).
    Surface(SurfaceInteraction),
    /// At a scattering event in medium `m`, at `p`.
    Medium(Vec3, u32),
    /// The ray left the scene.
    Escaped,
    /// More null surfaces than [`MAX_NULL_CROSSINGS`] in a row.
    Lost,
}

/// Follows `ray`, travelling in `medium`, to where it scatters: a free flight sampled in
/// each medium it crosses, null surfaces passed (`ray` and `medium` left as the last
/// stretch's). Without media, the first surface the ray finds.
pub fn advance<R: Random>(
    scene: &Scene,
    ray: &mut Ray,
    medium: &mut Option<u32>,
    rng: &mut R,
    counters: &mut Counters,
) -> Stop {
    for _ in 0..MAX_NULL_CROSSINGS {
        counters.extension_rays += 1;
        let hit = scene.intersect(ray);
        if let Some(m) = *medium
            && homogeneous(scene, m).scatters()
        {
            let len = ray.d.length();
            let t_max = hit.as_ref().map_or(f32::INFINITY, |si| si.t * len);
            let u_channel = rng.next_1d();
            let flight = homogeneous(scene, m).sample(t_max, u_channel, rng.next_1d());
            if flight.scattered {
                return Stop::Medium(ray.o + ray.d * (flight.t / len), m);
            }
        }
        let Some(si) = hit else { return Stop::Escaped };
        if !scene.bsdf(&si).is_null() {
            return Stop::Surface(si);
        }
        *medium = scene.medium_after(&si, ray.d, *medium);
        *ray = si.spawn_ray(ray.d);
    }
    Stop::Lost
}

/// What the edge between two vertices of a path crosses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Edge {
    /// The fraction of light that travels along it.
    pub tr: Rgb,
    /// The free-flight factor of a walk from its first vertex reaching its second.
    pub from_a: f64,
    /// The free-flight factor of a walk from its second vertex reaching its first.
    pub from_b: f64,
}

impl Edge {
    /// An edge through vacuum.
    pub const CLEAR: Edge = Edge { tr: Rgb::ONE, from_a: 1.0, from_b: 1.0 };
}

/// The edge from `a` to `b` (either may lie at infinity, not both): `None` when a surface
/// blocks it. In a scene without media or null surfaces, [`Edge::CLEAR`] (its visibility is
/// the caller's).
pub fn edge(scene: &Scene, a: &Vertex, b: &Vertex) -> Option<Edge> {
    if !scene.volumetric {
        return Some(Edge::CLEAR);
    }
    // Traced from the finite end whose medium is known (towards a light at infinity, the
    // light's direction).
    let reversed = a.infinite;
    let (a, b) = if reversed { (b, a) } else { (a, b) };
    let stretches = stretches(scene, a, b)?;
    let flight = |from_first: bool| -> f64 {
        let n = stretches.len();
        let mut p = 1.0f64;
        for (i, &(m, len)) in stretches.iter().enumerate() {
            let Some(m) = m else { continue };
            let (scatter, pass) = homogeneous(scene, m).densities(len);
            // The stretch the walk ends in, at the far vertex.
            let last = if from_first { i + 1 == n } else { i == 0 };
            let far = if from_first { b } else { a };
            p *= if last && far.kind == VertexKind::Medium { scatter } else { pass } as f64;
        }
        p
    };
    let mut tr = Rgb::ONE;
    for &(m, len) in &stretches {
        if let Some(m) = m {
            tr *= homogeneous(scene, m).transmittance(len);
        }
    }
    let (from_a, from_b) = (flight(true), flight(false));
    Some(if reversed { Edge { tr, from_a: from_b, from_b: from_a } } else { Edge { tr, from_a, from_b } })
}

/// The stretches of the segment from `a` (finite) to `b` between null surfaces, in order
/// from `a`: each one's medium and length (infinite towards a light at infinity through a
/// medium that nothing bounds). `None` when a surface other than a null one blocks it.
fn stretches(scene: &Scene, a: &Vertex, b: &Vertex) -> Option<Vec<(Option<u32>, f32)>> {
    let d = if b.infinite { b.ng } else { b.p - a.p };
    let o = if a.ng == Vec3::ZERO { a.p } else { offset_origin(a.p, a.ng, d) };
    let mut ray = if b.infinite {
        Ray::new(o, d)
    } else {
        let e = if b.ng == Vec3::ZERO { b.p } else { offset_origin(b.p, b.ng, -d) };
        Ray::segment(o, e - o, 1.0 - crate::math::SHADOW_EPSILON)
    };
    let end = ray.at(ray.tmax);
    let mut medium = a.medium_towards(scene, d);
    let mut out = Vec::with_capacity(2);
    for _ in 0..MAX_NULL_CROSSINGS {
        let hit = scene.intersect(&ray);
        let len = match &hit {
            Some(si) => si.t * ray.d.length(),
            None if b.infinite => f32::INFINITY,
            None => ray.tmax * ray.d.length(),
        };
        out.push((medium, len));
        let Some(si) = hit else { return Some(out) };
        if !scene.bsdf(&si).is_null() {
            return None;
        }
        medium = scene.medium_after(&si, ray.d, medium);
        ray = if b.infinite { si.spawn_ray(ray.d) } else { si.spawn_ray_to(end) };
    }
    None
}

/// The product of the transmittances of a path's edges (`None` when one is blocked), in a
/// scene with media; one in a scene without.
pub fn path_transmittance(scene: &Scene, v: &[Vertex]) -> Option<Rgb> {
    if !scene.volumetric {
        return Some(Rgb::ONE);
    }
    let mut tr = Rgb::ONE;
    for e in v.windows(2) {
        tr *= edge(scene, &e[0], &e[1])?.tr;
    }
    Some(tr)
}

/// Whether any vertex of `x` is a scattering event in a medium.
#[inline]
pub fn has_medium_vertex(x: &[Vertex]) -> bool {
    x.iter().any(|v| v.kind == VertexKind::Medium)
}
