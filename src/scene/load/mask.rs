//! Mitsuba's `mask` BSDF: a nested BSDF with an opacity, a number or a texture (the alpha
//! channel of a bitmap that has one). The opacity becomes the BSDF's cut-out, which the
//! accelerator applies to every ray (`accel::keeps_hit`).

use super::Builder;
use crate::bsdf::Bsdf;
use crate::error::{Error, Result};
use crate::scene::xml::NodeId;
use crate::texture::{AlphaBitmap, Opacity};
use glam::{Mat3, Mat4};
use std::sync::Arc;

/// Mitsuba's default opacity of a `mask`.
const DEFAULT_OPACITY: f32 = 0.5;

impl Builder<'_> {
    /// A `mask`: its nested BSDF with the opacity attached.
    pub(super) fn mask(&mut self, id: NodeId) -> Result<Bsdf> {
        let node = self.doc.node(id);
        let opacity = self.opacity(id)?;
        let inner: Vec<NodeId> = self.doc.children(id, "bsdf").map(|c| c.node).collect();
        let mut bsdf = match inner.as_slice() {
            [one] => self.bsdf_value(*one)?,
            [] => return Err(Error::input(&node.loc, "mask needs a nested <bsdf>")),
            [_, second, ..] => {
                return Err(Error::input(&self.doc.node(*second).loc, "mask takes one nested <bsdf>, not several"));
            }
        };
        if bsdf.opacity.is_some() {
            return Err(Error::input(&self.doc.node(inner[0]).loc, "a mask inside a mask is not supported"));
        }
        bsdf.opacity = Some(Arc::new(opacity));
        self.check_unused(id)?;
        Ok(bsdf)
    }

    /// The `opacity` of a mask: a number in `[0, 1]`, a colour, or a texture. A colour
    /// (Mitsuba 0.5/0.6 files give a `spectrum` or `rgb`) counts by its luminance, as Mitsuba
    /// 3 reads a colour where it wants a number: a grey one is its value, and a coloured one
    /// gets a warning (Mitsuba 0.6 made each channel an opacity of its own).
    fn opacity(&mut self, id: NodeId) -> Result<Opacity> {
        let node = self.doc.node(id);
        let nested: Vec<NodeId> = node
            .children
            .iter()
            .filter(|c| c.name.as_deref() == Some("opacity") && self.doc.node(c.node).tag == "texture")
            .map(|c| {
                c.used.set(true);
                c.node
            })
            .collect();
        let value = match node.rgb("opacity")? {
            Some(c) if c.x == c.y && c.y == c.z => Some(c.x),
            Some(c) => {
                let a = crate::math::luminance(c);
                self.stats.warnings.push(format!(
                    "{}: the mask's opacity ({}, {}, {}) is coloured: it counts by its luminance, {a}, as in Mitsuba 3 (Mitsuba 0.6 made each channel an opacity of its own)",
                    node.prop_loc("opacity"),
                    c.x,
                    c.y,
                    c.z
                ));
                Some(a)
            }
            None => None,
        };
        match (value, nested.as_slice()) {
            (Some(_), [t, ..]) => {
                Err(Error::input(&self.doc.node(*t).loc, "\"opacity\" is given both as a value and as a texture"))
            }
            (Some(a), []) if (0.0..=1.0).contains(&a) => Ok(Opacity::Constant(a)),
            (Some(a), []) => {
                Err(Error::input(&node.prop_loc("opacity"), format!("\"opacity\" must be between 0 and 1, got {a}")))
            }
            (None, []) => Ok(Opacity::Constant(DEFAULT_OPACITY)),
            (None, [t]) => self.opacity_texture(*t),
            (None, [_, t, ..]) => Err(Error::input(&self.doc.node(*t).loc, "\"opacity\" is given twice")),
        }
    }

    /// An opacity texture: a bitmap's alpha channel where it has one (kept only for such
    /// textures), else the luminance of the texture's colour, as Mitsuba 3 reads a colour
    /// texture where it wants a number.
    fn opacity_texture(&mut self, id: NodeId) -> Result<Opacity> {
        let node = self.doc.node(id);
        if node.plugin == "bitmap" {
            let (path, filter, wrap) = self.bitmap_params(id)?;
            let file_loc = node.prop_loc("filename");
            if !path.is_file() {
                let missing = Error::in_file(&path, "texture file does not exist");
                return Err(Error::input(&file_loc, missing.to_string()));
            }
            let alpha = crate::image_io::read_alpha(&path).map_err(|e| Error::input(&file_loc, e.to_string()))?;
            if let Some((width, height, texels)) = alpha {
                if width == 0 || height == 0 {
                    let empty = Error::in_file(&path, "texture has no pixels");
                    return Err(Error::input(&file_loc, empty.to_string()));
                }
                let to_uv = Mat3::from_mat4(node.transform("to_uv")?.unwrap_or(Mat4::IDENTITY));
                // `raw` changes how colour is decoded; alpha is linear either way.
                node.boolean_or("raw", false)?;
                self.check_unused(id)?;
                self.stats.files.push(path);
                let bitmap = Arc::new(AlphaBitmap { width, height, texels, filter, wrap });
                return Ok(Opacity::Alpha { bitmap, to_uv });
            }
        }
        Ok(Opacity::Luminance(self.texture_node(id)?))
    }
}
