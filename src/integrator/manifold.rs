//! Manifold Exploration's specular constraints (Jakob and Marschner 2012; contract
//! `memlt.md`, "Manifold perturbation", steps 6 and 8): the generalized half-vector
//! constraints of a chain of specular vertices between two fixed ends, their block-tridiagonal
//! Jacobian with respect to the vertices' surface parameters, its block-LU solve (the tangent
//! map a Newton step of the manifold walk takes) and its determinant (the factor the
//! transition density of the manifold perturbation carries).
//!
//! A chain is `x_0, x_1, …, x_k, x_{k+1}`: the ends are fixed, `x_1 … x_k` are specular. At a
//! specular vertex the generalized half-vector `h = η(wi) wi + η(wo) wo`, with `wi`, `wo`
//! the unit directions to its neighbours and `η(w)` the index of refraction on `w`'s side (1
//! outside, the BSDF's relative `eta` inside: for a reflection both are equal and `h` is the
//! usual half-vector), must point along the shading normal: the constraint is `(ĥ · s, ĥ · t)
//! = 0` in the vertex's shading frame `(s, t, n)`.
//!
//! Each vertex carries the first-order geometry of its surface (`dp/du`, `dp/dv`, `dn/du`,
//! `dn/dv` from [`crate::scene::shape::Shape::tangents`] and
//! [`crate::scene::shape::Shape::normal_derivatives`]): around it the chain is a function of
//! the parameters `(u, v)` of every vertex, with `p(u, v) = p + u dp/du + v dp/dv`, the normal
//! `n + u dn/du + v dn/dv` normalised, and the frame's tangent `s` the reference tangent
//! projected onto the tangent plane (so the frame turns with the normal: `ds = -n (dn · s)`).
//! All in `f64`: the walk's Newton steps compare constraints near zero.
//!
//! [`walk`] moves a chain traced through a scene ([`TracedChain`]) along its manifold until
//! its end reaches a target: Newton steps on the first specular vertex from the tangent map,
//! the chain re-traced from its fixed start by specular scattering after each.

use crate::accel::Ray;
use crate::bsdf::fresnel::refract;
use crate::math::reflect;
use crate::scene::Scene;
use crate::scene::shape::SurfaceInteraction;
use glam::{DMat2, DVec2, DVec3, Vec3};

/// A vertex of a chain: its position and normal with their first derivatives in the surface's
/// parameters, the tangent of its constraint frame, and the relative index of refraction of
/// its surface (interior over exterior; 1 for a mirror, which makes `h` the half-vector).
#[derive(Clone, Copy, Debug)]
pub struct ChainVertex {
    pub p: DVec3,
    pub dp_du: DVec3,
    pub dp_dv: DVec3,
    /// Unit shading normal.
    pub n: DVec3,
    pub dn_du: DVec3,
    pub dn_dv: DVec3,
    /// Unit tangent of the constraint frame (`dp/du` projected onto the tangent plane).
    pub s: DVec3,
    pub eta: f64,
}

impl ChainVertex {
    /// A vertex from its surface's first-order geometry; `None` when `dp/du` is parallel to
    /// the normal (no tangent frame).
    pub fn new(
        p: DVec3,
        (dp_du, dp_dv): (DVec3, DVec3),
        n: DVec3,
        (dn_du, dn_dv): (DVec3, DVec3),
        eta: f64,
    ) -> Option<Self> {
        let s = (dp_du - n * n.dot(dp_du)).try_normalize()?;
        Some(ChainVertex { p, dp_du, dp_dv, n, dn_du, dn_dv, s, eta })
    }

    /// The position's first-order change for a step `(du, dv)` in the surface's parameters.
    pub fn displacement(&self, d: DVec2) -> DVec3 {
        self.dp_du * d.x + self.dp_dv * d.y
    }

    /// The vertex moved by `(du, dv)` in its surface's parameters, to first order (the
    /// chain as a function of the parameters, which the Jacobian differentiates).
    pub fn moved(&self, d: DVec2) -> ChainVertex {
        let n = (self.n + self.dn_du * d.x + self.dn_dv * d.y).normalize();
        ChainVertex { p: self.p + self.displacement(d), n, s: (self.s - n * n.dot(self.s)).normalize(), ..*self }
    }

    fn t(&self) -> DVec3 {
        self.n.cross(self.s)
    }

    /// The index of refraction on the side of `w`.
    fn eta_towards(&self, w: DVec3) -> f64 {
        if w.dot(self.n) >= 0.0 { 1.0 } else { self.eta }
    }
}

/// The constraint of specular vertex `x` between `prev` and `next`.
fn constraint(prev: DVec3, x: &ChainVertex, next: DVec3) -> DVec2 {
    let (wi, wo) = ((prev - x.p).normalize(), (next - x.p).normalize());
    let h = (wi * x.eta_towards(wi) + wo * x.eta_towards(wo)).normalize();
    DVec2::new(h.dot(x.s), h.dot(x.t()))
}

/// The constraints of the chain's specular vertices `x_1 … x_k`.
pub fn constraints(chain: &[ChainVertex]) -> Vec<DVec2> {
    chain.windows(3).map(|w| constraint(w[0].p, &w[1], w[2].p)).collect()
}

/// The derivatives of a unit vector `w = d / |d|` along `dd`: `(I - w wᵀ) dd / |d|`.
fn unit_derivative(w: DVec3, len: f64, dd: DVec3) -> DVec3 {
    (dd - w * w.dot(dd)) / len
}

/// The Jacobian of the constraints in block-tridiagonal form: row `i` (vertex `x_{i+1}`) has
/// `below[i]` (with respect to the previous vertex's `(u, v)`), `diagonal[i]` (its own) and
/// `above[i]` (the next vertex's). `below[0]` belongs to the fixed start and `above[k - 1]`
/// to the fixed end: they are the right-hand sides of a walk that moves an end.
#[derive(Clone, Debug)]
pub struct Jacobian {
    pub below: Vec<DMat2>,
    pub diagonal: Vec<DMat2>,
    pub above: Vec<DMat2>,
}

