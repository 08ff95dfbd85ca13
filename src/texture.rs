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
    texels: Texels,
    pub filter: FilterType,
    pub wrap: WrapMode,
    mean: Rgb,
}

/// Side of the square blocks 8-bit texels are stored in: a 4×4 block of 4-byte texels is one
/// 64-byte cache line, so most bilinear footprints touch one line instead of two rows.
const BLOCK: usize = 4;

/// How the texels are stored. Textures read from 8-bit files (most JPEG and PNG) hold
/// linear values that are exactly `table[k]` for `k` in 0..=255 (sRGB-decoded or raw); they
/// keep the byte and look the value up, bit for bit what the `f32` would be, in a quarter of
/// the memory and in cache-line blocks: on real scenes texture lookups are cache misses.
#[derive(Debug, PartialEq)]
enum Texels {
    Float(Vec<Rgb>),
    Byte { blocks: Vec<[u8; 4]>, table: Box<[f32; 256]>, blocks_per_row: usize },
}

/// The linear values an 8-bit channel decodes to: sRGB-decoded, then raw (`k / 255`).
fn byte_tables() -> [Box<[f32; 256]>; 2] {
    let rgb8 = image::ColorType::Rgb8;
    [crate::image_io::byte_table(rgb8, true), crate::image_io::byte_table(rgb8, false)]
}

/// The byte whose table value is exactly `v`, if there is one (the table is increasing).
fn table_index(table: &[f32; 256], v: f32) -> Option<u8> {
    let k = table.partition_point(|&t| t < v);
    (k < 256 && table[k].to_bits() == v.to_bits()).then_some(k as u8)
}

impl Texels {
    fn new(width: usize, height: usize, texels: Vec<Rgb>) -> Texels {
        for table in byte_tables() {
            let bytes: Option<Vec<[u8; 4]>> = texels
                .iter()
                .map(|t| Some([table_index(&table, t.x)?, table_index(&table, t.y)?, table_index(&table, t.z)?, 0]))
                .collect();
            if let Some(bytes) = bytes {
                return Texels::blocks(width, height, |i| bytes[i], table);
            }
        }
        Texels::Float(texels)
    }

    /// The bytes `texel(i)` of texel `i` (row-major) laid out in blocks, standing for
    /// `table`'s values.
    fn blocks(width: usize, height: usize, texel: impl Fn(usize) -> [u8; 4], table: Box<[f32; 256]>) -> Texels {
        let blocks_per_row = width.div_ceil(BLOCK);
        let mut blocks = vec![[0u8; 4]; blocks_per_row * height.div_ceil(BLOCK) * BLOCK * BLOCK];
        for y in 0..height {
            for x in 0..width {
                blocks[block_index(blocks_per_row, x, y)] = texel(y * width + x);
            }
        }
        Texels::Byte { blocks, table, blocks_per_row }
    }
}

#[inline]
fn block_index(blocks_per_row: usize, x: usize, y: usize) -> usize {
    ((y / BLOCK) * blocks_per_row + x / BLOCK) * (BLOCK * BLOCK) + (y % BLOCK) * BLOCK + x % BLOCK
}

