//! Mitsuba 0.6's `coating` and `roughcoating`: any BSDF (the nested one) under a dielectric
//! layer of relative index `η` (interior / exterior), after Weidlich and Wilkie's
//! "Arbitrarily layered micro-facet surfaces".
//!
//! The layer's top reflects: a Dirac mirror weighted by the Fresnel reflectance `F(|cos θ|)`
//! for `coating`, a microfacet lobe (Beckmann or GGX, `F D G / (4 |cos θo| |cos θi|)`) for
//! `roughcoating`, each times `specular_reflectance`. Light that enters is bent by Snell's
//! law (both directions, keeping their side: the layer is the same seen from either side),
//! scattered by the nested BSDF at the bent pair, and attenuated on the way in and out by
//! the interface's transmittance — `1 - F` for the smooth layer, the rough dielectric's
//! directional transmittance `T(μ)` (its `(1 - F) G1` averaged over visible normals,
//! tabulated over `μ`) for the rough one, which bends directions as if it were smooth —
//! and by absorption along the two slanted paths through the layer,
//! `exp(-σa d (1/|cos θo'| + 1/|cos θi'|))` with the bent cosines. Light reflected back
//! inside at the top is discarded, as in Mitsuba 0.6. Outside, the nested value is divided
//! by `η²`: the solid angle compresses by `η² cos θ' / cos θ` going in and expands by the
//! inverse coming out. Every factor the layer adds is symmetric in the two directions, so
//! the importance-transport BSDF is the nested one's adjoint under the same factors (the
//! transport mode is passed to the nested BSDF). The layer has no front side: seen from
//! behind, a one-sided layer still reflects at its top (mirrored), as Mitsuba 0.6's does,
//! and its nested BSDF decides what lies under it.
//!
//! Sampling picks the layer's reflection with probability `p = F w / (F w + (1 - F)(1 - w))`
//! (`1 - T(μ)` in place of `F` for the rough layer), where `w = 1 / (1 + mean(exp(-2 σa d)))`
//! steers samples away from an absorbing layer's interior; otherwise it samples the nested
//! BSDF for the bent direction and bends the result out. The smooth layer's density is the
//! nested density times `(1 - p) cos θi / (η² cos θi')`; the rough layer's is the mixture of
//! both lobes' densities, as Mitsuba 0.6 evaluates it. Where the nested lobe is a Dirac one,
//! its sample is weighted by `1 / (1 - p)` under either layer (Mitsuba 0.6's `roughcoating`
//! leaves that division out, rendering a coated mirror or glass darker than its own model).

use super::conductor::mirror;
use super::fresnel::fresnel_dielectric;
use super::microfacet::Microfacet;
use super::plastic::transmittance_at;
use super::{Bsdf, BsdfSample, Lobe, TransportMode};
use crate::math::{Rgb, reflect};
use crate::texture::Texture;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A nested BSDF under a smooth (`coating`) or rough (`roughcoating`) dielectric layer.
#[derive(Clone, Debug, PartialEq)]
pub struct Coating {
    /// Relative index of refraction of the layer, interior / exterior (never 1 from a scene
    /// file: Mitsuba 0.6 refuses matched indices).
    pub eta: f32,
    /// Thickness of the layer, in inverse units of `sigma_a`.
    pub thickness: f32,
    /// Absorption coefficient inside the layer.
    pub sigma_a: Texture,
    pub specular_reflectance: Texture,
    /// The share of samples given to the layer's reflection before Fresnel weighting,
    /// `1 / (1 + mean(exp(-2 σa d)))` with the mean over the texture and the channels.
    pub specular_sampling_weight: f32,
    /// The rough interface of a `roughcoating`; `None` for a smooth `coating`.
    pub rough: Option<RoughInterface>,
    /// The BSDF under the layer (never bump-mapped or masked).
    pub nested: Bsdf,
}

/// The rough top of a `roughcoating`.
#[derive(Clone, Debug, PartialEq)]
pub struct RoughInterface {
    pub distribution: Microfacet,
    /// The interface's directional transmittance `T(μ)` at `μ = i / (n - 1)`, as
    /// `roughplastic` tabulates it (`plastic::RoughPlasticParams::external_transmittance`).
    pub transmittance: Arc<[f32]>,
}

impl RoughInterface {
    /// The interface of `distribution` between the exterior and a layer of relative index
    /// `eta`, its transmittance table computed here.
    pub fn new(distribution: Microfacet, eta: f32) -> RoughInterface {
        let params = super::plastic::RoughPlasticParams::new(distribution, eta, false, 0.5);
        RoughInterface { distribution, transmittance: params.external_transmittance }
    }
}

