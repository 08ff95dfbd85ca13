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
//! needs `I²` too, and takes `A·B`, whose expectation is `E[A] E[B] = I²` for independent
//! halves:
//!
//! ```text
//! relMSE ≈ mean over pixels and channels of  Var(F) / (max(A·B, 0) + 0.01)
//! ```
//!
//! `F²` in its place would be biased up by `Var(F)` and large exactly where the numerator
//! is (a pixel with a firefly), and the estimate low. `A·B` is still large where one half
//! holds a firefly, so where rare paths carry much of the light the estimate stays noisy
//! and can be low or high by tens of percent (docs/usage.md gives measurements).
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
        let relmse = relmse_estimate(&even, &odd, &v);
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

/// The relMSE that the per-pixel variance `variance` of the image of halves `a` and `b`
/// predicts against the true image: the mean of `variance / (max(a·b, 0) + 0.01)` over the
/// pixels and channels where all are finite (NaN where none is).
pub fn relmse_estimate(a: &[Rgb], b: &[Rgb], variance: &[Rgb]) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for ((a, b), v) in a.iter().zip(b).zip(variance) {
        if !a.is_finite() || !b.is_finite() || !v.is_finite() {
            continue;
        }
        for c in 0..3 {
            let square = (a[c] as f64 * b[c] as f64).max(0.0);
            sum += v[c] as f64 / (square + RELMSE_EPSILON);
        }
        n += 3;
    }
    if n == 0 { f64::NAN } else { sum / n as f64 }
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
    fn the_estimate_weighs_the_variance_by_the_product_of_the_halves() {
        // Variance 0.04 of halves 0.5 and 2 (product 1): 0.04 / (1 + 0.01); a NaN pixel
        // is left out, and a negative product counts as zero.
        let nan = Rgb::splat(f32::NAN);
        let (a, b) = ([Rgb::splat(0.5), nan, Rgb::ONE], [Rgb::splat(2.0), Rgb::ONE, -Rgb::ONE]);
        let e = relmse_estimate(&a[..1], &b[..1], &[Rgb::splat(0.04)]);
        assert!((e - 0.04 / 1.01).abs() < 1e-7, "{e}");
        let e = relmse_estimate(&a[..2], &b[..2], &[Rgb::splat(0.04), Rgb::ONE]);
        assert!((e - 0.04 / 1.01).abs() < 1e-7, "{e}");
        let e = relmse_estimate(&a[2..], &b[2..], &[Rgb::splat(0.01)]);
        assert!((e - 1.0).abs() < 1e-6, "{e}");
        assert!(relmse_estimate(&[], &[], &[]).is_nan());
    }
}
