//! Mitsuba's `plastic`: a diffuse base under a smooth dielectric coating. The coating
//! reflects specularly (a Dirac lobe weighted by Fresnel); light that enters is scattered by
//! the base, attenuated by the Fresnel transmittance in and out and by internal reflection
//! at the coating (`fdr_int`, the hemispherical Fresnel reflectance from inside), with
//! Mitsuba's linear or `nonlinear` normalisation.

use super::BsdfSample;
use super::conductor::mirror;
use super::fresnel::{fresnel_dielectric, refract};
use super::microfacet::Microfacet;
use crate::math::{Rgb, reflect};
use crate::sampling::{square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlasticParams {
    pub eta: f32,
    pub nonlinear: bool,
    /// Hemispherical reflectance of the coating seen from inside.
    pub fdr_int: f32,
    /// Share of samples for the specular lobe before Fresnel weighting.
    pub specular_sampling_weight: f32,
}

fn prob_specular(p: &PlasticParams, wo: Vec3) -> f32 {
    let fi = fresnel_dielectric(wo.z, p.eta);
    let ps = fi * p.specular_sampling_weight;
    let pd = (1.0 - fi) * (1.0 - p.specular_sampling_weight);
    if ps + pd > 0.0 { ps / (ps + pd) } else { 0.0 }
}

pub fn eval(p: &PlasticParams, diffuse: Rgb, wo: Vec3, wi: Vec3) -> Rgb {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return Rgb::ZERO;
    }
    let fi = fresnel_dielectric(wo.z, p.eta);
    let fo = fresnel_dielectric(wi.z, p.eta);
    let d = if p.nonlinear { diffuse / (Rgb::ONE - diffuse * p.fdr_int) } else { diffuse / (1.0 - p.fdr_int) };
    d * ((1.0 - fi) * (1.0 - fo) / (p.eta * p.eta) * FRAC_1_PI)
}

pub fn pdf(p: &PlasticParams, wo: Vec3, wi: Vec3) -> f32 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return 0.0;
    }
    (1.0 - prob_specular(p, wo)) * square_to_cosine_hemisphere_pdf(wi)
}

pub fn sample(p: &PlasticParams, diffuse: Rgb, specular: Rgb, wo: Vec3, u1: f32, u2: Vec2) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let ps = prob_specular(p, wo);
    if u1 < ps {
        let wi = mirror(wo);
        let f = specular * fresnel_dielectric(wo.z, p.eta);
        return Some(BsdfSample { wi, f: f / wi.z, pdf: ps, weight: f / ps, delta: true });
    }
    let wi = square_to_cosine_hemisphere(u2);
    let pdf = (1.0 - ps) * square_to_cosine_hemisphere_pdf(wi);
    if pdf <= 0.0 {
        return None;
    }
    let f = eval(p, diffuse, wo, wi);
    Some(BsdfSample { wi, f, pdf, weight: f * (wi.z / pdf), delta: false })
}

/// Mitsuba's `roughplastic`: the same diffuse base under a rough dielectric coating
/// (Beckmann or GGX, isotropic). Light entering and leaving the coating is attenuated by
/// the coating's directional transmittance `T(μ)` (the energy the rough interface
/// refracts, shadowing included), tabulated over `μ = cos θ` when the BSDF is made; the
/// internal reflectance is `2 mean(R_int(μ) μ)` over the same grid, with the inverted index.
#[derive(Clone, Debug, PartialEq)]
pub struct RoughPlasticParams {
    pub distribution: Microfacet,
    pub eta: f32,
    pub nonlinear: bool,
    pub specular_sampling_weight: f32,
    pub internal_reflectance: f32,
    /// `T(μ)` at `μ = i / (n - 1)`.
    pub external_transmittance: Arc<[f32]>,
}

/// Table size for the coating transmittance (as Mitsuba's `MI_ROUGH_TRANSMITTANCE_RES`).
const TRANSMITTANCE_RES: usize = 64;

impl RoughPlasticParams {
    pub fn new(
        distribution: Microfacet,
        eta: f32,
        nonlinear: bool,
        specular_sampling_weight: f32,
    ) -> RoughPlasticParams {
        let mu = |i: usize| (i as f32 / (TRANSMITTANCE_RES - 1) as f32).max(1e-4);
        // Each grid point's two integrals in parallel; the sums in order, as one thread would.
        let energies: Vec<(f32, f32)> = (0..TRANSMITTANCE_RES)
            .into_par_iter()
            .map(|i| {
                (interface_energy(&distribution, mu(i), eta).1, interface_energy(&distribution, mu(i), 1.0 / eta).0)
            })
            .collect();
        let external: Vec<f32> = energies.iter().map(|e| e.0).collect();
        let internal =
            2.0 * (0..TRANSMITTANCE_RES).map(|i| energies[i].1 * mu(i)).sum::<f32>() / TRANSMITTANCE_RES as f32;
        RoughPlasticParams {
            distribution,
            eta,
            nonlinear,
            specular_sampling_weight,
            internal_reflectance: internal,
            external_transmittance: external.into(),
        }
    }

    fn transmittance(&self, mu: f32) -> f32 {
        transmittance_at(&self.external_transmittance, mu)
    }

    fn prob_specular(&self, wo: Vec3) -> f32 {
        self.prob_specular_from(self.transmittance(wo.z))
    }

    /// The specular lobe's sampling probability given the transmittance `t` towards `wo`.
    #[inline]
    fn prob_specular_from(&self, t: f32) -> f32 {
        let ps = (1.0 - t) * self.specular_sampling_weight;
        let pd = t * (1.0 - self.specular_sampling_weight);
        if ps + pd > 0.0 { ps / (ps + pd) } else { 0.0 }
    }
}