/// The Jacobian of [`constraints`] with respect to every vertex's surface parameters.
pub fn jacobian(chain: &[ChainVertex]) -> Jacobian {
    let k = chain.len().saturating_sub(2);
    let mut jac =
        Jacobian { below: Vec::with_capacity(k), diagonal: Vec::with_capacity(k), above: Vec::with_capacity(k) };
    for w in chain.windows(3) {
        let (prev, x, next) = (&w[0], &w[1], &w[2]);
        let (di, dn) = (prev.p - x.p, next.p - x.p);
        let (li, lo) = (di.length(), dn.length());
        let (wi, wo) = (di / li, dn / lo);
        let (ei, eo) = (x.eta_towards(wi), x.eta_towards(wo));
        let h = wi * ei + wo * eo;
        let hl = h.length();
        let hn = h / hl;
        let t = x.t();
        // The constraint's change for a change `dh` of the unnormalised half-vector and
        // `(ds, dt)` of the frame.
        let dc = |dh: DVec3, ds: DVec3, dt: DVec3| {
            let dhn = unit_derivative(hn, hl, dh);
            DVec2::new(dhn.dot(x.s) + hn.dot(ds), dhn.dot(t) + hn.dot(dt))
        };
        // A neighbour moving along `dp` changes one direction; the vertex itself moving
        // along `dp` changes both, and turns its frame with the normal's change `dnrm`.
        let neighbour =
            |w: DVec3, len: f64, eta: f64, dp: DVec3| dc(unit_derivative(w, len, dp) * eta, DVec3::ZERO, DVec3::ZERO);
        let own = |dp: DVec3, dnrm: DVec3| {
            let dh = unit_derivative(wi, li, -dp) * ei + unit_derivative(wo, lo, -dp) * eo;
            dc(dh, -x.n * dnrm.dot(x.s), -x.n * dnrm.dot(t))
        };
        jac.below.push(DMat2::from_cols(neighbour(wi, li, ei, prev.dp_du), neighbour(wi, li, ei, prev.dp_dv)));
        jac.diagonal.push(DMat2::from_cols(own(x.dp_du, x.dn_du), own(x.dp_dv, x.dn_dv)));
        jac.above.push(DMat2::from_cols(neighbour(wo, lo, eo, next.dp_du), neighbour(wo, lo, eo, next.dp_dv)));
    }
    jac
}

impl Jacobian {
    /// The pivots `D_i = B_i - A_i D_{i-1}⁻¹ C_{i-1}` of the block LU factorisation of the
    /// specular vertices' part (the matrix without the ends' columns); `None` when one is
    /// singular.
    fn pivots(&self) -> Option<Vec<DMat2>> {
        let mut pivots: Vec<DMat2> = Vec::with_capacity(self.diagonal.len());
        for i in 0..self.diagonal.len() {
            let d = match pivots.last() {
                None => self.diagonal[i],
                Some(prev) => self.diagonal[i] - self.below[i] * inverse(*prev)? * self.above[i - 1],
            };
            pivots.push(d);
        }
        Some(pivots)
    }

    /// The determinant of the specular vertices' part: the product of the pivots'.
    pub fn determinant(&self) -> f64 {
        self.pivots().map_or(0.0, |p| p.iter().map(|d| d.determinant()).product())
    }

    /// Solves `J Δ = r` for the specular vertices' parameter steps `Δ` (block Thomas
    /// algorithm); `None` when the matrix is singular.
    pub fn solve(&self, r: &[DVec2]) -> Option<Vec<DVec2>> {
        let k = self.diagonal.len();
        assert_eq!(r.len(), k, "one right-hand side per specular vertex");
        let pivots = self.pivots()?;
        let inv: Vec<DMat2> = pivots.iter().map(|d| inverse(*d)).collect::<Option<_>>()?;
        // Forward: y_i = r_i - A_i D_{i-1}⁻¹ y_{i-1}.
        let mut y = r.to_vec();
        for i in 1..k {
            let carried = self.below[i] * (inv[i - 1] * y[i - 1]);
            y[i] -= carried;
        }
        // Back: Δ_i = D_i⁻¹ (y_i - C_i Δ_{i+1}).
        let mut x = vec![DVec2::ZERO; k];
        for i in (0..k).rev() {
            let rhs = if i + 1 < k { y[i] - self.above[i] * x[i + 1] } else { y[i] };
            x[i] = inv[i] * rhs;
        }
        Some(x)
    }

    /// The specular vertices' first-order steps when the chain's end `x_{k+1}` moves by `d`
    /// in its parameters and the constraints stay zero: `Δ = -J⁻¹ (C_k d)` (the tangent map).
    pub fn follow_end(&self, d: DVec2) -> Option<Vec<DVec2>> {
        let k = self.diagonal.len();
        let mut r = vec![DVec2::ZERO; k];
        r[k.checked_sub(1)?] = -(self.above[k - 1] * d);
        self.solve(&r)
    }
}

/// The inverse of a 2×2 matrix; `None` when it is singular.
fn inverse(m: DMat2) -> Option<DMat2> {
    let det = m.determinant();
    (det != 0.0 && det.is_finite()).then(|| m.inverse())
}

/// How a specular vertex scatters the chain: about its shading normal, by reflection or by
/// refraction with its BSDF's relative index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scatter {
    Reflect,
    Refract,
}

/// A chain traced through a scene: a fixed start (a point, not necessarily on a surface),
/// the hits of its specular vertices, and last the hit of its end.
#[derive(Clone, Debug)]
pub struct TracedChain {
    pub start: Vec3,
    /// The geometric normal of the surface the start lies on (rays leave it offset off that
    /// surface); zero for a point in space.
    pub start_ng: Vec3,
    pub hits: Vec<SurfaceInteraction>,
}

impl TracedChain {
    /// The end's hit.
    pub fn end(&self) -> &SurfaceInteraction {
        self.hits.last().expect("a chain has an end")
    }

    /// The chain's length, start to end (the scale of a walk's tolerance).
    pub fn length(&self) -> f64 {
        let mut prev = self.start;
        self.hits
            .iter()
            .map(|h| {
                let segment = (h.p - prev).length() as f64;
                prev = h.p;
                segment
            })
            .sum()
    }

