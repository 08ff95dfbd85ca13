//! The manifold perturbation of Manifold Exploration (Jakob and Marschner 2012; contract
//! `memlt.md`, "Manifold perturbation"), on the specular constraints, walk and densities of
//! [`crate::integrator::manifold`].
//!
//! A move is planned from the path's structure alone ([`Plan`]): a non-specular vertex `a`
//! (a rough surface, the pinhole or the light) and a direction of travel along the path;
//! `b`, the first non-specular vertex after the specular vertices that follow `a`; `c`, the
//! first non-specular vertex after the specular chain that follows `b` (none when `b` is the
//! light's point). One plan is chosen uniformly among those the path admits. The direction
//! leaving `a` is turned by a von Mises–Fisher lobe around the current one, of concentration
//! `max(1/4π, p) λ²` with `p` the scattering density of the current direction at `a`; the
//! ray is followed through the same Dirac lobes to the new `b`. Between `b` and `c` the
//! specular chain is walked onto its manifold, `c` fixed, until it ends at the new `b`; the
//! walk back from the proposal must return to the current path. Glossy vertices are never
//! treated as specular here: only Dirac lobes are.
//!
//! Densities are in the convention of the walks of [`super::path`] (each vertex reached
//! along a ray has area density `|cos| / d²` per unit solid angle behind it, the Dirac lobes'
//! coefficients left to `f`). From `a` to `b` they are those of a walk in the direction of
//! travel; from `b` to `c` those of a walk continuing past `b` whose direction at `b` is the
//! one that reaches `c`: the chain's `|cos| / d²` factors over `dω_b / dA_c`, the solid angle
//! at `b` per unit area at `c` through the chain (1 when `b` and `c` are neighbours).

use super::bidirectional::Proposal;
use super::path::{
    area_factor, as_light, connectible, contribution, join, lobe_pdf, ray_from, reflects, retrace, surface_vertex,
};
use crate::bsdf::TransportMode;
use crate::integrator::Counters;
use crate::integrator::bidir::{Vertex, VertexKind};
use crate::integrator::manifold::{self, Scatter, TracedChain};
use crate::math::Frame;
use crate::sampling::{Random, square_to_von_mises_fisher};
use crate::scene::Scene;
use serde::Serialize;

/// A walk's end must lie within this fraction of its chain's length of its target.
pub const TOLERANCE: f64 = 1e-5;

/// Where a manifold perturbation works on a path: from vertex `a` towards the light (to
/// lower indices) or towards the camera; `b` the first non-specular vertex on the way; `c`
/// the first non-specular vertex after `b`, `None` when `b` is the light's point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plan {
    pub a: usize,
    pub toward_light: bool,
    pub b: usize,
    pub c: Option<usize>,
}

impl Plan {
    /// The next index in the direction of travel.
    fn next(&self, i: usize) -> usize {
        if self.toward_light { i - 1 } else { i + 1 }
    }

    /// The previous index in the direction of travel.
    fn prev(&self, i: usize) -> usize {
        if self.toward_light { i + 1 } else { i - 1 }
    }

    /// The same plan travelling the other way (from `c` back to `b`).
    fn reversed(&self) -> Plan {
        Plan { toward_light: !self.toward_light, ..*self }
    }

    /// The indices from `from` (excluded) to `to` (included) in the direction of travel.
    fn span(&self, from: usize, to: usize) -> impl Iterator<Item = usize> + use<> {
        let toward_light = self.toward_light;
        let n = from.abs_diff(to);
        (1..=n).map(move |d| if toward_light { from - d } else { from + d })
    }
}

/// Manifold walks of a render.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct WalkStats {
    /// Walks tried (one per perturbation whose `b` and `c` are not neighbours).
    pub tried: u64,
    /// Walks that reached their target.
    pub converged: u64,
    /// Converged walks whose walk back did not return to the current path.
    pub irreversible: u64,
}

impl std::ops::AddAssign for WalkStats {
    fn add_assign(&mut self, o: WalkStats) {
        self.tried += o.tried;
        self.converged += o.converged;
        self.irreversible += o.irreversible;
    }
}

/// Whether `x_i` is a specular vertex: a surface scattering through a Dirac lobe.
#[inline]
fn specular(x: &Vertex) -> bool {
    x.kind == VertexKind::Surface && x.delta
}