impl Bitmap {
    /// A bitmap of `width × height` texels given row by row from the top.
    pub fn new(width: u32, height: u32, texels: Vec<Rgb>, filter: FilterType, wrap: WrapMode) -> Bitmap {
        let n = texels.len().max(1) as f64;
        let sum = texels.iter().fold([0.0f64; 3], |a, t| [a[0] + t.x as f64, a[1] + t.y as f64, a[2] + t.z as f64]);
        let mean = Rgb::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32);
        let texels = Texels::new(width as usize, height as usize, texels);
        Bitmap { width, height, texels, filter, wrap, mean }
    }

    /// A bitmap of 8-bit texels, three bytes each (row by row from the top), byte `k`
    /// standing for `table[k]`: the bitmap of those values (as [`Bitmap::new`] keeps them,
    /// or kept as bytes where it would keep them as `f32`), without a pass over them in `f32`.
    pub fn from_bytes(
        width: u32,
        height: u32,
        rgb: &[u8],
        table: Box<[f32; 256]>,
        filter: FilterType,
        wrap: WrapMode,
    ) -> Bitmap {
        assert_eq!(rgb.len(), 3 * width as usize * height as usize, "byte count does not match the size");
        // Summed in texel order, as `Bitmap::new` sums: the same mean to the last bit.
        let mut sum = [0.0f64; 3];
        for c in rgb.chunks_exact(3) {
            for i in 0..3 {
                sum[i] += table[c[i] as usize] as f64;
            }
        }
        let n = (width as usize * height as usize).max(1) as f64;
        let mean = Rgb::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32);
        let texel = |i: usize| [rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2], 0];
        let texels = Texels::blocks(width as usize, height as usize, texel, table);
        Bitmap { width, height, texels, filter, wrap, mean }
    }

    /// Mean texel value.
    pub fn mean(&self) -> Rgb {
        self.mean
    }

    /// The texel in column `x`, row `y` (from the top); both within the bitmap.
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> Rgb {
        self.fetch(x as usize, y as usize)
    }

    /// Every texel, row by row from the top.
    pub fn texels(&self) -> impl Iterator<Item = Rgb> + '_ {
        (0..self.height).flat_map(move |y| (0..self.width).map(move |x| self.get(x, y)))
    }

    /// Whether the texels are kept as bytes (see [`Texels`]).
    pub fn is_compact(&self) -> bool {
        matches!(self.texels, Texels::Byte { .. })
    }

    /// The texel at integer coordinates `(x, y)`, wrapped as the bitmap's wrap mode says.
    #[inline]
    fn texel(&self, x: i64, y: i64) -> Rgb {
        self.fetch(wrap_index(self.wrap, x, self.width), wrap_index(self.wrap, y, self.height))
    }

    #[inline]
    fn fetch(&self, x: usize, y: usize) -> Rgb {
        match &self.texels {
            Texels::Float(t) => t[y * self.width as usize + x],
            Texels::Byte { blocks, table, blocks_per_row } => {
                let [r, g, b, _] = blocks[block_index(*blocks_per_row, x, y)];
                Rgb::new(table[r as usize], table[g as usize], table[b as usize])
            }
        }
    }

    pub fn eval(&self, uv: Vec2) -> Rgb {
        lookup(self.width, self.height, self.filter, self.wrap, |x, y| self.fetch(x, y), uv)
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
        lookup(self.width, self.height, self.filter, self.wrap, |x, y| self.texels[y * self.width as usize + x], uv)
    }
}

