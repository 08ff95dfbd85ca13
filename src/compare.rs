//! Image comparison metrics.
//!
//! relMSE is defined once, here: per channel `(t - r)² / (r² + 0.01)`, averaged over all
//! pixels and channels (the 0.01 keeps black reference pixels from dominating).

use crate::error::{Error, Result};
use crate::image_io::Image;
use serde::Serialize;

/// Errors of a test image against a reference.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Metrics {
    pub mse: f64,
    pub relmse: f64,
    /// `mean(test) / mean(reference)`.
    pub mean_ratio: f64,
    pub reference_mean: f64,
    pub test_mean: f64,
    /// Pixels of the test image that are NaN or infinite (left out of the sums).
    pub non_finite: usize,
}

pub fn check_same_size(a: &Image, b: &Image) -> Result<()> {
    if a.width != b.width || a.height != b.height {
        return Err(Error::Usage(format!("image sizes differ: {}×{} vs {}×{}", a.width, a.height, b.width, b.height)));
    }
    Ok(())
}

/// The `0.01` of relMSE's denominator.
pub const RELMSE_EPSILON: f64 = 0.01;

/// Per-channel relative squared error of one value.
#[inline]
pub fn relmse_term(t: f32, r: f32) -> f64 {
    relative_square(t as f64 - r as f64, r)
}

/// A difference `d` squared relative to the reference value `r`, as relMSE weighs it.
#[inline]
pub fn relative_square(d: f64, r: f32) -> f64 {
    let r = r as f64;
    d * d / (r * r + RELMSE_EPSILON)
}

pub fn metrics(reference: &Image, test: &Image) -> Result<Metrics> {
    check_same_size(reference, test)?;
    let (mut mse, mut rel, mut n, mut bad) = (0.0f64, 0.0f64, 0usize, 0usize);
    for (r, t) in reference.pixels.iter().zip(&test.pixels) {
        if !t.is_finite() {
            bad += 1;
            continue;
        }
        for c in 0..3 {
            let d = (t[c] - r[c]) as f64;
            mse += d * d;
            rel += relmse_term(t[c], r[c]);
        }
        n += 3;
    }
    let n = n.max(1) as f64;
    let (rm, tm) = (reference.mean(), test.mean());
    Ok(Metrics {
        mse: mse / n,
        relmse: rel / n,
        mean_ratio: tm / rm,
        reference_mean: rm,
        test_mean: tm,
        non_finite: bad,
    })
}

/// The metrics `compare` and experiments can report.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Metric {
    /// Relative MSE (defined above).
    Relmse,
    /// Mean squared error.
    Mse,
    /// NVIDIA's FLIP (LDR): both images sRGB-encoded, clamped to [0, 1], 67 pixels per degree.
    Flip,
}

/// The `[x, y, width, height]` part of an image.
pub fn crop(img: &Image, c: [u32; 4]) -> Result<Image> {
    let [x, y, w, h] = c;
    if w == 0
        || h == 0
        || x.checked_add(w).is_none_or(|e| e > img.width)
        || y.checked_add(h).is_none_or(|e| e > img.height)
    {
        return Err(Error::Usage(format!("crop {x},{y},{w},{h} is not inside the {}×{} image", img.width, img.height)));
    }
    let pixels = (y..y + h)
        .flat_map(|j| (x..x + w).map(move |i| (i, j)))
        .map(|(i, j)| img.pixels[(j * img.width + i) as usize])
        .collect();
    Ok(Image::new(w, h, pixels))
}

/// A mask image: pixels whose brightest channel exceeds 0.5 are kept.
pub fn mask(img: &Image) -> Vec<bool> {
    img.pixels.iter().map(|p| p.max_element() > 0.5).collect()
}

/// [`metrics`] over the pixels `keep` marks (all when `None`).
pub fn metrics_masked(reference: &Image, test: &Image, keep: Option<&[bool]>) -> Result<Metrics> {
    check_same_size(reference, test)?;
    if let Some(k) = keep {
        if k.len() != reference.pixels.len() {
            return Err(Error::Usage("the mask is not the size of the images".into()));
        }
        let pick = |img: &Image| {
            let px: Vec<_> = img.pixels.iter().zip(k).filter(|(_, k)| **k).map(|(p, _)| *p).collect();
            Image::new(px.len() as u32, 1, px)
        };
        if !k.iter().any(|&x| x) {
            return Err(Error::Usage("the mask keeps no pixel".into()));
        }
        return metrics(&pick(reference), &pick(test));
    }
    metrics(reference, test)
}

