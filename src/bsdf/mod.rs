//! BSDFs: a closed set of scattering models dispatched through an enum.
//!
//! Directions are in the local shading frame (`z` = shading normal) and both point away
//! from the surface: `wo` towards where the path came from (the camera side when tracing
//! radiance), `wi` the new direction. Values returned by `eval` and `sample` exclude the
//! cosine foreshortening term; `sample` returns the ratio `f |cos θi| / pdf` as well.
//! Random numbers are arguments, never owned state. Both the forward pdf (of `wi` given
//! `wo`) and the reverse pdf (of `wo` given `wi`) are available, as bidirectional methods
//! need.

pub mod coating;
pub mod conductor;
pub mod dielectric;
pub mod diffuse;
pub mod fresnel;
pub mod microfacet;
pub mod perturb;
pub mod plastic;
pub mod roughdiffuse;
pub mod ward;

use crate::math::{Frame, Rgb};
use crate::texture::{Opacity, Texture};
use glam::{Vec2, Vec3};
use microfacet::Roughness;
pub use perturb::At;
use perturb::{Perturbation, same_side, shadow_terminator};
use plastic::{PlasticParams, RoughPlasticParams};
use ward::{WardAlpha, WardParams};

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

/// The scattering models (Mitsuba 3's plugins of the same names, and Mitsuba 0.6's `ward`).
#[derive(Clone, Debug, PartialEq)]
pub enum BsdfModel {
    /// Lambertian reflection.
    Diffuse { reflectance: Texture },
    /// Smooth metal.
    Conductor { eta: Rgb, k: Rgb, specular_reflectance: Texture },
    /// Microfacet metal.
    RoughConductor { distribution: Roughness, eta: Rgb, k: Rgb, specular_reflectance: Texture },
    /// Smooth glass; `eta` = interior / exterior index.
    Dielectric { eta: f32, specular_reflectance: Texture, specular_transmittance: Texture },
    /// A thin pane of glass.
    ThinDielectric { eta: f32, specular_reflectance: Texture, specular_transmittance: Texture },
    /// Microfacet glass.
    RoughDielectric {
        distribution: Roughness,
        eta: f32,
        specular_reflectance: Texture,
        specular_transmittance: Texture,
    },
    /// Diffuse base under a smooth coating.
    Plastic { params: PlasticParams, diffuse_reflectance: Texture, specular_reflectance: Texture },
    /// Diffuse base under a rough coating.
    RoughPlastic { params: RoughPlasticParams, diffuse_reflectance: Texture, specular_reflectance: Texture },
    /// Mitsuba 0.6's Oren–Nayar reflection; `alpha` is the RMS slope (its channels' mean),
    /// `fast` its qualitative model.
    RoughDiffuse { reflectance: Texture, alpha: Texture, fast: bool },
    /// Any BSDF under a smooth or rough dielectric layer (Mitsuba 0.6's `coating` and
    /// `roughcoating`).
    Coating(Box<coating::Coating>),
    /// Mitsuba 0.6's anisotropic Ward model: a glossy lobe over a diffuse base.
    Ward { params: WardParams, alpha: WardAlpha, diffuse_reflectance: Texture, specular_reflectance: Texture },
    /// No surface at all (Mitsuba's `null`): light goes straight through. What a shape that
    /// only bounds a participating medium has.
    Null,
}

/// A BSDF as attached to a shape: a model, one-sided (the front side of the shading
/// normal only, as in Mitsuba) unless wrapped by `twosided`, with the shading normal
/// perturbed by a `bumpmap` or `normalmap` around it.
#[derive(Clone, Debug, PartialEq)]
pub struct Bsdf {
    pub model: BsdfModel,
    pub two_sided: bool,
    /// The perturbation of the shading frame (applied where a ray hits the surface; see
    /// [`perturb`]), whose side test and shadowing term the BSDF's values include.
    pub perturbation: Option<Box<Perturbation>>,
    /// The opacity of a `mask` around the model: the accelerator skips the hits it does not
    /// keep (`accel::keeps_hit`), and a kept hit scatters by `model` alone.
    pub opacity: Option<std::sync::Arc<Opacity>>,
}

/// One lobe of a BSDF as Manifold Exploration sees it (contract `memlt.md`, "What the rest
/// of a renderer must supply"): whether it reflects or transmits, and how rough it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobe {
    pub transmission: bool,
    /// 0 for a Dirac lobe, the microfacet α for a glossy one (the mean of `α_u` and `α_v`
    /// where they differ, as Mitsuba 0.6's `getRoughness`), [`DIFFUSE_ROUGHNESS`] for a
    /// diffuse one.
    pub roughness: f32,
    /// The microfacet distribution of a glossy lobe.
    pub microfacet: Option<microfacet::MicrofacetType>,
}

/// The roughness of a diffuse lobe.
pub const DIFFUSE_ROUGHNESS: f32 = f32::INFINITY;

impl Lobe {
    /// `true` for a Dirac lobe (a mirror or a smooth interface).
    pub fn is_delta(&self) -> bool {
        self.roughness == 0.0
    }
}

/// Local-frame helpers.
#[inline]
pub fn cos_theta(w: Vec3) -> f32 {
    w.z
}

impl Bsdf {
    pub fn new(model: BsdfModel) -> Bsdf {
        Bsdf { model, two_sided: false, perturbation: None, opacity: None }
    }

    pub fn diffuse(reflectance: Texture) -> Bsdf {
        Bsdf::new(BsdfModel::Diffuse { reflectance })
    }