/// A coating's transmittance `T(μ)` from its table over `μ = i / (n - 1)` (linear
/// interpolation; `μ` clamped to [0, 1]).
pub(crate) fn transmittance_at(table: &[f32], mu: f32) -> f32 {
    let n = table.len();
    let x = mu.clamp(0.0, 1.0) * (n - 1) as f32;
    let i = (x as usize).min(n - 2);
    let f = x - i as f32;
    table[i] * (1.0 - f) + table[i + 1] * f
}

/// Energy a rough dielectric interface reflects and transmits for light arriving at
/// `cos θ = mu`: the visible-normal averages of `F G1(reflected)` and `(1 - F) G1(refracted)`
/// (as Mitsuba 3 defines them), by a deterministic stratified rule.
fn interface_energy(d: &Microfacet, mu: f32, eta: f32) -> (f32, f32) {
    let wi = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let visible = Microfacet { sample_visible: true, ..*d };
    let n = 64;
    let (mut r, mut t) = (0.0f64, 0.0f64);
    for a in 0..n {
        for b in 0..n {
            let m = visible.sample(wi, Vec2::new((a as f32 + 0.5) / n as f32, (b as f32 + 0.5) / n as f32));
            let c = wi.dot(m);
            if c <= 0.0 {
                continue;
            }
            let f = fresnel_dielectric(c, eta);
            let wr = reflect(wi, m);
            if wr.z > 0.0 {
                r += (f * d.g1(wr, m)) as f64;
            }
            if let Some((wt, _)) = refract(wi, m, eta).filter(|(wt, _)| wt.z < 0.0) {
                t += ((1.0 - f) * d.g1(wt, m)) as f64;
            }
        }
    }
    let k = (n * n) as f64;
    ((r / k) as f32, (t / k) as f32)
}

pub fn eval_rough(p: &RoughPlasticParams, diffuse: Rgb, specular: Rgb, wo: Vec3, wi: Vec3) -> Rgb {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return Rgb::ZERO;
    }
    value_rough(p, diffuse, specular, half_vector(p, wo, wi), p.transmittance(wo.z), wo, wi)
}

pub fn pdf_rough(p: &RoughPlasticParams, wo: Vec3, wi: Vec3) -> f32 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return 0.0;
    }
    pdf_rough_with(p, p.prob_specular(wo), half_vector(p, wo, wi), wo, wi)
}

/// [`eval_rough`] and [`pdf_rough`] together, the half vector, its microfacet density and
/// the coating's transmittance towards `wo` computed once (the same values as the two calls).
fn eval_pdf_rough(p: &RoughPlasticParams, diffuse: Rgb, specular: Rgb, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return (Rgb::ZERO, 0.0);
    }
    let half = half_vector(p, wo, wi);
    let t_o = p.transmittance(wo.z);
    (value_rough(p, diffuse, specular, half, t_o, wo, wi), pdf_rough_with(p, p.prob_specular_from(t_o), half, wo, wi))
}

/// The half vector of `wo` and `wi` and its microfacet density (zero where it is undefined).
#[inline]
fn half_vector(p: &RoughPlasticParams, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
    let m = (wo + wi).normalize_or_zero();
    (m, if m == Vec3::ZERO { 0.0 } else { p.distribution.d(m) })
}

/// [`eval_rough`] of two directions on the front side, given their half vector and its
/// density (`half_vector`) and the coating's transmittance `t_o` towards `wo`.
#[inline]
fn value_rough(
    p: &RoughPlasticParams,
    diffuse: Rgb,
    specular: Rgb,
    (m, d): (Vec3, f32),
    t_o: f32,
    wo: Vec3,
    wi: Vec3,
) -> Rgb {
    let spec = if m == Vec3::ZERO {
        0.0
    } else {
        fresnel_dielectric(wo.dot(m), p.eta) * d * p.distribution.g(wi, wo, m) / (4.0 * wo.z * wi.z)
    };
    let base = if p.nonlinear {
        diffuse / (Rgb::ONE - diffuse * p.internal_reflectance)
    } else {
        diffuse / (1.0 - p.internal_reflectance)
    };
    specular * spec + base * (FRAC_1_PI / (p.eta * p.eta) * t_o * p.transmittance(wi.z))
}

/// [`pdf_rough`] given the specular lobe's probability, the half vector and its density.
#[inline]
fn pdf_rough_with(p: &RoughPlasticParams, ps: f32, (m, d): (Vec3, f32), wo: Vec3, wi: Vec3) -> f32 {
    let spec = if m == Vec3::ZERO || wo.dot(m) <= 0.0 {
        0.0
    } else {
        p.distribution.pdf_given_d(wo, m, d) / (4.0 * wo.dot(m))
    };
    ps * spec + (1.0 - ps) * square_to_cosine_hemisphere_pdf(wi)
}

pub fn sample_rough(
    p: &RoughPlasticParams,
    diffuse: Rgb,
    specular: Rgb,
    wo: Vec3,
    u1: f32,
    u2: Vec2,
) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let wi = if u1 < p.prob_specular(wo) {
        let m = p.distribution.sample(wo, u2);
        if wo.dot(m) <= 0.0 {
            return None;
        }
        reflect(wo, m)
    } else {
        square_to_cosine_hemisphere(u2)
    };
    if wi.z <= 0.0 {
        return None;
    }
    let (f, pdf) = eval_pdf_rough(p, diffuse, specular, wo, wi);
    if pdf <= 0.0 || !pdf.is_finite() {
        return None;
    }
    Some(BsdfSample { wi, f, pdf, weight: f * (wi.z / pdf), delta: false })
}
