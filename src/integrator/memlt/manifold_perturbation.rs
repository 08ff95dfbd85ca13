//! The manifold perturbation of Manifold Exploration (Jakob and Marschner 2012; contract
//! `memlt.md`, "Manifold perturbation"), on the specular constraints, walk and densities of
//! [`crate::integrator::manifold`].
//!
//! A move is planned from the path's structure alone ([`Plan`]): a non-specular vertex `a`
//! (a rough surface, the pinhole or the light) and a direction of travel along the path;
//! `b`, the first non-specular vertex after the specular vertices that follow `a`; `c`, the
//! first non-specular vertex after the specular chain that follows `b` (none when `b` is the
//! light's point). The plan that starts at the camera is chosen with probability
//! [`SENSOR_PROBABILITY`] where the path admits it (Mitsuba 0.6's preference), otherwise one
//! uniformly among all those the path admits. The direction
//! leaving `a` is turned by a von Mises–Fisher lobe around the current one, of peak density
//! `max(1/4π, p) λ²` with `p` the scattering density of the current direction at `a`; the
//! ray is followed through the same Dirac lobes to the new `b`. Between `b` and `c` the
//! specular chain is walked onto its manifold, `c` fixed, until it ends at the new `b`; the
//! walk back from the proposal must return to the current path. One more plan moves the
//! light point itself ([`position_plan`]): an area light's point is displaced in its tangent
//! plane by a Gaussian whose density peaks at the light walk's density of the point times
//! `λ²`, projected back onto the light along its normal, and joined to `c`, the first rough
//! vertex after it, directly or through the specular chain between them, walked from `c`
//! to the new point (the walk back from the new point must find the current one; the
//! pinhole, the other end, has no area to move on).
//!
//! Under a light at infinity (`x_0` a direction) no plan starts at `x_0` (the direction it
//! sends light along is its own) or walks a chain to it (its edge has no length to walk
//! along); a plan towards the light may end there (`b = 0`: the moved ray leaves the scene,
//! and the light is found in its direction, a density per unit solid angle). The position
//! plan moves the line the light arrives along instead of `x_0`: displaced across its
//! direction by a Gaussian of deviation `R / (√2 λ)` (the density of the disk the light
//! walk enters from, `1 / (π R²)`, times `λ²` at its peak), it finds `x_1` and is followed
//! through the path's Dirac lobes to `b`; `|cos θ_1|` takes the offset's density to `x_1`'s
//! area, and the area factors of a walk from there on to `b`'s (a sun's caustic through
//! glass moves so).
//!
//! Which vertices count as specular is drawn before the plan ([`Treatment`]): Dirac ones
//! always, diffuse ones never, a glossy one with a probability set by its lobe's width
//! against `--theta-diff` ([`manifold::nonspecular_probability`]); the probability of the
//! draw enters both densities. A glossy vertex treated as specular keeps its half-vector in
//! its frame (the offset manifold of its constraint): followed from `a` by
//! [`manifold::scatter_about`], walked between `b` and `c` by the walk's re-traces.
//!
//! Densities are in the convention of the walks of [`crate::integrator::memlt::path`] (each vertex reached
//! along a ray has area density `|cos| / d²` per unit solid angle behind it, the Dirac lobes'
//! coefficients left to `f`). From `a` to `b` they are those of a walk in the direction of
//! travel; from `b` to `c` those of a walk continuing past `b` whose direction at `b` is the
//! one that reaches `c`: the chain's `|cos| / d²` factors over `dω_b / dA_c`, the solid angle
//! at `b` per unit area at `c` through the chain (1 when `b` and `c` are neighbours). A
//! glossy vertex treated as specular adds the density its kept half-vector gives the
//! direction leaving it in the direction of travel ([`manifold::half_vector_density`]): with
//! the half-vectors as the coordinates of those vertices, the map from `a`'s direction and
//! the half-vectors to the positions is triangular along the direction of travel, and from
//! `b` to `c` the chain's `dω_b / dA_c` is that of the whole offset chain.