    /// How each specular vertex scatters: a reflection where its neighbours lie on one side
    /// of its shading normal.
    pub fn scatters(&self) -> Vec<Scatter> {
        let k = self.hits.len().saturating_sub(1);
        (0..k)
            .map(|i| {
                let prev = if i == 0 { self.start } else { self.hits[i - 1].p };
                let (x, next) = (&self.hits[i], self.hits[i + 1].p);
                let n = x.shading.n;
                if (prev - x.p).dot(n) * (next - x.p).dot(n) > 0.0 { Scatter::Reflect } else { Scatter::Refract }
            })
            .collect()
    }

    /// The chain's vertices with their surfaces' first-order geometry; `None` where a
    /// surface has no tangent frame. The start gets a placeholder frame: it never moves.
    pub fn vertices(&self, scene: &Scene) -> Option<Vec<ChainVertex>> {
        let d = |v: Vec3| v.as_dvec3();
        let start = ChainVertex::new(d(self.start), (DVec3::X, DVec3::Y), DVec3::Z, (DVec3::ZERO, DVec3::ZERO), 1.0)?;
        let mut out = vec![start];
        for si in &self.hits {
            let shape = &scene.shapes[si.shape as usize];
            let (dp_du, dp_dv) = shape.tangents(si);
            let (dn_du, dn_dv) = shape.normal_derivatives(si);
            let eta = scene.bsdf(si).eta() as f64;
            let n = si.shading.n.as_dvec3().normalize();
            out.push(ChainVertex::new(d(si.p), (d(dp_du), d(dp_dv)), n, (d(dn_du), d(dn_dv)), eta)?);
        }
        Some(out)
    }
}

/// Traces a chain from `start` towards `aim`: at each hit before the last it scatters as
/// `scatters` says, and every hit must lie on the shape `shapes` names for it (a walk that
/// lands on another shape is rejected, contract `memlt.md`, "Pitfalls"). `None` when a ray
/// escapes, lands elsewhere, or a refraction is total internal reflection.
pub fn trace(
    scene: &Scene,
    (start, start_ng): (Vec3, Vec3),
    aim: Vec3,
    scatters: &[Scatter],
    shapes: &[u32],
) -> Option<TracedChain> {
    // The ray leaves from the start moved off its surface, and passes through `aim` exactly
    // (a walk re-traces its chains through their first vertex's hit).
    let o = if start_ng == Vec3::ZERO { start } else { crate::math::offset_origin(start, start_ng, aim - start) };
    let mut ray = Ray::new(o, (aim - o).try_normalize()?);
    let mut hits = Vec::with_capacity(shapes.len());
    for (i, &shape) in shapes.iter().enumerate() {
        let si = scene.intersect(&ray)?;
        if si.shape != shape {
            return None;
        }
        if let Some(scatter) = scatters.get(i) {
            let n = si.shading.n;
            let d = match scatter {
                Scatter::Reflect => reflect(si.wo, n),
                Scatter::Refract => refract(si.wo, n, scene.bsdf(&si).eta())?.0,
            };
            ray = si.spawn_ray(d.try_normalize()?);
        }
        hits.push(si);
    }
    Some(TracedChain { start, start_ng, hits })
}

/// The parameter offset `(du, dv)` that moves a vertex by `delta` as nearly as its tangent
/// plane allows (least squares on `dp/du`, `dp/dv`).
fn parameter_offset(v: &ChainVertex, delta: DVec3) -> Option<DVec2> {
    let g = DMat2::from_cols(
        DVec2::new(v.dp_du.dot(v.dp_du), v.dp_du.dot(v.dp_dv)),
        DVec2::new(v.dp_du.dot(v.dp_dv), v.dp_dv.dot(v.dp_dv)),
    );
    Some(inverse(g)? * DVec2::new(v.dp_du.dot(delta), v.dp_dv.dot(delta)))
}

/// The solid angle at the chain's start per unit area at its end, `dω₀/dA_{k+1}`, through
/// the specular vertices: what turns a density of directions at the start into a density of
/// positions at the end (times `|cos θ₀|`, Jakob and Marschner's generalized geometric term;
/// contract `memlt.md`, step 8). The end's parameter steps map to the first specular
/// vertex's by the tangent map; those move the start's direction by `(I - ω ωᵀ) dx₁ / d`;
/// the two directions' cross product is the solid angle per parameter area, divided by the
/// end's area per parameter area `|dp/du × dp/dv|`. A chain without specular vertices gives
/// `|cos θ| / d²`. `None` where the tangent map is singular.
pub fn solid_angle_density(vertices: &[ChainVertex]) -> Option<f64> {
    let (start, end) = (vertices.first()?, vertices.last()?);
    if vertices.len() == 2 {
        let d = end.p - start.p;
        return Some(end.n.dot(d).abs() / (d.length_squared() * d.length()));
    }
    let jac = jacobian(vertices);
    let first = &vertices[1];
    let to_first = first.p - start.p;
    let dist = to_first.length();
    let w = to_first / dist;
    let direction_step = |d: DVec2| -> Option<DVec3> {
        let step = jac.follow_end(d)?[0];
        Some(unit_derivative(w, dist, first.displacement(step)))
    };
    let (dw_du, dw_dv) = (direction_step(DVec2::X)?, direction_step(DVec2::Y)?);
    Some(dw_du.cross(dw_dv).length() / end.dp_du.cross(end.dp_dv).length())
}

/// `n_end / n_start`: the refractive index of the medium at the chain's end over that at its
/// start, from the refractions on the way (entering a surface from its front multiplies by
/// its relative index, leaving divides by it).
pub fn index_ratio(vertices: &[ChainVertex], scatters: &[Scatter]) -> f64 {
    let mut ratio = 1.0;
    for (i, scatter) in scatters.iter().enumerate() {
        let (prev, x) = (&vertices[i], &vertices[i + 1]);
        if *scatter == Scatter::Refract && x.eta != 1.0 {
            if (prev.p - x.p).dot(x.n) > 0.0 {
                ratio *= x.eta;
            } else {
                ratio /= x.eta;
            }
        }
    }
    ratio
}