impl Coating {
    /// A layer of relative index `eta` and `thickness` over `nested`, with Mitsuba 0.6's
    /// sampling weight from the mean absorption.
    pub fn new(
        eta: f32,
        thickness: f32,
        sigma_a: Texture,
        specular_reflectance: Texture,
        rough: Option<RoughInterface>,
        nested: Bsdf,
    ) -> Coating {
        let through = (sigma_a.mean() * (-2.0 * thickness)).exp().element_sum() / 3.0;
        let specular_sampling_weight = 1.0 / (through + 1.0);
        Coating { eta, thickness, sigma_a, specular_reflectance, specular_sampling_weight, rough, nested }
    }

    /// `true` when every lobe is a Dirac delta: a smooth layer over a Dirac BSDF.
    pub fn is_delta(&self) -> bool {
        self.rough.is_none() && self.nested.is_delta()
    }

    /// The layer's own reflection lobe (the nested BSDF's lobes follow it).
    pub fn lobe(&self) -> Lobe {
        match &self.rough {
            None => Lobe { transmission: false, roughness: 0.0, microfacet: None },
            Some(r) => {
                let m = r.distribution;
                Lobe { transmission: false, roughness: 0.5 * (m.alpha_u + m.alpha_v), microfacet: Some(m.kind) }
            }
        }
    }

    /// The fraction of light arriving at `cos θ = mu` that the top does not let in:
    /// the Fresnel reflectance, or `1 - T(μ)` for the rough interface.
    #[inline]
    fn reflected(&self, mu: f32) -> f32 {
        match &self.rough {
            None => fresnel_dielectric(mu.abs(), self.eta),
            Some(r) => 1.0 - transmittance_at(&r.transmittance, mu.abs()),
        }
    }

    /// The probability of sampling the layer's reflection when the top reflects `r`.
    #[inline]
    fn prob_specular(&self, r: f32) -> f32 {
        let w = self.specular_sampling_weight;
        let (ps, pn) = (r * w, (1.0 - r) * (1.0 - w));
        if ps + pn > 0.0 { ps / (ps + pn) } else { 0.0 }
    }

    /// `w` bent into the layer (tangential part divided by `η`, its side kept); `None` on
    /// total internal reflection (a layer less dense than the exterior).
    #[inline]
    fn enter(&self, w: Vec3) -> Option<Vec3> {
        bend(w, 1.0 / self.eta)
    }

    /// `w` inside the layer bent out of it; `None` on total internal reflection.
    #[inline]
    fn leave(&self, w: Vec3) -> Option<Vec3> {
        bend(w, self.eta)
    }

    /// Transmission through the top towards an outside direction of cosine `mu`: `1 - F`
    /// for the smooth interface, `T(μ)` for the rough one.
    #[inline]
    fn transmitted(&self, mu: f32) -> f32 {
        1.0 - self.reflected(mu)
    }

    /// Absorption along the paths through the layer of the bent directions `a` and `b`.
    fn absorption(&self, uv: Vec2, a: Vec3, b: Vec3) -> Rgb {
        let sigma = self.sigma_a.eval(uv) * self.thickness;
        if sigma == Rgb::ZERO {
            return Rgb::ONE;
        }
        let length = 1.0 / a.z.abs() + 1.0 / b.z.abs();
        let channel = |s: f32| if s == 0.0 { 1.0 } else { (-s * length).exp() };
        Rgb::new(channel(sigma.x), channel(sigma.y), channel(sigma.z))
    }

    /// The nested lobe seen from outside, for the bent pair `(wo_in, wi_in)` whose nested
    /// value is `f`: the transmittances, the absorption and `1/η²`.
    #[inline]
    fn through(&self, uv: Vec2, wo: Vec3, wi: Vec3, wo_in: Vec3, wi_in: Vec3, f: Rgb) -> Rgb {
        if f == Rgb::ZERO {
            return Rgb::ZERO;
        }
        let t = self.transmitted(wo.z) * self.transmitted(wi.z);
        f * (t / (self.eta * self.eta)) * self.absorption(uv, wo_in, wi_in)
    }

    /// The Jacobian from the bent direction's solid angle to the outside one's,
    /// `cos θi / (η² cos θi')`.
    #[inline]
    fn jacobian(&self, wi: Vec3, wi_in: Vec3) -> f32 {
        if wi_in.z == 0.0 { 0.0 } else { wi.z.abs() / (self.eta * self.eta * wi_in.z.abs()) }
    }