use crate::accel::Ray;
use crate::bsdf::TransportMode;
use crate::integrator::bidir::{Vertex, VertexKind, disk_pdf};
use crate::integrator::manifold::{self, Half, Scatter, TracedChain};
use crate::integrator::memlt::bidirectional::Proposal;
use crate::integrator::memlt::path::{
    area_factor, as_light, connectible, contribution, hittable_light, join, lobe_pdf, pdf_from_light, ray_from,
    reflects, retrace, settle_sky, sky_vertex, surface_vertex,
};
use crate::integrator::stats::Counters;
use crate::math::Frame;
use crate::sampling::{Random, square_to_gaussian_2d, square_to_gaussian_2d_pdf, square_to_von_mises_fisher};
use crate::scene::Scene;
use glam::DVec3;
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
    /// The light point itself moves (`a = b = 0`, towards the camera): displaced on its
    /// light's surface by a Gaussian, then joined to `c` (through the specular chain between
    /// them where there is one).
    pub position: bool,
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
    /// Perturbations that treated a glossy vertex as specular.
    pub glossy: u64,
    /// Perturbations that moved the light point on its surface.
    pub light_points: u64,
    /// Perturbations that moved the line a light at infinity arrives along.
    pub sky_points: u64,
}

impl std::ops::AddAssign for WalkStats {
    fn add_assign(&mut self, o: WalkStats) {
        self.tried += o.tried;
        self.converged += o.converged;
        self.irreversible += o.irreversible;
        self.glossy += o.glossy;
        self.light_points += o.light_points;
        self.sky_points += o.sky_points;
    }
}

/// Whether `x_i` scatters through a Dirac lobe.
#[inline]
fn dirac(x: &Vertex) -> bool {
    x.kind == VertexKind::Surface && x.delta
}

/// The 90% half-angle of the glossy lobe through which interior vertex `x_i` scatters (by
/// reflection or transmission, as it does; the narrowest where there are several); `None`
/// for endpoints, Dirac and diffuse scattering.
fn glossy_half_angle(scene: &Scene, x: &[Vertex], i: usize) -> Option<f64> {
    let v = &x[i];
    if v.kind != VertexKind::Surface || v.delta || i == 0 || i + 1 >= x.len() {
        return None;
    }
    let transmission = !reflects(x, i);
    v.bsdf(scene)
        .lobes(v.uv)
        .filter(|l| l.transmission == transmission && l.roughness > 0.0 && l.roughness.is_finite())
        .filter_map(|l| Some(manifold::lobe_half_angle(l.microfacet?, l.roughness as f64)))
        .min_by(f64::total_cmp)
}

/// Which vertices of a path a manifold perturbation treats as specular (contract
/// `memlt.md`, "Manifold perturbation", step 2).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Treatment(Vec<bool>);

impl Treatment {
    /// Dirac vertices only: what decides whether the perturbation suits a path.
    fn dirac(x: &[Vertex]) -> Treatment {
        Treatment(x.iter().map(dirac).collect())
    }

    /// A draw: Dirac vertices specular, diffuse ones not, each glossy one specular with
    /// probability `1 - nonspecular_probability(θ_d, theta_diff)` (never at `theta_diff` 0).
    fn draw<R: Random>(scene: &Scene, x: &[Vertex], theta_diff: f64, rng: &mut R) -> Treatment {
        if theta_diff <= 0.0 {
            return Treatment::dirac(x);
        }
        Treatment(
            (0..x.len())
                .map(|i| match glossy_half_angle(scene, x, i) {
                    Some(t) => (rng.next_1d() as f64) >= manifold::nonspecular_probability(Some(t), theta_diff),
                    None => dirac(&x[i]),
                })
                .collect(),
        )
    }

    /// The probability of this treatment of path `x`'s vertices `indices` (a move's changed
    /// vertices: the others are the same in both paths, and so are their probabilities).
    fn probability(&self, scene: &Scene, x: &[Vertex], theta_diff: f64, indices: impl Iterator<Item = usize>) -> f64 {
        if theta_diff <= 0.0 {
            return f64::from(u8::from(self.0.iter().zip(x).all(|(&s, v)| s == dirac(v))));
        }
        indices
            .map(|i| match glossy_half_angle(scene, x, i) {
                Some(t) => {
                    let p = manifold::nonspecular_probability(Some(t), theta_diff);
                    if self.0[i] { 1.0 - p } else { p }
                }
                None => f64::from(u8::from(self.0[i] == dirac(&x[i]))),
            })
            .product()
    }

