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

/// Per-channel relative squared error of one value.
#[inline]
pub fn relmse_term(t: f32, r: f32) -> f64 {
    let (t, r) = (t as f64, r as f64);
    (t - r) * (t - r) / (r * r + 0.01)
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
    fn relmse_matches_its_definition() {
        let r = Image::new(1, 1, vec![Rgb::new(1.0, 0.0, 0.5)]);
        let t = Image::new(1, 1, vec![Rgb::new(1.5, 0.1, 0.5)]);
        let m = metrics(&r, &t).unwrap();
        let expect = (0.25 / 1.01 + 0.01 / 0.01 + 0.0) / 3.0;
        assert!((m.relmse - expect).abs() < 1e-6);
    }
}
