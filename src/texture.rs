//! Textures: colours that vary over a surface, looked up by `uv` (Mitsuba's `bitmap` and
//! `checkerboard`, or a constant).
//!
//! Conventions follow Mitsuba 3: `to_uv` is the upper-left 3×3 block of the 4×4 transform
//! given in the scene, applied to `(u, v, 1)`; `uv = (0, 0)` is the top-left corner of a
//! bitmap's first row; bilinear lookups interpolate between texel centres at
//! `(i + 0.5) / width`.

use crate::math::Rgb;
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

    pub fn eval(&self, uv: Vec2) -> Rgb {
        lookup(self.width, self.height, self.filter, self.wrap, &self.texels, uv)
    }
}

/// A bitmap's alpha channel (a `mask`'s opacity), as stored: alpha is linear.
#[derive(Debug, PartialEq)]
pub struct AlphaBitmap {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<f32>,
    pub filter: FilterType,
    pub wrap: WrapMode,
}

impl AlphaBitmap {
    pub fn eval(&self, uv: Vec2) -> f32 {
        lookup(self.width, self.height, self.filter, self.wrap, &self.texels, uv)
    }
}

fn wrap_index(wrap: WrapMode, i: i64, n: u32) -> usize {
    let n = n as i64;
    (match wrap {
        WrapMode::Repeat => i.rem_euclid(n),
        WrapMode::Clamp => i.clamp(0, n - 1),
        WrapMode::Mirror => {
            let p = i.rem_euclid(2 * n);
            if p < n { p } else { 2 * n - 1 - p }
        }
    }) as usize
}

/// A nearest or bilinear lookup of a `width × height` image of texels `T` at `uv`.
#[inline]
fn lookup<T>(width: u32, height: u32, filter: FilterType, wrap: WrapMode, texels: &[T], uv: Vec2) -> T
where
    T: Copy + std::ops::Mul<f32, Output = T> + std::ops::Add<Output = T>,
{
    let texel = |x: i64, y: i64| texels[wrap_index(wrap, y, height) * width as usize + wrap_index(wrap, x, width)];
    let p = Vec2::new(uv.x * width as f32, uv.y * height as f32);
    match filter {
        FilterType::Nearest => texel(p.x.floor() as i64, p.y.floor() as i64),
        FilterType::Bilinear => {
            let q = p - Vec2::splat(0.5);
            let (x0, y0) = (q.x.floor(), q.y.floor());
            let (fx, fy) = (q.x - x0, q.y - y0);
            let (x0, y0) = (x0 as i64, y0 as i64);
            let a = texel(x0, y0) * (1.0 - fx) + texel(x0 + 1, y0) * fx;
            let b = texel(x0, y0 + 1) * (1.0 - fx) + texel(x0 + 1, y0 + 1) * fx;
            a * (1.0 - fy) + b * fy
        }
    }
}

/// The opacity of a `mask` BSDF, a value in `[0, 1]` over the surface: a constant, the alpha
/// channel of a bitmap that has one, or else the luminance of a colour texture (Mitsuba 3's
/// scalar lookup of a colour texture). Values outside `[0, 1]` are clamped.
#[derive(Clone, Debug, PartialEq)]
pub enum Opacity {
    Constant(f32),
    Alpha { bitmap: Arc<AlphaBitmap>, to_uv: Mat3 },
    Luminance(Texture),
}

impl Opacity {
    #[inline]
    pub fn eval(&self, uv: Vec2) -> f32 {
        let a = match self {
            Opacity::Constant(a) => *a,
            Opacity::Alpha { bitmap, to_uv } => bitmap.eval(apply(to_uv, uv)),
            Opacity::Luminance(t) => crate::math::luminance(t.eval(uv)),
        };
        a.clamp(0.0, 1.0)
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
    fn opacity_is_alpha_luminance_or_a_constant_clamped_to_one() {
        let bitmap = AlphaBitmap {
            width: 2,
            height: 1,
            texels: vec![0.0, 1.0],
            filter: FilterType::Nearest,
            wrap: WrapMode::Clamp,
        };
        let alpha = Opacity::Alpha { bitmap: Arc::new(bitmap), to_uv: Mat3::IDENTITY };
        assert_eq!((alpha.eval(Vec2::new(0.25, 0.5)), alpha.eval(Vec2::new(0.75, 0.5))), (0.0, 1.0));
        // Mitsuba 3's scalar lookup of a colour: its luminance.
        let red = Opacity::Luminance(Texture::Constant(Rgb::new(1.0, 0.0, 0.0)));
        assert!((red.eval(Vec2::ZERO) - 0.212671).abs() < 1e-5);
        assert_eq!(Opacity::Luminance(Texture::Constant(Rgb::splat(3.0))).eval(Vec2::ZERO), 1.0);
        assert_eq!(Opacity::Constant(0.3).eval(Vec2::ZERO), 0.3);
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