/// The plan from `a` in the given direction, when the path's structure admits one.
pub fn plan(scene: &Scene, x: &[Vertex], a: usize, toward_light: bool) -> Option<Plan> {
    let k = x.len() - 1;
    let ok_start = match x[a].kind {
        VertexKind::Camera => toward_light,
        VertexKind::Light(_) => !toward_light,
        VertexKind::Surface => connectible(scene, &x[a]),
        VertexKind::Sky => false,
    };
    if !ok_start || (toward_light && a == 0) || (!toward_light && a == k) {
        return None;
    }
    let step = |i: usize| if toward_light { i.checked_sub(1) } else { (i < k).then_some(i + 1) };
    let mut b = step(a)?;
    while specular(&x[b]) {
        b = step(b)?;
    }
    if b == 0 {
        return matches!(x[0].kind, VertexKind::Light(_)).then_some(Plan { a, toward_light, b, c: None });
    }
    if b == k || !connectible(scene, &x[b]) {
        return None;
    }
    let mut c = step(b)?;
    while specular(&x[c]) {
        c = step(c)?;
    }
    // A specular chain cannot end at the pinhole: it has no area to find it on.
    if c == k && c.abs_diff(b) > 1 {
        return None;
    }
    (x[c].kind != VertexKind::Surface || connectible(scene, &x[c])).then_some(Plan { a, toward_light, b, c: Some(c) })
}

/// Every plan a path admits, in a fixed order.
pub fn plans<'a>(scene: &'a Scene, x: &'a [Vertex]) -> impl Iterator<Item = Plan> + 'a {
    (0..x.len()).flat_map(move |a| [true, false].into_iter().filter_map(move |t| plan(scene, x, a, t)))
}

/// Whether the manifold perturbation suits `x`.
pub fn suits(scene: &Scene, x: &[Vertex]) -> bool {
    plans(scene, x).next().is_some()
}

/// The solid-angle density at `a` of scattering towards its neighbour in the direction of
/// travel (given its other neighbour): what sets the perturbation's concentration.
fn direction_density(scene: &Scene, x: &[Vertex], plan: &Plan) -> f64 {
    let a = &x[plan.a];
    let w = (x[plan.next(plan.a)].p - a.p).normalize();
    let p = match a.kind {
        VertexKind::Camera => scene.camera.pdf_direction(w),
        VertexKind::Light(l) => scene.lights[l as usize].pdf_emission_direction(a.ng, w),
        VertexKind::Surface => {
            let back = (x[plan.prev(plan.a)].p - a.p).normalize();
            let mode = if plan.toward_light { TransportMode::Radiance } else { TransportMode::Importance };
            lobe_pdf(scene, a, back, w, mode)
        }
        VertexKind::Sky => 0.0,
    };
    p as f64
}

/// The von Mises–Fisher concentration for a path.
fn concentration(scene: &Scene, x: &[Vertex], plan: &Plan, lambda: f64) -> f64 {
    (direction_density(scene, x, plan).max(1.0 / (4.0 * std::f64::consts::PI)) * lambda * lambda).min(1e6)
}

/// The von Mises–Fisher solid-angle density, concentration `kappa`, of a direction at
/// squared distance `d2` (between unit vectors) from the mean: `1 - cos θ = d2 / 2`, exact
/// for the small angles of sharp lobes.
fn vmf_density(d2: f64, kappa: f64) -> f64 {
    kappa / (2.0 * std::f64::consts::PI * -(-2.0 * kappa).exp_m1()) * (-kappa * d2 * 0.5).exp()
}

/// The density, up to the direction's, of a path's vertices `a+1 ..= b ..= c` (in the
/// direction of travel) as the plan produces them; `chain` is its specular chain from `c` to
/// `b` where `b` and `c` are not neighbours.
fn jacobian(scene: &Scene, v: &[Vertex], plan: &Plan, chain: Option<&TracedChain>) -> Option<f64> {
    let factors =
        |from: usize, to: usize| plan.span(from, to).map(|i| area_factor(v, i, plan.prev(i))).product::<f64>();
    let mut j = factors(plan.a, plan.b);
    if let (Some(c), Some(chain)) = (plan.c, chain) {
        let along = factors(plan.b, c);
        let solid = chain.end_solid_angle_density(scene)?;
        j *= along / solid;
    }
    (j > 0.0 && j.is_finite()).then_some(j)
}

