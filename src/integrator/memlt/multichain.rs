//! Veach's multi-chain perturbation (Veach and Guibas 1997; contract `memlt.md`,
//! "Mutators"): the lens perturbation for paths whose camera end holds more than one chain
//! of Dirac vertices, each ending at a rough vertex (`… D S+ D S+ E`, a floor seen in a
//! mirror through glass), where the lens perturbation cannot join its first rough vertex to
//! the next (a Dirac one).
//!
//! The film position moves as in the lens perturbation; the camera ray is followed through
//! the same Dirac lobes, and at each rough vertex on the way the direction leaving it is the
//! current path's turned by a small angle (density `∝ 1/θ` between 10⁻⁴ and 0.1 degrees,
//! uniform azimuth), until the first rough vertex `x_{l+1}` whose predecessor `x_l` is rough
//! too, which is joined to it by a shadow ray. The film offset's and the angles' densities
//! are symmetric in the two paths; what remains of the transition density is the Jacobian
//! from the film and those directions to the re-traced vertices' areas: the pinhole's
//! direction density times each re-traced vertex's area factor.
//!
//! **The light hit** ([`Mutator::LightHit`](crate::integrator::memlt::Mutator), beyond Veach and Mitsuba 0.6):
//! where no two neighbouring vertices of the path are rough, its light end is a chain of
//! Dirac vertices that no shadow ray joins (`L S+ D S+ E`: a floor's caustic seen in a glass
//! ball; `L S+ E`: a small light seen in it). Then the same re-trace goes on to the light
//! itself, which the ray must find (an area light; `x_0` is re-traced too, its area factor
//! in the Jacobian). With no Newton walk, the move is not held at a caustic's fold, where the
//! manifold perturbation's walk fails: like a primary-sample-space step, `f / T` stays
//! bounded there, both holding the chain's singular geometric factor.

use crate::integrator::bidir::{Vertex, VertexKind};
use crate::integrator::memlt::bidirectional::Proposal;
use crate::integrator::memlt::lens::Radii;
use crate::integrator::memlt::media::has_medium_vertex;
use crate::integrator::memlt::path::{
    area_factor, as_light, connectible, contribution, hittable_light, join, ray_from, retrace, settle_sky,
};
use crate::integrator::stats::Counters;
use crate::math::Frame;
use crate::sampling::Random;
use crate::scene::Scene;
use glam::{Vec2, Vec3};

/// The range of the angle by which the direction leaving a rough vertex turns, in radians
/// (Mitsuba 0.6's: 10⁻⁴ to 0.1 degrees).
const THETA: (f32, f32) = (1e-4 * std::f32::consts::PI / 180.0, 0.1 * std::f32::consts::PI / 180.0);

/// The first pair of neighbouring rough vertices from the camera, `(x_{i-1}, x_i)`: `i`
/// (`0` when there is none), and the number of rough vertices from `x_i` to the pinhole
/// (`x_i` included, the pinhole excluded).
fn first_rough_pair(scene: &Scene, x: &[Vertex]) -> Option<(usize, usize)> {
    let k = x.len() - 1;
    let rough = |i: usize| x[i].kind != VertexKind::Camera && connectible(scene, &x[i]);
    let mut i = k.checked_sub(1)?;
    let mut rough_seen = usize::from(rough(i));
    while i >= 1 && !(rough(i) && rough(i - 1)) {
        i -= 1;
        rough_seen += usize::from(rough(i));
    }
    Some((i, rough_seen))
}

/// Where the multi-chain perturbation works: the number of vertices it keeps at the light's
/// end, `x_0 ..= x_l` (`l + 1`; `x_l` and `x_{l+1}` rough, the first such pair from the
/// camera, and the re-traced camera end joined to `x_l`), when more than one rough vertex
/// lies between `x_l` and the pinhole.
pub fn suits(scene: &Scene, x: &[Vertex]) -> Option<usize> {
    let (i, rough) = first_rough_pair(scene, x)?;
    // It re-traces surfaces: a medium's scattering event has no counterpart on the new path.
    (i >= 1 && rough >= 2 && x[i].kind == VertexKind::Surface && !has_medium_vertex(&x[i..])).then_some(i)
}

/// Where the light hit works: `Some(0)` (no vertex kept; the re-trace ends on the light)
/// when no two neighbouring vertices of `x` are rough and its light is an area light a ray
/// can find.
pub fn suits_light_hit(scene: &Scene, x: &[Vertex]) -> Option<usize> {
    let (i, _) = first_rough_pair(scene, x)?;
    (i == 0 && !x[0].infinite && hittable_light(scene, &x[0]) && !has_medium_vertex(x)).then_some(0)
}

/// The Jacobian of the re-traced vertices `x_kept .. x_{k-1}` with respect to the film and
/// the turned directions: the pinhole's direction density and each vertex's area factor.
fn jacobian(scene: &Scene, x: &[Vertex], kept: usize) -> f64 {
    let k = x.len() - 1;
    let w = (x[k - 1].p - x[k].p).normalize();
    let mut j = scene.camera.pdf_direction(w) as f64;
    for i in kept..k {
        j *= area_factor(x, i, i + 1);
    }
    j
}

/// Proposes a multi-chain perturbation of `x` (film position `raster`), keeping its first
/// `kept` vertices ([`suits`]) or none (the light hit, [`suits_light_hit`]).
pub fn propose<R: Random>(
    scene: &Scene,
    x: &[Vertex],
    raster: Vec2,
    kept: usize,
    radii: Radii,
    rng: &mut R,
    counters: &mut Counters,
) -> Option<Proposal> {
    let k = x.len() - 1;
    let mut ray = radii.camera_ray(scene, raster, rng.next_2d(), counters)?;
    let mut y = x.to_vec();
    let mut medium = scene.camera_medium;
    for i in (kept..k).rev() {
        let specular = x[i].delta;
        y[i] = retrace(scene, &mut ray, &mut medium, x, i, specular && i > kept, counters)?;
        if !specular && i > kept {
            if !connectible(scene, &y[i]) {
                return None;
            }
            // The current path's direction towards `x_{i-1}`, turned.
            let u = rng.next_2d();
            let theta = THETA.0 * (THETA.1 / THETA.0).powf(u.x);
            let phi = 2.0 * std::f32::consts::PI * u.y;
            let old = (x[i - 1].p - x[i].p).normalize();
            let local = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
            ray = ray_from(&y[i], Frame::from_normal(old).to_world(local));
            medium = y[i].medium_towards(scene, ray.d);
        }
    }
    if kept == 0 {
        // The ray found the light's point (or another area light's).
        y[0] = as_light(scene, &y[0])?;
    } else {
        settle_sky(scene, &mut y);
        if !join(scene, &y[kept - 1], &y[kept], counters) {
            return None;
        }
    }
    let measured = contribution(scene, &y)?;
    let forward = jacobian(scene, &y, kept);
    let backward = jacobian(scene, x, kept);
    Some(Proposal { path: y, measured, forward, backward })
}
