//! The BSDF plugins: each `<bsdf>` node instantiated once into a [`Bsdf`] (shared through
//! `ref`), and the properties BSDFs share: indices of refraction, microfacet roughness,
//! conductors' `eta` and `k`, rough plastics' coating tables.

use super::{Builder, non_negative_rgb, positive};
use crate::bsdf::fresnel::{fresnel_diffuse_reflectance, lookup_conductor, lookup_ior};
use crate::bsdf::microfacet::{Microfacet, MicrofacetType, Roughness};
use crate::bsdf::plastic::{PlasticParams, RoughPlasticParams};
use crate::bsdf::ward::{WardAlpha, WardParams, WardVariant};
use crate::bsdf::{Bsdf, BsdfModel};
use crate::error::{Error, Result};
use crate::scene::xml::{NodeId, Value};
use crate::texture::Texture;
use glam::Vec3;

/// BSDF plugins this renderer implements.
pub const BSDF_PLUGINS: &[&str] = &[
    "diffuse",
    "null",
    "mask",
    "twosided",
    "conductor",
    "roughconductor",
    "dielectric",
    "thindielectric",
    "roughdielectric",
    "plastic",
    "roughplastic",
    "roughdiffuse",
    "coating",
    "roughcoating",
    "ward",
    "bumpmap",
    "normalmap",
];