/// The specular chain of `x` from `c` to `b` as a traced chain: how its vertices scatter,
/// their shapes, and the chain re-traced from `c` through them. `None` when the re-traced
/// chain misses `x_b` by more than a thousandth of its length.
fn chain_of(scene: &Scene, x: &[Vertex], plan: &Plan) -> Option<TracedChain> {
    let (b, c) = (plan.b, plan.c?);
    let indices: Vec<usize> = plan.reversed().span(c, b).collect();
    let scatters: Vec<Scatter> = indices[..indices.len() - 1]
        .iter()
        .map(|&i| if reflects(x, i) { Scatter::Reflect } else { Scatter::Refract })
        .collect();
    let shapes: Vec<u32> = indices.iter().map(|&i| x[i].shape).collect();
    let chain = manifold::trace(scene, (x[c].p, x[c].ng), x[indices[0]].p, &scatters, &shapes)?;
    ((chain.end().p - x[b].p).length() as f64 <= 1e-3 * chain.length()).then_some(chain)
}

/// Proposes a manifold perturbation of `x`, with `lambda` the lobe's sharpness.
pub fn propose<R: Random>(
    scene: &Scene,
    x: &[Vertex],
    lambda: f64,
    rng: &mut R,
    counters: &mut Counters,
    walks: &mut WalkStats,
) -> Option<Proposal> {
    let n_x = plans(scene, x).count();
    let pick = ((rng.next_1d() * n_x as f32) as usize).min(n_x.checked_sub(1)?);
    let plan = plans(scene, x).nth(pick)?;
    let (a, b) = (plan.a, plan.b);
    let next = plan.next(a);
    let wx = (x[next].p - x[a].p).normalize();
    let kappa_x = concentration(scene, x, &plan, lambda);
    let local = square_to_von_mises_fisher(rng.next_2d(), kappa_x as f32);
    let mut ray = ray_from(&x[a], Frame::from_normal(wx).to_world(local));
    // From `a` through the same Dirac lobes to the new `b`.
    let mut y = x.to_vec();
    for i in plan.span(a, b) {
        let follow = i != b;
        y[i] = retrace(scene, &mut ray, x, i, follow, counters)?;
    }
    if b == 0 {
        y[0] = as_light(scene, &y[0])?;
    } else if !connectible(scene, &y[b]) {
        return None;
    }
    // From `c` through the specular chain to the new `b`.
    let mut chains = None;
    if let Some(c) = plan.c {
        if c.abs_diff(b) == 1 {
            if !join(scene, &y[b], &y[c], counters) {
                return None;
            }
        } else {
            let current = chain_of(scene, x, &plan)?;
            walks.tried += 1;
            let walked = manifold::walk(scene, &current, y[b].p, TOLERANCE).chain?;
            walks.converged += 1;
            if !manifold::returns_to(scene, &walked, &current, TOLERANCE) {
                walks.irreversible += 1;
                return None;
            }
            for (si, i) in walked.hits.iter().zip(plan.reversed().span(c, b)).filter(|&(_, i)| i != b) {
                y[i] = surface_vertex(scene, si, true);
            }
            chains = Some((current, walked));
        }
    }
    // The reverse move must be planned the same way.
    if self::plan(scene, &y, a, plan.toward_light) != Some(plan) {
        return None;
    }
    let n_y = plans(scene, &y).count();
    let measured = contribution(scene, &y)?;
    let wy = (y[next].p - y[a].p).normalize();
    let d2 = (wy - wx).length_squared() as f64;
    let kappa_y = concentration(scene, &y, &plan, lambda);
    let forward = vmf_density(d2, kappa_x) * jacobian(scene, &y, &plan, chains.as_ref().map(|c| &c.1))? / n_x as f64;
    let backward = vmf_density(d2, kappa_y) * jacobian(scene, x, &plan, chains.as_ref().map(|c| &c.0))? / n_y as f64;
    Some(Proposal { path: y, measured, forward, backward })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vmf_density_integrates_to_one() {
        for kappa in [0.5, 20.0, 2000.0] {
            // ∫ p 2π sin θ dθ, midpoint rule, with `d² = 2 (1 - cos θ)`.
            let n = 400_000;
            let h = std::f64::consts::PI / n as f64;
            let total: f64 = (0..n)
                .map(|i| {
                    let t = (i as f64 + 0.5) * h;
                    vmf_density(2.0 * (1.0 - t.cos()), kappa) * 2.0 * std::f64::consts::PI * t.sin() * h
                })
                .sum();
            assert!((total - 1.0).abs() < 1e-3, "κ {kappa}: {total}");
        }
    }
}
