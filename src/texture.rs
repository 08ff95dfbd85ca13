//! Textures: spatially varying colours looked up by surface `uv`.

use crate::math::Rgb;
use glam::Vec2;

/// A colour-valued texture. Plugins beyond a constant arrive with the materials work;
/// every BSDF parameter that Mitsuba accepts as a texture is a `Texture` here.
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    Constant(Rgb),
}

impl Texture {
    #[inline]
    pub fn eval(&self, _uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
        }
    }

    /// The mean value over the texture (for light power estimates).
    pub fn mean(&self) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
        }
    }
}