/// Index `i` of a row or column of `n` texels wrapped into `0..n` (inside already: as it is,
/// without a division).
#[inline]
fn wrap_index(wrap: WrapMode, i: i64, n: u32) -> usize {
    if (i as u64) < n as u64 {
        return i as usize;
    }
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

/// A nearest or bilinear lookup at `uv` of a `width × height` image whose texel in column
/// `x`, row `y` (both inside) `fetch` reads: what colour bitmaps (bytes or floats) and alpha
/// bitmaps share.
#[inline]
fn lookup<T>(
    width: u32,
    height: u32,
    filter: FilterType,
    wrap: WrapMode,
    fetch: impl Fn(usize, usize) -> T,
    uv: Vec2,
) -> T
where
    T: Copy + std::ops::Mul<f32, Output = T> + std::ops::Add<Output = T>,
{
    let p = Vec2::new(uv.x * width as f32, uv.y * height as f32);
    match filter {
        FilterType::Nearest => {
            fetch(wrap_index(wrap, p.x.floor() as i64, width), wrap_index(wrap, p.y.floor() as i64, height))
        }
        FilterType::Bilinear => {
            let q = p - Vec2::splat(0.5);
            let (x0, y0) = (q.x.floor(), q.y.floor());
            let (fx, fy) = (q.x - x0, q.y - y0);
            let (x0, y0) = (x0 as i64, y0 as i64);
            let (xa, xb) = (wrap_index(wrap, x0, width), wrap_index(wrap, x0 + 1, width));
            let (ya, yb) = (wrap_index(wrap, y0, height), wrap_index(wrap, y0 + 1, height));
            let a = fetch(xa, ya) * (1.0 - fx) + fetch(xb, ya) * fx;
            let b = fetch(xa, yb) * (1.0 - fx) + fetch(xb, yb) * fx;
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

    /// Every value the texture takes: a constant's, a bitmap's texels, a checkerboard's two
    /// colours.
    pub fn values(&self) -> Box<dyn Iterator<Item = Rgb> + '_> {
        match self {
            Texture::Constant(c) => Box::new(std::iter::once(*c)),
            Texture::Bitmap { bitmap, .. } => Box::new(bitmap.texels()),
            Texture::Checkerboard { color0, color1, .. } => Box::new([*color0, *color1].into_iter()),
        }
    }

    /// The component-wise maximum over the texture (every texel of a bitmap; as Mitsuba
    /// 0.6's `getMaximum`, which BSDFs compare against 1 to keep energy).
    pub fn max(&self) -> Rgb {
        self.values().fold(Rgb::splat(f32::NEG_INFINITY), Rgb::max)
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

    /// 8-bit texels (sRGB-decoded or raw) are kept as bytes and read back bit for bit, in
    /// blocks, whatever the bitmap's size; other values stay `f32`.
    #[test]
    fn byte_texels_read_back_exactly() {
        let srgb = |k: u32| crate::image_io::srgb_to_linear(k as f32 / 255.0);
        for (w, h) in [(1, 1), (5, 3), (7, 9), (16, 4)] {
            for decode in [&srgb as &dyn Fn(u32) -> f32, &|k: u32| k as f32 / 255.0] {
                let texels: Vec<Rgb> = (0..w * h)
                    .map(|i| Rgb::new(decode(i * 37 % 256), decode(i * 11 % 256), decode(255 - i % 256)))
                    .collect();
                let b = Bitmap::new(w, h, texels.clone(), FilterType::Nearest, WrapMode::Clamp);
                assert!(b.is_compact(), "{w}x{h}");
                assert_eq!(b.texels().collect::<Vec<_>>(), texels);
                for y in 0..h {
                    for x in 0..w {
                        let uv = Vec2::new((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                        assert_eq!(
                            b.eval(uv).to_array().map(f32::to_bits),
                            texels[(y * w + x) as usize].to_array().map(f32::to_bits)
                        );
                    }
                }
            }
        }
        // One value off the table (and one negative) keeps the texels as they are.
        for odd in [srgb(200) + 1e-6, -0.5] {
            let texels = vec![Rgb::new(srgb(3), odd, 0.0), Rgb::ZERO];
            let b = Bitmap::new(2, 1, texels.clone(), FilterType::Nearest, WrapMode::Clamp);
            assert!(!b.is_compact());
            assert_eq!(b.texels().collect::<Vec<_>>(), texels);
        }
    }

    /// What the image readers return for 8-bit files is on the tables: a JPEG (sRGB-decoded
    /// and raw) is kept as bytes, and the bitmap made from its bytes is the bitmap made from
    /// its linear values.
    #[test]
    fn eight_bit_files_are_kept_as_bytes() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/staircase2/textures/Wallpaper.jpg");
        for raw in [false, true] {
            let img = crate::image_io::read_texture(&path, raw).unwrap();
            let b = Bitmap::new(img.width, img.height, img.pixels.clone(), FilterType::Bilinear, WrapMode::Repeat);
            assert!(b.is_compact(), "raw = {raw}");
            assert!(b.texels().eq(img.pixels.iter().copied()));
            let crate::image_io::TextureData::Bytes { width, height, rgb, table } =
                crate::image_io::read_texture_data(&path, raw).unwrap()
            else {
                panic!("a JPEG's texels are bytes")
            };
            let from_bytes = Bitmap::from_bytes(width, height, &rgb, table, FilterType::Bilinear, WrapMode::Repeat);
            // Raw texels all on the sRGB table too would have picked that table: not here.
            assert_eq!(from_bytes, b, "raw = {raw}");
        }
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