    /// Whether `x_i` is treated as specular.
    fn specular(&self, i: usize) -> bool {
        self.0[i]
    }

    /// Whether `x_i` is a glossy vertex treated as specular.
    fn glossy(&self, x: &[Vertex], i: usize) -> bool {
        self.0[i] && !x[i].delta
    }
}

/// The plan from `a` in the given direction, when the path's structure and the treatment of
/// its vertices admit one.
pub fn plan(scene: &Scene, x: &[Vertex], a: usize, toward_light: bool, treatment: &Treatment) -> Option<Plan> {
    let k = x.len() - 1;
    let specular = |i: usize| treatment.specular(i);
    let ok_start = match x[a].kind {
        VertexKind::Camera => toward_light,
        VertexKind::Light(_) => !toward_light,
        VertexKind::Surface => connectible(scene, &x[a]) && !specular(a),
        // MEMLT renders no media (scenes with them are refused).
        VertexKind::Sky | VertexKind::Medium => false,
    };
    // A light at infinity starts no plan (the direction it sends light along is its own)
    // and ends no walk (its edge has no length to walk along).
    if !ok_start || (toward_light && a == 0) || (!toward_light && a == k) || (x[0].infinite && a == 0) {
        return None;
    }
    let step = |i: usize| if toward_light { i.checked_sub(1) } else { (i < k).then_some(i + 1) };
    let mut b = step(a)?;
    while specular(b) {
        b = step(b)?;
    }
    if b == 0 {
        // The moved ray must find the light: not a point or spot light's position, nor a
        // directional light's direction (a light at infinity it finds by leaving the scene).
        return hittable_light(scene, &x[0]).then_some(Plan { a, toward_light, b, c: None, position: false });
    }
    if b == k || !connectible(scene, &x[b]) {
        return None;
    }
    let mut c = step(b)?;
    while specular(c) {
        c = step(c)?;
    }
    // A specular chain cannot end at the pinhole: it has no area to find it on.
    if (c == k && c.abs_diff(b) > 1) || (c == 0 && x[0].infinite) {
        return None;
    }
    (x[c].kind != VertexKind::Surface || connectible(scene, &x[c])).then_some(Plan {
        a,
        toward_light,
        b,
        c: Some(c),
        position: false,
    })
}

/// The plan that moves the light point on its surface, where the path admits it: an area
/// light's point and `c`, the first rough vertex after it, joined to the moved point directly
/// (`c = 1`) or through the specular chain between them, walked onto its manifold from `c`
/// (not the pinhole: a path of one edge is the direct light's, or moves with the camera's
/// plans, and no chain can end at the pinhole). Under a light
/// at infinity the line the light arrives along moves instead, its direction kept: `x_1`
/// is the first surface on the displaced line, the light follows the path's Dirac lobes (and
/// kept half-vectors) from there to `b`, the first non-specular vertex after `x_0`, which is
/// joined to `c`, the first non-specular vertex after it (through a specular chain walked
/// onto its manifold where there is one).
pub fn position_plan(scene: &Scene, x: &[Vertex], treatment: &Treatment) -> Option<Plan> {
    let k = x.len() - 1;
    if !x[0].infinite {
        // `c` is the first rough vertex after the light point; the specular chain between
        // them is walked from `c` to the moved point (a caustic's light point moves with
        // the point on the floor kept).
        if !hittable_light(scene, &x[0]) || k < 2 {
            return None;
        }
        let mut c = 1;
        while c < k && treatment.specular(c) {
            c += 1;
        }
        let ok = c < k && x[c].kind == VertexKind::Surface && connectible(scene, &x[c]);
        return ok.then_some(Plan { a: 0, toward_light: false, b: 0, c: Some(c), position: true });
    }
    let mut b = 1;
    while b < k && treatment.specular(b) {
        b += 1;
    }
    if b >= k || x[b].kind != VertexKind::Surface || !connectible(scene, &x[b]) {
        return None;
    }
    let mut c = b + 1;
    while c < k && treatment.specular(c) {
        c += 1;
    }
    // A specular chain cannot end at the pinhole: it has no area to find it on.
    let ok = (c < k || c == b + 1) && (x[c].kind != VertexKind::Surface || connectible(scene, &x[c]));
    ok.then_some(Plan { a: 0, toward_light: false, b, c: Some(c), position: true })
}