    /// `true` when every lobe is a Dirac delta (no light sampling possible).
    pub fn is_delta(&self) -> bool {
        match &self.model {
            BsdfModel::Coating(c) => c.is_delta(),
            m => matches!(
                m,
                BsdfModel::Conductor { .. }
                    | BsdfModel::Dielectric { .. }
                    | BsdfModel::ThinDielectric { .. }
                    | BsdfModel::Null
            ),
        }
    }

    /// Whether the surface is only a boundary between media (Mitsuba's `null`).
    #[inline]
    pub fn is_null(&self) -> bool {
        matches!(self.model, BsdfModel::Null)
    }

    /// The lobes of the model at texture coordinates `uv` (where a textured roughness is
    /// looked up): a smooth coating's Dirac reflection over a diffuse base counts as two; a
    /// coating's own lobe comes before its nested BSDF's.
    pub fn lobes(&self, uv: Vec2) -> impl Iterator<Item = Lobe> {
        let lobe = |transmission, roughness, microfacet| Some(Lobe { transmission, roughness, microfacet });
        let reflection = |roughness| lobe(false, roughness, None);
        let both = |roughness| [reflection(roughness), lobe(true, roughness, None)];
        let glossy =
            |m: microfacet::Microfacet, transmission| lobe(transmission, 0.5 * (m.alpha_u + m.alpha_v), Some(m.kind));
        let lobes = match &self.model {
            BsdfModel::Diffuse { .. } | BsdfModel::RoughDiffuse { .. } => [reflection(DIFFUSE_ROUGHNESS), None],
            BsdfModel::Conductor { .. } => [reflection(0.0), None],
            BsdfModel::RoughConductor { distribution, .. } => [glossy(distribution.at(uv), false), None],
            BsdfModel::Dielectric { .. } | BsdfModel::ThinDielectric { .. } => both(0.0),
            BsdfModel::RoughDielectric { distribution, .. } => {
                [glossy(distribution.at(uv), false), glossy(distribution.at(uv), true)]
            }
            BsdfModel::Plastic { .. } => [reflection(0.0), reflection(DIFFUSE_ROUGHNESS)],
            BsdfModel::RoughPlastic { params, .. } => {
                [glossy(params.distribution, false), reflection(DIFFUSE_ROUGHNESS)]
            }
            BsdfModel::Coating(c) => [Some(c.lobe()), None],
            BsdfModel::Null => [lobe(true, 0.0, None), None],
            // Ward's half vectors follow the Beckmann distribution of the same roughness.
            BsdfModel::Ward { alpha, .. } => {
                let (alpha_u, alpha_v) = alpha.at(uv);
                let m = microfacet::Microfacet {
                    kind: microfacet::MicrofacetType::Beckmann,
                    alpha_u,
                    alpha_v,
                    sample_visible: false,
                };
                [glossy(m, false), reflection(DIFFUSE_ROUGHNESS)]
            }
        };
        let nested: Vec<Lobe> = match &self.model {
            BsdfModel::Coating(c) => c.nested.lobes(uv).collect(),
            _ => Vec::new(),
        };
        lobes.into_iter().flatten().chain(nested)
    }

    /// The relative index of refraction (interior over exterior) of light crossing the
    /// surface: 1 where none crosses, and for a thin pane, which lets light through unbent.
    pub fn eta(&self) -> f32 {
        match &self.model {
            BsdfModel::Dielectric { eta, .. } | BsdfModel::RoughDielectric { eta, .. } => *eta,
            // The layer bends light back as it leaves: what crosses is bent by the nested BSDF.
            BsdfModel::Coating(c) => c.nested.eta(),
            _ => 1.0,
        }
    }

    /// `true` when the BSDF can transmit light to the other side.
    pub fn transmits(&self) -> bool {
        match &self.model {
            BsdfModel::Coating(c) => c.nested.transmits(),
            m => matches!(
                m,
                BsdfModel::Dielectric { .. }
                    | BsdfModel::ThinDielectric { .. }
                    | BsdfModel::RoughDielectric { .. }
                    | BsdfModel::Null
            ),
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

    /// The world directions `wo` and `wi` in `frame`, as far as this BSDF looks at them: a
    /// diffuse BSDF depends on their cosines with the normal alone, so only those (the `z`
    /// components) are computed and `x`, `y` are left zero.
    #[inline]
    pub fn to_local(&self, frame: &Frame, wo: Vec3, wi: Vec3) -> (Vec3, Vec3) {
        match self.model {
            BsdfModel::Diffuse { .. } if self.perturbation.is_none() => {
                (Vec3::new(0.0, 0.0, wo.dot(frame.n)), Vec3::new(0.0, 0.0, wi.dot(frame.n)))
            }
            _ => (frame.to_local(wo), frame.to_local(wi)),
        }
    }

    /// `true` when a perturbed BSDF is zero for the pair: a direction on opposite sides of
    /// the unperturbed and the perturbed normal (as Mitsuba's `bumpmap` and `normalmap`).
    #[inline]
    fn cut(&self, wo: Vec3, wi: Vec3, at: &At) -> bool {
        self.perturbation.is_some() && !(same_side(at.base_n, wo) && same_side(at.base_n, wi))
    }

    /// The shadowing factor of a perturbed BSDF for the light's direction: `wi` when
    /// tracing radiance, `wo` when tracing importance (the adjoint keeps it on the light's
    /// side); 1 without a perturbation or with `use_shadowing_function` off.
    #[inline]
    fn shadowing(&self, wo: Vec3, wi: Vec3, at: &At, mode: TransportMode) -> f32 {
        match &self.perturbation {
            Some(p) if p.shadowing => {
                shadow_terminator(at.base_n, if mode == TransportMode::Radiance { wi } else { wo })
            }
            _ => 1.0,
        }
    }

    /// BSDF value for light arriving along `wi` and leaving along `wo`.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3, at: impl Into<At>, mode: TransportMode) -> Rgb {
        let at = at.into();
        if self.perturbation.is_none() {
            return self.eval_model(wo, wi, at.uv, mode);
        }
        if self.cut(wo, wi, &at) {
            return Rgb::ZERO;
        }
        self.eval_model(wo, wi, at.uv, mode) * self.shadowing(wo, wi, &at, mode)
    }

    /// Solid-angle density of sampling `wi` given `wo`.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3, at: impl Into<At>, mode: TransportMode) -> f32 {
        let at = at.into();
        if self.cut(wo, wi, &at) { 0.0 } else { self.pdf_model(wo, wi, at.uv, mode) }
    }

