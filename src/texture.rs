//! Textures: colours that vary over a surface, looked up by `uv` (Mitsuba's `bitmap` and
//! `checkerboard`, or a constant).
//!
//! Conventions follow Mitsuba 3: `to_uv` is the upper-left 3×3 block of the 4×4 transform
//! given in the scene, applied to `(u, v, 1)`; `uv = (0, 0)` is the top-left corner of a
//! bitmap's first row; bilinear lookups interpolate between texel centres at
//! `(i + 0.5) / width`.

use crate::math::{Rgb, luminance};
use glam::{Mat3, Vec2, Vec3};
use std::sync::Arc;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilterType {
    Nearest,
    Bilinear,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WrapMode {
    Repeat,
    Mirror,
    Clamp,
}

/// An image texture in linear RGB.
#[derive(Debug, PartialEq)]
pub struct Bitmap {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<Rgb>,
    pub filter: FilterType,
    pub wrap: WrapMode,
    mean: Rgb,
}

impl Bitmap {
    pub fn new(width: u32, height: u32, texels: Vec<Rgb>, filter: FilterType, wrap: WrapMode) -> Bitmap {
        let n = texels.len().max(1) as f64;
        let sum = texels.iter().fold([0.0f64; 3], |a, t| [a[0] + t.x as f64, a[1] + t.y as f64, a[2] + t.z as f64]);
        let mean = Rgb::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32);
        Bitmap { width, height, texels, filter, wrap, mean }
    }

    /// Mean texel value.
    pub fn mean(&self) -> Rgb {
        self.mean
    }

    fn wrap_index(&self, i: i64, n: u32) -> usize {
        let n = n as i64;
        (match self.wrap {
            WrapMode::Repeat => i.rem_euclid(n),
            WrapMode::Clamp => i.clamp(0, n - 1),
            WrapMode::Mirror => {
                let p = i.rem_euclid(2 * n);
                if p < n { p } else { 2 * n - 1 - p }
            }
        }) as usize
    }

    #[inline]
    fn texel(&self, x: i64, y: i64) -> Rgb {
        self.texels[self.wrap_index(y, self.height) * self.width as usize + self.wrap_index(x, self.width)]
    }

    pub fn eval(&self, uv: Vec2) -> Rgb {
        let p = Vec2::new(uv.x * self.width as f32, uv.y * self.height as f32);
        match self.filter {
            FilterType::Nearest => self.texel(p.x.floor() as i64, p.y.floor() as i64),
            FilterType::Bilinear => {
                let q = p - Vec2::splat(0.5);
                let (x0, y0) = (q.x.floor(), q.y.floor());
                let (fx, fy) = (q.x - x0, q.y - y0);
                let (x0, y0) = (x0 as i64, y0 as i64);
                let a = self.texel(x0, y0) * (1.0 - fx) + self.texel(x0 + 1, y0) * fx;
                let b = self.texel(x0, y0 + 1) * (1.0 - fx) + self.texel(x0 + 1, y0 + 1) * fx;
                a * (1.0 - fy) + b * fy
            }
        }
    }

    /// The gradient `(∂/∂u, ∂/∂v)` of the luminance of [`Bitmap::eval`] at `uv`, where `to_uv`
    /// (its upper-left 2×2 block) maps the surface's `uv` to the bitmap's: the derivative
    /// of the bilinear interpolation that `eval` computes, within the texel cell that
    /// contains `uv` (Mitsuba 3's `eval_1_grad`, which also multiplies the transposed
    /// transform's partials by the resolution last). Zero for nearest-neighbour lookups.
    pub fn luminance_gradient(&self, uv: Vec2, to_uv: &Mat3) -> Vec2 {
        if self.filter == FilterType::Nearest {
            return Vec2::ZERO;
        }
        let uv = apply(to_uv, uv);
        let q = Vec2::new(uv.x * self.width as f32, uv.y * self.height as f32) - Vec2::splat(0.5);
        let (x0, y0) = (q.x.floor(), q.y.floor());
        let (fx, fy) = (q.x - x0, q.y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let f00 = luminance(self.texel(x0, y0));
        let f10 = luminance(self.texel(x0 + 1, y0));
        let f01 = luminance(self.texel(x0, y0 + 1));
        let f11 = luminance(self.texel(x0 + 1, y0 + 1));
        // Partials with respect to the pixel coordinates.
        let dx = (1.0 - fy) * (f10 - f00) + fy * (f11 - f01);
        let dy = (1.0 - fx) * (f01 - f00) + fx * (f11 - f10);
        let m = to_uv;
        let du = m.x_axis.x * dx + m.x_axis.y * dy;
        let dv = m.y_axis.x * dx + m.y_axis.y * dy;
        Vec2::new(self.width as f32 * du, self.height as f32 * dv)
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    Constant(Rgb),
    Bitmap {
        bitmap: Arc<Bitmap>,
        to_uv: Mat3,
    },
    /// `color0` where the fractional parts of u and v are on the same side of ½.
    Checkerboard {
        color0: Rgb,
        color1: Rgb,
        to_uv: Mat3,
    },
}

#[inline]
fn apply(m: &Mat3, uv: Vec2) -> Vec2 {
    let p = *m * Vec3::new(uv.x, uv.y, 1.0);
    Vec2::new(p.x, p.y)
}

impl Texture {
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Bitmap { bitmap, to_uv } => bitmap.eval(apply(to_uv, uv)),
            Texture::Checkerboard { color0, color1, to_uv } => {
                let t = apply(to_uv, uv);
                let f = t - t.floor();
                if (f.x > 0.5) == (f.y > 0.5) { *color0 } else { *color1 }
            }
        }
    }

    /// The gradient of the texture's luminance with respect to the surface's `uv` (see
    /// [`Bitmap::luminance_gradient`]); zero for a constant. `None` for a checkerboard, whose
    /// gradient is zero except on its edges, where it does not exist (Mitsuba 3 has none).
    pub fn luminance_gradient(&self, uv: Vec2) -> Option<Vec2> {
        match self {
            Texture::Constant(_) => Some(Vec2::ZERO),
            Texture::Bitmap { bitmap, to_uv } => Some(bitmap.luminance_gradient(uv, to_uv)),
            Texture::Checkerboard { .. } => None,
        }
    }

    /// The mean value over the texture (for light power and sampling weights).
    pub fn mean(&self) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Bitmap { bitmap, .. } => bitmap.mean(),
            Texture::Checkerboard { color0, color1, .. } => (*color0 + *color1) * 0.5,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bm(filter: FilterType, wrap: WrapMode) -> Bitmap {
        Bitmap::new(2, 2, vec![Rgb::splat(0.0), Rgb::splat(1.0), Rgb::splat(2.0), Rgb::splat(3.0)], filter, wrap)
    }

    #[test]
    fn bilinear_hits_texel_centres_and_interpolates() {
        let b = bm(FilterType::Bilinear, WrapMode::Clamp);
        assert_eq!(b.eval(Vec2::new(0.25, 0.25)), Rgb::splat(0.0));
        assert_eq!(b.eval(Vec2::new(0.75, 0.75)), Rgb::splat(3.0));
        assert!((b.eval(Vec2::new(0.5, 0.25)).x - 0.5).abs() < 1e-6);
        assert!((b.eval(Vec2::new(0.5, 0.5)).x - 1.5).abs() < 1e-6);
        let r = bm(FilterType::Bilinear, WrapMode::Repeat);
        // Between the last and (wrapped) first column.
        assert!((r.eval(Vec2::new(1.0, 0.25)).x - 0.5).abs() < 1e-6);
        assert_eq!(bm(FilterType::Nearest, WrapMode::Repeat).eval(Vec2::new(1.3, -0.2)), Rgb::splat(2.0));
        assert_eq!(bm(FilterType::Nearest, WrapMode::Mirror).eval(Vec2::new(1.3, 0.2)), Rgb::splat(1.0));
    }

    #[test]
    fn checkerboard_alternates() {
        let t = Texture::Checkerboard {
            color0: Rgb::ONE,
            color1: Rgb::ZERO,
            to_uv: Mat3::from_diagonal(Vec3::new(2.0, 2.0, 1.0)),
        };
        assert_eq!(t.eval(Vec2::new(0.1, 0.1)), Rgb::ONE);
        assert_eq!(t.eval(Vec2::new(0.3, 0.1)), Rgb::ZERO);
        assert_eq!(t.eval(Vec2::new(0.3, 0.3)), Rgb::ONE);
        assert_eq!(t.mean(), Rgb::splat(0.5));
    }
}
