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
//! `n + u dn/du + v dn/dv` normalised, and the frame's tangent `s` one fixed world vector
//! projected onto the tangent plane (so the frame turns with the normal alone).
//!
//! A glossy vertex treated as specular keeps its current half-vector rather than the
//! normal: its constraint is offset by the half-vector's coordinates in the frame ([`Half`]),
//! and the Jacobian, which differentiates the frame too, is that of the offset constraint.
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
    /// Unit tangent of the constraint frame ([`FRAME_REFERENCE`] projected onto the tangent
    /// plane).
    pub s: DVec3,
    pub eta: f64,
}

impl ChainVertex {
    /// A vertex from its surface's first-order geometry; `None` where the normal is
    /// [`FRAME_REFERENCE`] (no tangent frame).
    pub fn new(
        p: DVec3,
        (dp_du, dp_dv): (DVec3, DVec3),
        n: DVec3,
        (dn_du, dn_dv): (DVec3, DVec3),
        eta: f64,
    ) -> Option<Self> {
        let s = frame_tangent(n)?;
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
        ChainVertex { p: self.p + self.displacement(d), n, s: frame_tangent(n).unwrap_or(self.s), ..*self }
    }

    fn t(&self) -> DVec3 {
        self.n.cross(self.s)
    }

    /// The index of refraction on the side of `w`.
    fn eta_towards(&self, w: DVec3) -> f64 {
        eta_towards(self.n, self.eta, w)
    }

    /// The vertex at a hit, from its surface's first-order geometry.
    pub fn at(scene: &Scene, si: &SurfaceInteraction) -> Option<ChainVertex> {
        let d = |v: Vec3| v.as_dvec3();
        let shape = &scene.shapes[si.shape as usize];
        let (dp_du, dp_dv) = shape.tangents(si);
        let (dn_du, dn_dv) = shape.normal_derivatives(si);
        let eta = scene.bsdf(si).eta() as f64;
        let n = si.shading.n.as_dvec3().normalize();
        ChainVertex::new(d(si.p), (d(dp_du), d(dp_dv)), n, (d(dn_du), d(dn_dv)), eta)
    }

    /// A fixed point on a surface of geometric normal `ng` (a chain's start, which never
    /// moves): an orthonormal tangent frame, so that its parameter area is its area.
    fn fixed(p: DVec3, ng: DVec3) -> Option<ChainVertex> {
        let n = ng.try_normalize()?;
        let (s, t) = n.any_orthonormal_pair();
        ChainVertex::new(p, (s, t), n, (DVec3::ZERO, DVec3::ZERO), 1.0)
    }

    /// `w` in the constraint frame `(s, t, n)`.
    pub fn to_local(&self, w: DVec3) -> DVec3 {
        DVec3::new(w.dot(self.s), w.dot(self.t()), w.dot(self.n))
    }

    /// `m` of the constraint frame `(s, t, n)` in the world.
    pub fn to_world(&self, m: DVec3) -> DVec3 {
        self.s * m.x + self.t() * m.y + self.n * m.z
    }
}

/// The world vector whose projection onto a vertex's tangent plane is its constraint frame's
/// tangent `s`: one fixed vector for every vertex, so that the frame is a function of the
/// normal alone, as the Jacobian differentiates it (a glossy vertex treated as specular
/// keeps its half-vector's coordinates in this frame, and the frame's turn about the normal
/// moves the half-vector it keeps). Its direction is no axis, which floors and walls share.
const FRAME_REFERENCE: DVec3 = DVec3::new(0.267_261_241_912_424_4, 0.534_522_483_824_848_8, 0.801_783_725_737_273_2);

/// The constraint frame's tangent at unit normal `n`: [`FRAME_REFERENCE`] projected onto the
/// tangent plane; `None` where the normal is that vector.
fn frame_tangent(n: DVec3) -> Option<DVec3> {
    (FRAME_REFERENCE - n * n.dot(FRAME_REFERENCE)).try_normalize()
}

/// The change of [`frame_tangent`] `s` at normal `n` for a change `dn` of the normal:
/// `(I - s sᵀ) du / |u|` with `u = r - n (n·r)`, `du = -dn (n·r) - n (dn·r)`.
fn frame_tangent_derivative(n: DVec3, s: DVec3, dn: DVec3) -> DVec3 {
    let r = FRAME_REFERENCE;
    let u = r - n * n.dot(r);
    let du = -dn * n.dot(r) - n * dn.dot(r);
    (du - s * s.dot(du)) / u.length()
}

