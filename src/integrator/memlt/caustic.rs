//! Veach's caustic perturbation (Veach and Guibas 1997; contract `memlt.md`, "Mutators"):
//! for a path whose camera end is a rough vertex seen directly after a chain of Dirac lobes
//! (`(L|D) S+ D E`, a caustic seen by the camera), turns the direction leaving the chain's
//! light-side end `x_m` by a small angle, re-traces the chain through the same lobes to a
//! new rough vertex and joins it to the pinhole. As in Mitsuba 0.6 the chain may be empty
//! (`(L|D) D E`): the perturbation then moves the point the camera sees from the light's
//! side, keeping the rest of the path. The light must be one with a position: a light at
//! infinity sends its light along its own directions, which no turn may change.
//!
//! The angle has density `∝ 1/θ` between `θ1` and `θ2`, in a uniform azimuth around the
//! current direction: the image-space radii of the lens perturbation (0.1 pixel, 5% of the
//! image) turned into angles at the camera and scaled by the ratio of the eye edge's length
//! to the chain's, as Veach does. That range depends on the path, so each direction's
//! density uses its own path's range. The re-traced vertices' area densities per unit solid
//! angle at `x_m` (the chain's geometric factors, the Dirac lobes' coefficients left to `f`)
//! complete the transition densities.

use crate::integrator::bidir::{Vertex, VertexKind};
use crate::integrator::memlt::bidirectional::Proposal;
use crate::integrator::memlt::lens::Radii;
use crate::integrator::memlt::path::{area_factor, connectible, contribution, join, ray_from, retrace};
use crate::integrator::stats::Counters;
use crate::math::Frame;
use crate::sampling::Random;
use crate::scene::Scene;
use glam::Vec3;

/// Where the caustic perturbation turns the path: the index `m` of the rough vertex (or the
/// light) before the Dirac chain (possibly empty) that ends at the rough vertex `x_{k-1}`
/// the camera sees.
pub fn suits(scene: &Scene, x: &[Vertex]) -> Option<usize> {
    let k = x.len() - 1;
    if k < 2 || x[k - 1].kind != VertexKind::Surface || !connectible(scene, &x[k - 1]) {
        return None;
    }
    let mut m = k - 2;
    while m >= 1 && x[m].delta {
        m -= 1;
    }
    // The direction leaving a light at infinity is the light's own: nothing to turn.
    (!x[m].delta && !x[m].infinite && connectible(scene, &x[m])).then_some(m)
}

/// The angles `[θ1, θ2]` for a path: the radii's angles at the camera, times the eye edge's
/// length over the chain's from `x_m` to `x_{k-1}`.
fn angles(scene: &Scene, x: &[Vertex], m: usize, radii: Radii) -> (f32, f32) {
    let k = x.len() - 1;
    let per_pixel = 2.0 * scene.camera.tan_half.y / scene.film.height as f32;
    let eye = (x[k].p - x[k - 1].p).length();
    let chain: f32 = (m..k - 1).map(|j| (x[j + 1].p - x[j].p).length()).sum();
    let scale = per_pixel * eye / chain.max(1e-6);
    let t2 = (radii.r2 * scale).clamp(2e-7, std::f32::consts::FRAC_PI_2);
    let t1 = (radii.r1 * scale).clamp(1e-7, t2 * 0.5);
    (t1, t2)
}

/// Solid-angle density of turning a direction by `theta` with the range `(t1, t2)`.
fn angle_density(theta: f32, (t1, t2): (f32, f32)) -> f64 {
    if !(t1..=t2).contains(&theta) || theta <= 0.0 {
        return 0.0;
    }
    let (theta, t1, t2) = (theta as f64, t1 as f64, t2 as f64);
    1.0 / (theta * (t2 / t1).ln() * 2.0 * std::f64::consts::PI * theta.sin())
}

/// The re-traced vertices' area densities per unit solid angle at `x_m`: the chain's
/// `|cos| / d²` factors ([`area_factor`]).
fn jacobian(x: &[Vertex], m: usize) -> f64 {
    let k = x.len() - 1;
    (m + 1..k).map(|j| area_factor(x, j, j - 1)).product()
}

/// The direction leaving `x_m` towards `x_{m+1}`.
fn leaving(x: &[Vertex], m: usize) -> Vec3 {
    (x[m + 1].p - x[m].p).normalize()
}

/// Proposes a caustic perturbation of `x` at `x_m`.
pub fn propose<R: Random>(
    scene: &Scene,
    x: &[Vertex],
    m: usize,
    radii: Radii,
    rng: &mut R,
    counters: &mut Counters,
) -> Option<Proposal> {
    let k = x.len() - 1;
    let range_x = angles(scene, x, m, radii);
    let u = rng.next_2d();
    let theta = range_x.0 * (range_x.1 / range_x.0).powf(u.x);
    let phi = 2.0 * std::f32::consts::PI * u.y;
    let w = leaving(x, m);
    let local = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
    let mut ray = ray_from(&x[m], Frame::from_normal(w).to_world(local));
    let mut medium = x[m].medium_towards(scene, ray.d);
    let mut y = x.to_vec();
    for (j, v) in y.iter_mut().enumerate().take(k).skip(m + 1) {
        *v = retrace(scene, &mut ray, &mut medium, x, j, j + 1 < k, counters)?;
    }
    if !join(scene, &y[k - 1], &y[k], counters) {
        return None;
    }
    let measured = contribution(scene, &y)?;
    // The angle between the two paths' directions at `x_m`, from the vertex positions.
    let turned = leaving(x, m).dot(leaving(&y, m)).clamp(-1.0, 1.0).acos();
    let forward = angle_density(turned, range_x) * jacobian(&y, m);
    let backward = angle_density(turned, angles(scene, &y, m, radii)) * jacobian(x, m);
    Some(Proposal { path: y, measured, forward, backward })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angle_density_integrates_to_one() {
        // ∫ p(θ) 2π sin θ dθ over [θ1, θ2] by the midpoint rule.
        let range = (0.001f32, 0.2f32);
        let n = 200_000;
        let h = (range.1 - range.0) as f64 / n as f64;
        let total: f64 = (0..n)
            .map(|i| {
                let t = range.0 as f64 + (i as f64 + 0.5) * h;
                angle_density(t as f32, range) * 2.0 * std::f64::consts::PI * t.sin() * h
            })
            .sum();
        assert!((total - 1.0).abs() < 1e-3, "{total}");
        assert_eq!(angle_density(0.3, range), 0.0);
    }
}
