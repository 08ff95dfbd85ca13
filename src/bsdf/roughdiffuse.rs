//! Mitsuba 0.6's `roughdiffuse`: Oren and Nayar's rough diffuse reflection ("Generalization
//! of Lambert's Reflectance Model", 1994) on the front side, as Mitsuba 0.6 evaluates it: the
//! full model with its interreflection term, or with `useFastApprox` the qualitative model.
//! The roughness `alpha` is a Beckmann-style RMS slope, converted to Oren–Nayar's standard
//! deviation of facet angles by `σ = α / √2`. Directions are sampled from the cosine, as
//! Mitsuba 0.6 samples them.

use super::BsdfSample;
use super::diffuse;
use crate::math::Rgb;
use crate::sampling::{square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf};
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, SQRT_2};

/// `sin θ`, `cos φ` and `sin φ` of a local direction.
fn angles(w: Vec3) -> (f32, f32, f32) {
    let sin_theta = (1.0 - w.z * w.z).max(0.0).sqrt();
    if sin_theta <= 1e-4 {
        return (sin_theta, 1.0, 0.0);
    }
    (sin_theta, (w.x / sin_theta).clamp(-1.0, 1.0), (w.y / sin_theta).clamp(-1.0, 1.0))
}

/// The BSDF (without the cosine) for reflectance `rho` and roughness `alpha`.
pub fn eval(rho: Rgb, alpha: f32, fast: bool, wo: Vec3, wi: Vec3) -> Rgb {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return Rgb::ZERO;
    }
    let sigma = alpha / SQRT_2;
    let sigma2 = sigma * sigma;
    let ((sin_o, cos_po, sin_po), (sin_i, cos_pi, sin_pi)) = (angles(wo), angles(wi));
    let cos_phi_diff = if sin_o > 1e-4 && sin_i > 1e-4 { cos_po * cos_pi + sin_po * sin_pi } else { 0.0 };
    // α is the larger polar angle, β the smaller.
    let (sin_alpha, sin_beta, tan_beta) =
        if wo.z > wi.z { (sin_i, sin_o, sin_o / wo.z) } else { (sin_o, sin_i, sin_i / wi.z) };
    let a = 1.0 - 0.5 * sigma2 / (sigma2 + 0.33);
    if fast {
        let b = 0.45 * sigma2 / (sigma2 + 0.09);
        return rho * (FRAC_1_PI * (a + b * cos_phi_diff.max(0.0) * sin_alpha * tan_beta));
    }
    let (theta_o, theta_i) = (wo.z.clamp(-1.0, 1.0).acos(), wi.z.clamp(-1.0, 1.0).acos());
    let (alpha_angle, beta_angle) = (theta_o.max(theta_i), theta_o.min(theta_i));
    let tmp = sigma2 / (sigma2 + 0.09);
    let tmp2 = 4.0 * FRAC_1_PI * FRAC_1_PI * alpha_angle * beta_angle;
    let tmp3 = 2.0 * beta_angle * FRAC_1_PI;
    let c2 = 0.45 * tmp * if cos_phi_diff > 0.0 { sin_alpha } else { sin_alpha - tmp3 * tmp3 * tmp3 };
    let c3 = 0.125 * tmp * tmp2 * tmp2;
    let c4 = 0.17 * sigma2 / (sigma2 + 0.13);
    // tan((α + β) / 2) from the half-angle formula.
    let tan_half = (sin_alpha + sin_beta)
        / ((1.0 - sin_alpha * sin_alpha).max(0.0).sqrt() + (1.0 - sin_beta * sin_beta).max(0.0).sqrt());
    let single = rho * (a + cos_phi_diff * c2 * tan_beta + (1.0 - cos_phi_diff.abs()) * c3 * tan_half);
    let double = rho * rho * (c4 * (1.0 - cos_phi_diff * tmp3 * tmp3));
    (single + double) * FRAC_1_PI
}

/// The cosine-weighted density of `wi` (as [`diffuse::pdf`]).
pub fn pdf(wo: Vec3, wi: Vec3) -> f32 {
    diffuse::pdf(wo, wi)
}

/// A cosine-weighted direction, its value and weight `f cos / pdf`.
pub fn sample(rho: Rgb, alpha: f32, fast: bool, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let wi = square_to_cosine_hemisphere(u);
    let pdf = square_to_cosine_hemisphere_pdf(wi);
    if pdf <= 0.0 || wi.z <= 0.0 {
        return None;
    }
    let f = eval(rho, alpha, fast, wo, wi);
    Some(BsdfSample { wi, f, pdf, weight: f * (wi.z / pdf), delta: false })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    fn hemisphere(u: Vec2) -> Vec3 {
        square_to_cosine_hemisphere(u)
    }

    /// A smooth surface (`alpha` 0) is Lambertian, in both models; a rough one is reciprocal,
    /// flatter than Lambert's law towards grazing views (backscatter brightens it where light
    /// and view coincide), and its two models agree at normal incidence.
    #[test]
    fn smooth_is_lambertian_and_rough_is_reciprocal() {
        let rho = Rgb::new(0.2, 0.5, 0.8);
        let mut rng = Sampler::new(&[3]);
        for _ in 0..200 {
            let (wo, wi) = (hemisphere(rng.next_2d()), hemisphere(rng.next_2d()));
            for fast in [false, true] {
                let f = eval(rho, 0.0, fast, wo, wi);
                assert!((f - rho * FRAC_1_PI).abs().max_element() < 1e-6, "{f}");
                let (a, b) = (eval(rho, 0.6, fast, wo, wi), eval(rho, 0.6, fast, wi, wo));
                assert!((a - b).abs().max_element() <= 1e-5 * a.max_element(), "{a} against {b}");
            }
        }
        let grazing = Vec3::new(0.95, 0.0, 0.31225).normalize();
        let back = eval(rho, 0.6, false, grazing, grazing).y;
        assert!(back > rho.y * FRAC_1_PI, "no backscatter: {back}");
        let normal = Vec3::Z;
        let (full, fast) = (eval(rho, 0.3, false, normal, normal), eval(rho, 0.3, true, normal, normal));
        // At normal incidence only A (and the full model's interreflection term) remain.
        assert!((full - fast).abs().max_element() < 0.1 * fast.max_element(), "{full} against {fast}");
        // Below the surface, nothing.
        assert_eq!(eval(rho, 0.3, false, normal, -normal), Rgb::ZERO);
    }

    /// A sample's weight is its value times the cosine over its density.
    #[test]
    fn sample_weight_is_value_cosine_over_density() {
        let rho = Rgb::splat(0.6);
        let mut rng = Sampler::new(&[4]);
        let wo = Vec3::new(0.3, -0.2, 0.9).normalize();
        for _ in 0..100 {
            let s = sample(rho, 0.5, false, wo, rng.next_2d()).unwrap();
            assert!((s.weight - s.f * s.wi.z / s.pdf).abs().max_element() < 1e-5);
            assert!((s.pdf - pdf(wo, s.wi)).abs() < 1e-6);
        }
        assert!(sample(rho, 0.5, false, -wo, Vec2::splat(0.5)).is_none());
    }
}
