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

use glam::{DMat2, DVec2, DVec3};

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

    /// The vertex moved by `(du, dv)` in its surface's parameters, to first order (the
    /// chain as a function of the parameters, which the Jacobian differentiates).
    pub fn moved(&self, d: DVec2) -> ChainVertex {
        let n = (self.n + self.dn_du * d.x + self.dn_dv * d.y).normalize();
        ChainVertex {
            p: self.p + self.dp_du * d.x + self.dp_dv * d.y,
            n,
            s: (self.s - n * n.dot(self.s)).normalize(),
            ..*self
        }
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
