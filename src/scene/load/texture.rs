//! Textures of a scene: a colour property given as a value or a nested texture, the
//! `bitmap` and `checkerboard` plugins, and the bitmaps read from image files (taken from
//! the files read ahead, `load/prefetch.rs`, where they are there).

use super::{Builder, non_negative_rgb};
use crate::error::{Error, Result};
use crate::image_io::TextureData;
use crate::scene::xml::NodeId;
use crate::texture::{Bitmap, FilterType, Texture, WrapMode};
use glam::{Mat3, Mat4, Vec3};
use std::path::{Path, PathBuf};
use std::sync::Arc;

impl Builder<'_> {
    /// A colour property that Mitsuba would also accept as a texture.
    pub(super) fn texture_prop(&mut self, id: NodeId, name: &str, default: Vec3) -> Result<Texture> {
        let node = self.node(id);
        let nested: Vec<NodeId> = node
            .children
            .iter()
            .filter(|c| c.name.as_deref() == Some(name) && self.node(c.node).tag == "texture")
            .map(|c| {
                c.used.set(true);
                c.node
            })
            .collect();
        match (node.rgb(name)?, nested.as_slice()) {
            (Some(_), [t, ..]) => {
                Err(Error::input(&self.node(*t).loc, format!("\"{name}\" is given both as a value and as a texture")))
            }
            (Some(v), []) => Ok(Texture::Constant(non_negative_rgb(node, name, v)?)),
            (None, []) => Ok(Texture::Constant(default)),
            (None, [t]) => self.texture_node(*t),
            (None, [_, t, ..]) => Err(Error::input(&self.node(*t).loc, format!("\"{name}\" is given twice"))),
        }
    }

    /// The bitmap in the image file `path` (read ahead, or read now).
    pub(super) fn load_bitmap(&mut self, path: &Path, raw: bool, filter: FilterType, wrap: WrapMode) -> Result<Bitmap> {
        let mut bitmap = match self.prefetched.take_texture(path, raw) {
            Some(bitmap) => bitmap?,
            None => read_bitmap(path, raw)?,
        };
        bitmap.filter = filter;
        bitmap.wrap = wrap;
        Ok(bitmap)
    }

    pub(super) fn texture_node(&mut self, id: NodeId) -> Result<Texture> {
        if let Some(t) = self.textures.get(&id) {
            return Ok(t.clone());
        }
        let node = self.doc.node(id);
        let to_uv = Mat3::from_mat4(node.transform("to_uv")?.unwrap_or(Mat4::IDENTITY));
        let t = match node.plugin.as_str() {
            "bitmap" => {
                let (path, filter, wrap) = self.bitmap_params(id)?;
                let raw = node.boolean_or("raw", false)?;
                let bitmap = self
                    .load_bitmap(&path, raw, filter, wrap)
                    .map_err(|e| Error::input(&node.prop_loc("filename"), e.to_string()))?;
                self.stats.files.push(path.clone());
                Texture::Bitmap { bitmap: Arc::new(bitmap), to_uv }
            }
            "checkerboard" => {
                let color0 = non_negative_rgb(node, "color0", node.rgb("color0")?.unwrap_or(Vec3::splat(0.4)))?;
                let color1 = non_negative_rgb(node, "color1", node.rgb("color1")?.unwrap_or(Vec3::splat(0.2)))?;
                Texture::Checkerboard { color0, color1, to_uv }
            }
            _ => return Err(self.unknown_plugin(id, &["bitmap", "checkerboard"])),
        };
        self.check_unused(id)?;
        self.textures.insert(id, t.clone());
        Ok(t)
    }

    /// A `bitmap` texture's file, filter and wrap mode.
    pub(super) fn bitmap_params(&mut self, id: NodeId) -> Result<(PathBuf, FilterType, WrapMode)> {
        let node = self.doc.node(id);
        let path = self.resolve_path(node, "filename")?;
        let filter = match node.string("filter_type")?.unwrap_or("bilinear") {
            "bilinear" => FilterType::Bilinear,
            "nearest" => FilterType::Nearest,
            // Mitsuba 0.6's mip-mapped filters: bilinear lookups of the full-resolution
            // image (README, "Mitsuba 0.5/0.6 scenes").
            f @ ("trilinear" | "ewa") => {
                self.read_as_bilinear.push((f.to_string(), node.prop_loc("filter_type")));
                FilterType::Bilinear
            }
            f => {
                return Err(Error::input(
                    &node.prop_loc("filter_type"),
                    format!("unknown filter_type \"{f}\" (bilinear, nearest; trilinear and ewa are read as bilinear)"),
                ));
            }
        };
        let wrap = match node.string("wrap_mode")?.unwrap_or("repeat") {
            "repeat" => WrapMode::Repeat,
            "mirror" => WrapMode::Mirror,
            "clamp" => WrapMode::Clamp,
            w => {
                return Err(Error::input(
                    &node.prop_loc("wrap_mode"),
                    format!("unknown wrap_mode \"{w}\" (repeat, mirror, clamp)"),
                ));
            }
        };
        Ok((path, filter, wrap))
    }
}

/// The bitmap in the image file `path` (bilinear, repeating; the caller sets both): 8-bit
/// PNG/JPEG/TGA/BMP decoded from sRGB unless `raw` and kept as bytes, EXR and HDR as
/// linear; with `--features oiio`, every format OpenImageIO reads (see [`crate::image_io`]).
pub(super) fn read_bitmap(path: &Path, raw: bool) -> Result<Bitmap> {
    if !path.is_file() {
        return Err(Error::in_file(path, "texture file does not exist"));
    }
    let data = crate::image_io::read_texture_data(path, raw)?;
    if data.width() == 0 || data.height() == 0 {
        return Err(Error::in_file(path, "texture has no pixels"));
    }
    let (filter, wrap) = (FilterType::Bilinear, WrapMode::Repeat);
    Ok(match data {
        TextureData::Bytes { width, height, rgb, table } => {
            Bitmap::from_bytes(width, height, &rgb, table, filter, wrap)
        }
        TextureData::Linear(img) => Bitmap::new(img.width, img.height, img.pixels, filter, wrap),
    })
}