/// The line a light at infinity (direction `w` towards the light) arrives at `x1` along,
/// moved across `w` by `offset` (in the frame of `w`): the ray along it from beyond the
/// scene.
fn displaced_sky_ray(scene: &Scene, x1: glam::Vec3, w: glam::Vec3, offset: glam::Vec2) -> Ray {
    let q = displaced(w, x1, offset);
    Ray::new(scene.bounds.beyond(q, w), -w)
}

/// Every plan a path admits under a treatment, in a fixed order.
pub fn plans<'a>(scene: &'a Scene, x: &'a [Vertex], treatment: &'a Treatment) -> impl Iterator<Item = Plan> + 'a {
    position_plan(scene, x, treatment).into_iter().chain(
        (0..x.len()).flat_map(move |a| [true, false].into_iter().filter_map(move |t| plan(scene, x, a, t, treatment))),
    )
}

/// The light point `x_0` displaced by `offset` in the plane of its geometric normal and
/// projected back onto its light along that normal (the nearer of the two directions): the
/// light vertex there, `None` when neither direction finds the same light first.
fn displaced_light_point(scene: &Scene, x0: &Vertex, offset: glam::Vec2, counters: &mut Counters) -> Option<Vertex> {
    let VertexKind::Light(l) = x0.kind else { return None };
    let q = displaced(x0.ng, x0.p, offset);
    let eps = 1e-4 * (1.0 + q.abs().max_element());
    let mut best: Option<(f32, Vertex)> = None;
    for d in [-x0.ng, x0.ng] {
        counters.extension_rays += 1;
        let Some(si) = scene.intersect(&Ray::new(q - d * eps, d)) else { continue };
        let on_light = scene.shapes.get(si.shape as usize).and_then(|s| s.light) == Some(l as usize);
        let dist = (si.p - q).length();
        if on_light && best.as_ref().is_none_or(|(t, _)| dist < *t) {
            best = Some((dist, as_light(scene, &surface_vertex(scene, &si, false))?));
        }
    }
    best.map(|(_, v)| v)
}

/// The Gaussian position perturbation's standard deviation at a light point: its density
/// peaks at the light walk's density of the point times `λ²`.
fn position_sigma(scene: &Scene, x: &[Vertex], lambda: f64) -> f64 {
    // Under a light at infinity, the density of the point on the disk the light walk
    // enters from.
    let p = if x[0].infinite { disk_pdf(scene) as f64 } else { pdf_from_light(scene, x, 0) };
    1.0 / (2.0 * std::f64::consts::PI * p * lambda * lambda).sqrt()
}

/// The area density with which [`displaced_light_point`] moves `from` to `to`, deviation
/// `sigma`: the Gaussian's density of the offset in `from`'s plane times the cosine between
/// the two normals.
fn position_density(from: &Vertex, to: &Vertex, sigma: f64) -> f64 {
    square_to_gaussian_2d_pdf(across(from.ng, from.p, to.p), sigma as f32) as f64 * from.ng.dot(to.ng).abs() as f64
}

/// `p` moved by `offset` in the plane across the unit `w`, in `w`'s frame: how the light
/// point ([`displaced_light_point`], across its normal) and the line a light at infinity
/// arrives along ([`displaced_sky_ray`], across its direction) are displaced.
fn displaced(w: glam::Vec3, p: glam::Vec3, offset: glam::Vec2) -> glam::Vec3 {
    let f = Frame::from_normal(w);
    p + f.s * offset.x + f.t * offset.y
}

