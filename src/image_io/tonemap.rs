//! Tonemapping to 8-bit images as Mitsuba 0.5/0.6's `ldrfilm` does it: an exposure in
//! f-stops (`gamma` method) or Reinhard et al.'s photographic operator (`reinhard`: the
//! log-average luminance mapped to `key`, highlights compressed so that the brightest pixel,
//! scaled by the `burn` knob, is white), then the sRGB curve or a power-law gamma, and
//! rounding to 8 bits. A linear EXR is the same image before any of this.

use crate::image_io::Image;
use crate::math::Rgb;

/// How linear radiance becomes displayable values in `[0, 1]` before the transfer curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tonemap {
    /// Multiply by `2^exposure`.
    Exposure(f32),
    /// Reinhard et al. 2002 on the image's luminance: `key` in `(0, 1]` is the value the
    /// log-average luminance maps to, `burn` in `[0, 1]` how far highlights may burn out.
    Reinhard { key: f32, burn: f32 },
}

/// The transfer curve from display-linear values to the 8-bit code values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Transfer {
    /// The sRGB curve (Mitsuba's `gamma = -1`).
    Srgb,
    /// `v^(1/gamma)`.
    Gamma(f32),
}

impl Transfer {
    /// Mitsuba's `gamma` property: -1 is sRGB, a positive value a power law.
    pub fn from_gamma(gamma: f32) -> Option<Transfer> {
        if gamma == -1.0 {
            Some(Transfer::Srgb)
        } else if gamma > 0.0 && gamma.is_finite() {
            Some(Transfer::Gamma(gamma))
        } else {
            None
        }
    }

    /// The curve's value at the display-linear `v` (clamped to `[0, 1]`).
    #[inline]
    pub fn encode(self, v: f32) -> f32 {
        match self {
            Transfer::Srgb => crate::image_io::linear_to_srgb(v),
            Transfer::Gamma(g) => v.clamp(0.0, 1.0).powf(1.0 / g),
        }
    }
}

/// An 8-bit output as a low-dynamic-range film describes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ldr {
    pub tonemap: Tonemap,
    pub transfer: Transfer,
}

impl Default for Ldr {
    /// What a PNG of a scene without an `ldrfilm` gets: the sRGB curve, no exposure change.
    fn default() -> Ldr {
        Ldr { tonemap: Tonemap::Exposure(0.0), transfer: Transfer::Srgb }
    }
}

/// Rec. 709 linear RGB to CIE XYZ and back (D65), the matrices Mitsuba's tonemapper uses
/// (their digits as published, beyond what an `f32` holds).
#[allow(clippy::excessive_precision)]
const RGB_TO_XYZ: [[f32; 3]; 3] =
    [[0.412453, 0.357580, 0.180423], [0.212671, 0.715160, 0.072169], [0.019334, 0.119193, 0.950227]];
#[allow(clippy::excessive_precision)]
const XYZ_TO_RGB: [[f32; 3]; 3] =
    [[3.240479, -1.537150, -0.498535], [-0.969256, 1.875991, 0.041556], [0.055648, -0.204043, 1.057311]];

fn mul(m: &[[f32; 3]; 3], v: [f32; 3]) -> [f32; 3] {
    m.map(|row| row[0] * v[0] + row[1] * v[1] + row[2] * v[2])
}

/// Rec. 709 luminance.
#[inline]
fn luminance(p: Rgb) -> f32 {
    mul(&RGB_TO_XYZ, p.to_array())[1]
}

impl Ldr {
    /// The image as 8-bit RGB code values, row by row: the tonemap, the transfer curve, and
    /// rounding to the nearest code.
    pub fn encode8(&self, image: &Image) -> Vec<u8> {
        let code = |v: f32| (self.transfer.encode(v) * 255.0 + 0.5) as u8;
        match self.tonemap {
            Tonemap::Exposure(stops) => {
                let m = 2f32.powf(stops);
                image.pixels.iter().flat_map(|p| (*p * m).to_array()).map(code).collect()
            }
            Tonemap::Reinhard { key, burn } => {
                reinhard(&image.pixels, key, burn).iter().flat_map(|p| p.to_array()).map(code).collect()
            }
        }
    }
}

