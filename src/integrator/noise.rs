//! A render's own estimate of its noise, from two independent half-images: the per-pixel
//! variance of the image (the `Variance` AOV) and the relMSE it predicts against the true
//! image (what `--noise-threshold` stops at).
//!
//! The render loop keeps, beside the film of every iteration, a film of the odd iterations
//! alone (`B`, from `n_B` iterations); the even ones (`A`, `n_A`) are the difference. Each
//! iteration is an independent estimate of the pixel with some variance `s²`, so
//! `Var(A) = s²/n_A`, `Var(B) = s²/n_B`, and the image `F = (n_A A + n_B B)/n` has variance
//! `s²/n`. As `E[(A − B)²] = s² (1/n_A + 1/n_B) = s² n / (n_A n_B)`, the unbiased estimate of
//! the image's variance is
//!
//! ```text
//! Var(F) ≈ (A − B)² · n_A n_B / n²        (= ((A − B)/2)² for equal halves)
//! ```
//!
//! per pixel and channel: one degree of freedom, so a single pixel's estimate is very noisy
//! (a χ² of one degree), but its mean over many pixels is not. The relMSE of
//! [`crate::compare`] is the mean of `(F − I)² / (I² + 0.01)` against the true image `I`;
//! its expectation is the mean of `Var(F) / (I² + 0.01)` for an unbiased `F`. The estimate
//! needs `I²` too, and takes it from the pixel's neighbours, not from the pixel itself:
//!
//! ```text
//! relMSE ≈ mean over pixels and channels of  Var(F) / (max(Ā·B̄, 0) + 0.01)
//! ```
//!
//! where `Ā` and `B̄` are the means of the halves over the 7×7 pixels around the pixel, the
//! pixel left out (fewer at the image's border). The halves are independent, so
//! `E[Ā·B̄] = Ī²`, and the neighbours' samples are independent of the pixel's `Var(F)`.
//! That independence is what matters where rare paths carry much of the light: a pixel's
//! own `A·B` (or `F²`) is large exactly where one half caught a firefly, that is, where
//! `Var(F)` is, and divides the largest terms by too much (the path tracer's estimate on
//! `veach-ajar` was 40% low at 256 spp that way; at 64 spp, where many halves are still
//! near zero and their product too small, it was 60% high instead). The price is the
//! neighbourhood's own bias where the image changes within 7 pixels: at an edge between a
//! bright and a dark region the dark side's `I²` is overestimated (on `cornell-ply` the
//! reference's own 7×7 means would put the estimate 4.5% low). `docs/results/noise.md`
//! gives the measurements.
//!
//! Light-tracing splats go into the halves by iteration like camera samples, each half
//! divided by its own light paths. The halves are independent only where iterations are:
//! an integrator that learns from earlier iterations (PCBPT's cache, SPCBPT's training)
//! makes them slightly dependent, and a biased integrator's bias is not seen at all.

use crate::compare::RELMSE_EPSILON;
use crate::film::Film;
use crate::math::Rgb;

/// The odd iterations of a render, the second half-image.
pub(crate) struct Halves {
    pub odd: Film,
    /// Iterations in `odd`, and in the whole film.
    pub odd_iterations: u32,
    pub iterations: u32,
}

impl Halves {
    pub fn new(film: &Film) -> Halves {
        Halves { odd: Film::new(film.width, film.height, film.filter), odd_iterations: 0, iterations: 0 }
    }

    /// The per-pixel variance of `film`'s image (which holds every iteration, `odd` among
    /// them; NaN where a half is still empty) and the relMSE estimate.
    pub fn estimate(&self, film: &Film) -> (Vec<Rgb>, f64) {
        let even = film.develop_without(&self.odd);
        let odd = self.odd.develop();
        let (nb, n) = (self.odd_iterations as f64, self.iterations as f64);
        let factor = if nb > 0.0 && n > nb { (n - nb) * nb / (n * n) } else { f64::NAN };
        let v = variance(&even, &odd, factor);
        let relmse = relmse_estimate(&even, &odd, &v, film.width as usize);
        (v, relmse)
    }
}