/// The offset of `to` from `from` across the unit `w`, in the frame [`displaced`] moves
/// points in.
fn across(w: glam::Vec3, from: glam::Vec3, to: glam::Vec3) -> glam::Vec2 {
    let f = Frame::from_normal(w);
    let rel = to - from;
    glam::Vec2::new(rel.dot(f.s), rel.dot(f.t))
}

/// The probability with which a perturbation starts at the camera, towards the light, where
/// a path admits that plan (Mitsuba 0.6's preference for perturbations from the sensor);
/// otherwise a plan is chosen uniformly among all the path admits.
pub const SENSOR_PROBABILITY: f32 = 0.25;

/// The plan that starts at the camera, when the path admits it.
fn camera_plan(scene: &Scene, x: &[Vertex], treatment: &Treatment) -> Option<Plan> {
    plan(scene, x, x.len() - 1, true, treatment)
}

/// The probability of choosing `plan` on a path that admits `n` plans, `camera` among them
/// where it admits the camera's.
fn plan_probability(plan: &Plan, camera: Option<Plan>, n: usize) -> f64 {
    match camera {
        Some(c) => {
            let s = SENSOR_PROBABILITY as f64;
            (1.0 - s) / n as f64 + if c == *plan { s } else { 0.0 }
        }
        None => 1.0 / n as f64,
    }
}

/// Whether the manifold perturbation suits `x`: a plan with its Dirac vertices alone
/// specular. (Other treatments may admit none; the perturbation then keeps the path.)
pub fn suits(scene: &Scene, x: &[Vertex]) -> bool {
    // Its chains are walked on surfaces, through no null surface or free flight.
    !scene.volumetric && plans(scene, x, &Treatment::dirac(x)).next().is_some()
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
        VertexKind::Sky | VertexKind::Medium => 0.0,
    };
    p as f64
}

/// The von Mises–Fisher concentration for a path: the lobe's peak density is
/// `max(1/4π, p) λ²`, which for a lobe this sharp (a peak of at least `λ²/4π`) is a
/// concentration of `2π` times the peak.
fn concentration(scene: &Scene, x: &[Vertex], plan: &Plan, lambda: f64) -> f64 {
    let peak = direction_density(scene, x, plan).max(1.0 / (4.0 * std::f64::consts::PI)) * lambda * lambda;
    (2.0 * std::f64::consts::PI * peak).min(1e6)
}

/// The von Mises–Fisher solid-angle density, concentration `kappa`, of a direction at
/// squared distance `d2` (between unit vectors) from the mean: `1 - cos θ = d2 / 2`, exact
/// for the small angles of sharp lobes.
fn vmf_density(d2: f64, kappa: f64) -> f64 {
    kappa / (2.0 * std::f64::consts::PI * -(-2.0 * kappa).exp_m1()) * (-kappa * d2 * 0.5).exp()
}

/// The density its kept half-vector gives the direction leaving `v_i` (a glossy vertex
/// treated as specular) in the direction of travel.
fn kept_half_density(scene: &Scene, v: &[Vertex], plan: &Plan, i: usize) -> f64 {
    let d = |j: usize| (v[j].p - v[i].p).normalize().as_dvec3();
    manifold::half_vector_density(
        d(plan.prev(i)),
        d(plan.next(i)),
        v[i].frame.n.as_dvec3(),
        v[i].bsdf(scene).eta() as f64,
    )
}

/// The density, up to the direction's, of a path's vertices `a+1 ..= b ..= c` (in the
/// direction of travel) as the plan produces them; `chain` is its specular chain from `c` to
/// `b` where `b` and `c` are not neighbours.
fn jacobian(
    scene: &Scene,
    v: &[Vertex],
    plan: &Plan,
    treatment: &Treatment,
    chain: Option<&TracedChain>,
) -> Option<f64> {
    let factors = |from: usize, to: usize| {
        plan.span(from, to)
            .map(|i| {
                let kept = if treatment.glossy(v, i) { kept_half_density(scene, v, plan, i) } else { 1.0 };
                area_factor(v, i, plan.prev(i)) * kept
            })
            .product::<f64>()
    };
    let mut j = factors(plan.a, plan.b);
    if let (Some(c), Some(chain)) = (plan.c, chain) {
        let along = factors(plan.b, c);
        let solid = chain.end_solid_angle_density(scene)?;
        j *= along / solid;
    }
    (j > 0.0 && j.is_finite()).then_some(j)
}

