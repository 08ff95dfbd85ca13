//! Mitsuba's `conductor` (a smooth metal: a Dirac reflection scaled by the conductor
//! Fresnel term) and `roughconductor` (Cook–Torrance with a Beckmann or GGX distribution).

use super::BsdfSample;
use super::fresnel::fresnel_conductor;
use super::microfacet::Microfacet;
use crate::math::{Rgb, reflect};
use glam::{Vec2, Vec3};

/// Mirror reflection about +z.
#[inline]
pub fn mirror(w: Vec3) -> Vec3 {
    Vec3::new(-w.x, -w.y, w.z)
}

pub fn sample_smooth(eta: Rgb, k: Rgb, r: Rgb, wo: Vec3) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let wi = mirror(wo);
    let weight = r * fresnel_conductor(wo.z, eta, k);
    Some(BsdfSample { wi, f: weight / wi.z, pdf: 1.0, weight, delta: true })
}

pub fn eval_rough(d: &Microfacet, eta: Rgb, k: Rgb, r: Rgb, wo: Vec3, wi: Vec3) -> Rgb {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return Rgb::ZERO;
    }
    let m = (wo + wi).normalize_or_zero();
    if m == Vec3::ZERO {
        return Rgb::ZERO;
    }
    let dg = d.d(m) * d.g(wi, wo, m);
    if dg == 0.0 {
        return Rgb::ZERO;
    }
    r * fresnel_conductor(wi.dot(m), eta, k) * (dg / (4.0 * wo.z * wi.z))
}

pub fn pdf_rough(d: &Microfacet, wo: Vec3, wi: Vec3) -> f32 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return 0.0;
    }
    let m = (wo + wi).normalize_or_zero();
    let c = wo.dot(m);
    if m == Vec3::ZERO || c <= 0.0 {
        return 0.0;
    }
    d.pdf(wo, m) / (4.0 * c)
}

pub fn sample_rough(d: &Microfacet, eta: Rgb, k: Rgb, r: Rgb, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let m = d.sample(wo, u);
    if wo.dot(m) <= 0.0 {
        return None;
    }
    let wi = reflect(wo, m);
    if wi.z <= 0.0 {
        return None;
    }
    let pdf = pdf_rough(d, wo, wi);
    let f = eval_rough(d, eta, k, r, wo, wi);
    if pdf <= 0.0 || !pdf.is_finite() {
        return None;
    }
    Some(BsdfSample { wi, f, pdf, weight: f * (wi.z / pdf), delta: false })
}