impl TracedChain {
    /// The solid angle at the chain's end per unit area at its start, `dω_{k+1}/dA_0`: by
    /// the reciprocity of the generalized geometric term (étendue `n² cos dA dω` is the same
    /// at both ends of a bundle of rays), `(n_0 / n_{k+1})² (cos θ_0 / cos θ_{k+1})` times
    /// [`solid_angle_density`]'s `dω_0/dA_{k+1}`, with the cosines to the geometric normals.
    /// What a chain whose end moves and whose start stays needs to express the start's area
    /// density. `None` where the tangent map is singular or the start has no surface.
    pub fn end_solid_angle_density(&self, scene: &Scene) -> Option<f64> {
        let vertices = self.vertices(scene)?;
        let forward = solid_angle_density(&vertices)?;
        let ratio = index_ratio(&vertices, &self.scatters());
        let first = self.hits.first()?.p;
        let before_end = if self.hits.len() >= 2 { self.hits[self.hits.len() - 2].p } else { self.start };
        let end = self.end();
        let cos_start = self.start_ng.dot((first - self.start).normalize()).abs() as f64;
        let cos_end = end.ng.dot((before_end - end.p).normalize()).abs() as f64;
        (cos_end > 0.0).then(|| forward * cos_start / cos_end / (ratio * ratio))
    }
}

/// Whether the walk back from `proposal` to `current`'s end returns to `current` (contract
/// `memlt.md`, step 7): the walk back converges (its end within `tolerance` times the
/// chain's length of `current`'s end) and every vertex lands on `current`'s shape within ten
/// times that (the vertices before the end follow it to within the ray epsilons). A
/// proposal whose walk back ends elsewhere (another branch of the manifold, another shape)
/// has no reverse move, and the perturbation must reject it.
pub fn returns_to(scene: &Scene, proposal: &TracedChain, current: &TracedChain, tolerance: f64) -> bool {
    if proposal.hits.len() != current.hits.len() || proposal.start != current.start {
        return false;
    }
    let Some(back) = walk(scene, proposal, current.end().p, tolerance).chain else { return false };
    let length = current.length();
    back.hits
        .iter()
        .zip(&current.hits)
        .all(|(a, b)| a.shape == b.shape && ((a.p - b.p).length() as f64) <= tolerance * length * 10.0)
}

/// The half-angle `θ_d` around the normal that holds 90% of a microfacet distribution of
/// roughness `alpha` (of its normals weighted by `cos θ`): `tan² θ_d = -α² ln 0.1` for
/// Beckmann, `9 α²` for GGX.
pub fn lobe_half_angle(kind: crate::bsdf::microfacet::MicrofacetType, alpha: f64) -> f64 {
    use crate::bsdf::microfacet::MicrofacetType::*;
    let tan2 = match kind {
        Beckmann => -alpha * alpha * 0.1f64.ln(),
        Ggx => 9.0 * alpha * alpha,
    };
    tan2.sqrt().atan()
}

/// The probability that the manifold perturbation treats a vertex as non-specular (contract
/// `memlt.md`, step 2): 1 for a diffuse lobe, 0 for a Dirac one, and for a glossy one of
/// 90% half-angle `θ_d` (see [`lobe_half_angle`]) `(1 - cos θ_d) / (1 - cos(θ_d + θ_diff))`,
/// where `θ_diff` is the running average of the half-vector changes the perturbation has
/// produced: a lobe much wider than the changes is walked over as if it were diffuse, one
/// much narrower as if it were a mirror. The probability enters both proposal densities.
pub fn nonspecular_probability(lobe_half_angle: Option<f64>, theta_diff: f64) -> f64 {
    match lobe_half_angle {
        None => 1.0,
        Some(t) if t <= 0.0 => 0.0,
        Some(t) => ((1.0 - t.cos()) / (1.0 - (t + theta_diff).min(std::f64::consts::PI).cos())).clamp(0.0, 1.0),
    }
}

/// The result of a manifold walk.
#[derive(Clone, Debug)]
pub struct Walk {
    /// The chain whose end reached the target (`None` when the walk did not converge).
    pub chain: Option<TracedChain>,
    /// Newton iterations taken.
    pub iterations: u32,
}

/// Newton iterations a walk may take (Mitsuba 0.6's limit).
pub const MAX_ITERATIONS: u32 = 20;

/// The smallest fraction of the Newton step a walk tries before it gives up.
pub const MIN_STEP: f64 = 1.0 / 256.0;

