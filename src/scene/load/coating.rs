//! Mitsuba 0.6's `coating` and `roughcoating` BSDFs: a nested BSDF (required, one) under a
//! dielectric layer with `int_ior` and `ext_ior` (numbers or named indices; default `bk7`
//! over `air`, and they must differ), `thickness` (default 1), `sigma_a` (absorption, a
//! colour or texture, default 0), `specular_reflectance` (default 1, scaled down below 1
//! with a warning unless `ensure_energy_conservation` is off, as Mitsuba 0.6 did), and for
//! `roughcoating` an isotropic, constant `alpha` (default 0.1) with a Beckmann or GGX
//! `distribution` and `sample_visible`.

use super::Builder;
use crate::bsdf::coating::{Coating, RoughInterface};
use crate::bsdf::{Bsdf, BsdfModel};
use crate::error::{Error, Result};
use crate::scene::xml::NodeId;
use crate::texture::{Bitmap, Texture};
use glam::Vec3;

impl Builder<'_> {
    /// A `coating` or `roughcoating` around its nested BSDF.
    pub(super) fn coated(&mut self, id: NodeId) -> Result<Bsdf> {
        let node = self.node(id);
        let plugin = node.plugin.clone();
        let inner: Vec<NodeId> = self.doc.children(id, "bsdf").map(|c| c.node).collect();
        let nested_id = match inner.as_slice() {
            [one] => *one,
            [] => return Err(Error::input(&node.loc, format!("{plugin} needs a nested <bsdf> to coat"))),
            [_, second, ..] => {
                return Err(Error::input(&self.node(*second).loc, format!("{plugin} takes one nested <bsdf>")));
            }
        };
        let int_ior = self.ior(id, "int_ior", "bk7")?;
        let ext_ior = self.ior(id, "ext_ior", "air")?;
        if int_ior == ext_ior {
            let at = if node.prop("int_ior").is_some() { node.prop_loc("int_ior") } else { node.loc.clone() };
            return Err(Error::input(
                &at,
                format!("{plugin}: the interior and exterior indices of refraction must differ (both are {int_ior})"),
            ));
        }
        let eta = int_ior / ext_ior;
        let thickness = node.float_or("thickness", 1.0)?;
        if !(thickness >= 0.0 && thickness.is_finite()) {
            return Err(Error::input(
                &node.prop_loc("thickness"),
                format!("\"thickness\" must be finite and non-negative, got {thickness}"),
            ));
        }
        let sigma_a = self.texture_prop(id, "sigma_a", Vec3::ZERO)?;
        if extreme(&sigma_a).0 < 0.0 {
            return Err(Error::input(&node.prop_loc("sigma_a"), "\"sigma_a\" must be non-negative"));
        }
        let specular_reflectance = self.texture_prop(id, "specular_reflectance", Vec3::ONE)?;
        let specular_reflectance = if node.boolean_or("ensure_energy_conservation", true)? {
            self.energy_conserving(id, specular_reflectance)
        } else {
            specular_reflectance
        };
        let rough = if plugin == "roughcoating" {
            let distribution = self.microfacet(id)?;
            if distribution.alpha_u != distribution.alpha_v {
                return Err(Error::input(&node.loc, "roughcoating is isotropic: give \"alpha\""));
            }
            // The interface's transmittance is roughplastic's table for the same interface.
            let transmittance = self.coating(distribution, eta, false, 0.5).external_transmittance;
            Some(RoughInterface { distribution, transmittance })
        } else {
            None
        };
        let nested = self.bsdf_value(nested_id)?;
        let refused = if nested.perturbation.is_some() {
            Some("a bump- or normal-mapped BSDF")
        } else if nested.opacity.is_some() {
            Some("a mask")
        } else {
            None
        };
        if let Some(what) = refused {
            return Err(Error::input(
                &self.node(nested_id).loc,
                format!("{what} inside a {plugin} is not supported (put the {plugin} inside it instead)"),
            ));
        }
        self.check_unused(id)?;
        let layer = Coating::new(eta, thickness, sigma_a, specular_reflectance, rough, nested);
        Ok(Bsdf::new(BsdfModel::Coating(Box::new(layer))))
    }

    /// `specular_reflectance` scaled to a largest channel of 0.99 where it exceeds 1, with a
    /// warning (Mitsuba 0.6's `ensureEnergyConservation`).
    fn energy_conserving(&mut self, id: NodeId, t: Texture) -> Texture {
        let max = extreme(&t).1;
        if max <= 1.0 {
            return t;
        }
        let node = self.node(id);
        let scale = 0.99 / max;
        self.stats.warnings.push(format!(
            "{}: the {}'s specular_reflectance reaches {max} (> 1) and is scaled by {scale}, as Mitsuba 0.6 does \
             (set ensure_energy_conservation to false to keep it)",
            node.prop_loc("specular_reflectance"),
            node.plugin
        ));
        match t {
            Texture::Constant(c) => Texture::Constant(c * scale),
            Texture::Bitmap { bitmap, to_uv } => {
                let texels = bitmap.texels().map(|v| v * scale).collect();
                let scaled = Bitmap::new(bitmap.width, bitmap.height, texels, bitmap.filter, bitmap.wrap);
                Texture::Bitmap { bitmap: std::sync::Arc::new(scaled), to_uv }
            }
            Texture::Checkerboard { color0, color1, to_uv } => {
                Texture::Checkerboard { color0: color0 * scale, color1: color1 * scale, to_uv }
            }
        }
    }
}