/// The half-vector vertex `x_i` keeps: the shading normal for a Dirac vertex, its current
/// generalized half-vector in the world for a glossy one treated as specular.
fn kept_half(scene: &Scene, x: &[Vertex], i: usize, treatment: &Treatment) -> Half {
    if treatment.glossy(x, i) { Half::World(half_vector_of(scene, x, i)) } else { Half::Normal }
}

/// The generalized half-vector of interior vertex `x_i` in the world.
fn half_vector_of(scene: &Scene, x: &[Vertex], i: usize) -> DVec3 {
    let d = |j: usize| (x[j].p - x[i].p).normalize().as_dvec3();
    manifold::half_vector(d(i - 1), d(i + 1), x[i].frame.n.as_dvec3(), x[i].bsdf(scene).eta() as f64)
}

/// How interior vertex `x_i` scatters: by reflection or by refraction.
fn scatter_of(x: &[Vertex], i: usize) -> Scatter {
    if reflects(x, i) { Scatter::Reflect } else { Scatter::Refract }
}

/// The specular chain of `x` from `c` to `b` as a traced chain: how its vertices scatter,
/// the half-vectors they keep, their shapes, and the chain re-traced from `c` through them.
/// `None` when the re-traced chain misses `x_b` by more than a thousandth of its length.
fn chain_of(scene: &Scene, x: &[Vertex], plan: &Plan, treatment: &Treatment) -> Option<TracedChain> {
    let (b, c) = (plan.b, plan.c?);
    let indices: Vec<usize> = plan.reversed().span(c, b).collect();
    let interior = &indices[..indices.len() - 1];
    let scatters: Vec<Scatter> = interior.iter().map(|&i| scatter_of(x, i)).collect();
    let halves: Vec<Half> = interior.iter().map(|&i| kept_half(scene, x, i, treatment)).collect();
    let shapes: Vec<u32> = indices.iter().map(|&i| shape_of(scene, &x[i])).collect();
    let chain = manifold::trace(scene, (x[c].p, x[c].ng), x[indices[0]].p, (&scatters, &halves), &shapes)?;
    ((chain.end().p - x[b].p).length() as f64 <= 1e-3 * chain.length()).then_some(chain)
}

/// The shape a vertex lies on: an area light's point sampled on its light carries none.
fn shape_of(scene: &Scene, v: &Vertex) -> u32 {
    match v.kind {
        VertexKind::Light(l) if v.shape == u32::MAX => match scene.lights[l as usize] {
            crate::light::Light::Area { shape, .. } => shape as u32,
            _ => v.shape,
        },
        _ => v.shape,
    }
}

/// Re-traces glossy vertex `x_i` along `ray` keeping its half-vector: the hit's vertex, and
/// the ray turned into the one leaving it with `x_i`'s half-vector in the hit's shading
/// frame. `None` when the ray leaves the scene or the half-vector cannot be kept there.
fn retrace_glossy(scene: &Scene, ray: &mut Ray, x: &[Vertex], i: usize, counters: &mut Counters) -> Option<Vertex> {
    let h = half_vector_of(scene, x, i);
    let f = &x[i].frame;
    let local = DVec3::new(h.dot(f.s.as_dvec3()), h.dot(f.t.as_dvec3()), h.dot(f.n.as_dvec3()));
    counters.extension_rays += 1;
    let si = scene.intersect(ray)?;
    let v = surface_vertex(scene, &si, false);
    let g = &v.frame;
    let m = g.s.as_dvec3() * local.x + g.t.as_dvec3() * local.y + g.n.as_dvec3() * local.z;
    let eta = v.bsdf(scene).eta() as f64;
    let wo = manifold::scatter_about(si.wo.as_dvec3().normalize(), m, g.n.as_dvec3(), eta, scatter_of(x, i))?;
    *ray = si.spawn_ray(wo.as_vec3());
    Some(v)
}