/// Walks `chain` on its specular manifold until its end reaches `target` (a point on the
/// end's surface), keeping the start fixed (contract `memlt.md`, "Manifold perturbation",
/// step 6): each Newton step moves the end towards the target in its tangent plane, takes
/// the first specular vertex's step from the tangent map ([`Jacobian::follow_end`]),
/// re-traces the chain from the start through it, scattering specularly at every specular
/// vertex (so the constraints hold by construction and only the end can miss), and keeps the
/// new chain only if its end came closer; the step doubles (up to the full one) after a
/// success and halves after a failure. Converged when the end lies within `tolerance` times
/// the chain's length of the target.
pub fn walk(scene: &Scene, chain: &TracedChain, target: Vec3, tolerance: f64) -> Walk {
    let scatters = chain.scatters();
    let shapes: Vec<u32> = chain.hits.iter().map(|h| h.shape).collect();
    let target = target.as_dvec3();
    let length = chain.length();
    let mut current = chain.clone();
    let mut dist = (current.end().p.as_dvec3() - target).length();
    let mut step = 1.0;
    let mut iterations = 0;
    while dist > tolerance * length && iterations < MAX_ITERATIONS && !scatters.is_empty() {
        iterations += 1;
        let Some(vertices) = current.vertices(scene) else { break };
        let end = vertices.last().expect("a chain has an end");
        let Some(offset) = parameter_offset(end, target - end.p) else { break };
        let Some(steps) = jacobian(&vertices).follow_end(offset * step) else { break };
        let first = &vertices[1];
        let aim = first.p + first.displacement(steps[0]);
        let next = trace(scene, (chain.start, chain.start_ng), aim.as_vec3(), &scatters, &shapes);
        match next.map(|n| ((n.end().p.as_dvec3() - target).length(), n)) {
            Some((d, next)) if d < dist => {
                dist = d;
                current = next;
                step = (step * 2.0).min(1.0);
            }
            _ => {
                step *= 0.5;
                // Eight halvings in a row: the Newton direction no longer leads to the target.
                if step < MIN_STEP {
                    break;
                }
            }
        }
    }
    Walk { chain: (dist <= tolerance * length).then_some(current), iterations }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    fn rand3(rng: &mut Sampler) -> DVec3 {
        DVec3::new(rng.next_1d() as f64, rng.next_1d() as f64, rng.next_1d() as f64) * 2.0 - DVec3::ONE
    }

    /// A chain of `k` specular vertices zig-zagging along `+x`, with curved surfaces (normal
    /// derivatives in the tangent plane) and skewed parameterisations; vertex `i` refracts
    /// where `refract(i)`. The constraints need not hold: the Jacobian is checked anywhere.
    fn chain(rng: &mut Sampler, k: usize, refract: impl Fn(usize) -> bool) -> Vec<ChainVertex> {
        (0..k + 2)
            .map(|i| {
                let p = DVec3::new(i as f64 * 1.3, if i % 2 == 0 { 0.0 } else { 1.1 }, 0.0) + rand3(rng) * 0.2;
                // Normals facing the previous vertex roughly, so that reflections stay on one
                // side and refractions cross.
                let n = (DVec3::new(-0.3, if i % 2 == 0 { 1.0 } else { -1.0 }, 0.2) + rand3(rng) * 0.2).normalize();
                let tangent = |v: DVec3| v - n * n.dot(v);
                let dp_du = tangent(rand3(rng)) + n * 0.1 * rng.next_1d() as f64 + n.any_orthonormal_vector();
                let dp_dv = tangent(rand3(rng)) + n.cross(dp_du) * 0.8;
                let (dn_du, dn_dv) = (tangent(rand3(rng)) * 0.7, tangent(rand3(rng)) * 0.7);
                ChainVertex::new(p, (dp_du, dp_dv), n, (dn_du, dn_dv), if refract(i) { 1.5 } else { 1.0 }).unwrap()
            })
            .collect()
    }

    /// Central differences of the constraints, one parameter of one vertex at a time.
    fn numeric_column(chain: &[ChainVertex], vertex: usize, axis: usize, h: f64) -> Vec<DVec2> {
        let mut d = DVec2::ZERO;
        d[axis] = h;
        let at = |step: DVec2| {
            let mut c = chain.to_vec();
            c[vertex] = chain[vertex].moved(step);
            constraints(&c)
        };
        at(d).iter().zip(at(-d)).map(|(a, b)| (*a - b) / (2.0 * h)).collect()
    }

    /// The whole Jacobian (specular rows, every vertex's columns), dense.
    fn dense(chain: &[ChainVertex], jac: &Jacobian) -> Vec<Vec<f64>> {
        let k = chain.len() - 2;
        let mut m = vec![vec![0.0; 2 * (k + 2)]; 2 * k];
        for i in 0..k {
            for (block, col) in [(jac.below[i], i), (jac.diagonal[i], i + 1), (jac.above[i], i + 2)] {
                for a in 0..2 {
                    for r in 0..2 {
                        m[2 * i + r][2 * col + a] = block.col(a)[r];
                    }
                }
            }
        }
        m
    }

    /// Determinant by Gaussian elimination with partial pivoting.
    fn dense_determinant(mut m: Vec<Vec<f64>>) -> f64 {
        let n = m.len();
        let mut det = 1.0;
        for c in 0..n {
            let p = (c..n).max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs())).unwrap();
            if p != c {
                m.swap(p, c);
                det = -det;
            }
            det *= m[c][c];
            let (top, rest) = m.split_at_mut(c + 1);
            let pivot = &top[c];
            for row in rest {
                let f = row[c] / pivot[c];
                for (x, p) in row.iter_mut().zip(pivot).skip(c) {
                    *x -= f * p;
                }
            }
        }
        det
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let mut rng = Sampler::new(&[11]);
        for k in 1..=3 {
            for pattern in 0..4 {
                let refract = |i: usize| i >= 1 && i <= k && (pattern >> ((i - 1) % 2)) & 1 == 1;
                let c = chain(&mut rng, k, refract);
                let jac = jacobian(&c);
                let analytic = dense(&c, &jac);
                for vertex in 0..k + 2 {
                    for axis in 0..2 {
                        let numeric = numeric_column(&c, vertex, axis, 1e-6);
                        for (i, n) in numeric.iter().enumerate() {
                            let a =
                                DVec2::new(analytic[2 * i][2 * vertex + axis], analytic[2 * i + 1][2 * vertex + axis]);
                            assert!(
                                (a - *n).length() <= 1e-6 * (1.0 + n.length()),
                                "k {k}, pattern {pattern}, row {i}, vertex {vertex}, axis {axis}: {a} against {n}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn block_solve_and_determinant_match_dense_ones() {
        let mut rng = Sampler::new(&[12]);
        for k in 1..=4 {
            let c = chain(&mut rng, k, |i| i % 2 == 0);
            let jac = jacobian(&c);
            // The specular columns of the finite-difference Jacobian.
            let mut inner = vec![vec![0.0; 2 * k]; 2 * k];
            for vertex in 1..=k {
                for axis in 0..2 {
                    for (i, n) in numeric_column(&c, vertex, axis, 1e-6).iter().enumerate() {
                        inner[2 * i][2 * (vertex - 1) + axis] = n.x;
                        inner[2 * i + 1][2 * (vertex - 1) + axis] = n.y;
                    }
                }
            }
            let numeric_det = dense_determinant(inner.clone());
            // Hadamard's bound: the determinant's scale for the rows' sizes.
            let scale: f64 = inner.iter().map(|row| row.iter().map(|v| v * v).sum::<f64>().sqrt()).product();
            assert!(numeric_det.abs() > 1e-3 * scale, "k {k}: a well-conditioned test chain ({numeric_det}, {scale})");
            let det = jac.determinant();
            assert!((det - numeric_det).abs() <= 1e-6 * scale, "k {k}: {det} against {numeric_det}");
            let r: Vec<DVec2> = (0..k).map(|_| DVec2::new(rng.next_1d() as f64, rng.next_1d() as f64)).collect();
            let x = jac.solve(&r).unwrap();
            for (row, want) in inner.iter().zip(r.iter().flat_map(|v| [v.x, v.y])) {
                let got: f64 = row.iter().zip(x.iter().flat_map(|v| [v.x, v.y])).map(|(a, b)| a * b).sum();
                assert!((got - want).abs() < 1e-5, "k {k}: {got} against {want}");
            }
        }
    }

    #[test]
    fn constraints_vanish_on_mirror_reflections_and_snell_refractions() {
        // A flat interface z = 0 (normal +z, glass of index 1.5 below), light from above.
        let surface = |eta: f64| {
            let (du, dv) = (DVec3::X, DVec3::Y);
            ChainVertex::new(DVec3::ZERO, (du, dv), DVec3::Z, (DVec3::ZERO, DVec3::ZERO), eta).unwrap()
        };
        let from = DVec3::new(-0.8, 0.3, 1.0);
        let wi = from.normalize();
        let mirrored = DVec3::new(-wi.x, -wi.y, wi.z);
        // Snell: the transmitted direction's tangential part is the incident one's over η.
        let refracted = |eta: f64| {
            let t = DVec3::new(-wi.x, -wi.y, 0.0) / eta;
            DVec3::new(t.x, t.y, -(1.0 - t.length_squared()).sqrt())
        };
        let c = |eta: f64, to: DVec3| constraint(from, &surface(eta), to * 2.0).length();
        assert!(c(1.0, mirrored) < 1e-12);
        assert!(c(1.5, refracted(1.5)) < 1e-12);
        // Seen from inside: the same path reversed.
        assert!(constraint(refracted(1.5) * 2.0, &surface(1.5), from).length() < 1e-12);
        // Bent by the wrong index, or not bent, the constraint is not met.
        assert!(c(1.5, refracted(1.0 / 1.5)) > 1e-2 && c(1.5, refracted(1.0)) > 1e-2);
        assert!(c(1.0, mirrored + DVec3::new(0.05, 0.0, 0.0)) > 1e-2);
    }

    fn scene(shapes: &str) -> Scene {
        let text = format!(
            r#"<scene version="3.0.0">
<sensor type="perspective"><float name="fov" value="40"/><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
<emitter type="point"><point name="position" x="0" y="0" z="50"/></emitter>
{shapes}
</scene>"#
        );
        Scene::load_str(&text, std::path::Path::new("manifold.xml"), &crate::scene::LoadOptions::default()).unwrap()
    }

    const GLASS_BALL: &str = r#"<shape type="sphere"><point name="center" x="0" y="0" z="0"/><float name="radius" value="1"/><bsdf type="dielectric"/></shape>"#;
    const MIRROR_FLOOR: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/><translate z="-2"/></transform><bsdf type="conductor"/></shape>"#;
    const DIFFUSE_FLOOR: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/><translate z="-2"/></transform><bsdf type="diffuse"/></shape>"#;
    const NEAR_FLOOR: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/><translate z="-1.2"/></transform><bsdf type="diffuse"/></shape>"#;
    const MIRROR_WALL: &str = r#"<shape type="rectangle"><transform name="to_world"><rotate y="1" angle="-90"/><scale value="3"/><translate x="3" z="1"/></transform><bsdf type="conductor"/></shape>"#;
    const CEILING: &str = r#"<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="180"/><scale value="10"/><translate z="4"/></transform><bsdf type="diffuse"/></shape>"#;

    /// Walks the chain traced from `start` towards `aim` to its end moved by `offset`, and
    /// checks the result: the end at the target, the shapes kept, the constraints met.
    fn check_walk(scene: &Scene, start: Vec3, aim: Vec3, scatters: &[Scatter], shapes: &[u32], offset: Vec3) {
        let chain = trace(scene, (start, Vec3::ZERO), aim, scatters, shapes).expect("the test chain traces");
        assert_eq!(chain.scatters(), scatters);
        let target = chain.end().p + offset;
        let walk = walk(scene, &chain, target, 1e-5);
        let walked = walk.chain.unwrap_or_else(|| panic!("{scatters:?}: no convergence in {} steps", walk.iterations));
        assert!((walked.end().p - target).length() < 1e-4, "{scatters:?}: {} against {target}", walked.end().p);
        assert_eq!(walked.hits.iter().map(|h| h.shape).collect::<Vec<_>>(), shapes);
        assert!((walked.hits[0].p - chain.hits[0].p).length() > 1e-3, "the first vertex moves");
        // The re-traced chain scatters exactly at its hits, but each ray leaves its surface
        // from a point moved off it by the ray epsilon: the constraints from the hits hold to
        // a few times that.
        let epsilon = crate::math::RAY_EPSILON as f64;
        for c in constraints(&walked.vertices(scene).unwrap()) {
            assert!(c.length() < 10.0 * epsilon, "{scatters:?}: constraint {c}");
        }
    }

    #[test]
    fn walks_reach_their_targets_through_reflections_and_refractions() {
        use Scatter::*;
        // One mirror reflection up to a ceiling.
        let s = scene(&format!("{MIRROR_FLOOR}{CEILING}"));
        check_walk(
            &s,
            Vec3::new(-1.0, 0.3, 1.0),
            Vec3::new(0.0, 0.0, -2.0),
            &[Reflect],
            &[0, 1],
            Vec3::new(0.2, -0.1, 0.0),
        );
        // Two refractions through a glass ball onto a floor.
        let s = scene(&format!("{GLASS_BALL}{DIFFUSE_FLOOR}"));
        check_walk(
            &s,
            Vec3::new(0.3, 0.2, 5.0),
            Vec3::new(0.3, 0.2, 0.0),
            &[Refract, Refract],
            &[0, 0, 1],
            Vec3::new(0.05, -0.03, 0.0),
        );
        // A mirror on a wall, then two refractions through the ball onto the floor.
        let s = scene(&format!("{GLASS_BALL}{DIFFUSE_FLOOR}{MIRROR_WALL}"));
        check_walk(
            &s,
            Vec3::new(-2.0, 0.1, 3.0),
            Vec3::new(3.0, 0.1, 1.3),
            &[Reflect, Refract, Refract],
            &[2, 0, 0, 1],
            Vec3::new(0.1, 0.05, 0.0),
        );
    }

    /// The solid-angle density from walks to the end moved by `±h` along `dp/du` and
    /// `dp/dv`: the start's directions' central differences, their cross product over the
    /// end's area.
    fn walked_density(scene: &Scene, chain: &TracedChain, h: f32) -> f64 {
        let vertices = chain.vertices(scene).unwrap();
        let end = vertices.last().unwrap();
        let direction = |offset: DVec3| {
            let target = chain.end().p + offset.as_vec3();
            let w = walk(scene, chain, target, 1e-5);
            let walked = w
                .chain
                .unwrap_or_else(|| panic!("{offset} from {}: not reached in {} steps", chain.end().p, w.iterations));
            (walked.hits[0].p - chain.start).normalize().as_dvec3()
        };
        let h64 = h as f64;
        let dw_du = (direction(end.dp_du * h64) - direction(-end.dp_du * h64)) / (2.0 * h64);
        let dw_dv = (direction(end.dp_dv * h64) - direction(-end.dp_dv * h64)) / (2.0 * h64);
        dw_du.cross(dw_dv).length() / end.dp_du.cross(end.dp_dv).length()
    }

    #[test]
    fn solid_angle_density_is_the_walks_and_a_mirrors_unfolded_one() {
        use Scatter::*;
        // A flat mirror: the end seen in the mirror is at the unfolded distance.
        let s = scene(&format!("{MIRROR_FLOOR}{CEILING}"));
        let chain =
            trace(&s, (Vec3::new(-1.0, 0.3, 1.0), Vec3::ZERO), Vec3::new(0.0, 0.0, -2.0), &[Reflect], &[0, 1]).unwrap();
        let v = chain.vertices(&s).unwrap();
        let unfolded = (v[1].p - v[0].p).length() + (v[2].p - v[1].p).length();
        let cos_end = v[2].n.dot((v[1].p - v[2].p).normalize()).abs();
        let analytic = solid_angle_density(&v).unwrap();
        let expected = cos_end / (unfolded * unfolded);
        assert!((analytic / expected - 1.0).abs() < 1e-5, "{analytic} against {expected}");
        let walked = walked_density(&s, &chain, 5e-4);
        assert!((walked / analytic - 1.0).abs() < 1e-2, "mirror: walks {walked} against {analytic}");
        // Through the glass ball, and through a mirror and the ball, onto a floor just below
        // it (the ball focuses light near z = -2, where the density has a caustic).
        let s = scene(&format!("{GLASS_BALL}{NEAR_FLOOR}{MIRROR_WALL}"));
        for (start, aim, scatters, shapes) in [
            (Vec3::new(0.3, 0.2, 5.0), Vec3::new(0.3, 0.2, 0.0), &[Refract, Refract][..], &[0, 0, 1][..]),
            (Vec3::new(-2.0, 0.1, 3.0), Vec3::new(3.0, 0.1, 1.3), &[Reflect, Refract, Refract], &[2, 0, 0, 1]),
        ] {
            let chain = trace(&s, (start, Vec3::ZERO), aim, scatters, shapes).unwrap();
            let analytic = solid_angle_density(&chain.vertices(&s).unwrap()).unwrap();
            let walked = walked_density(&s, &chain, 5e-4);
            assert!((walked / analytic - 1.0).abs() < 1e-2, "{scatters:?}: walks {walked} against {analytic}");
            // Without the refractions' bending the density is another: the test resolves it.
            let straight = 1.0 / (chain.end().p - chain.start).length_squared() as f64;
            assert!((straight / analytic - 1.0).abs() > 0.1, "{scatters:?}");
        }
    }

    /// The chain traced back from `chain`'s end (on a surface) to its start's surface: the
    /// same vertices in the other order, with the start's real tangent frame at its end.
    fn reversed(scene: &Scene, chain: &TracedChain, start_shape: u32) -> TracedChain {
        let end = chain.end();
        let mut scatters = chain.scatters();
        scatters.reverse();
        let mut shapes: Vec<u32> = chain.hits[..chain.hits.len() - 1].iter().rev().map(|h| h.shape).collect();
        shapes.push(start_shape);
        let aim = chain.hits[chain.hits.len() - 2].p;
        trace(scene, (end.p, end.ng), aim, &scatters, &shapes).expect("the reversed chain traces")
    }

    #[test]
    fn end_solid_angle_density_is_the_reversed_chains() {
        use Scatter::*;
        // A dielectric half-space below z = 0 over a floor inside it: the chain's two ends lie
        // in media of different indices (the étendue's n² enters).
        const WATER: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/></transform><bsdf type="dielectric"><float name="int_ior" value="1.33"/></bsdf></shape>"#;
        const SUNK_FLOOR: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/><translate z="-1"/></transform><bsdf type="diffuse"/></shape>"#;
        let cases = [
            (
                format!("{GLASS_BALL}{NEAR_FLOOR}{CEILING}"),
                2u32,
                Vec3::new(2.5, 0.5, 4.0),
                Vec3::new(0.3, 0.2, 0.0),
                vec![Refract, Refract],
                vec![0u32, 0, 1],
                true,
            ),
            (
                format!("{MIRROR_FLOOR}{CEILING}"),
                1,
                Vec3::new(-1.0, 0.3, 4.0),
                Vec3::new(0.0, 0.0, -2.0),
                vec![Reflect],
                vec![0, 1],
                false,
            ),
            (
                format!("{WATER}{SUNK_FLOOR}{CEILING}"),
                2,
                Vec3::new(-0.7, 0.3, 4.0),
                Vec3::new(0.0, 0.0, 0.0),
                vec![Refract],
                vec![0, 1],
                true,
            ),
        ];
        for (shapes_xml, start_shape, start, aim, scatters, shapes, asymmetric) in cases {
            let s = scene(&shapes_xml);
            let ng = Vec3::new(0.0, 0.0, -1.0);
            let chain = trace(&s, (start, ng), aim, &scatters, &shapes).expect("the test chain traces");
            let back = reversed(&s, &chain, start_shape);
            assert!((back.end().p - start).length() < 1e-3, "{scatters:?}: the reversed chain returns");
            let expected = solid_angle_density(&back.vertices(&s).unwrap()).unwrap();
            let got = chain.end_solid_angle_density(&s).unwrap();
            // The walks work from either end.
            let walked = walked_density(&s, &back, 5e-4);
            assert!((walked / expected - 1.0).abs() < 1e-2, "{scatters:?}: reversed walks {walked} against {expected}");
            assert!((got / expected - 1.0).abs() < 1e-3, "{scatters:?}: {got} against {expected}");
            // Without the cosines' ratio (or the indices', in the water) it would be another
            // (a mirror between two points of one plane gives both ends the same cosine).
            if !asymmetric {
                continue;
            }
            let forward = solid_angle_density(&chain.vertices(&s).unwrap()).unwrap();
            assert!((forward / expected - 1.0).abs() > 0.05, "{scatters:?}: {forward} against {expected}");
        }
    }

    #[test]
    fn lobe_half_angles_hold_ninety_percent_of_the_lobe() {
        use crate::bsdf::microfacet::{Microfacet, MicrofacetType};
        for kind in [MicrofacetType::Beckmann, MicrofacetType::Ggx] {
            for alpha in [0.05f32, 0.2, 0.6] {
                let m = Microfacet { kind, alpha_u: alpha, alpha_v: alpha, sample_visible: false };
                // ∫ D(m) cos θ dω over the cap θ < θ_d, by the midpoint rule in θ (the
                // distribution is isotropic: 2π sin θ dθ).
                let theta_d = lobe_half_angle(kind, alpha as f64);
                let cap = |limit: f64| {
                    let n = 20_000;
                    (0..n)
                        .map(|i| {
                            let t = (i as f64 + 0.5) / n as f64 * limit;
                            let h = Vec3::new(t.sin() as f32, 0.0, t.cos() as f32);
                            m.d(h) as f64 * t.cos() * 2.0 * std::f64::consts::PI * t.sin() * limit / n as f64
                        })
                        .sum::<f64>()
                };
                let (inside, all) = (cap(theta_d), cap(std::f64::consts::FRAC_PI_2));
                assert!((all - 1.0).abs() < 2e-3, "{kind:?} α {alpha}: D cos integrates to {all}");
                assert!((inside / all - 0.9).abs() < 2e-3, "{kind:?} α {alpha}: {inside} of {all}");
            }
        }
    }

    #[test]
    fn nonspecular_probability_goes_from_mirror_to_diffuse() {
        let diff = 1f64.to_radians();
        assert_eq!(nonspecular_probability(None, diff), 1.0);
        assert_eq!(nonspecular_probability(Some(0.0), diff), 0.0);
        let p = |alpha: f64| {
            nonspecular_probability(
                Some(lobe_half_angle(crate::bsdf::microfacet::MicrofacetType::Beckmann, alpha)),
                diff,
            )
        };
        let ps: Vec<f64> = [1e-4, 1e-3, 0.01, 0.1, 0.5, 2.0].iter().map(|&a| p(a)).collect();
        assert!(ps.windows(2).all(|w| w[0] < w[1]), "rougher lobes are walked over less often: {ps:?}");
        assert!(ps[0] < 1e-3 && ps[5] > 0.9, "{ps:?}");
        // (1 - cos θ_d) / (1 - cos 2θ_d) when the lobe is as wide as the changes: about ¼.
        let q = nonspecular_probability(Some(diff), diff);
        assert!((q - (1.0 - diff.cos()) / (1.0 - (2.0 * diff).cos())).abs() < 1e-12 && (q - 0.25).abs() < 1e-3);
    }

    #[test]
    fn walks_are_reversible() {
        use Scatter::*;
        let s = scene(&format!("{GLASS_BALL}{NEAR_FLOOR}{MIRROR_WALL}"));
        for (start, aim, scatters, shapes) in [
            (Vec3::new(0.3, 0.2, 5.0), Vec3::new(0.3, 0.2, 0.0), &[Refract, Refract][..], &[0, 0, 1][..]),
            (Vec3::new(-2.0, 0.1, 3.0), Vec3::new(3.0, 0.1, 1.3), &[Reflect, Refract, Refract], &[2, 0, 0, 1]),
        ] {
            let current = trace(&s, (start, Vec3::ZERO), aim, scatters, shapes).unwrap();
            let proposal = walk(&s, &current, current.end().p + Vec3::new(0.05, -0.04, 0.0), 1e-5).chain.unwrap();
            assert!(returns_to(&s, &proposal, &current, 1e-5), "{scatters:?}");
            // A chain through other points is not where the walk back goes.
            let other = trace(&s, (start, Vec3::ZERO), aim + Vec3::new(0.0, 0.1, 0.0), scatters, shapes).unwrap();
            let mut elsewhere = other.clone();
            elsewhere.hits.last_mut().unwrap().p = current.end().p;
            assert!(!returns_to(&s, &proposal, &elsewhere, 1e-5), "{scatters:?}");
        }
    }

    #[test]
    fn walks_to_unreachable_targets_fail() {
        // Light refracted twice by the ball reaches the floor only near its axis.
        let s = scene(&format!("{GLASS_BALL}{DIFFUSE_FLOOR}"));
        let scatters = [Scatter::Refract, Scatter::Refract];
        let chain =
            trace(&s, (Vec3::new(0.3, 0.2, 5.0), Vec3::ZERO), Vec3::new(0.3, 0.2, 0.0), &scatters, &[0, 0, 1]).unwrap();
        let w = walk(&s, &chain, Vec3::new(8.0, 8.0, -2.0), 1e-5);
        assert!(w.chain.is_none() && w.iterations > 5, "{} iterations", w.iterations);
    }

    #[test]
    fn following_the_end_keeps_the_constraints_to_second_order() {
        // Moving the end by `ε d` and the specular vertices by the tangent map's `ε Δ`
        // changes the constraints by O(ε²); moving the end alone changes them by O(ε).
        let mut rng = Sampler::new(&[13]);
        for k in 1..=3 {
            let c = chain(&mut rng, k, |i| i == 1);
            let jac = jacobian(&c);
            let d = DVec2::new(0.6, -0.8);
            let steps = jac.follow_end(d).unwrap();
            let change = |eps: f64, follow: bool| {
                let mut moved = c.clone();
                moved[k + 1] = c[k + 1].moved(d * eps);
                if follow {
                    for (i, s) in steps.iter().enumerate() {
                        moved[i + 1] = c[i + 1].moved(*s * eps);
                    }
                }
                let before = constraints(&c);
                constraints(&moved).iter().zip(&before).map(|(a, b)| (*a - *b).length()).fold(0.0, f64::max)
            };
            let (followed, alone) = (change(1e-4, true), change(1e-4, false));
            assert!(followed < 1e-6 && alone > 1e-6, "k {k}: followed {followed}, end alone {alone}");
            // Second order: a ten times smaller step, a hundred times smaller change.
            assert!(change(1e-5, true) < followed / 30.0, "k {k}");
        }
    }
}