    /// Forward and reverse densities of a pair: of `wi` given `wo`, and of `wo` given `wi`
    /// (what a path generated from the other end would have used).
    #[inline]
    pub fn pdf_pair(&self, wo: Vec3, wi: Vec3, at: impl Into<At>, mode: TransportMode) -> (f32, f32) {
        let at = at.into();
        if self.cut(wo, wi, &at) { (0.0, 0.0) } else { self.pdf_pair_model(wo, wi, at.uv, mode) }
    }

    /// [`Bsdf::eval`] and [`Bsdf::pdf_pair`] together, with one dispatch: what a
    /// connection needs from each of its ends.
    #[inline]
    pub fn eval_pdfs(&self, wo: Vec3, wi: Vec3, at: impl Into<At>, mode: TransportMode) -> (Rgb, f32, f32) {
        let at = at.into();
        if self.perturbation.is_none() {
            return self.eval_pdfs_model(wo, wi, at.uv, mode);
        }
        if self.cut(wo, wi, &at) {
            return (Rgb::ZERO, 0.0, 0.0);
        }
        let (f, fwd, rev) = self.eval_pdfs_model(wo, wi, at.uv, mode);
        (f * self.shadowing(wo, wi, &at, mode), fwd, rev)
    }

    /// Samples `wi` given `wo` with the random numbers `u1` (lobe choice) and `u2`.
    #[inline]
    pub fn sample(&self, wo: Vec3, at: impl Into<At>, u1: f32, u2: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let at = at.into();
        if self.perturbation.is_none() {
            return self.sample_model(wo, at.uv, u1, u2, mode);
        }
        if !same_side(at.base_n, wo) {
            return None;
        }
        let mut s = self.sample_model(wo, at.uv, u1, u2, mode)?;
        if !same_side(at.base_n, s.wi) {
            return None;
        }
        let g = self.shadowing(wo, s.wi, &at, mode);
        s.f *= g;
        s.weight *= g;
        Some(s)
    }