/// Follows the moved `ray` through `x`'s Dirac lobes and kept half-vectors to the new `b`
/// (from `a`, or from beyond the scene for a light at infinity's displaced line), writing
/// the vertices it finds into `y`: the light at `b = 0` (at infinity the ray must leave the
/// scene), else a vertex that can take a connection. `None` when the ray does not get there.
fn follow(
    scene: &Scene,
    mut ray: Ray,
    x: &[Vertex],
    y: &mut [Vertex],
    plan: &Plan,
    treatment: &Treatment,
    counters: &mut Counters,
) -> Option<()> {
    let (a, b) = (plan.a, plan.b);
    for i in plan.span(a, b) {
        y[i] = if i == 0 && x[0].infinite {
            counters.extension_rays += 1;
            if scene.intersect(&ray).is_some() {
                return None;
            }
            sky_vertex(scene, None, ray.o, ray.d)?
        } else if treatment.glossy(x, i) {
            retrace_glossy(scene, &mut ray, x, i, counters)?
        } else {
            retrace(scene, &mut ray, &mut None, x, i, i != b, counters)?
        };
    }
    // A light at infinity back on the line from the (possibly moved) `x_1`.
    settle_sky(scene, y);
    if b == 0 && !x[0].infinite {
        y[0] = as_light(scene, &y[0])?;
    } else if b > 0 && !connectible(scene, &y[b]) {
        return None;
    }
    Some(())
}

