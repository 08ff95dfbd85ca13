//! The `sobol` sampler: each pixel draws its samples from its own Owen-scrambled Sobol
//! sequence (Burley's hash-based scrambling, the `sobol_burley` crate), sample `s` of the
//! pixel being point `s` of the sequence and the `k`-th number a sample asks for its
//! dimension `k`. Every prefix of `2^m` samples of a pixel is then stratified in every
//! elementary interval of the first two dimensions (the position in the pixel) and, Owen
//! scrambling being a random permutation of the sequence's digits, each point is uniformly
//! distributed on its own, so estimates stay unbiased.
//!
//! Only a sample's first [`SOBOL_DIMENSIONS`] numbers come from the sequence; the rest from
//! an independent stream of the sample. The sequences have `2^16` points: the samples of a
//! pixel past `2^16` continue with a freshly seeded sequence (independent of the first,
//! without stratification against it).

use crate::sampling::{Random, Sampler, hash_words};

/// Points of one scrambled sequence.
const POINTS: u32 = 1 << 16;

/// The dimensions of a camera sample taken from its pixel's Sobol sequence: the position in
/// the pixel and the first bounces' light and BSDF samples, where stratification pays most;
/// a deeper bounce's numbers cost as much to compute and gain little.
pub const SOBOL_DIMENSIONS: u32 = 24;

/// The random numbers of one camera sample: its first [`SOBOL_DIMENSIONS`] are point
/// `index` of the pixel's sequence, computed four dimensions at a time; the rest come from an
/// independent stream of the sample.
pub struct SobolSampler {
    /// The pixel's scramble, for the sequence `index` lies in.
    seed: u64,
    index: u32,
    /// The next dimension to hand out.
    dimension: u32,
    /// Dimensions `dimension & !3 ..` of the point.
    four: [f32; 4],
    /// The numbers past the Sobol dimensions.
    rest: Option<Sampler>,
}

impl SobolSampler {
    /// Sample `sample` of the pixel whose stream is keyed by `key` (e.g. `[seed, pixel]`).
    pub fn new(key: &[u64], sample: u32) -> SobolSampler {
        SobolSampler {
            seed: hash_words(key) ^ (sample / POINTS) as u64,
            index: sample % POINTS,
            dimension: 0,
            four: [0.0; 4],
            rest: None,
        }
    }
}

impl Random for SobolSampler {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        let d = self.dimension;
        if d >= SOBOL_DIMENSIONS {
            let (seed, index) = (self.seed, self.index);
            return self.rest.get_or_insert_with(|| Sampler::new(&[seed, index as u64])).next_1d();
        }
        self.dimension += 1;
        if d.is_multiple_of(4) {
            self.four = sobol_burley::sample_4d(self.index, d / 4, self.seed as u32);
        }
        self.four[(d % 4) as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether the first `n = 2^m` samples of a pixel put exactly one point in every cell of
    /// each `2^a × 2^(m-a)` grid of dimensions `d0`, `d1`.
    fn stratified(points: &[(f32, f32)]) -> bool {
        let n = points.len();
        let m = n.trailing_zeros();
        (0..=m).all(|a| {
            let (nx, ny) = (1usize << a, 1usize << (m - a));
            let mut seen = vec![false; n];
            points.iter().all(|&(x, y)| {
                let cell = ((y * ny as f32) as usize).min(ny - 1) * nx + ((x * nx as f32) as usize).min(nx - 1);
                !std::mem::replace(&mut seen[cell], true)
            })
        })
    }

    fn points(pixel: u64, n: u32, dims: (u32, u32), sobol: bool) -> Vec<(f32, f32)> {
        (0..n)
            .map(|s| {
                let mut v = [0.0f32; 8];
                if sobol {
                    let mut r = SobolSampler::new(&[7, pixel], s);
                    v.iter_mut().for_each(|x| *x = r.next_1d());
                } else {
                    let mut r = Sampler::new(&[7, pixel, s as u64]);
                    v.iter_mut().for_each(|x| *x = Random::next_1d(&mut r));
                }
                (v[dims.0 as usize], v[dims.1 as usize])
            })
            .collect()
    }

    #[test]
    fn every_power_of_two_prefix_of_a_pixel_is_stratified_in_the_pixel() {
        for pixel in 0..20 {
            for n in [4, 16, 64, 256] {
                assert!(stratified(&points(pixel, n, (0, 1), true)), "pixel {pixel}, {n} samples");
            }
        }
        // Negative control: independent samples are not.
        let independent = (0..20).filter(|&p| stratified(&points(p, 64, (0, 1), false))).count();
        assert_eq!(independent, 0, "independent samples came out stratified");
    }

    #[test]
    fn later_dimensions_are_stratified_in_one_dimension_and_pixels_are_independent() {
        // Every dimension of a 2^m prefix has one point in each of 2^m intervals.
        for d in 0..8u32 {
            let p = points(3, 32, (d, d), true);
            let mut seen = [false; 32];
            for (x, _) in p {
                assert!(!std::mem::replace(&mut seen[(x * 32.0) as usize], true), "dimension {d}");
            }
        }
        // Two pixels' sequences are scrambled apart.
        assert_ne!(points(1, 16, (0, 1), true), points(2, 16, (0, 1), true));
    }

    #[test]
    fn numbers_are_uniform_across_pixels_samples_and_dimensions_past_the_sequence() {
        // χ² over 64 bins of the numbers of many pixels at dimensions below and past 256 and
        // samples below and past 2^16; the negative control is a skewed copy.
        let mut values = Vec::new();
        for pixel in 0..400u64 {
            for s in [0u32, 1, 5, 70_000] {
                let mut r = SobolSampler::new(&[1, pixel], s);
                for d in 0..300 {
                    let v = r.next_1d();
                    if d % 37 == 0 || d >= 256 {
                        values.push(v);
                    }
                }
            }
        }
        let chi2 = |vals: &[f32]| {
            let mut bins = [0f64; 64];
            for v in vals {
                assert!((0.0..1.0).contains(v));
                bins[(v * 64.0) as usize] += 1.0;
            }
            let e = vals.len() as f64 / 64.0;
            bins.iter().map(|o| (o - e) * (o - e) / e).sum::<f64>()
        };
        // 63 degrees of freedom: the 99.9th percentile is 103.4.
        let c = chi2(&values);
        assert!(c < 103.4, "χ² {c}");
        let skewed: Vec<f32> = values.iter().map(|v| v * v).collect();
        assert!(chi2(&skewed) > 103.4, "the skewed copy passed");
    }
}