/// Reinhard et al.'s operator on the luminance `Y` of each pixel, its chromaticity kept:
/// `L = Y key / Ȳ` with `Ȳ` the log-average luminance (`exp(mean(ln(10⁻³ + Y)))`), then
/// `L (1 + L / L_w²) / (1 + L)` with the white point `L_w` the brightest pixel's `L` times
/// `(1 - burn)²` (burn clamped to `[0, 1)`). A black image stays black.
fn reinhard(pixels: &[Rgb], key: f32, burn: f32) -> Vec<Rgb> {
    let (mut max, mut log_sum) = (0.0f32, 0.0f64);
    for p in pixels {
        let y = luminance(*p);
        max = max.max(y);
        log_sum += ((1e-3 + y) as f64).ln();
    }
    if max <= 0.0 || pixels.is_empty() {
        return pixels.to_vec();
    }
    let log_average = (log_sum / pixels.len() as f64).exp() as f32;
    let burn = (1.0 - burn).clamp(1e-8, 1.0);
    let scale = key / log_average;
    let white = max * scale;
    let inv_white2 = 1.0 / (white * white * burn.powi(4));
    pixels
        .iter()
        .map(|p| {
            let [x, y, z] = mul(&RGB_TO_XYZ, p.to_array());
            let sum = x + y + z;
            if sum <= 0.0 || sum.is_nan() {
                return Rgb::ZERO;
            }
            let (cx, cy) = (x / sum, y / sum);
            let l = y * scale;
            let mapped = l * (1.0 + l * inv_white2) / (1.0 + l);
            let ratio = mapped / cy;
            Rgb::from_array(mul(&XYZ_TO_RGB, [ratio * cx, mapped, ratio * (1.0 - cx - cy)]))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(pixels: Vec<Rgb>) -> Image {
        Image::new(pixels.len() as u32, 1, pixels)
    }

    #[test]
    fn the_default_is_the_srgb_curve_rounded_to_8_bits() {
        let img = image((0..64).map(|i| Rgb::splat(i as f32 / 40.0) * Rgb::new(1.0, 0.5, 0.25)).collect());
        let srgb = |v: f32| {
            let v = v.clamp(0.0, 1.0);
            let e = if v <= 0.003_130_8 { 12.92 * v } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
            (e * 255.0 + 0.5) as u8
        };
        let want: Vec<u8> = img.pixels.iter().flat_map(|p| p.to_array()).map(srgb).collect();
        assert_eq!(Ldr::default().encode8(&img), want);
    }

    #[test]
    fn exposure_is_in_stops_and_gamma_a_power_law() {
        let img = image(vec![Rgb::splat(0.125)]);
        let ldr = Ldr { tonemap: Tonemap::Exposure(2.0), transfer: Transfer::Gamma(2.0) };
        // 0.125 × 4 = 0.5; 0.5^(1/2) = 0.7071 → 180.8.
        assert_eq!(ldr.encode8(&img), vec![180, 180, 180]);
    }

    #[test]
    fn reinhard_maps_the_log_average_to_the_key_and_keeps_the_chromaticity() {
        // A uniform image: its log-average is its luminance (up to the 10⁻³ offset), so every
        // pixel maps to key (1 + key / L_w²) / (1 + key) with L_w = key.
        let grey = Rgb::splat(3.0);
        let out = reinhard(&[grey; 4], 0.18, 0.0);
        let l = 0.18 * 3.0 / (1e-3f32 + 3.0);
        let want = l * (1.0 + l / (l * l)) / (1.0 + l);
        for p in &out {
            assert!((luminance(*p) - want).abs() < 1e-3, "{p:?} against {want}");
            assert!((p.x - p.y).abs() < 1e-4 && (p.y - p.z).abs() < 1e-4, "grey stays grey: {p:?}");
        }
        // A coloured pixel keeps its chromaticity.
        let c = Rgb::new(2.0, 1.0, 0.5);
        let out = reinhard(&[c, Rgb::splat(0.1)], 0.3, 0.2);
        let xyz = |p: Rgb| mul(&RGB_TO_XYZ, p.to_array());
        let (a, b) = (xyz(c), xyz(out[0]));
        let chroma = |v: [f32; 3]| [v[0] / (v[0] + v[1] + v[2]), v[1] / (v[0] + v[1] + v[2])];
        let (ca, cb) = (chroma(a), chroma(b));
        assert!((ca[0] - cb[0]).abs() < 1e-4 && (ca[1] - cb[1]).abs() < 1e-4, "{ca:?} against {cb:?}");
        // Black stays black.
        assert_eq!(reinhard(&[Rgb::ZERO; 3], 0.18, 0.0), vec![Rgb::ZERO; 3]);
    }

    #[test]
    fn mitsubas_gamma_property() {
        assert_eq!(Transfer::from_gamma(-1.0), Some(Transfer::Srgb));
        assert_eq!(Transfer::from_gamma(2.2), Some(Transfer::Gamma(2.2)));
        assert_eq!(Transfer::from_gamma(0.0), None);
        assert_eq!(Transfer::from_gamma(-2.0), None);
    }
}