    /// BSDF value (without the cosine) for light arriving along `wi`, leaving along `wo`.
    pub fn eval(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> Rgb {
        let specular = match &self.rough {
            Some(r) => self.specular_value(r, wo, wi) * self.specular_reflectance.eval(uv),
            None => Rgb::ZERO,
        };
        specular + self.nested_value(wo, wi, uv, mode)
    }

    /// The nested lobe's value seen from outside (zero where the top totally reflects).
    fn nested_value(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> Rgb {
        if self.reflected(wo.z) >= 1.0 || self.reflected(wi.z) >= 1.0 {
            return Rgb::ZERO;
        }
        let (Some(wo_in), Some(wi_in)) = (self.enter(wo), self.enter(wi)) else { return Rgb::ZERO };
        self.through(uv, wo, wi, wo_in, wi_in, self.nested.eval_model(wo_in, wi_in, uv, mode))
    }

    /// The rough top's reflection `F D G / (4 |cos θo| |cos θi|)` (either side, mirrored).
    fn specular_value(&self, r: &RoughInterface, wo: Vec3, wi: Vec3) -> f32 {
        let Some((wo, wi)) = front_pair(wo, wi) else { return 0.0 };
        let m = (wo + wi).normalize_or_zero();
        if m == Vec3::ZERO {
            return 0.0;
        }
        let d = &r.distribution;
        let dg = d.d(m) * d.g(wi, wo, m);
        if dg == 0.0 {
            return 0.0;
        }
        fresnel_dielectric(wo.dot(m).abs(), self.eta) * dg / (4.0 * wo.z * wi.z)
    }

    /// Solid-angle density of sampling `wi` given `wo`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> f32 {
        let r = self.reflected(wo.z);
        let ps = self.prob_specular(r);
        let specular = match &self.rough {
            Some(rough) => ps * specular_pdf(rough, wo, wi),
            None => 0.0,
        };
        if r >= 1.0 || self.reflected(wi.z) >= 1.0 {
            return specular;
        }
        let (Some(wo_in), Some(wi_in)) = (self.enter(wo), self.enter(wi)) else { return specular };
        let nested = self.nested.pdf_model(wo_in, wi_in, uv, mode) * self.jacobian(wi, wi_in);
        specular + (1.0 - ps) * nested
    }

    /// Samples `wi` given `wo`: the layer's reflection or, with `u1` rescaled, the nested
    /// BSDF through the layer.
    pub fn sample(&self, wo: Vec3, uv: Vec2, u1: f32, u2: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let r = self.reflected(wo.z);
        let ps = self.prob_specular(r);
        if u1 < ps {
            return match &self.rough {
                None => {
                    // The Dirac mirror of the smooth top, weighted by the Fresnel reflectance.
                    let wi = mirror(wo);
                    let weight = self.specular_reflectance.eval(uv) * (r / ps);
                    Some(BsdfSample { wi, f: weight * ps / wi.z.abs(), pdf: ps, weight, delta: true })
                }
                Some(rough) => {
                    let flip = wo.z < 0.0;
                    let wo_f = front(wo, flip);
                    let m = rough.distribution.sample(wo_f, u2);
                    if wo_f.dot(m) <= 0.0 {
                        return None;
                    }
                    let wi_f = reflect(wo_f, m);
                    if wi_f.z <= 0.0 {
                        return None;
                    }
                    self.rough_sample(wo, front(wi_f, flip), uv, mode)
                }
            };
        }
        if r >= 1.0 {
            return None;
        }
        let u1 = ((u1 - ps) / (1.0 - ps)).min(1.0 - f32::EPSILON / 2.0);
        let wo_in = self.enter(wo)?;
        let s = self.nested.sample_model(wo_in, uv, u1, u2, mode)?;
        let wi = self.leave(s.wi)?;
        if self.reflected(wi.z) >= 1.0 {
            return None;
        }
        if s.delta {
            let weight = self.through(uv, wo, wi, wo_in, s.wi, s.weight) * ((self.eta * self.eta) / (1.0 - ps));
            let pdf = s.pdf * (1.0 - ps);
            return Some(BsdfSample { wi, f: weight * pdf / wi.z.abs(), pdf, weight, delta: true });
        }
        if self.rough.is_some() {
            // The mixture of both lobes, as the density says.
            return self.rough_sample(wo, wi, uv, mode);
        }
        let f = self.through(uv, wo, wi, wo_in, s.wi, s.f);
        let weight = self.through(uv, wo, wi, wo_in, s.wi, s.weight) * ((self.eta * self.eta) / (1.0 - ps));
        let pdf = s.pdf * (1.0 - ps) * self.jacobian(wi, s.wi);
        if pdf <= 0.0 || !pdf.is_finite() {
            return None;
        }
        Some(BsdfSample { wi, f, pdf, weight, delta: false })
    }

    /// A sample of the rough layer towards `wi`, valued and weighted by the whole BSDF and
    /// its mixture density.
    fn rough_sample(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let pdf = self.pdf(wo, wi, uv, mode);
        if pdf <= 0.0 || !pdf.is_finite() {
            return None;
        }
        let f = self.eval(wo, wi, uv, mode);
        Some(BsdfSample { wi, f, pdf, weight: f * (wi.z.abs() / pdf), delta: false })
    }
}

/// `w` refracted through a flat interface that scales its tangential part by `k` (the ratio
/// of the indices on its side and on the other), on the same side as `w`; `None` on total
/// internal reflection. `k = 1` leaves `w` as it is.
#[inline]
fn bend(w: Vec3, k: f32) -> Option<Vec3> {
    if k == 1.0 {
        return Some(w);
    }
    let sin2 = k * k * (1.0 - w.z * w.z).max(0.0);
    if sin2 >= 1.0 {
        return None;
    }
    let cos = (1.0 - sin2).sqrt();
    Some(Vec3::new(k * w.x, k * w.y, cos.copysign(w.z)))
}

/// `w` mirrored to the front side when `flip`.
#[inline]
fn front(w: Vec3, flip: bool) -> Vec3 {
    if flip { Vec3::new(w.x, w.y, -w.z) } else { w }
}

/// A reflected pair moved to the front side (both mirrored when both lie behind); `None`
/// when they lie on different sides or one is grazing.
#[inline]
fn front_pair(wo: Vec3, wi: Vec3) -> Option<(Vec3, Vec3)> {
    if wo.z * wi.z <= 0.0 {
        return None;
    }
    let flip = wo.z < 0.0;
    Some((front(wo, flip), front(wi, flip)))
}

/// The density of the rough top's reflection sampling `wi` given `wo` (visible normals, or
/// the whole distribution, of the front-side pair; the half-vector Jacobian `1/(4 |wi·m|)`).
fn specular_pdf(r: &RoughInterface, wo: Vec3, wi: Vec3) -> f32 {
    let Some((wo, wi)) = front_pair(wo, wi) else { return 0.0 };
    let m = (wo + wi).normalize_or_zero();
    let c = wi.dot(m);
    if m == Vec3::ZERO || c <= 0.0 {
        return 0.0;
    }
    r.distribution.pdf(wo, m) / (4.0 * c)
}

#[cfg(test)]
mod tests {
    use super::super::microfacet::MicrofacetType;
    use super::super::{BsdfModel, dielectric};
    use super::*;
    use crate::sampling::{Sampler, square_to_uniform_sphere};

