//! Phase functions: Mitsuba's `isotropic` and `hg` (Henyey–Greenstein).
//!
//! Both directions point away from the scattering point (Mitsuba's convention): `wo`
//! towards where the light goes (the previous vertex of a camera path), `wi` towards where
//! it comes from. Light that keeps its direction has `wi = -wo`; a positive `g` favours it.
//! Each phase function is normalised over the sphere and sampled exactly, so its value is
//! also the density (per unit solid angle) of the direction it samples.

use crate::math::Frame;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

const INV_4PI: f32 = 0.25 / PI;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    Isotropic,
    /// Henyey and Greenstein's lobe with mean cosine `g` in (−1, 1).
    HenyeyGreenstein {
        g: f32,
    },
}

impl Phase {
    /// The phase function's value (and density) for the pair `wo`, `wi`.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> f32 {
        match *self {
            Phase::Isotropic => INV_4PI,
            // The cosine between the propagation directions `-wi` → `-wo` is `wo · wi`.
            Phase::HenyeyGreenstein { g } => henyey_greenstein(wo.dot(wi), g),
        }
    }

    /// Samples `wi` for `wo` from the uniform point `u`; returns it with its density.
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> (Vec3, f32) {
        match *self {
            Phase::Isotropic => (crate::sampling::square_to_uniform_sphere(u), INV_4PI),
            Phase::HenyeyGreenstein { g } => {
                // The cosine between the light's direction before (`-wi`) and after (`-wo`)
                // the event: inverting the CDF of HG's distribution of it.
                let cos = if g.abs() < 1e-3 {
                    1.0 - 2.0 * u.x
                } else {
                    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
                    (1.0 + g * g - s * s) / (2.0 * g)
                };
                let cos = cos.clamp(-1.0, 1.0);
                let sin = (1.0 - cos * cos).max(0.0).sqrt();
                let phi = 2.0 * PI * u.y;
                // `wi` makes the angle with `wo` whose cosine is `-cos`.
                let local = Vec3::new(sin * phi.cos(), sin * phi.sin(), -cos);
                let wi = Frame::from_normal(wo).to_world(local);
                (wi, henyey_greenstein(-cos, g))
            }
        }
    }
}

/// HG's density for `wo · wi = dot` (the cosine of the propagation directions).
#[inline]
fn henyey_greenstein(dot: f32, g: f32) -> f32 {
    let denom = 1.0 + g * g + 2.0 * g * dot;
    INV_4PI * (1.0 - g * g) / (denom * denom.max(0.0).sqrt()).max(1e-20)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::chi2::{Chi2Test, SphereDomain};

    fn wo() -> Vec3 {
        Vec3::new(0.3, -0.5, 0.8).normalize()
    }

    #[test]
    fn phase_functions_sample_their_density() {
        for phase in [
            Phase::Isotropic,
            Phase::HenyeyGreenstein { g: 0.0 },
            Phase::HenyeyGreenstein { g: 0.7 },
            Phase::HenyeyGreenstein { g: -0.4 },
            Phase::HenyeyGreenstein { g: 0.95 },
        ] {
            let mut t = Chi2Test::new(SphereDomain::default());
            t.tests = 5;
            let r = t.run(|u| Some(phase.sample(wo(), u).0), |wi| phase.eval(wo(), wi));
            assert!(r.passed(), "{phase:?}: {r}");
        }
    }

    #[test]
    fn sampled_density_is_the_value() {
        let phase = Phase::HenyeyGreenstein { g: 0.6 };
        let mut rng = crate::sampling::Sampler::new(&[3]);
        for _ in 0..1000 {
            let (wi, pdf) = phase.sample(wo(), rng.next_2d());
            assert!((wi.length() - 1.0).abs() < 1e-4);
            assert!((pdf - phase.eval(wo(), wi)).abs() <= 1e-3 * pdf, "{pdf} {}", phase.eval(wo(), wi));
        }
    }

    #[test]
    fn forward_scattering_keeps_the_direction() {
        // With g > 0 light mostly goes on: wi close to -wo.
        let phase = Phase::HenyeyGreenstein { g: 0.8 };
        assert!(phase.eval(wo(), -wo()) > 10.0 * phase.eval(wo(), wo()));
        let mut rng = crate::sampling::Sampler::new(&[4]);
        let mean: f32 = (0..20_000).map(|_| -phase.sample(wo(), rng.next_2d()).0.dot(wo())).sum::<f32>() / 20_000.0;
        assert!((mean - 0.8).abs() < 0.01, "mean cosine {mean}");
    }

    #[test]
    fn a_wrong_lobe_is_rejected() {
        // Negative control: sampling g = 0.7 against the density of g = 0.6.
        let (a, b) = (Phase::HenyeyGreenstein { g: 0.7 }, Phase::HenyeyGreenstein { g: 0.6 });
        let r = Chi2Test::new(SphereDomain::default()).run(|u| Some(a.sample(wo(), u).0), |wi| b.eval(wo(), wi));
        assert!(!r.passed());
        // And a lobe mirrored (the convention of wo's sign).
        let r = Chi2Test::new(SphereDomain::default()).run(|u| Some(a.sample(wo(), u).0), |wi| a.eval(-wo(), wi));
        assert!(!r.passed());
    }
}