/// The smallest and the largest channel of a texture's values.
fn extreme(t: &Texture) -> (f32, f32) {
    let fold = |(lo, hi): (f32, f32), v: Vec3| (lo.min(v.min_element()), hi.max(v.max_element()));
    let start = (f32::INFINITY, f32::NEG_INFINITY);
    match t {
        Texture::Constant(c) => fold(start, *c),
        Texture::Bitmap { bitmap, .. } => bitmap.texels().fold(start, fold),
        Texture::Checkerboard { color0, color1, .. } => fold(fold(start, *color0), *color1),
    }
}

#[cfg(test)]
mod tests {
    use crate::bsdf::BsdfModel;
    use crate::bsdf::coating::Coating;
    use crate::scene::{LoadOptions, Scene};
    use crate::texture::Texture;
    use glam::Vec3;
    use std::sync::Arc;

    /// A Mitsuba 0.6 scene made of `bsdfs`.
    fn load(bsdfs: &str) -> Scene {
        let text = format!(
            r#"<scene version="0.6.0">
    <sensor type="perspective"><float name="fov" value="40"/><film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>
    <shape type="rectangle"><emitter type="area"><spectrum name="radiance" value="1"/></emitter></shape>
    {bsdfs}
</scene>"#
        );
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/layers.xml");
        Scene::load_str(&text, &path, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn mitsuba_06_defaults_names_and_energy_conservation() {
        let s = load(
            r#"<bsdf type="coating"><bsdf type="diffuse"/></bsdf>
    <bsdf type="roughcoating"><string name="intIOR" value="polypropylene"/><float name="alpha" value="0.2"/>
        <rgb name="sigmaA" value="0.5, 0, 1"/><float name="thickness" value="0"/>
        <spectrum name="specularReflectance" value="2"/>
        <bsdf type="twosided"><bsdf type="coating"><float name="intIOR" value="1.3"/><bsdf type="conductor"/></bsdf></bsdf>
    </bsdf>
    <bsdf type="roughplastic"><float name="alpha" value="0.2"/></bsdf>
    <bsdf type="coating"><rgb name="specularReflectance" value="0.5, 1.5, 1"/>
        <boolean name="ensureEnergyConservation" value="false"/><bsdf type="diffuse"/></bsdf>"#,
        );
        let l: Vec<&Coating> = s
            .bsdfs
            .iter()
            .filter_map(|b| match &b.model {
                BsdfModel::Coating(c) => Some(&**c),
                _ => None,
            })
            .collect();
        assert_eq!(l.len(), 3);
        // Mitsuba 0.6's defaults: bk7 over air, thickness 1, clear, white, smooth.
        assert_eq!(l[0].eta, 1.5046 / 1.000277);
        assert_eq!((l[0].thickness, l[0].specular_sampling_weight), (1.0, 0.5));
        assert_eq!(l[0].sigma_a, Texture::Constant(Vec3::ZERO));
        assert_eq!(l[0].specular_reflectance, Texture::Constant(Vec3::ONE));
        assert!(l[0].rough.is_none() && !l[0].nested.two_sided);
        // A rough layer, tinted but of thickness 0 (absorbing nothing), its reflectance
        // scaled below 1 with a warning, over a two-sided smooth layer over a mirror.
        let r = l[1];
        assert_eq!(r.eta, 1.49 / 1.000277);
        assert_eq!(r.rough.as_ref().unwrap().distribution.alpha_u, 0.2);
        assert_eq!((r.thickness, r.specular_sampling_weight), (0.0, 0.5));
        assert_eq!(r.specular_reflectance, Texture::Constant(Vec3::splat(0.99)));
        let w = &s.stats.warnings;
        assert_eq!(w.iter().filter(|w| w.contains("specular_reflectance reaches 2")).count(), 1, "{w:?}");
        assert!(r.nested.two_sided && r.nested.is_delta());
        // The rough layer's transmittance is the table of the rough plastic's identical
        // coating (polypropylene over air, Beckmann, α = 0.2).
        let plastic = s.bsdfs.iter().find_map(|b| match &b.model {
            BsdfModel::RoughPlastic { params, .. } => Some(params),
            _ => None,
        });
        let table = &r.rough.as_ref().unwrap().transmittance;
        assert!(Arc::ptr_eq(table, &plastic.unwrap().external_transmittance));
        // Kept as given where energy conservation is off.
        assert_eq!(l[2].specular_reflectance, Texture::Constant(Vec3::new(0.5, 1.5, 1.0)));
    }
}