/// The index of refraction on the side of `w` of a surface of shading normal `n` and
/// relative index `eta`.
fn eta_towards(n: DVec3, eta: f64, w: DVec3) -> f64 {
    if w.dot(n) >= 0.0 { 1.0 } else { eta }
}

/// The unit generalized half-vector `ĥ` of unit directions `wi` and `wo` at a surface of
/// shading normal `n` and relative index `eta`: `η(wi) wi + η(wo) wo` normalised (the usual
/// half-vector for a reflection).
pub fn half_vector(wi: DVec3, wo: DVec3, n: DVec3, eta: f64) -> DVec3 {
    (wi * eta_towards(n, eta, wi) + wo * eta_towards(n, eta, wo)).normalize()
}

/// The direction `wo` leaving a surface (shading normal `n`, relative index `eta`) for unit
/// `wi` whose generalized half-vector with `wi` is the unit `m`: the reflection of `wi`
/// about `m`, or its refraction through a facet of normal `m` to the other side of `n`.
/// `None` at total internal reflection, or when the direction found lies on the wrong side
/// of `n` or gives `-m` (the half-vector cannot be kept).
pub fn scatter_about(wi: DVec3, m: DVec3, n: DVec3, eta: f64, scatter: Scatter) -> Option<DVec3> {
    let cos_i = wi.dot(m);
    let wo = match scatter {
        Scatter::Reflect => m * (2.0 * cos_i) - wi,
        Scatter::Refract => {
            let eta_i = eta_towards(n, eta, wi);
            let eta_o = if eta_i == 1.0 { eta } else { 1.0 };
            let r = eta_i / eta_o;
            let tangential = wi - m * cos_i;
            let sin2 = r * r * tangential.length_squared();
            if sin2 >= 1.0 {
                return None;
            }
            -tangential * r - m * (cos_i.signum() * (1.0 - sin2).sqrt())
        }
    };
    let wo = wo.try_normalize()?;
    let same_side = wo.dot(n) * wi.dot(n) > 0.0;
    (same_side == (scatter == Scatter::Reflect) && half_vector(wi, wo, n, eta).dot(m) > 0.999).then_some(wo)
}

/// `|det ∂(ĥ·s, ĥ·t) / ∂wo|` at fixed `wi`, with `wo` in solid angle: how the half-vector's
/// tangential coordinates (any orthonormal tangents `s`, `t` of the shading normal `n`) change
/// with the leaving direction. `η(wo)² |wo·ĥ| |ĥ·n| / |h|²`, the unnormalised `h` projected
/// onto the sphere at `ĥ` and then onto the tangent plane; `1/(4 |wo·ĥ|)` times `|ĥ·n|` for
/// a reflection. A glossy vertex the manifold perturbation treats as specular keeps its
/// half-vector, and this is the density that keeping it gives the direction leaving it.
pub fn half_vector_density(wi: DVec3, wo: DVec3, n: DVec3, eta: f64) -> f64 {
    let eta_o = eta_towards(n, eta, wo);
    let h = wi * eta_towards(n, eta, wi) + wo * eta_o;
    let len2 = h.length_squared();
    let hn = h / len2.sqrt();
    eta_o * eta_o * wo.dot(hn).abs() * hn.dot(n).abs() / len2
}

/// The constraint of specular vertex `x` between `prev` and `next`.
fn constraint(prev: DVec3, x: &ChainVertex, next: DVec3) -> DVec2 {
    let h = half_vector((prev - x.p).normalize(), (next - x.p).normalize(), x.n, x.eta);
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
            let ds = frame_tangent_derivative(x.n, x.s, dnrm);
            dc(dh, ds, dnrm.cross(x.s) + x.n.cross(ds))
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

/// The half-vector a specular vertex of a chain keeps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Half {
    /// The shading normal: a Dirac lobe's mirror reflection or Snell refraction.
    Normal,
    /// A unit half-vector in the vertex's constraint frame `(s, t, n)` (a glossy vertex
    /// treated as specular keeps its current one: its constraint is offset by it).
    Local(DVec3),
    /// A unit half-vector in the world, for a first trace through a path's known vertices;
    /// the traced chain keeps it as [`Half::Local`] at the hit.
    World(DVec3),
}

