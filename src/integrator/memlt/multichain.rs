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

use super::bidirectional::Proposal;
use super::lens::Radii;
use super::path::{area_factor, connectible, contribution, join, ray_from, retrace, settle_sky};
use crate::integrator::Counters;
use crate::integrator::bidir::{Vertex, VertexKind};
use crate::math::Frame;
use crate::sampling::Random;
use crate::scene::Scene;
use glam::{Vec2, Vec3};

/// The range of the angle by which the direction leaving a rough vertex turns, in radians
/// (Mitsuba 0.6's: 10⁻⁴ to 0.1 degrees).
const THETA: (f32, f32) = (1e-4 * std::f32::consts::PI / 180.0, 0.1 * std::f32::consts::PI / 180.0);

/// Where the multi-chain perturbation works: the index `l` of the kept vertex that the
/// re-traced camera end is joined to (`x_l` and `x_{l+1}` rough, the first such pair from
/// the camera), when more than one rough vertex lies between it and the pinhole.
pub fn suits(scene: &Scene, x: &[Vertex]) -> Option<usize> {
    let k = x.len() - 1;
    let rough = |i: usize| x[i].kind != VertexKind::Camera && connectible(scene, &x[i]);
    let mut i = k.checked_sub(1)?;
    let mut chains = 1;
    while i >= 1 && !(rough(i) && rough(i - 1)) {
        if rough(i) {
            chains += 1;
        }
        i -= 1;
    }
    (i >= 1 && chains >= 2 && x[i].kind == VertexKind::Surface).then_some(i - 1)
}

/// The Jacobian of the re-traced vertices `x_{l+1} .. x_{k-1}` with respect to the film and
/// the turned directions: the pinhole's direction density and each vertex's area factor.
fn jacobian(scene: &Scene, x: &[Vertex], l: usize) -> f64 {
    let k = x.len() - 1;
    let w = (x[k - 1].p - x[k].p).normalize();
    let mut j = scene.camera.pdf_direction(w) as f64;
    for i in l + 1..k {
        j *= area_factor(x, i, i + 1);
    }
    j
}

/// Proposes a multi-chain perturbation of `x` (film position `raster`), keeping `x_0 ..=
/// x_l`.
pub fn propose<R: Random>(
    scene: &Scene,
    x: &[Vertex],
    raster: Vec2,
    l: usize,
    radii: Radii,
    rng: &mut R,
    counters: &mut Counters,
) -> Option<Proposal> {
    let k = x.len() - 1;
    let mut ray = radii.camera_ray(scene, raster, rng.next_2d(), counters)?;
    let mut y = x.to_vec();
    for i in (l + 1..k).rev() {
        let specular = x[i].delta;
        y[i] = retrace(scene, &mut ray, x, i, specular && i > l + 1, counters)?;
        if !specular && i > l + 1 {
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
        }
    }
    settle_sky(scene, &mut y);
    if !join(scene, &y[l], &y[l + 1], counters) {
        return None;
    }
    let measured = contribution(scene, &y)?;
    let forward = jacobian(scene, &y, l);
    let backward = jacobian(scene, x, l);
    Some(Proposal { path: y, measured, forward, backward })
}