/// `(a − b)² · factor` per pixel and channel.
fn variance(a: &[Rgb], b: &[Rgb], factor: f64) -> Vec<Rgb> {
    a.iter()
        .zip(b)
        .map(|(a, b)| {
            let d = *a - *b;
            let v = |x: f32| (x as f64 * x as f64 * factor) as f32;
            Rgb::new(v(d.x), v(d.y), v(d.z))
        })
        .collect()
}

/// Half the side of the square of neighbours whose mean stands for a pixel's value.
const RADIUS: usize = 3;

/// The relMSE that the per-pixel variance `variance` of the `width`-pixel-wide image of
/// halves `a` and `b` predicts against the true image: the mean of
/// `variance / (max(Ā·B̄, 0) + 0.01)` over the pixels and channels where the variance is
/// finite, `Ā` and `B̄` the means of the halves' finite values around the pixel (NaN where
/// nothing is finite).
pub fn relmse_estimate(a: &[Rgb], b: &[Rgb], variance: &[Rgb], width: usize) -> f64 {
    assert!(a.len() == b.len() && a.len() == variance.len(), "images of one size");
    if a.is_empty() {
        return f64::NAN;
    }
    let (sa, sb) = (Neighbourhoods::new(a, width), Neighbourhoods::new(b, width));
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (p, v) in variance.iter().enumerate() {
        if !v.is_finite() {
            continue;
        }
        let (ma, mb) = (sa.mean_around(p), sb.mean_around(p));
        for c in 0..3 {
            let square = (ma[c] * mb[c]).max(0.0);
            sum += v[c] as f64 / (if square.is_finite() { square } else { 0.0 } + RELMSE_EPSILON);
        }
        n += 3;
    }
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

/// Summed-area tables of an image's finite pixels and of their count, for the mean over
/// the square of side `2·RADIUS + 1` around a pixel.
struct Neighbourhoods {
    width: usize,
    height: usize,
    /// `(width + 1) × (height + 1)` sums of the pixels above and left of each corner.
    sums: Vec<[f64; 3]>,
    counts: Vec<u32>,
    image: Vec<Option<[f64; 3]>>,
}

impl Neighbourhoods {
    fn new(image: &[Rgb], width: usize) -> Neighbourhoods {
        let height = image.len() / width;
        let image: Vec<Option<[f64; 3]>> =
            image.iter().map(|p| p.is_finite().then_some([p.x as f64, p.y as f64, p.z as f64])).collect();
        let stride = width + 1;
        let mut sums = vec![[0.0; 3]; stride * (height + 1)];
        let mut counts = vec![0u32; stride * (height + 1)];
        for y in 0..height {
            let (mut row, mut row_count) = ([0.0; 3], 0u32);
            for x in 0..width {
                if let Some(v) = image[y * width + x] {
                    (0..3).for_each(|c| row[c] += v[c]);
                    row_count += 1;
                }
                let (i, up) = ((y + 1) * stride + x + 1, y * stride + x + 1);
                sums[i] = [0, 1, 2].map(|c| sums[up][c] + row[c]);
                counts[i] = counts[up] + row_count;
            }
        }
        Neighbourhoods { width, height, sums, counts, image }
    }

    /// The mean of the finite pixels around pixel `p`, itself left out (NaN where none is).
    fn mean_around(&self, p: usize) -> [f64; 3] {
        let (x, y) = (p % self.width, p / self.width);
        let (x0, y0) = (x.saturating_sub(RADIUS), y.saturating_sub(RADIUS));
        let (x1, y1) = ((x + RADIUS + 1).min(self.width), (y + RADIUS + 1).min(self.height));
        let stride = self.width + 1;
        let corner = |xx: usize, yy: usize| yy * stride + xx;
        let (a, b, c, d) = (corner(x0, y0), corner(x1, y0), corner(x0, y1), corner(x1, y1));
        let mut sum = [0, 1, 2].map(|k| self.sums[d][k] - self.sums[b][k] - self.sums[c][k] + self.sums[a][k]);
        let mut count = self.counts[d] + self.counts[a] - self.counts[b] - self.counts[c];
        if let Some(v) = self.image[p] {
            (0..3).for_each(|k| sum[k] -= v[k]);
            count -= 1;
        }
        if count == 0 { [f64::NAN; 3] } else { sum.map(|s| s / count as f64) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_halves_give_the_square_of_half_their_difference() {
        let v = variance(&[Rgb::new(1.0, 2.0, 3.0)], &[Rgb::new(3.0, 2.0, 0.0)], 0.25);
        assert_eq!(v, vec![Rgb::new(1.0, 0.0, 2.25)]);
    }

    #[test]
    fn the_estimate_weighs_a_pixel_s_variance_by_its_neighbours_not_by_itself() {
        // A firefly in the middle pixel of a row of three: its variance 1 is weighed by the
        // square of its neighbours' value 2, not by its own 50 (which the old estimate, the
        // pixel's own A·B, would have divided by); the neighbours have no variance.
        let (a, b) = (vec![Rgb::splat(2.0), Rgb::splat(50.0), Rgb::splat(2.0)], vec![Rgb::splat(2.0); 3]);
        let v = vec![Rgb::ZERO, Rgb::ONE, Rgb::ZERO];
        let e = relmse_estimate(&a, &b, &v, 3);
        assert!((e - 3.0 / 4.01 / 9.0).abs() < 1e-9, "{e}");
        // A NaN pixel is neither a term nor a neighbour; a negative product counts as zero.
        let nan = Rgb::splat(f32::NAN);
        let e = relmse_estimate(&[Rgb::ONE, nan, Rgb::ONE], &[Rgb::ONE, nan, Rgb::ONE], &[Rgb::ONE, nan, Rgb::ONE], 3);
        assert!((e - 1.0 / 1.01).abs() < 1e-9, "{e}");
        let e = relmse_estimate(&[Rgb::ONE, Rgb::ONE], &[-Rgb::ONE, -Rgb::ONE], &[Rgb::splat(0.01); 2], 2);
        assert!((e - 1.0).abs() < 1e-6, "{e}");
        assert!(relmse_estimate(&[], &[], &[], 1).is_nan());
        assert!(relmse_estimate(&[nan], &[nan], &[nan], 1).is_nan());
    }

    #[test]
    fn the_neighbourhood_mean_is_that_of_the_square_around_the_pixel_without_it() {
        // Against a direct sum on a 13×11 image with a NaN pixel, borders and corners
        // included.
        let (w, h) = (13usize, 11usize);
        let mut image: Vec<Rgb> =
            (0..w * h).map(|i| Rgb::new(i as f32, (i * i % 17) as f32, -(i as f32) * 0.5)).collect();
        image[5 * w + 6] = Rgb::splat(f32::NAN);
        let n = Neighbourhoods::new(&image, w);
        for p in 0..w * h {
            let (x, y) = ((p % w) as i64, (p / w) as i64);
            let (mut sum, mut count) = ([0.0f64; 3], 0);
            for (q, v) in image.iter().enumerate() {
                let (qx, qy) = ((q % w) as i64, (q / w) as i64);
                let near = (qx - x).abs() <= RADIUS as i64 && (qy - y).abs() <= RADIUS as i64;
                if near && q != p && v.is_finite() {
                    (0..3).for_each(|c| sum[c] += v[c] as f64);
                    count += 1;
                }
            }
            let got = n.mean_around(p);
            for c in 0..3 {
                assert!((got[c] - sum[c] / count as f64).abs() < 1e-9, "pixel {p}: {got:?}");
            }
        }
    }
}