    fn c(v: f32) -> Texture {
        Texture::Constant(Rgb::splat(v))
    }

    fn diffuse(rho: f32) -> Bsdf {
        Bsdf::diffuse(c(rho))
    }

    fn rough_conductor(alpha: f32) -> Bsdf {
        let (eta, k) = super::super::fresnel::lookup_conductor("Cu").unwrap();
        let distribution =
            Microfacet { kind: MicrofacetType::Ggx, alpha_u: alpha, alpha_v: alpha, sample_visible: true };
        Bsdf::new(BsdfModel::RoughConductor { distribution: distribution.into(), eta, k, specular_reflectance: c(1.0) })
    }

    fn rough_dielectric(alpha: f32) -> Bsdf {
        let distribution =
            Microfacet { kind: MicrofacetType::Beckmann, alpha_u: alpha, alpha_v: alpha, sample_visible: true };
        Bsdf::new(BsdfModel::RoughDielectric {
            distribution: distribution.into(),
            eta: 1.33,
            specular_reflectance: c(1.0),
            specular_transmittance: c(1.0),
        })
    }

    fn beckmann(alpha: f32) -> Microfacet {
        Microfacet { kind: MicrofacetType::Beckmann, alpha_u: alpha, alpha_v: alpha, sample_visible: true }
    }

    fn coated(eta: f32, sigma: Rgb, thickness: f32, rough: Option<Microfacet>, nested: Bsdf) -> Bsdf {
        let rough = rough.map(|d| RoughInterface::new(d, eta));
        Bsdf::new(BsdfModel::Coating(Box::new(Coating::new(
            eta,
            thickness,
            Texture::Constant(sigma),
            c(1.0),
            rough,
            nested,
        ))))
    }

    fn coating_of(b: &Bsdf) -> &Coating {
        match &b.model {
            BsdfModel::Coating(c) => c,
            _ => unreachable!("a coating"),
        }
    }

    const MODES: [TransportMode; 2] = [TransportMode::Radiance, TransportMode::Importance];