/// Mean FLIP error (LDR FLIP on sRGB-encoded, clamped images) over the pixels `keep` marks.
pub fn flip(reference: &Image, test: &Image, keep: Option<&[bool]>) -> Result<f64> {
    check_same_size(reference, test)?;
    let ldr = |img: &Image| -> Vec<u8> {
        img.pixels
            .iter()
            .flat_map(|p| p.to_array())
            .map(|v| {
                let v = if v.is_finite() { v.clamp(0.0, 1.0) } else { 1.0 };
                (crate::image_io::linear_to_srgb(v) * 255.0 + 0.5) as u8
            })
            .collect()
    };
    let (w, h) = (reference.width, reference.height);
    let r = nv_flip::FlipImageRgb8::with_data(w, h, &ldr(reference));
    let t = nv_flip::FlipImageRgb8::with_data(w, h, &ldr(test));
    let err = nv_flip::flip(r, t, nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec();
    let (sum, n) = err
        .iter()
        .enumerate()
        .filter(|(i, _)| keep.is_none_or(|k| k[*i]))
        .fold((0.0f64, 0usize), |(s, n), (_, e)| (s + *e as f64, n + 1));
    if n == 0 {
        return Err(Error::Usage("the mask keeps no pixel".into()));
    }
    Ok(sum / n as f64)
}

/// A false-colour map of the per-pixel relMSE (black = 0, through blue, green and yellow
/// to white at `scale`), as 8-bit RGB.
pub fn error_image(reference: &Image, test: &Image, scale: f64) -> Result<Vec<u8>> {
    check_same_size(reference, test)?;
    let mut out = Vec::with_capacity(reference.pixels.len() * 3);
    for (r, t) in reference.pixels.iter().zip(&test.pixels) {
        let e = (0..3).map(|c| relmse_term(t[c], r[c])).sum::<f64>() / 3.0;
        let x = if e.is_finite() { (e / scale).clamp(0.0, 1.0) } else { 1.0 };
        out.extend(false_colour(x as f32));
    }
    Ok(out)
}

/// A perceptually ordered colour ramp for `x` in `[0, 1]`.
fn false_colour(x: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 5] =
        [[0.0, 0.0, 0.0], [0.1, 0.1, 0.8], [0.0, 0.75, 0.3], [1.0, 0.85, 0.0], [1.0, 1.0, 1.0]];
    let s = x * (STOPS.len() - 1) as f32;
    let i = (s as usize).min(STOPS.len() - 2);
    let f = s - i as f32;
    let c = |k: usize| ((STOPS[i][k] * (1.0 - f) + STOPS[i + 1][k] * f) * 255.0 + 0.5) as u8;
    [c(0), c(1), c(2)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Rgb;

    #[test]
    fn identical_images_have_zero_error() {
        let a = Image::new(2, 1, vec![Rgb::new(0.1, 0.2, 0.3), Rgb::ONE]);
        let m = metrics(&a, &a).unwrap();
        assert_eq!(m.mse, 0.0);
        assert_eq!(m.relmse, 0.0);
        assert_eq!(m.mean_ratio, 1.0);
    }

    #[test]
    fn flip_is_zero_for_identical_images_and_grows_with_the_difference() {
        let px: Vec<Rgb> = (0..64).map(|i| Rgb::new(i as f32 / 64.0, 0.5, 1.0 - i as f32 / 64.0)).collect();
        let a = Image::new(8, 8, px.clone());
        assert_eq!(flip(&a, &a, None).unwrap(), 0.0);
        let b = Image::new(8, 8, px.iter().map(|p| *p * 0.9).collect());
        let c = Image::new(8, 8, px.iter().map(|p| *p * 0.5).collect());
        let (fb, fc) = (flip(&a, &b, None).unwrap(), flip(&a, &c, None).unwrap());
        assert!(0.0 < fb && fb < fc && fc <= 1.0, "{fb} {fc}");
    }

    #[test]
    fn crops_and_masks_restrict_the_metrics() {
        let r = Image::new(2, 2, vec![Rgb::ONE; 4]);
        let t = Image::new(2, 2, vec![Rgb::ONE, Rgb::splat(2.0), Rgb::ONE, Rgb::ONE]);
        assert!(metrics(&r, &t).unwrap().relmse > 0.0);
        let keep = [true, false, true, true];
        assert_eq!(metrics_masked(&r, &t, Some(&keep)).unwrap().relmse, 0.0);
        let c = crop(&t, [0, 1, 2, 1]).unwrap();
        assert_eq!(c.pixels, vec![Rgb::ONE, Rgb::ONE]);
        assert!(crop(&t, [1, 1, 2, 1]).is_err());
        assert!(metrics_masked(&r, &t, Some(&[false; 4])).is_err());
    }

    #[test]
    fn relmse_matches_its_definition() {
        let r = Image::new(1, 1, vec![Rgb::new(1.0, 0.0, 0.5)]);
        let t = Image::new(1, 1, vec![Rgb::new(1.5, 0.1, 0.5)]);
        let m = metrics(&r, &t).unwrap();
        let expect = (0.25 / 1.01 + 0.01 / 0.01 + 0.0) / 3.0;
        assert!((m.relmse - expect).abs() < 1e-6);
    }
}