    /// [`Bsdf::eval`] of the model alone (no perturbation's terms).
    fn eval_model(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> Rgb {
        let (wo, wi) = self.orient(wo, wi);
        match &self.model {
            BsdfModel::Diffuse { reflectance } => diffuse::eval(reflectance.eval(uv), wo, wi),
            BsdfModel::RoughDiffuse { reflectance, alpha, fast } => {
                roughdiffuse::eval(reflectance.eval(uv), alpha.eval(uv).element_sum() / 3.0, *fast, wo, wi)
            }
            BsdfModel::Conductor { .. }
            | BsdfModel::Dielectric { .. }
            | BsdfModel::ThinDielectric { .. }
            | BsdfModel::Null => Rgb::ZERO,
            BsdfModel::RoughConductor { distribution, eta, k, specular_reflectance } => {
                conductor::eval_rough(&distribution.at(uv), *eta, *k, specular_reflectance.eval(uv), wo, wi)
            }
            BsdfModel::RoughDielectric { distribution, eta, specular_reflectance, specular_transmittance } => {
                let (r, t) = (specular_reflectance.eval(uv), specular_transmittance.eval(uv));
                dielectric::eval_rough(&distribution.at(uv), *eta, r, t, wo, wi, mode)
            }
            BsdfModel::Plastic { params, diffuse_reflectance, .. } => {
                plastic::eval(params, diffuse_reflectance.eval(uv), wo, wi)
            }
            BsdfModel::RoughPlastic { params, diffuse_reflectance, specular_reflectance } => {
                plastic::eval_rough(params, diffuse_reflectance.eval(uv), specular_reflectance.eval(uv), wo, wi)
            }
            BsdfModel::Coating(c) => c.eval(wo, wi, uv, mode),
            BsdfModel::Ward { params, alpha, diffuse_reflectance, specular_reflectance } => {
                let (d, sp) = (diffuse_reflectance.eval(uv), specular_reflectance.eval(uv));
                ward::eval(params, alpha.at(uv), d, sp, wo, wi)
            }
        }
    }

    /// [`Bsdf::pdf`] of the model alone.
    fn pdf_model(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> f32 {
        let (wo, wi) = self.orient(wo, wi);
        match &self.model {
            BsdfModel::Diffuse { .. } => diffuse::pdf(wo, wi),
            BsdfModel::RoughDiffuse { .. } => roughdiffuse::pdf(wo, wi),
            BsdfModel::Conductor { .. }
            | BsdfModel::Dielectric { .. }
            | BsdfModel::ThinDielectric { .. }
            | BsdfModel::Null => 0.0,
            BsdfModel::RoughConductor { distribution, .. } => conductor::pdf_rough(&distribution.at(uv), wo, wi),
            BsdfModel::RoughDielectric { distribution, eta, .. } => {
                dielectric::pdf_rough(&distribution.at(uv), *eta, wo, wi)
            }
            BsdfModel::Plastic { params, .. } => plastic::pdf(params, wo, wi),
            BsdfModel::RoughPlastic { params, .. } => plastic::pdf_rough(params, wo, wi),
            BsdfModel::Coating(c) => c.pdf(wo, wi, uv, mode),
            BsdfModel::Ward { params, alpha, .. } => ward::pdf(params, alpha.at(uv), wo, wi),
        }
    }

    /// [`Bsdf::pdf_pair`] of the model alone.
    fn pdf_pair_model(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> (f32, f32) {
        match &self.model {
            // One side test for both directions (the same values as two `pdf` calls).
            BsdfModel::Diffuse { .. } => {
                let (wo, wi) = self.orient(wo, wi);
                diffuse::pdf_pair(wo, wi)
            }
            _ => (self.pdf_model(wo, wi, uv, mode), self.pdf_model(wi, wo, uv, mode)),
        }
    }

    /// [`Bsdf::eval_pdfs`] of the model alone.
    #[inline]
    fn eval_pdfs_model(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> (Rgb, f32, f32) {
        match &self.model {
            BsdfModel::Diffuse { reflectance } => {
                let (wo, wi) = self.orient(wo, wi);
                // Both directions on the front side, or nothing (no texture lookup).
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return (Rgb::ZERO, 0.0, 0.0);
                }
                let (fwd, rev) = diffuse::pdf_pair(wo, wi);
                (diffuse::eval(reflectance.eval(uv), wo, wi), fwd, rev)
            }
            _ => self.eval_pdfs_general(wo, wi, uv, mode),
        }
    }

    /// [`Bsdf::eval_pdfs_model`] of the other models, out of line so that the diffuse case stays
    /// small where it is inlined.
    #[inline(never)]
    fn eval_pdfs_general(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> (Rgb, f32, f32) {
        let (fwd, rev) = self.pdf_pair_model(wo, wi, uv, mode);
        (self.eval_model(wo, wi, uv, mode), fwd, rev)
    }

    /// [`Bsdf::sample`] of the model alone.
    #[inline]
    fn sample_model(&self, wo: Vec3, uv: Vec2, u1: f32, u2: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let flip = self.two_sided && wo.z < 0.0;
        let wo_f = if flip { Vec3::new(wo.x, wo.y, -wo.z) } else { wo };
        let mut s = match &self.model {
            BsdfModel::Diffuse { reflectance } => diffuse::sample(reflectance.eval(uv), wo_f, u2)?,
            _ => self.sample_general(wo_f, uv, u1, u2, mode)?,
        };
        if flip {
            s.wi.z = -s.wi.z;
        }
        Some(s)
    }

    /// [`Bsdf::sample_model`] of the other models (with `wo` already on the front side), out of
    /// line so that the diffuse case stays small where it is inlined.
    #[inline(never)]
    fn sample_general(&self, wo_f: Vec3, uv: Vec2, u1: f32, u2: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        let s = match &self.model {
            BsdfModel::Diffuse { reflectance } => diffuse::sample(reflectance.eval(uv), wo_f, u2)?,
            BsdfModel::RoughDiffuse { reflectance, alpha, fast } => {
                let a = alpha.eval(uv).element_sum() / 3.0;
                roughdiffuse::sample(reflectance.eval(uv), a, *fast, wo_f, u2)?
            }
            BsdfModel::Conductor { eta, k, specular_reflectance } => {
                conductor::sample_smooth(*eta, *k, specular_reflectance.eval(uv), wo_f)?
            }
            BsdfModel::RoughConductor { distribution, eta, k, specular_reflectance } => {
                conductor::sample_rough(&distribution.at(uv), *eta, *k, specular_reflectance.eval(uv), wo_f, u2)?
            }
            BsdfModel::Dielectric { eta, specular_reflectance, specular_transmittance } => {
                let (r, t) = (specular_reflectance.eval(uv), specular_transmittance.eval(uv));
                dielectric::sample_smooth(*eta, r, t, wo_f, u1, mode)?
            }
            BsdfModel::ThinDielectric { eta, specular_reflectance, specular_transmittance } => {
                let (r, t) = (specular_reflectance.eval(uv), specular_transmittance.eval(uv));
                dielectric::sample_thin(*eta, r, t, wo_f, u1)?
            }
            BsdfModel::RoughDielectric { distribution, eta, specular_reflectance, specular_transmittance } => {
                let (r, t) = (specular_reflectance.eval(uv), specular_transmittance.eval(uv));
                dielectric::sample_rough(&distribution.at(uv), *eta, r, t, wo_f, u1, u2, mode)?
            }
            BsdfModel::Plastic { params, diffuse_reflectance, specular_reflectance } => {
                plastic::sample(params, diffuse_reflectance.eval(uv), specular_reflectance.eval(uv), wo_f, u1, u2)?
            }
            BsdfModel::RoughPlastic { params, diffuse_reflectance, specular_reflectance } => {
                let (d, sp) = (diffuse_reflectance.eval(uv), specular_reflectance.eval(uv));
                plastic::sample_rough(params, d, sp, wo_f, u1, u2)?
            }
            BsdfModel::Coating(c) => c.sample(wo_f, uv, u1, u2, mode)?,
            BsdfModel::Ward { params, alpha, diffuse_reflectance, specular_reflectance } => {
                let (d, sp) = (diffuse_reflectance.eval(uv), specular_reflectance.eval(uv));
                ward::sample(params, alpha.at(uv), d, sp, wo_f, u1, u2)?
            }
            BsdfModel::Null => {
                let wi = -wo_f;
                BsdfSample { wi, f: Rgb::ONE / wi.z.abs().max(1e-20), pdf: 1.0, weight: Rgb::ONE, delta: true }
            }
        };
        Some(s)
    }
}

#[cfg(test)]
mod tests {
    use super::microfacet::{Microfacet, MicrofacetType};
    use super::*;
    use crate::sampling::Sampler;
    use crate::sampling::chi2::{Chi2Test, SphereDomain};

    fn c(v: f32) -> Texture {
        Texture::Constant(Vec3::splat(v))
    }

    fn rough(kind: MicrofacetType, au: f32, av: f32) -> Microfacet {
        Microfacet { kind, alpha_u: au, alpha_v: av, sample_visible: true }
    }

    /// Glossy and diffuse BSDFs under test, with their names.
    fn models() -> Vec<(String, Bsdf)> {
        let mut v = vec![("diffuse".to_string(), Bsdf::diffuse(c(0.5)))];
        let (eta, k) = fresnel::lookup_conductor("Cu").unwrap();
        for kind in [MicrofacetType::Beckmann, MicrofacetType::Ggx] {
            for (au, av) in [(0.05, 0.05), (0.2, 0.2), (0.6, 0.6), (0.1, 0.5)] {
                let distribution = Microfacet { kind, alpha_u: au, alpha_v: av, sample_visible: au != 0.6 };
                let name = format!("{kind:?} α=({au},{av})");
                v.push((
                    format!("roughconductor {name}"),
                    Bsdf {
                        model: BsdfModel::RoughConductor {
                            distribution: distribution.into(),
                            eta,
                            k,
                            specular_reflectance: c(1.0),
                        },
                        two_sided: false,
                        perturbation: None,
                        opacity: None,
                    },
                ));
                v.push((
                    format!("roughdielectric {name}"),
                    Bsdf {
                        model: BsdfModel::RoughDielectric {
                            distribution: distribution.into(),
                            eta: 1.5,
                            specular_reflectance: c(1.0),
                            specular_transmittance: c(1.0),
                        },
                        two_sided: false,
                        perturbation: None,
                        opacity: None,
                    },
                ));
            }
        }
        let params = plastic::PlasticParams {
            eta: 1.49,
            nonlinear: false,
            fdr_int: fresnel::fresnel_diffuse_reflectance(1.0 / 1.49),
            specular_sampling_weight: 0.6,
        };
        v.push((
            "plastic".into(),
            Bsdf {
                model: BsdfModel::Plastic { params, diffuse_reflectance: c(0.5), specular_reflectance: c(1.0) },
                two_sided: false,
                perturbation: None,
                opacity: None,
            },
        ));
        for (kind, alpha) in [(MicrofacetType::Beckmann, 0.1), (MicrofacetType::Ggx, 0.4)] {
            let params = RoughPlasticParams::new(rough(kind, alpha, alpha), 1.5, false, 0.5);
            let model = BsdfModel::RoughPlastic { params, diffuse_reflectance: c(0.5), specular_reflectance: c(1.0) };
            v.push((
                format!("roughplastic {kind:?} α={alpha}"),
                Bsdf { model, two_sided: false, perturbation: None, opacity: None },
            ));
        }
        for (alpha, fast) in [(0.2, false), (0.8, false), (0.5, true)] {
            let model = BsdfModel::RoughDiffuse { reflectance: c(0.7), alpha: c(alpha), fast };
            v.push((format!("roughdiffuse α={alpha} fast={fast}"), Bsdf::new(model)));
        }
        // Mitsuba 0.6's layers, smooth and rough, clear and tinted, over a diffuse base, a
        // rough metal and rough glass.
        let tint = Texture::Constant(Vec3::new(0.1, 0.3, 0.6));
        let metal = |kind, alpha| Bsdf {
            model: BsdfModel::RoughConductor {
                distribution: rough(kind, alpha, alpha).into(),
                eta,
                k,
                specular_reflectance: c(1.0),
            },
            two_sided: false,
            perturbation: None,
            opacity: None,
        };
        let glass = Bsdf::new(BsdfModel::RoughDielectric {
            distribution: rough(MicrofacetType::Beckmann, 0.3, 0.3).into(),
            eta: 1.33,
            specular_reflectance: c(1.0),
            specular_transmittance: c(1.0),
        });
        let layers = [
            ("coating/diffuse", None, c(0.0), Bsdf::diffuse(c(0.8))),
            ("coating/diffuse σa", None, tint.clone(), Bsdf::diffuse(c(0.8))),
            ("coating/roughconductor σa", None, tint.clone(), metal(MicrofacetType::Ggx, 0.2)),
            (
                "roughcoating Beckmann α=0.1/diffuse",
                Some(rough(MicrofacetType::Beckmann, 0.1, 0.1)),
                c(0.0),
                Bsdf::diffuse(c(0.8)),
            ),
            (
                "roughcoating GGX α=0.4/roughconductor σa",
                Some(rough(MicrofacetType::Ggx, 0.4, 0.4)),
                tint,
                metal(MicrofacetType::Beckmann, 0.3),
            ),
            ("roughcoating GGX α=0.2/roughdielectric", Some(rough(MicrofacetType::Ggx, 0.2, 0.2)), c(0.0), glass),
        ];
        for (name, distribution, sigma_a, nested) in layers {
            let interface = distribution.map(|d| coating::RoughInterface::new(d, 1.5));
            let layer = coating::Coating::new(1.5, 2.0, sigma_a, c(1.0), interface, nested);
            v.push((name.to_string(), Bsdf::new(BsdfModel::Coating(Box::new(layer)))));
        }
        // Mitsuba 0.6's Ward model: each variant, isotropic and anisotropic, over a diffuse
        // base (0.6's default reflectances), and a white glossy lobe alone.
        for variant in [ward::WardVariant::Ward, ward::WardVariant::WardDuer, ward::WardVariant::Balanced] {
            for (au, av) in [(0.05, 0.05), (0.3, 0.3), (0.1, 0.4)] {
                let params = WardParams::new(variant, &c(0.5), &c(0.2), true);
                let alpha = WardAlpha::Fixed { u: au, v: av };
                let model =
                    BsdfModel::Ward { params, alpha, diffuse_reflectance: c(0.5), specular_reflectance: c(0.2) };
                v.push((format!("ward {variant:?} α=({au},{av})"), Bsdf::new(model)));
            }
        }
        let params = WardParams::new(ward::WardVariant::Balanced, &c(0.0), &c(1.0), true);
        let model = BsdfModel::Ward {
            params,
            alpha: WardAlpha::Fixed { u: 0.2, v: 0.2 },
            diffuse_reflectance: c(0.0),
            specular_reflectance: c(1.0),
        };
        v.push(("ward Balanced α=0.2, glossy only".into(), Bsdf::new(model)));
        v
    }

    #[test]
    fn eval_pdfs_is_eval_and_both_densities() {
        // Every model, one- and two-sided, directions on both sides: the one-dispatch
        // evaluation (and pdf_pair's diffuse shortcut) give exactly the separate calls.
        let mut rng = Sampler::new(&[5]);
        for (name, b) in models() {
            for two_sided in [false, true] {
                let b = Bsdf { two_sided, ..b.clone() };
                for _ in 0..500 {
                    let wo = crate::sampling::square_to_uniform_sphere(rng.next_2d());
                    let wi = crate::sampling::square_to_uniform_sphere(rng.next_2d());
                    for mode in [TransportMode::Radiance, TransportMode::Importance] {
                        let (f, fwd, rev) = b.eval_pdfs(wo, wi, Vec2::ZERO, mode);
                        let expected = (
                            b.eval(wo, wi, Vec2::ZERO, mode),
                            b.pdf(wo, wi, Vec2::ZERO, mode),
                            b.pdf(wi, wo, Vec2::ZERO, mode),
                        );
                        assert_eq!((f, fwd, rev), expected, "{name}, two-sided {two_sided}, {wo} {wi}");
                        assert_eq!(b.pdf_pair(wo, wi, Vec2::ZERO, mode), (expected.1, expected.2), "{name}");
                    }
                }
            }
        }
    }

    #[test]
    fn lobes_are_what_sampling_produces() {
        // Which kinds of direction each model's sampling produces (Dirac or not, reflected
        // or transmitted) are exactly the kinds its lobes name.
        let mut rng = Sampler::new(&[8]);
        let (eta, k) = fresnel::lookup_conductor("Au").unwrap();
        let smooth = [
            ("conductor", BsdfModel::Conductor { eta, k, specular_reflectance: c(1.0) }),
            (
                "dielectric",
                BsdfModel::Dielectric { eta: 1.5, specular_reflectance: c(1.0), specular_transmittance: c(1.0) },
            ),
            (
                "thindielectric",
                BsdfModel::ThinDielectric { eta: 1.5, specular_reflectance: c(1.0), specular_transmittance: c(1.0) },
            ),
        ]
        .map(|(name, model)| (name.to_string(), Bsdf::new(model)));
        for (name, b) in models().into_iter().chain(smooth) {
            let lobes: Vec<Lobe> = b.lobes(Vec2::ZERO).collect();
            let mut named: Vec<(bool, bool)> = lobes.iter().map(|l| (l.is_delta(), l.transmission)).collect();
            let mut seen = Vec::new();
            let wo = Vec3::new(0.3, -0.2, 0.9).normalize();
            for _ in 0..4000 {
                if let Some(s) = b.sample(wo, Vec2::ZERO, rng.next_1d(), rng.next_2d(), TransportMode::Radiance) {
                    // A thin pane's transmission keeps `wi = -wo`: below the surface too.
                    seen.push((s.delta, s.wi.z < 0.0));
                }
            }
            for v in [&mut named, &mut seen] {
                v.sort();
                v.dedup();
            }
            assert_eq!(named, seen, "{name}: lobes {lobes:?}");
            assert_eq!(lobes.iter().all(Lobe::is_delta), b.is_delta(), "{name}");
            assert_eq!(lobes.iter().any(|l| l.transmission), b.transmits(), "{name}");
            for l in &lobes {
                let expected = match &b.model {
                    BsdfModel::RoughConductor { distribution, .. }
                    | BsdfModel::RoughDielectric { distribution, .. } => {
                        let m = distribution.at(Vec2::ZERO);
                        0.5 * (m.alpha_u + m.alpha_v)
                    }
                    BsdfModel::RoughPlastic { params, .. } if l.roughness.is_finite() => params.distribution.alpha_u,
                    BsdfModel::Ward { alpha, .. } if l.roughness.is_finite() => {
                        let (u, v) = alpha.at(Vec2::ZERO);
                        0.5 * (u + v)
                    }
                    _ => l.roughness,
                };
                assert_eq!(l.roughness, expected, "{name}");
                assert!(l.roughness == 0.0 || l.roughness == DIFFUSE_ROUGHNESS || l.roughness > 0.0, "{name}");
            }
            // A Dirac transmission bends by Snell's law with `eta()` (entering from outside:
            // sin θ_o = η sin θ_i); nothing else refracts.
            match lobes.iter().find(|l| l.transmission) {
                Some(l) if l.is_delta() => {
                    let s = (0..100)
                        .filter_map(|_| b.sample(wo, Vec2::ZERO, rng.next_1d(), rng.next_2d(), TransportMode::Radiance))
                        .find(|s| s.wi.z < 0.0)
                        .unwrap();
                    let (sin_o, sin_i) = (wo.truncate().length(), s.wi.truncate().length());
                    assert!((sin_o - b.eta() * sin_i).abs() < 1e-5, "{name}: {sin_o} against {} · {sin_i}", b.eta());
                }
                Some(_) => assert!(b.eta() > 1.0, "{name}"),
                None => assert_eq!(b.eta(), 1.0, "{name}"),
            }
        }
    }

    fn check_bsdf(name: &str, b: &Bsdf, wo: Vec3, mode: TransportMode, tests: usize) {
        let mut t = Chi2Test::new(SphereDomain::default());
        t.tests = tests;
        let mut u1 = Sampler::new(&[99]);
        let r = t.run(
            |u| b.sample(wo, Vec2::ZERO, u1.next_1d(), u, mode).filter(|s| !s.delta).map(|s| s.wi),
            |wi| b.pdf(wo, wi, Vec2::ZERO, mode),
        );
        assert!(r.passed(), "{name}, wo = {wo}, {mode:?}: {r}");
    }

    #[test]
    fn every_bsdf_samples_its_pdf_chi2() {
        let wos = [
            Vec3::Z,
            Vec3::new(0.6, 0.0, 0.8),
            Vec3::new(0.3, -0.5, 0.81).normalize(),
            Vec3::new(0.999, 0.0, 0.0447).normalize(),
        ];
        let ms = models();
        let n = ms.len() * (wos.len() + 1) * 2;
        for (name, b) in &ms {
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                for wo in wos {
                    check_bsdf(name, b, wo, mode, n);
                }
                if b.transmits() {
                    // From inside the glass.
                    check_bsdf(name, b, Vec3::new(0.2, 0.3, -0.93).normalize(), mode, n);
                }
            }
        }
        let two = Bsdf { two_sided: true, ..Bsdf::diffuse(c(0.5)) };
        check_bsdf("twosided diffuse", &two, Vec3::new(0.3, 0.4, -0.866).normalize(), TransportMode::Radiance, 1);
    }

    #[test]
    fn chi2_rejects_a_wrong_microfacet_pdf() {
        // Negative control: GGX samples checked against the Beckmann pdf of the same α.
        let g = rough(MicrofacetType::Ggx, 0.3, 0.3);
        let bk = rough(MicrofacetType::Beckmann, 0.3, 0.3);
        let wo = Vec3::new(0.5, 0.0, 0.866);
        let r = Chi2Test::new(SphereDomain::default()).run(
            |u| conductor::sample_rough(&g, Vec3::ZERO, Vec3::ONE, Vec3::ONE, wo, u).map(|s| s.wi),
            |wi| conductor::pdf_rough(&bk, wo, wi),
        );
        assert!(!r.passed(), "{r}");
    }

    #[test]
    fn chi2_rejects_a_ward_pdf_with_its_roughnesses_swapped() {
        // Negative control: an anisotropic Ward lobe's samples checked against the density
        // of the lobe stretched along the other axis.
        let p = WardParams::new(ward::WardVariant::Balanced, &c(0.0), &c(1.0), true);
        let wo = Vec3::new(0.3, 0.2, 0.93).normalize();
        let r = Chi2Test::new(SphereDomain::default()).run(
            |u| ward::sample(&p, (0.1, 0.4), Vec3::ZERO, Vec3::ONE, wo, 0.0, u).map(|s| s.wi),
            |wi| ward::pdf(&p, (0.4, 0.1), wo, wi),
        );
        assert!(!r.passed(), "{r}");
    }

    #[test]
    fn sample_weight_is_eval_cos_over_pdf() {
        let mut s = Sampler::new(&[5]);
        for (name, b) in models() {
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                let wo = Vec3::new(0.1, 0.2, 0.97).normalize();
                for _ in 0..200 {
                    let Some(bs) = b.sample(wo, Vec2::ZERO, s.next_1d(), s.next_2d(), mode) else { continue };
                    if bs.delta {
                        continue;
                    }
                    let f = b.eval(wo, bs.wi, Vec2::ZERO, mode);
                    let pdf = b.pdf(wo, bs.wi, Vec2::ZERO, mode);
                    assert!((bs.pdf - pdf).abs() <= 1e-3 * pdf.max(1e-3), "{name}: pdf {} vs {pdf}", bs.pdf);
                    assert!(
                        (bs.f - f).abs().max_element() <= 1e-3 * f.max_element().max(1e-3),
                        "{name}: f {} vs {f}",
                        bs.f
                    );
                    let (fwd, rev) = b.pdf_pair(wo, bs.wi, Vec2::ZERO, mode);
                    assert!(fwd == pdf && rev == b.pdf(bs.wi, wo, Vec2::ZERO, mode), "{name}");
                    let w = f * bs.wi.z.abs() / pdf;
                    assert!((bs.weight - w).abs().max_element() <= 1e-3 * w.max_element().max(1.0), "{name}");
                }
            }
        }
    }

    #[test]
    fn white_rough_conductor_never_reflects_more_than_it_receives() {
        let mut s = Sampler::new(&[8]);
        for kind in [MicrofacetType::Beckmann, MicrofacetType::Ggx] {
            for alpha in [0.01, 0.1, 0.3, 0.7, 1.0] {
                let b = Bsdf {
                    model: BsdfModel::RoughConductor {
                        distribution: rough(kind, alpha, alpha).into(),
                        eta: Vec3::ZERO,
                        k: Vec3::ONE,
                        specular_reflectance: c(1.0),
                    },
                    two_sided: false,
                    perturbation: None,
                    opacity: None,
                };
                for cos in [1.0f32, 0.7, 0.3, 0.05] {
                    let wo = Vec3::new((1.0 - cos * cos).sqrt(), 0.0, cos);
                    let n = 20000;
                    let albedo: f32 = (0..n)
                        .filter_map(|_| b.sample(wo, Vec2::ZERO, s.next_1d(), s.next_2d(), TransportMode::Radiance))
                        .map(|x| x.weight.x)
                        .sum::<f32>()
                        / n as f32;
                    assert!(albedo <= 1.0 + 0.01, "{kind:?} α={alpha} cos={cos}: albedo {albedo}");
                    if alpha <= 0.1 && cos >= 0.5 {
                        assert!(albedo > 0.95, "{kind:?} α={alpha} cos={cos}: albedo {albedo}");
                    }
                }
            }
        }
    }

    #[test]
    fn smooth_dielectric_chooses_lobes_by_fresnel_and_scales_radiance() {
        let b = Bsdf {
            model: BsdfModel::Dielectric { eta: 1.5, specular_reflectance: c(1.0), specular_transmittance: c(1.0) },
            two_sided: false,
            perturbation: None,
            opacity: None,
        };
        let mut s = Sampler::new(&[11]);
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let f = fresnel::fresnel_dielectric(0.8, 1.5);
        let n = 100_000;
        let mut refl = 0;
        for _ in 0..n {
            let bs = b.sample(wo, Vec2::ZERO, s.next_1d(), s.next_2d(), TransportMode::Radiance).unwrap();
            assert!(bs.delta);
            if bs.wi.z > 0.0 {
                refl += 1;
                assert!((bs.wi - Vec3::new(-0.6, 0.0, 0.8)).length() < 1e-6);
                assert!((bs.weight.x - 1.0).abs() < 1e-6);
            } else {
                assert!((bs.weight.x - 1.0 / 2.25).abs() < 1e-5);
                let imp = b.sample(wo, Vec2::ZERO, 0.999, Vec2::ZERO, TransportMode::Importance).unwrap();
                assert!((imp.weight.x - 1.0).abs() < 1e-6);
            }
        }
        let p = refl as f64 / n as f64;
        let sigma = (f as f64 * (1.0 - f as f64) / n as f64).sqrt();
        assert!((p - f as f64).abs() < 4.0 * sigma, "reflected {p}, Fresnel {f}");
        // From inside beyond the critical angle: total internal reflection only.
        let inside = Vec3::new(0.9, 0.0, -0.436).normalize();
        for _ in 0..100 {
            assert!(
                b.sample(inside, Vec2::ZERO, s.next_1d(), s.next_2d(), TransportMode::Radiance).unwrap().wi.z < 0.0
            );
        }
    }

    #[test]
    fn thin_dielectric_conserves_energy() {
        let b = Bsdf {
            model: BsdfModel::ThinDielectric { eta: 1.5, specular_reflectance: c(1.0), specular_transmittance: c(1.0) },
            two_sided: false,
            perturbation: None,
            opacity: None,
        };
        let mut s = Sampler::new(&[12]);
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.0, 0.6, -0.8)] {
            let bs = b.sample(wo, Vec2::ZERO, s.next_1d(), s.next_2d(), TransportMode::Radiance).unwrap();
            assert!((bs.weight.x - 1.0).abs() < 1e-6);
            assert!(bs.wi == -wo || (bs.wi.z - wo.z).abs() < 1e-6);
        }
    }

    #[test]
    fn diffuse_chi2_front_and_two_sided_back() {
        let d = Bsdf::diffuse(c(0.5));
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8)] {
            check_bsdf("diffuse", &d, wo, TransportMode::Radiance, 1);
        }
    }

    #[test]
    fn one_sided_diffuse_is_black_from_behind() {
        let d = Bsdf::diffuse(c(1.0));
        let below = Vec3::new(0.0, 0.6, -0.8);
        assert_eq!(d.eval(below, Vec3::Z, Vec2::ZERO, TransportMode::Radiance), Vec3::ZERO);
        assert!(d.sample(below, Vec2::ZERO, 0.5, Vec2::splat(0.3), TransportMode::Radiance).is_none());
        let two = Bsdf { two_sided: true, ..d };
        assert!(two.eval(below, -Vec3::Z, Vec2::ZERO, TransportMode::Radiance).x > 0.0);
    }
}
