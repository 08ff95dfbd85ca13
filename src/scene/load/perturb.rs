//! The BSDF wrappers that perturb the shading normal: `bumpmap` and `normalmap`.

use super::Builder;
use crate::bsdf::Bsdf;
use crate::bsdf::perturb::{PerturbKind, Perturbation};
use crate::error::{Error, Result};
use crate::scene::xml::NodeId;
use crate::texture::Texture;
use glam::Vec3;

impl Builder<'_> {
    /// `bumpmap` (a nested height texture, then the nested BSDF; `scale`, default 1) or
    /// `normalmap` (a nested texture named `normalmap` and the nested BSDF), with Mitsuba 3's
    /// `use_shadowing_function` (default on) and `flip_invalid_normals` (read; README,
    /// "Known differences from Mitsuba 3").
    pub(super) fn perturbed_bsdf(&mut self, id: NodeId) -> Result<Bsdf> {
        let node = self.node(id);
        let plugin = node.plugin.clone();
        let inner: Vec<NodeId> = self.doc.children(id, "bsdf").map(|c| c.node).collect();
        let nested = match inner.as_slice() {
            [one] => *one,
            [] => return Err(Error::input(&node.loc, format!("{plugin} needs a nested <bsdf> to perturb"))),
            [_, two, ..] => {
                return Err(Error::input(&self.node(*two).loc, format!("{plugin} takes one nested <bsdf>")));
            }
        };
        let kind = if plugin == "bumpmap" {
            let textures: Vec<NodeId> = self.doc.children(id, "texture").map(|c| c.node).collect();
            let (height, texture_scale) = match textures.as_slice() {
                [t] => self.height_texture(*t)?,
                [] => {
                    return Err(Error::input(
                        &node.loc,
                        "bumpmap needs a nested height <texture> (a bitmap) before its nested <bsdf>",
                    ));
                }
                [_, two, ..] => {
                    return Err(Error::input(&self.node(*two).loc, "bumpmap takes one nested height <texture>"));
                }
            };
            let scale = node.float("scale")?.unwrap_or(1.0);
            if !scale.is_finite() {
                return Err(Error::input(&node.prop_loc("scale"), "bumpmap's \"scale\" must be a finite number"));
            }
            PerturbKind::Bump { height, scale: scale * texture_scale }
        } else {
            let given = node.prop("normalmap").is_some()
                || node.children.iter().any(|c| c.name.as_deref() == Some("normalmap"));
            if !given {
                return Err(Error::input(
                    &node.loc,
                    "normalmap needs a nested <texture name=\"normalmap\"> (a bitmap with raw=\"true\")",
                ));
            }
            PerturbKind::Normal { normals: self.texture_prop(id, "normalmap", Vec3::Z)? }
        };
        let shadowing = node.boolean_or("use_shadowing_function", true)?;
        node.boolean_or("flip_invalid_normals", true)?;
        let mut bsdf = self.bsdf_value(nested)?;
        if bsdf.perturbation.is_some() {
            return Err(Error::input(
                &self.node(nested).loc,
                format!("{plugin} of a BSDF that is already bump- or normal-mapped is not supported"),
            ));
        }
        bsdf.perturbation = Some(Box::new(Perturbation { kind, shadowing }));
        self.check_unused(id)?;
        Ok(bsdf)
    }

    /// A bump map's height texture and the factor on its gradient: a `bitmap`, or Mitsuba
    /// 0.6's `scale` texture around one (its `scale`, default 1, multiplies the heights).
    fn height_texture(&mut self, id: NodeId) -> Result<(Texture, f32)> {
        let node = self.node(id);
        if node.plugin == "scale" {
            let inner: Vec<NodeId> = self.doc.children(id, "texture").map(|c| c.node).collect();
            let [t] = inner.as_slice() else {
                return Err(Error::input(&node.loc, "a \"scale\" texture needs one nested <texture>"));
            };
            let scale = node.float("scale")?.unwrap_or(1.0);
            if !scale.is_finite() {
                return Err(Error::input(&node.prop_loc("scale"), "\"scale\" must be a finite number"));
            }
            let (texture, inner_scale) = self.height_texture(*t)?;
            self.check_unused(id)?;
            return Ok((texture, scale * inner_scale));
        }
        let loc = node.loc.clone();
        let texture = self.texture_node(id)?;
        if texture.luminance_gradient(glam::Vec2::ZERO).is_none() {
            return Err(Error::input(
                &loc,
                format!("a bump map's height texture must be a bitmap (its gradient), not \"{}\"", node.plugin),
            ));
        }
        Ok((texture, 1.0))
    }
}
