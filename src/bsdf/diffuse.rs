//! Mitsuba's `diffuse`: Lambertian reflection, `f = ρ / π` on the front side.

use super::BsdfSample;
use crate::math::Rgb;
use crate::sampling::{square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[inline]
pub fn eval(reflectance: Rgb, wo: Vec3, wi: Vec3) -> Rgb {
    if wo.z <= 0.0 || wi.z <= 0.0 { Rgb::ZERO } else { reflectance * FRAC_1_PI }
}

#[inline]
pub fn pdf(wo: Vec3, wi: Vec3) -> f32 {
    if wo.z <= 0.0 { 0.0 } else { square_to_cosine_hemisphere_pdf(wi) }
}

/// `(pdf(wo, wi), pdf(wi, wo))`: both are zero unless both directions lie on the front side.
#[inline]
pub fn pdf_pair(wo: Vec3, wi: Vec3) -> (f32, f32) {
    if wo.z <= 0.0 || wi.z <= 0.0 { (0.0, 0.0) } else { (wi.z * FRAC_1_PI, wo.z * FRAC_1_PI) }
}

pub fn sample(reflectance: Rgb, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let wi = square_to_cosine_hemisphere(u);
    let pdf = square_to_cosine_hemisphere_pdf(wi);
    if pdf <= 0.0 {
        return None;
    }
    // f cos / pdf = (ρ/π) cos / (cos/π) = ρ.
    Some(BsdfSample { wi, f: reflectance * FRAC_1_PI, pdf, weight: reflectance, delta: false })
}