    /// Mean and standard error of the sampling weights: the directional albedo for `wo`.
    fn albedo(b: &Bsdf, wo: Vec3, n: usize, rng: &mut Sampler) -> (f64, f64) {
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            if let Some(s) = b.sample(wo, Vec2::ZERO, rng.next_1d(), rng.next_2d(), TransportMode::Radiance) {
                let w = s.weight.x as f64;
                sum += w;
                sum2 += w * w;
            }
        }
        let mean = sum / n as f64;
        (mean, ((sum2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt())
    }

    /// `2 ∫ g(μ) μ dμ` over [0, 1] by the midpoint rule.
    fn hemispherical(g: impl Fn(f64) -> f64) -> f64 {
        let n = 20_000;
        (0..n).map(|i| (i as f64 + 0.5) / n as f64).map(|mu| 2.0 * g(mu) * mu).sum::<f64>() / n as f64
    }

    /// The cosine inside the layer of a direction of cosine `mu` outside (Snell's law).
    fn bent_cos(mu: f64, eta: f64) -> f64 {
        (1.0 - (1.0 - mu * mu) / (eta * eta)).sqrt()
    }

    /// The albedo of a smooth layer of index `eta` and absorption `sigma_d = σa d` over a
    /// Lambertian base of reflectance `rho`, for light from `cos θ = mu`, from Fresnel's
    /// and Snell's laws alone: `F + (1 - F) (ρ/η²) e^{-σd/μ'} 2 ∫ (1 - F) e^{-σd/μ''} μ dμ`.
    fn coated_lambertian_albedo(mu: f64, eta: f64, rho: f64, sigma_d: f64) -> f64 {
        let f = |m: f64| fresnel_dielectric(m as f32, eta as f32) as f64;
        let inside = hemispherical(|m| (1.0 - f(m)) * (-sigma_d / bent_cos(m, eta)).exp());
        f(mu) + (1.0 - f(mu)) * rho / (eta * eta) * (-sigma_d / bent_cos(mu, eta)).exp() * inside
    }

    #[test]
    fn white_furnace_albedo_is_the_layered_lambertian_one_and_at_most_one() {
        // A clear, white layer over a white Lambertian base: the sampled directional albedo
        // is the one Fresnel and Snell give (and so ≤ 1) at every angle, with and without
        // absorption; a rough white layer over it never exceeds 1 either.
        let mut rng = Sampler::new(&[3]);
        let n = 200_000;
        let eta = 1.5;
        for (sigma_d, thickness) in [(0.0, 1.0), (0.4, 2.0)] {
            let b = coated(eta, Rgb::splat(sigma_d / thickness), thickness, None, diffuse(1.0));
            for mu in [1.0f32, 0.8, 0.5, 0.2, 0.05] {
                let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let (a, err) = albedo(&b, wo, n, &mut rng);
                let expected = coated_lambertian_albedo(mu as f64, eta as f64, 1.0, sigma_d as f64);
                eprintln!("σd {sigma_d}, μ {mu}: albedo {a:.5} ± {err:.5}, expected {expected:.5}");
                assert!(a <= 1.0 + 4.0 * err, "σd {sigma_d}, μ {mu}: albedo {a} ± {err}");
                assert!((a - expected).abs() <= 4.0 * err + 1e-4, "σd {sigma_d}, μ {mu}: {a} ± {err} vs {expected}");
                // Negative control: the albedo a layer without the 1/η² factor would have
                // (the base's share η² times larger) is rejected at every angle.
                let f = fresnel_dielectric(mu, eta) as f64;
                let wrong = f + (expected - f) * (eta * eta) as f64;
                assert!((a - wrong).abs() > 4.0 * err + 1e-4, "σd {sigma_d}, μ {mu}: {a} passes for {wrong}");
            }
        }
        for kind in [MicrofacetType::Beckmann, MicrofacetType::Ggx] {
            for alpha in [0.05, 0.3, 0.8] {
                let d = Microfacet { kind, alpha_u: alpha, alpha_v: alpha, sample_visible: true };
                let b = coated(eta, Rgb::ZERO, 1.0, Some(d), diffuse(1.0));
                for mu in [1.0f32, 0.5, 0.1] {
                    let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                    let (a, err) = albedo(&b, wo, n / 4, &mut rng);
                    assert!(a <= 1.0 + 4.0 * err, "rough {kind:?} α {alpha}, μ {mu}: albedo {a} ± {err}");
                    assert!(a > 0.1, "rough {kind:?} α {alpha}, μ {mu}: albedo {a}");
                }
            }
        }
        // Negative control for the bound itself: a base reflecting three times what it
        // receives under the same layer is caught.
        let b = coated(eta, Rgb::ZERO, 1.0, None, diffuse(3.0));
        let (a, err) = albedo(&b, Vec3::Z, n, &mut rng);
        assert!(a > 1.0 + 4.0 * err, "albedo {a} ± {err}");
    }

    #[test]
    fn an_index_matched_clear_layer_is_its_nested_bsdf() {
        // η = 1 and no absorption: the top neither reflects nor bends, so value, densities
        // and samples are the nested BSDF's, bit for bit, from either side, in both modes.
        let mut rng = Sampler::new(&[4]);
        for nested in [diffuse(0.7), rough_conductor(0.3), rough_dielectric(0.4)] {
            for two_sided in [false, true] {
                let nested = Bsdf { two_sided, ..nested.clone() };
                let b = coated(1.0, Rgb::ZERO, 1.0, None, nested.clone());
                for _ in 0..2000 {
                    let wo = square_to_uniform_sphere(rng.next_2d());
                    let wi = square_to_uniform_sphere(rng.next_2d());
                    for mode in MODES {
                        assert_eq!(b.eval(wo, wi, Vec2::ZERO, mode), nested.eval(wo, wi, Vec2::ZERO, mode));
                        assert_eq!(b.pdf(wo, wi, Vec2::ZERO, mode), nested.pdf(wo, wi, Vec2::ZERO, mode));
                        assert_eq!(b.pdf_pair(wo, wi, Vec2::ZERO, mode), nested.pdf_pair(wo, wi, Vec2::ZERO, mode));
                        let (u1, u2) = (rng.next_1d(), rng.next_2d());
                        let (s, t) =
                            (b.sample(wo, Vec2::ZERO, u1, u2, mode), nested.sample(wo, Vec2::ZERO, u1, u2, mode));
                        match (s, t) {
                            (Some(s), Some(t)) => {
                                assert_eq!((s.wi, s.f, s.pdf, s.weight, s.delta), (t.wi, t.f, t.pdf, t.weight, t.delta))
                            }
                            (None, None) => {}
                            (s, t) => panic!("{s:?} against {t:?}"),
                        }
                    }
                }
            }
        }
        // Negative control: a layer of index 1.01 is already something else.
        let b = coated(1.01, Rgb::ZERO, 1.0, None, diffuse(0.7));
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let m = TransportMode::Radiance;
        assert_ne!(b.eval(wo, Vec3::Z, Vec2::ZERO, m), diffuse(0.7).eval(wo, Vec3::Z, Vec2::ZERO, m));
    }

    #[test]
    fn absorption_follows_the_bent_path_lengths() {
        // The nested lobe is attenuated by exp(-σa d (1/cos θo' + 1/cos θi')), the cosines
        // inside the layer from Snell's law; at normal incidence exp(-2 σa d). The top's
        // Fresnel factors cancel in the ratio to the clear layer.
        let sigma = Rgb::new(0.1, 0.5, 1.0);
        let (eta, thickness) = (1.5f32, 2.0f32);
        for (rough, nested) in [(None, diffuse(0.8)), (None, rough_conductor(0.5)), (Some(beckmann(0.2)), diffuse(0.8))]
        {
            let tinted = coated(eta, sigma, thickness, rough, nested.clone());
            let clear = coated(eta, Rgb::ZERO, thickness, rough, nested);
            for (mo, mi) in [(1.0f32, 1.0f32), (0.9, 0.3), (0.2, 0.7), (0.05, 0.95)] {
                let wo = Vec3::new((1.0 - mo * mo).sqrt(), 0.0, mo);
                let wi = Vec3::new(0.0, -(1.0 - mi * mi).sqrt(), mi);
                let mode = TransportMode::Radiance;
                // The nested lobe alone: the rough top's own reflection is not absorbed.
                let strip = |b: &Bsdf| coating_of(b).nested_value(wo, wi, Vec2::ZERO, mode);
                let (t, c) = (strip(&tinted), strip(&clear));
                let length = 1.0 / bent_cos(mo as f64, eta as f64) + 1.0 / bent_cos(mi as f64, eta as f64);
                for ch in 0..3 {
                    let expected = (-(sigma[ch] * thickness) as f64 * length).exp();
                    let ratio = (t[ch] / c[ch]) as f64;
                    assert!(
                        (ratio / expected - 1.0).abs() < 1e-4,
                        "μ ({mo}, {mi}) channel {ch}: {ratio} vs {expected}"
                    );
                }
                if mo == 1.0 && mi == 1.0 {
                    let normal = (-sigma * (2.0 * thickness)).exp();
                    assert!(((t / c) / normal - Rgb::ONE).abs().max_element() < 1e-5, "{}", t / c);
                }
            }
            // Sampling steers towards the top as the layer darkens: w = 1 / (1 + mean e^{-2σd}).
            let w = coating_of(&tinted).specular_sampling_weight;
            let mean = (-sigma * (2.0 * thickness)).exp().element_sum() / 3.0;
            assert!((w - 1.0 / (1.0 + mean)).abs() < 1e-6, "{w}");
            assert_eq!(coating_of(&clear).specular_sampling_weight, 0.5);
        }
    }

    #[test]
    fn importance_transport_is_the_adjoint_of_radiance_transport() {
        // f_importance(wo, wi) = f_radiance(wi, wo) for any nested BSDF, on either side and
        // through a layer on both sides of a rough dielectric; the layer's factors are
        // symmetric, so over a reciprocal base the BSDF is reciprocal too.
        let mut rng = Sampler::new(&[6]);
        let sigma = Rgb::new(0.2, 0.0, 0.6);
        let cases = [
            ("coating/diffuse", None, diffuse(0.6), true),
            ("coating/roughconductor", None, rough_conductor(0.2), true),
            ("coating/roughdielectric", None, rough_dielectric(0.3), false),
            ("roughcoating/diffuse", Some(beckmann(0.3)), diffuse(0.6), true),
            ("roughcoating/roughdielectric", Some(beckmann(0.3)), rough_dielectric(0.3), false),
        ];
        // Relative agreement, where the values are not vanishingly small (the tails of a
        // microfacet lobe, evaluated along two different paths, round apart).
        let close = |a: Rgb, b: Rgb| {
            (a - b).abs().max_element() <= 1e-4 * a.abs().max_element().max(b.abs().max_element()) + 1e-9
        };
        for (name, rough, nested, reciprocal) in cases {
            let b = coated(1.5, sigma, 1.0, rough, nested);
            let mut transmitted = 0;
            let mut asymmetric = 0;
            for _ in 0..5000 {
                let wo = square_to_uniform_sphere(rng.next_2d());
                let wi = square_to_uniform_sphere(rng.next_2d());
                let rad = b.eval(wo, wi, Vec2::ZERO, TransportMode::Radiance);
                let imp = b.eval(wi, wo, Vec2::ZERO, TransportMode::Importance);
                assert!(close(rad, imp), "{name}: {wo} {wi}: {rad} vs {imp}");
                let back = b.eval(wi, wo, Vec2::ZERO, TransportMode::Radiance);
                if reciprocal {
                    assert!(close(rad, back), "{name}: {wo} {wi}: {rad} vs {back}");
                } else if rad.max_element() > 1e-4 && wo.z * wi.z < 0.0 {
                    transmitted += 1;
                    asymmetric += usize::from(!close(rad, back));
                }
            }
            if !reciprocal {
                // Negative control: through glass, radiance transport alone is not reciprocal.
                assert!(transmitted > 100 && asymmetric == transmitted, "{name}: {asymmetric} of {transmitted}");
            }
        }
    }

    #[test]
    fn a_rough_top_reflects_as_a_rough_dielectric_and_transmits_its_table() {
        // The rough top's lobe is roughdielectric's reflection at the same index; the nested
        // lobe is scaled by T(μo) T(μi) / η², which at the table's points are its entries.
        let eta = 1.5;
        let d = beckmann(0.25);
        let b = coated(eta, Rgb::ZERO, 1.0, Some(d), diffuse(1.0));
        let coat = coating_of(&b);
        let mode = TransportMode::Radiance;
        let mut rng = Sampler::new(&[9]);
        for _ in 0..500 {
            let wo = square_to_uniform_sphere(rng.next_2d());
            let wi = square_to_uniform_sphere(rng.next_2d());
            if wo.z <= 0.0 || wi.z <= 0.0 {
                continue;
            }
            let top = coat.specular_value(coat.rough.as_ref().unwrap(), wo, wi);
            let reference = dielectric::eval_rough(&d, eta, Rgb::ONE, Rgb::ONE, wo, wi, mode).x;
            assert!((top - reference).abs() <= 1e-5 * reference.max(1e-3), "{top} vs {reference}");
            // Seen from behind, the layer reflects the mirrored pair alike (Mitsuba 0.6's
            // layer has no front side).
            let behind = coat.specular_value(coat.rough.as_ref().unwrap(), front(wo, true), front(wi, true));
            assert_eq!(top, behind);
        }
        let table = &coat.rough.as_ref().unwrap().transmittance;
        let n = table.len();
        for (i, j) in [(n - 1, n - 1), (n / 2, n - 1), (n / 4, n / 3)] {
            let (mo, mi) = (i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32);
            let wo = Vec3::new((1.0 - mo * mo).sqrt(), 0.0, mo);
            let wi = Vec3::new(-(1.0 - mi * mi).sqrt(), 0.0, mi);
            let nested = coat.nested_value(wo, wi, Vec2::ZERO, mode).x;
            let expected = table[i] * table[j] / (eta * eta) / std::f32::consts::PI;
            assert!((nested / expected - 1.0).abs() < 1e-5, "{nested} vs {expected}");
        }
        // The table is what the rough interface lets through: less than the smooth one's
        // 1 - F near normal incidence, and far less at grazing angles.
        assert!(table[n - 1] < 1.0 - fresnel_dielectric(1.0, eta) && table[n - 1] > 0.9, "{}", table[n - 1]);
        assert!(table[1] < table[n - 1] - 0.2, "{} {}", table[1], table[n - 1]);
    }

    #[test]
    fn the_rough_transmittance_is_mitsuba_06s() {
        // T(μ) at nodes of Mitsuba 0.6's precomputed tables (`data/microfacet/*.dat`: index
        // η = 1.0001 + 2.9999 (i/49)^4, α = 4 (j/49)^4, μ = (k/99)^4), read from them:
        // (distribution, i, j, [T at μ = 0.13492, 0.42640, 1]). The tables interpolate
        // cubically in μ^(1/4), this one linearly in μ; they agree within 0.004.
        let mitsuba = [
            (MicrofacetType::Beckmann, 20, 12, [0.75061, 0.98236, 0.9984]),
            (MicrofacetType::Beckmann, 20, 25, [0.87878, 0.97439, 0.99839]),
            (MicrofacetType::Beckmann, 30, 12, [0.54054, 0.89592, 0.96969]),
            (MicrofacetType::Beckmann, 30, 20, [0.60822, 0.89372, 0.96968]),
            (MicrofacetType::Beckmann, 30, 25, [0.74495, 0.89161, 0.96955]),
            (MicrofacetType::Ggx, 20, 20, [0.81728, 0.97142, 0.9981]),
            (MicrofacetType::Ggx, 20, 25, [0.75421, 0.93059, 0.99662]),
            (MicrofacetType::Ggx, 30, 12, [0.5465, 0.89576, 0.96969]),
            (MicrofacetType::Ggx, 30, 20, [0.6724, 0.89251, 0.96876]),
            (MicrofacetType::Ggx, 30, 25, [0.7462, 0.87996, 0.96418]),
        ];
        let node = |i: i32| (i as f64 / 49.0).powi(4);
        for (kind, i, j, expected) in mitsuba {
            let eta = (1.0001 + 2.9999 * node(i)) as f32;
            let alpha = (4.0 * node(j)) as f32;
            let d = Microfacet { kind, alpha_u: alpha, alpha_v: alpha, sample_visible: true };
            let interface = RoughInterface::new(d, eta);
            for (k, t) in [60, 80, 99].into_iter().zip(expected) {
                let mu = (k as f64 / 99.0).powi(4) as f32;
                let ours = transmittance_at(&interface.transmittance, mu);
                assert!((ours - t).abs() < 0.004, "{kind:?} η {eta} α {alpha} μ {mu}: {ours} vs {t}");
                // Negative control: the smooth interface's 1 - F is far from the rough one's.
                if i == 30 && j == 25 && k == 60 {
                    let smooth = 1.0 - fresnel_dielectric(mu, eta);
                    assert!((smooth - t).abs() > 0.05, "{kind:?} η {eta}: {smooth} vs {t}");
                }
            }
        }
    }

    #[test]
    fn a_layer_over_a_mirror_is_dirac_and_weights_both_mirrors() {
        // A smooth layer over a smooth conductor: two Dirac lobes along the mirror direction,
        // chosen by the sampling weights, whose expected weight is R + (1 - R)² R_metal e^{-2σd/μ'}.
        let (eta_c, k) = super::super::fresnel::lookup_conductor("Au").unwrap();
        let metal = Bsdf::new(BsdfModel::Conductor { eta: eta_c, k, specular_reflectance: c(1.0) });
        let sigma = 0.3;
        let b = coated(1.5, Rgb::splat(sigma), 1.0, None, metal);
        assert!(b.is_delta() && !b.transmits() && b.lobes(Vec2::ZERO).count() == 2);
        let mu = 0.6f32;
        let wo = Vec3::new(0.8, 0.0, mu);
        let mut rng = Sampler::new(&[10]);
        let n = 100_000;
        let mut sum = Rgb::ZERO;
        for _ in 0..n {
            let s = b.sample(wo, Vec2::ZERO, rng.next_1d(), rng.next_2d(), TransportMode::Radiance).unwrap();
            assert!(s.delta && (s.wi - mirror(wo)).length() < 1e-5, "{}", s.wi);
            sum += s.weight;
        }
        let mean = sum / n as f32;
        let r = fresnel_dielectric(mu, 1.5);
        let inside = bent_cos(mu as f64, 1.5) as f32;
        let mu_in = Vec3::new(0.8 / 1.5, 0.0, inside);
        let metal_r = super::super::fresnel::fresnel_conductor(mu_in.z, eta_c, k);
        let expected = Rgb::splat(r) + metal_r * ((1.0 - r) * (1.0 - r) * (-2.0 * sigma / inside).exp());
        assert!((mean - expected).abs().max_element() < 0.01, "{mean} vs {expected}");
    }
}