/// Proposes a manifold perturbation of `x`, with `lambda` the lobe's sharpness and
/// `theta_diff` (radians) the half-vector change glossy lobes are judged against.
pub fn propose<R: Random>(
    scene: &Scene,
    x: &[Vertex],
    (lambda, theta_diff): (f64, f64),
    rng: &mut R,
    counters: &mut Counters,
    walks: &mut WalkStats,
) -> Option<Proposal> {
    let treatment = Treatment::draw(scene, x, theta_diff, rng);
    let n_x = plans(scene, x, &treatment).count();
    let camera_x = camera_plan(scene, x, &treatment);
    let u = rng.next_1d();
    let plan = match camera_x {
        Some(p) if u < SENSOR_PROBABILITY => p,
        _ => {
            let u = if camera_x.is_some() { (u - SENSOR_PROBABILITY) / (1.0 - SENSOR_PROBABILITY) } else { u };
            let pick = ((u * n_x as f32) as usize).min(n_x.checked_sub(1)?);
            plans(scene, x, &treatment).nth(pick)?
        }
    };
    let (a, b) = (plan.a, plan.b);
    // The vertices the move changes.
    let changed = || plan.span(a, plan.c.unwrap_or(b));
    if changed().any(|i| treatment.glossy(x, i)) {
        walks.glossy += 1;
    }
    let next = plan.next(a);
    let wx = (x[next].p - x[a].p).normalize();
    let mut y = x.to_vec();
    let mut kappa_x = 0.0;
    // The position perturbation's deviation at the current light point (plans that move it).
    let sigma_x = if plan.position { position_sigma(scene, x, lambda) } else { 0.0 };
    if plan.position && x[0].infinite {
        // The line the light arrives at `x_1` along, displaced across its direction, and
        // the light followed through the same Dirac lobes to the new `b`.
        walks.sky_points += 1;
        let offset = square_to_gaussian_2d(rng.next_2d(), sigma_x as f32);
        let ray = displaced_sky_ray(scene, x[1].p, x[0].ng, offset);
        follow(scene, ray, x, &mut y, &plan, &treatment, counters)?;
    } else if plan.position {
        // The light point moved on its surface.
        walks.light_points += 1;
        let offset = square_to_gaussian_2d(rng.next_2d(), sigma_x as f32);
        y[0] = displaced_light_point(scene, &x[0], offset, counters)?;
    } else {
        kappa_x = concentration(scene, x, &plan, lambda);
        let local = square_to_von_mises_fisher(rng.next_2d(), kappa_x as f32);
        let ray = ray_from(&x[a], Frame::from_normal(wx).to_world(local));
        follow(scene, ray, x, &mut y, &plan, &treatment, counters)?;
    }
    // From `c` through the specular chain to the new `b`.
    let mut chains = None;
    if let Some(c) = plan.c {
        if c.abs_diff(b) == 1 {
            if !join(scene, &y[b], &y[c], counters) {
                return None;
            }
        } else {
            let current = chain_of(scene, x, &plan, &treatment)?;
            walks.tried += 1;
            let walked = manifold::walk(scene, &current, y[b].p, TOLERANCE).chain?;
            walks.converged += 1;
            if !manifold::returns_to(scene, &walked, &current, TOLERANCE) {
                walks.irreversible += 1;
                return None;
            }
            for (si, i) in walked.hits.iter().zip(plan.reversed().span(c, b)).filter(|&(_, i)| i != b) {
                y[i] = surface_vertex(scene, si, x[i].delta);
            }
            chains = Some((current, walked));
        }
    }
    // The reverse move must be planned the same way (and a moved light point must be found
    // again from the new one).
    if plan.position && x[0].infinite {
        if position_plan(scene, &y, &treatment) != Some(plan) {
            return None;
        }
        let w = x[0].ng;
        counters.extension_rays += 1;
        let back = scene.intersect(&displaced_sky_ray(scene, y[1].p, w, across(w, y[1].p, x[1].p)))?;
        let scale = 1.0 + x[1].p.abs().max_element();
        if ((back.p - x[1].p).length() as f64) > 1e-3 * sigma_x + 1e-5 * scale as f64 {
            return None;
        }
    } else if plan.position {
        if position_plan(scene, &y, &treatment) != Some(plan) {
            return None;
        }
        let back = displaced_light_point(scene, &y[0], across(y[0].ng, y[0].p, x[0].p), counters)?;
        let scale = 1.0 + x[0].p.abs().max_element();
        if ((back.p - x[0].p).length() as f64) > 1e-3 * sigma_x + 1e-5 * scale as f64 {
            return None;
        }
    } else if self::plan(scene, &y, a, plan.toward_light, &treatment) != Some(plan) {
        return None;
    }
    let n_y = plans(scene, &y, &treatment).count();
    let (p_x, p_y) =
        (plan_probability(&plan, camera_x, n_x), plan_probability(&plan, camera_plan(scene, &y, &treatment), n_y));
    let measured = contribution(scene, &y)?;
    // The densities of the moved vertex: the line's offset across a light at infinity's
    // direction (the Jacobian's factor `|cos θ_1|` takes it to `x_1`'s area), the light
    // point's position, or `a`'s direction.
    let (moved_x, moved_y) = if plan.position && x[0].infinite {
        let offset = across(x[0].ng, x[1].p, y[1].p);
        let gaussian = square_to_gaussian_2d_pdf(offset, sigma_x as f32) as f64;
        (gaussian, gaussian)
    } else if plan.position {
        (position_density(&x[0], &y[0], sigma_x), position_density(&y[0], &x[0], position_sigma(scene, &y, lambda)))
    } else {
        let wy = (y[next].p - y[a].p).normalize();
        let d2 = (wy - wx).length_squared() as f64;
        (vmf_density(d2, kappa_x), vmf_density(d2, concentration(scene, &y, &plan, lambda)))
    };
    let (t_x, t_y) = (
        treatment.probability(scene, x, theta_diff, changed()),
        treatment.probability(scene, &y, theta_diff, changed()),
    );
    let jacobian = |v: &[Vertex], chain: Option<&TracedChain>| jacobian(scene, v, &plan, &treatment, chain);
    let forward = moved_x * jacobian(&y, chains.as_ref().map(|c| &c.1))? * t_x * p_x;
    let backward = moved_y * jacobian(x, chains.as_ref().map(|c| &c.0))? * t_y * p_y;
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
