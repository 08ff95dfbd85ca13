//! Mitsuba's `plastic`: a diffuse base under a smooth dielectric coating. The coating
//! reflects specularly (a Dirac lobe weighted by Fresnel); light that enters is scattered by
//! the base, attenuated by the Fresnel transmittance in and out and by internal reflection
//! at the coating (`fdr_int`, the hemispherical Fresnel reflectance from inside), with
//! Mitsuba's linear or `nonlinear` normalisation.

use super::BsdfSample;
use super::conductor::mirror;
use super::fresnel::fresnel_dielectric;
use crate::math::Rgb;
use crate::sampling::{square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

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
