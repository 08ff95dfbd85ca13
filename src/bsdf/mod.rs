//! BSDFs: a closed set of scattering models dispatched through an enum.
//!
//! Directions are in the local shading frame (`z` = shading normal) and both point away
//! from the surface: `wo` towards where the path came from (the camera side when tracing
//! radiance), `wi` the new direction. Values returned by `eval` and `sample` exclude the
//! cosine foreshortening term; `sample` returns the ratio `f |cos θi| / pdf` as well.
//! Random numbers are arguments, never owned state. Both the forward pdf (of `wi` given
//! `wo`) and the reverse pdf (of `wo` given `wi`) are available, as bidirectional methods
//! need.

pub mod diffuse;

use crate::math::Rgb;
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// Which quantity a path carries: radiance (from the camera) or importance (from lights).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransportMode {
    Radiance,
    Importance,
}

/// The result of sampling a BSDF.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Sampled direction (local frame).
    pub wi: Vec3,
    /// BSDF value for (wo, wi), without cosine.
    pub f: Rgb,
    /// Solid-angle density of `wi` given `wo`.
    pub pdf: f32,
    /// `f |cos θi| / pdf`.
    pub weight: Rgb,
    /// Sampled from a Dirac delta lobe (pdf and f are then relative to the delta).
    pub delta: bool,
}

/// The scattering models.
#[derive(Clone, Debug, PartialEq)]
pub enum BsdfModel {
    /// Lambertian reflection.
    Diffuse { reflectance: Texture },
}

/// A BSDF as attached to a shape: a model, one-sided (the front side of the shading
/// normal only, as in Mitsuba) unless wrapped by `twosided`.
#[derive(Clone, Debug, PartialEq)]
pub struct Bsdf {
    pub model: BsdfModel,
    pub two_sided: bool,
}

/// Local-frame helpers.
#[inline]
pub fn cos_theta(w: Vec3) -> f32 {
    w.z
}

impl Bsdf {
    pub fn diffuse(reflectance: Texture) -> Bsdf {
        Bsdf { model: BsdfModel::Diffuse { reflectance }, two_sided: false }
    }

    /// `true` when every lobe is a Dirac delta (no light sampling possible).
    pub fn is_delta(&self) -> bool {
        match &self.model {
            BsdfModel::Diffuse { .. } => false,
        }
    }

    /// Mirrors both directions to the front side for two-sided BSDFs; `None` when the
    /// one-sided model is seen from its back.
    #[inline]
    fn orient(&self, wo: Vec3, wi: Vec3) -> (Vec3, Vec3) {
        if self.two_sided && wo.z < 0.0 {
            (Vec3::new(wo.x, wo.y, -wo.z), Vec3::new(wi.x, wi.y, -wi.z))
        } else {
            (wo, wi)
        }
    }

    /// BSDF value for light arriving along `wi` and leaving along `wo`.
    pub fn eval(&self, wo: Vec3, wi: Vec3, uv: Vec2, _mode: TransportMode) -> Rgb {
        let (wo, wi) = self.orient(wo, wi);
        match &self.model {
            BsdfModel::Diffuse { reflectance } => diffuse::eval(reflectance.eval(uv), wo, wi),
        }
    }

    /// Solid-angle density of sampling `wi` given `wo`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3, _uv: Vec2, _mode: TransportMode) -> f32 {
        let (wo, wi) = self.orient(wo, wi);
        match &self.model {
            BsdfModel::Diffuse { .. } => diffuse::pdf(wo, wi),
        }
    }

    /// Samples `wi` given `wo` with the random numbers `u1` (lobe choice) and `u2`.
    pub fn sample(&self, wo: Vec3, uv: Vec2, u1: f32, u2: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        let flip = self.two_sided && wo.z < 0.0;
        let wo_f = if flip { Vec3::new(wo.x, wo.y, -wo.z) } else { wo };
        let _ = u1;
        let mut s = match &self.model {
            BsdfModel::Diffuse { reflectance } => diffuse::sample(reflectance.eval(uv), wo_f, u2)?,
        };
        if flip {
            s.wi.z = -s.wi.z;
        }
        Some(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::chi2::{Chi2Test, SphereDomain};

    fn check_bsdf(b: &Bsdf, wo: Vec3) {
        let t = Chi2Test::new(SphereDomain::default());
        let mut u1 = crate::sampling::Sampler::new(&[99]);
        t.run(
            |u| b.sample(wo, Vec2::ZERO, u1.next_1d(), u, TransportMode::Radiance).map(|s| s.wi),
            |wi| b.pdf(wo, wi, Vec2::ZERO, TransportMode::Radiance),
        )
        .assert_pass();
    }

    #[test]
    fn diffuse_chi2_front_and_two_sided_back() {
        let d = Bsdf::diffuse(Texture::Constant(Vec3::splat(0.5)));
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.999, 0.0, 0.0447).normalize()] {
            check_bsdf(&d, wo);
        }
        let two = Bsdf { two_sided: true, ..d.clone() };
        check_bsdf(&two, Vec3::new(0.3, 0.4, -0.866).normalize());
    }

    #[test]
    fn diffuse_sample_weight_matches_eval_over_pdf() {
        let d = Bsdf::diffuse(Texture::Constant(Vec3::new(0.2, 0.5, 0.8)));
        let wo = Vec3::new(0.1, 0.2, 0.97).normalize();
        let mut s = crate::sampling::Sampler::new(&[5]);
        for _ in 0..100 {
            let bs = d.sample(wo, Vec2::ZERO, s.next_1d(), s.next_2d(), TransportMode::Radiance).unwrap();
            let f = d.eval(wo, bs.wi, Vec2::ZERO, TransportMode::Radiance);
            let pdf = d.pdf(wo, bs.wi, Vec2::ZERO, TransportMode::Radiance);
            assert!((bs.pdf - pdf).abs() < 1e-4 * pdf.max(1.0));
            assert!((bs.weight - f * bs.wi.z / pdf).abs().max_element() < 1e-4);
        }
    }

    #[test]
    fn one_sided_diffuse_is_black_from_behind() {
        let d = Bsdf::diffuse(Texture::Constant(Vec3::ONE));
        let below = Vec3::new(0.0, 0.6, -0.8);
        assert_eq!(d.eval(below, Vec3::Z, Vec2::ZERO, TransportMode::Radiance), Vec3::ZERO);
        assert!(d.sample(below, Vec2::ZERO, 0.5, Vec2::splat(0.3), TransportMode::Radiance).is_none());
        let two = Bsdf { two_sided: true, ..d };
        assert!(two.eval(below, -Vec3::Z, Vec2::ZERO, TransportMode::Radiance).x > 0.0);
    }
}