impl Half {
    /// The half-vector in the world at vertex `v`.
    fn world(self, v: &ChainVertex) -> DVec3 {
        match self {
            Half::Normal => v.n,
            Half::Local(m) => v.to_world(m),
            Half::World(m) => m,
        }
    }
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
    /// The half-vector each specular vertex keeps ([`Half::Normal`] or [`Half::Local`]).
    pub halves: Vec<Half>,
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
        let start =
            ChainVertex::new(self.start.as_dvec3(), (DVec3::X, DVec3::Y), DVec3::Z, (DVec3::ZERO, DVec3::ZERO), 1.0)?;
        std::iter::once(Some(start)).chain(self.hits.iter().map(|si| ChainVertex::at(scene, si))).collect()
    }
}

/// Traces a chain from `start` towards `aim`: at each hit before the last it scatters as
/// `scatters` says, about the half-vector `halves` gives it (all [`Half::Normal`] where
/// `halves` is empty), and every hit must lie on the shape `shapes` names for it (a walk
/// that lands on another shape is rejected, contract `memlt.md`, "Pitfalls"). `None` when a
/// ray escapes, lands elsewhere, or a refraction is total internal reflection.
pub fn trace(
    scene: &Scene,
    (start, start_ng): (Vec3, Vec3),
    aim: Vec3,
    (scatters, halves): (&[Scatter], &[Half]),
    shapes: &[u32],
) -> Option<TracedChain> {
    // The ray leaves from the start moved off its surface, and passes through `aim` exactly
    // (a walk re-traces its chains through their first vertex's hit).
    let o = if start_ng == Vec3::ZERO { start } else { crate::math::offset_origin(start, start_ng, aim - start) };
    let mut ray = Ray::new(o, (aim - o).try_normalize()?);
    let mut hits = Vec::with_capacity(shapes.len());
    let mut kept = Vec::with_capacity(scatters.len());
    for (i, &shape) in shapes.iter().enumerate() {
        let si = scene.intersect(&ray)?;
        if si.shape != shape {
            return None;
        }
        if let Some(&scatter) = scatters.get(i) {
            let n = si.shading.n;
            let half = halves.get(i).copied().unwrap_or(Half::Normal);
            let (d, keep) = match (half, scatter) {
                (Half::Normal, Scatter::Reflect) => (reflect(si.wo, n), half),
                (Half::Normal, Scatter::Refract) => (refract(si.wo, n, scene.bsdf(&si).eta())?.0, half),
                _ => {
                    let v = ChainVertex::at(scene, &si)?;
                    let m = half.world(&v);
                    let wo = scatter_about(si.wo.as_dvec3().normalize(), m, v.n, v.eta, scatter)?;
                    (wo.as_vec3(), Half::Local(v.to_local(m)))
                }
            };
            kept.push(if let Half::World(_) = half { keep } else { half });
            ray = si.spawn_ray(d.try_normalize()?);
        }
        hits.push(si);
    }
    Some(TracedChain { start, start_ng, hits, halves: kept })
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

impl TracedChain {
    /// The solid angle at the chain's end per unit area at its start, `dω_{k+1}/dA_0`:
    /// [`solid_angle_density`] of the vertices in reverse order, the start given a tangent
    /// frame of its surface (so that its parameter area is its area). What a chain whose end
    /// moves and whose start stays needs to express the start's area density. For Dirac
    /// vertices alone it is the reciprocity of the generalized geometric term (étendue
    /// `n² cos dA dω` is the same at both ends of a bundle of rays); offset constraints (glossy
    /// vertices keeping a half-vector off the normal) do not conserve étendue, and the
    /// reversed tangent map holds for both. `None` where the tangent map is singular or the
    /// start has no surface.
    pub fn end_solid_angle_density(&self, scene: &Scene) -> Option<f64> {
        let mut vertices = self.vertices(scene)?;
        vertices[0] = ChainVertex::fixed(self.start.as_dvec3(), self.start_ng.as_dvec3())?;
        vertices.reverse();
        solid_angle_density(&vertices)
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
/// where `θ_diff` is the half-vector change lobes are judged against (`--theta-diff`; Mitsuba
/// 0.6 keeps a running average of the changes its perturbations produced): a lobe much
/// wider than the changes is walked over as if it were diffuse, one much narrower as if it
/// were a mirror. The probability enters both proposal densities.
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
        let next = trace(scene, (chain.start, chain.start_ng), aim.as_vec3(), (&scatters, &chain.halves), &shapes);
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
mod tests;