impl Builder<'_> {
    /// A rough plastic's parameters, its coating's tables shared with an earlier material of
    /// the same distribution and index (the same values as [`RoughPlasticParams::new`]).
    pub(super) fn coating(
        &mut self,
        distribution: Microfacet,
        eta: f32,
        nonlinear: bool,
        weight: f32,
    ) -> RoughPlasticParams {
        if let Some(c) =
            self.coatings.iter().find(|c| c.distribution == distribution && c.eta.to_bits() == eta.to_bits())
        {
            return RoughPlasticParams { nonlinear, specular_sampling_weight: weight, ..c.clone() };
        }
        let params = RoughPlasticParams::new(distribution, eta, nonlinear, weight);
        self.coatings.push(params.clone());
        params
    }

    /// An index of refraction given as a number or by name (`bk7`, `air`, …).
    pub(super) fn ior(&self, id: NodeId, name: &str, default: &str) -> Result<f32> {
        let node = self.doc.node(id);
        let v = match node.prop(name).map(|p| (&p.value, p.loc.clone())) {
            None => lookup_ior(default).unwrap_or(1.0),
            Some((Value::Float(f), _)) => *f as f32,
            Some((Value::Integer(i), _)) => *i as f32,
            Some((Value::String(s), loc)) => {
                lookup_ior(s).ok_or_else(|| Error::input(&loc, format!("unknown index of refraction \"{s}\"")))?
            }
            Some((v, loc)) => {
                return Err(Error::input(
                    &loc,
                    format!("\"{name}\" has type {}, expected a number or a material name", v.type_name()),
                ));
            }
        };
        positive(node, name, v)
    }

    /// `distribution` and `sample_visible` of a microfacet BSDF.
    pub(super) fn microfacet_kind(&self, id: NodeId) -> Result<(MicrofacetType, bool)> {
        let node = self.doc.node(id);
        let kind = match node.string("distribution")?.unwrap_or("beckmann") {
            "beckmann" => MicrofacetType::Beckmann,
            "ggx" => MicrofacetType::Ggx,
            d => {
                let msg = format!("unknown distribution \"{d}\" (beckmann, ggx)");
                return Err(Error::input(&node.prop_loc("distribution"), msg));
            }
        };
        Ok((kind, node.boolean_or("sample_visible", true)?))
    }

    /// A roughness given as a positive number or a texture (`alpha`, `alpha_u`, `alpha_v`).
    pub(super) fn alpha_texture(&mut self, id: NodeId, name: &str) -> Result<Option<Texture>> {
        let node = self.doc.node(id);
        let nested =
            node.children.iter().find(|c| c.name.as_deref() == Some(name) && self.doc.node(c.node).tag == "texture");
        if let Some(c) = nested {
            c.used.set(true);
        }
        match (node.float(name)?, nested.map(|c| c.node)) {
            (Some(_), Some(t)) => {
                Err(Error::input(&self.node(t).loc, format!("\"{name}\" is given both as a value and as a texture")))
            }
            (Some(v), None) => Ok(Some(Texture::Constant(Vec3::splat(positive(node, name, v)?)))),
            (None, Some(t)) => Ok(Some(self.texture_node(t)?)),
            (None, None) => Ok(None),
        }
    }

    /// Microfacet roughness: `alpha`, or `alpha_u` and `alpha_v`, each a number or a texture
    /// (default 0.1). Roughness is kept at least 1e-4, as in Mitsuba.
    pub(super) fn roughness(&mut self, id: NodeId) -> Result<Roughness> {
        let (kind, sample_visible) = self.microfacet_kind(id)?;
        let a = self.alpha_texture(id, "alpha")?;
        let au = self.alpha_texture(id, "alpha_u")?;
        let av = self.alpha_texture(id, "alpha_v")?;
        let (tu, tv) = match (a, au, av) {
            (Some(a), None, None) => (a.clone(), a),
            (None, Some(u), Some(v)) => (u, v),
            (None, None, None) => (Texture::Constant(Vec3::splat(0.1)), Texture::Constant(Vec3::splat(0.1))),
            _ => {
                return Err(Error::input(
                    &self.node(id).loc,
                    "give either \"alpha\" or both \"alpha_u\" and \"alpha_v\"",
                ));
            }
        };
        let base = Microfacet { kind, alpha_u: 0.1, alpha_v: 0.1, sample_visible };
        Ok(match (&tu, &tv) {
            (Texture::Constant(u), Texture::Constant(v)) => {
                Roughness::Fixed(Microfacet { alpha_u: u.x.max(1e-4), alpha_v: v.x.max(1e-4), ..base })
            }
            _ => Roughness::Textured { base, alpha_u: tu, alpha_v: tv },
        })
    }

    /// A constant microfacet distribution (for plugins that precompute tables from it).
    pub(super) fn microfacet(&mut self, id: NodeId) -> Result<Microfacet> {
        match self.roughness(id)? {
            Roughness::Fixed(m) => Ok(m),
            Roughness::Textured { .. } => {
                Err(Error::input(&self.node(id).loc, format!("{} needs a constant roughness", self.node(id).plugin)))
            }
        }
    }

    /// Mitsuba 0.6's `ward`: `variant` (default `balanced`), the roughness `alpha` (default
    /// 0.1) that `alpha_u` and `alpha_v` override, each a positive number or a texture,
    /// `specular_reflectance` (default 0.2) and `diffuse_reflectance` (default 0.5), scaled
    /// together where they sum to more than 1 unless `ensure_energy_conservation` is off
    /// (with a warning, as 0.6 gave).
    pub(super) fn ward(&mut self, id: NodeId) -> Result<BsdfModel> {
        let node = self.doc.node(id);
        let name = node.string("variant")?.unwrap_or("balanced");
        let variant = WardVariant::from_name(name).ok_or_else(|| {
            let msg = format!("unknown ward variant \"{name}\" ({})", WardVariant::NAMES.join(", "));
            Error::input(&node.prop_loc("variant"), msg)
        })?;
        let alpha = self.alpha_texture(id, "alpha")?.unwrap_or(Texture::Constant(Vec3::splat(0.1)));
        let alpha_u = self.alpha_texture(id, "alpha_u")?.unwrap_or_else(|| alpha.clone());
        let alpha_v = self.alpha_texture(id, "alpha_v")?.unwrap_or(alpha);
        let alpha = match (alpha_u, alpha_v) {
            (Texture::Constant(u), Texture::Constant(v)) => WardAlpha::Fixed { u: u.x, v: v.x },
            (u, v) => WardAlpha::Textured { u, v },
        };
        let diffuse_reflectance = self.texture_prop(id, "diffuse_reflectance", Vec3::splat(0.5))?;
        let specular_reflectance = self.texture_prop(id, "specular_reflectance", Vec3::splat(0.2))?;
        let ensure = node.boolean_or("ensure_energy_conservation", true)?;
        let params = WardParams::new(variant, &diffuse_reflectance, &specular_reflectance, ensure);
        if params.scale != 1.0 {
            let sum = (diffuse_reflectance.max() + specular_reflectance.max()).max_element();
            self.stats.warnings.push(format!(
                "{}: the ward BSDF's specular_reflectance and diffuse_reflectance sum to {sum} (> 1) in a channel; \
                 both are scaled by {} to keep energy, as Mitsuba 0.6 did (ensure_energy_conservation=false keeps them)",
                node.loc, params.scale
            ));
        }
        Ok(BsdfModel::Ward { params, alpha, diffuse_reflectance, specular_reflectance })
    }

    /// Conductor parameters: a named `material` or `eta` and `k` (default: a perfect mirror),
    /// relative to the exterior medium's index `ext_eta` (Mitsuba 0.6's `extEta`, a number
    /// or a named index; default 1): both are divided by it, as Mitsuba 0.6 did. A version
    /// 0.x file's `eta` and `k` may have negative channels (RGB fits of measured data do),
    /// which Mitsuba 0.6 rendered: its Fresnel term, like this renderer's, depends on
    /// `(eta + ik)²` up to complex conjugation, which the magnitudes keep, so they are taken,
    /// with a warning.
    pub(super) fn conductor(&mut self, id: NodeId) -> Result<(Vec3, Vec3)> {
        let node = self.doc.node(id);
        let (eta, k) = match (node.string("material")?, node.rgb("eta")?, node.rgb("k")?) {
            (Some(m), None, None) => lookup_conductor(m).ok_or_else(|| {
                Error::input(&node.prop_loc("material"), format!("unknown conductor material \"{m}\""))
            })?,
            (None, Some(eta), Some(k)) if node.legacy && (eta.min_element() < 0.0 || k.min_element() < 0.0) => {
                let mut magnitude = |name: &str, v: Vec3| {
                    if v.is_finite() && v.min_element() < 0.0 {
                        self.stats.warnings.push(format!(
                            "{}: the conductor's {name} {v} has a negative channel; its magnitude is used (the Fresnel \
                             term depends on (eta + ik)² up to conjugation, as in Mitsuba 0.6)",
                            node.prop_loc(name)
                        ));
                    }
                    non_negative_rgb(node, name, v.abs())
                };
                (magnitude("eta", eta)?, magnitude("k", k)?)
            }
            (None, Some(eta), Some(k)) => (non_negative_rgb(node, "eta", eta)?, non_negative_rgb(node, "k", k)?),
            (None, None, None) => (Vec3::ZERO, Vec3::ONE),
            _ => return Err(Error::input(&node.loc, "give either \"material\" or both \"eta\" and \"k\"")),
        };
        let ext_eta = match node.prop("ext_eta") {
            None => 1.0,
            Some(_) => self.ior(id, "ext_eta", "air")?,
        };
        Ok((eta / ext_eta, k / ext_eta))
    }

    /// Instantiates a BSDF once per node (shared through `ref`).
    pub(super) fn bsdf(&mut self, id: NodeId) -> Result<usize> {
        if let Some(&i) = self.bsdf_ids.get(&id) {
            return Ok(i);
        }
        let bsdf = self.bsdf_value(id)?;
        self.bsdfs.push(bsdf);
        self.bsdf_ids.insert(id, self.bsdfs.len() - 1);
        Ok(self.bsdfs.len() - 1)
    }

    pub(super) fn bsdf_value(&mut self, id: NodeId) -> Result<Bsdf> {
        let plugin = self.node(id).plugin.clone();
        let one = Vec3::ONE;
        let model = match plugin.as_str() {
            "bumpmap" | "normalmap" => return self.perturbed_bsdf(id),
            "null" => BsdfModel::Null,
            "diffuse" => BsdfModel::Diffuse { reflectance: self.texture_prop(id, "reflectance", Vec3::splat(0.5))? },
            "roughdiffuse" => self.rough_diffuse(id)?,
            "twosided" => {
                let inner: Vec<NodeId> = self.doc.children(id, "bsdf").map(|c| c.node).collect();
                return match inner.as_slice() {
                    [one] => {
                        let mut b = self.bsdf_value(*one)?;
                        b.two_sided = true;
                        self.check_unused(id)?;
                        Ok(b)
                    }
                    [] => Err(Error::input(&self.node(id).loc, "twosided needs a nested <bsdf>")),
                    _ => Err(Error::input(
                        &self.node(id).loc,
                        "twosided with different front and back BSDFs is not supported",
                    )),
                };
            }
            "conductor" => {
                let (eta, k) = self.conductor(id)?;
                BsdfModel::Conductor {
                    eta,
                    k,
                    specular_reflectance: self.texture_prop(id, "specular_reflectance", one)?,
                }
            }
            "roughconductor" => {
                let (eta, k) = self.conductor(id)?;
                let distribution = self.roughness(id)?;
                let specular_reflectance = self.texture_prop(id, "specular_reflectance", one)?;
                BsdfModel::RoughConductor { distribution, eta, k, specular_reflectance }
            }
            "dielectric" | "thindielectric" | "roughdielectric" => {
                let eta = self.ior(id, "int_ior", "bk7")? / self.ior(id, "ext_ior", "air")?;
                let specular_reflectance = self.texture_prop(id, "specular_reflectance", one)?;
                let specular_transmittance = self.texture_prop(id, "specular_transmittance", one)?;
                match plugin.as_str() {
                    "dielectric" => BsdfModel::Dielectric { eta, specular_reflectance, specular_transmittance },
                    "thindielectric" => BsdfModel::ThinDielectric { eta, specular_reflectance, specular_transmittance },
                    _ => {
                        let distribution = self.roughness(id)?;
                        BsdfModel::RoughDielectric { distribution, eta, specular_reflectance, specular_transmittance }
                    }
                }
            }
            "plastic" | "roughplastic" => {
                let eta = self.ior(id, "int_ior", "polypropylene")? / self.ior(id, "ext_ior", "air")?;
                let diffuse_reflectance = self.texture_prop(id, "diffuse_reflectance", Vec3::splat(0.5))?;
                let specular_reflectance = self.texture_prop(id, "specular_reflectance", one)?;
                let nonlinear = self.node(id).boolean_or("nonlinear", false)?;
                let d = diffuse_reflectance.mean().element_sum() / 3.0;
                let s = specular_reflectance.mean().element_sum() / 3.0;
                let weight = if d + s > 0.0 { s / (d + s) } else { 0.5 };
                if plugin == "plastic" {
                    let fdr_int = fresnel_diffuse_reflectance(1.0 / eta);
                    let params = PlasticParams { eta, nonlinear, fdr_int, specular_sampling_weight: weight };
                    BsdfModel::Plastic { params, diffuse_reflectance, specular_reflectance }
                } else {
                    let distribution = self.microfacet(id)?;
                    if distribution.alpha_u != distribution.alpha_v {
                        return Err(Error::input(&self.node(id).loc, "roughplastic is isotropic: give \"alpha\""));
                    }
                    let params = self.coating(distribution, eta, nonlinear, weight);
                    BsdfModel::RoughPlastic { params, diffuse_reflectance, specular_reflectance }
                }
            }
            "ward" => self.ward(id)?,
            "mask" => return self.mask(id),
            "coating" | "roughcoating" => return self.coated(id),
            _ => return Err(self.unknown_plugin(id, BSDF_PLUGINS)),
        };
        self.check_unused(id)?;
        Ok(Bsdf::new(model))
    }

    /// Mitsuba 0.6's `roughdiffuse`: `reflectance` (or `diffuseReflectance`), `alpha` (a
    /// number or a texture, default 0.2) and `useFastApprox`.
    pub(super) fn rough_diffuse(&mut self, id: NodeId) -> Result<BsdfModel> {
        let name =
            if self.node(id).prop("diffuse_reflectance").is_some() { "diffuse_reflectance" } else { "reflectance" };
        let reflectance = self.texture_prop(id, name, Vec3::splat(0.5))?;
        let alpha = self.texture_prop(id, "alpha", Vec3::splat(0.2))?;
        if let Some(bad) = alpha.values().find(|v| !(v.is_finite() && v.min_element() >= 0.0)) {
            return Err(Error::input(
                &self.node(id).prop_loc("alpha"),
                format!("roughdiffuse's alpha must be finite and non-negative, got {bad}"),
            ));
        }
        let fast = self.node(id).boolean_or("use_fast_approx", false)?;
        Ok(BsdfModel::RoughDiffuse { reflectance, alpha, fast })
    }
}
