//! Mitsuba's `dielectric` (smooth glass: Fresnel-weighted Dirac reflection and refraction),
//! `thindielectric` (a thin pane: internal reflections summed, no refraction offset) and
//! `roughdielectric` (Walter et al. 2007 microfacet reflection and transmission).
//!
//! `eta` is the relative index inside / outside (the side the normal points to is outside).
//! Transmitted radiance is scaled by `1/η²` in radiance mode and not in importance mode: the
//! adjoint BSDF is not symmetric.

use super::conductor::mirror;
use super::fresnel::{fresnel_dielectric, refract};
use super::microfacet::Microfacet;
use super::{BsdfSample, TransportMode};
use crate::math::{Rgb, reflect};
use glam::{Vec2, Vec3};

pub fn sample_smooth(eta: f32, r: Rgb, t: Rgb, wo: Vec3, u1: f32, mode: TransportMode) -> Option<BsdfSample> {
    if wo.z == 0.0 {
        return None;
    }
    let f = fresnel_dielectric(wo.z, eta);
    if u1 < f {
        let wi = mirror(wo);
        return Some(BsdfSample { wi, f: r * f / wi.z.abs(), pdf: f, weight: r, delta: true });
    }
    let (wi, etap) = refract(wo, Vec3::Z, eta)?;
    let scale = if mode == TransportMode::Radiance { 1.0 / (etap * etap) } else { 1.0 };
    let weight = t * scale;
    let pdf = 1.0 - f;
    Some(BsdfSample { wi, f: weight * pdf / wi.z.abs(), pdf, weight, delta: true })
}

pub fn sample_thin(eta: f32, r: Rgb, t: Rgb, wo: Vec3, u1: f32) -> Option<BsdfSample> {
    if wo.z == 0.0 {
        return None;
    }
    let mut f = fresnel_dielectric(wo.z.abs(), eta);
    if f < 1.0 {
        // Light bouncing inside the pane: R + T² R / (1 - R²) = 2R / (1 + R).
        f += (1.0 - f) * (1.0 - f) * f / (1.0 - f * f);
    }
    if u1 < f {
        let wi = mirror(wo);
        Some(BsdfSample { wi, f: r * f / wi.z.abs(), pdf: f, weight: r, delta: true })
    } else {
        let wi = -wo;
        let pdf = 1.0 - f;
        Some(BsdfSample { wi, f: t * pdf / wi.z.abs(), pdf, weight: t, delta: true })
    }
}

/// Upper-hemisphere version of a direction (for sampling normals seen from below).
#[inline]
fn up(w: Vec3) -> Vec3 {
    if w.z < 0.0 { -w } else { w }
}

/// The generalised half vector of a pair and the relative index along the path, or `None`
/// when the pair is impossible (a grazing direction, a back-facing microfacet).
fn half_vector(eta: f32, wo: Vec3, wi: Vec3) -> Option<(Vec3, f32, bool)> {
    if wo.z == 0.0 || wi.z == 0.0 {
        return None;
    }
    let reflect = wo.z * wi.z > 0.0;
    let etap = if reflect {
        1.0
    } else if wo.z > 0.0 {
        eta
    } else {
        1.0 / eta
    };
    let wm = (wi * etap + wo).normalize_or_zero();
    if wm == Vec3::ZERO {
        return None;
    }
    let wm = up(wm);
    if wm.dot(wi) * wi.z < 0.0 || wm.dot(wo) * wo.z < 0.0 {
        return None;
    }
    Some((wm, etap, reflect))
}

pub fn eval_rough(d: &Microfacet, eta: f32, r: Rgb, t: Rgb, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
    let Some((wm, etap, reflect)) = half_vector(eta, wo, wi) else { return Rgb::ZERO };
    let dg = d.d(wm) * d.g(up(wi), up(wo), wm);
    if dg == 0.0 {
        return Rgb::ZERO;
    }
    let f = fresnel_dielectric(wo.dot(wm), eta);
    if reflect {
        r * (dg * f / (4.0 * wo.z * wi.z).abs())
    } else {
        let denom = (wi.dot(wm) + wo.dot(wm) / etap).powi(2) * wi.z * wo.z;
        let mut ft = dg * (1.0 - f) * (wi.dot(wm) * wo.dot(wm) / denom).abs();
        if mode == TransportMode::Radiance {
            ft /= etap * etap;
        }
        t * ft
    }
}

pub fn pdf_rough(d: &Microfacet, eta: f32, wo: Vec3, wi: Vec3) -> f32 {
    let Some((wm, etap, reflect)) = half_vector(eta, wo, wi) else { return 0.0 };
    let pdf_m = d.pdf(up(wo), wm);
    let f = fresnel_dielectric(wo.dot(wm), eta);
    if reflect {
        pdf_m / (4.0 * wo.dot(wm).abs()) * f
    } else {
        let denom = (wi.dot(wm) + wo.dot(wm) / etap).powi(2);
        pdf_m * (wi.dot(wm).abs() / denom) * (1.0 - f)
    }
}

#[allow(clippy::too_many_arguments)]
pub fn sample_rough(
    d: &Microfacet,
    eta: f32,
    r: Rgb,
    t: Rgb,
    wo: Vec3,
    u1: f32,
    u2: Vec2,
    mode: TransportMode,
) -> Option<BsdfSample> {
    if wo.z == 0.0 {
        return None;
    }
    let wm = d.sample(up(wo), u2);
    if wo.dot(wm) * wo.z <= 0.0 {
        // A microfacet facing away from wo (possible without visible-normal sampling).
        return None;
    }
    let f = fresnel_dielectric(wo.dot(wm), eta);
    let wi = if u1 < f {
        let wi = reflect(wo, wm);
        if wo.z * wi.z <= 0.0 {
            return None;
        }
        wi
    } else {
        let (wi, _) = refract(wo, wm, eta)?;
        if wo.z * wi.z >= 0.0 || wi.z == 0.0 {
            return None;
        }
        wi
    };
    let pdf = pdf_rough(d, eta, wo, wi);
    if pdf <= 0.0 || !pdf.is_finite() {
        return None;
    }
    let fv = eval_rough(d, eta, r, t, wo, wi, mode);
    Some(BsdfSample { wi, f: fv, pdf, weight: fv * (wi.z.abs() / pdf), delta: false })
}
