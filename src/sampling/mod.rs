//! Random numbers and the warps from the unit square to the distributions the renderer
//! samples. BSDFs and lights never own a random-number generator: their samples come in as
//! arguments, which is what makes χ² tests and (later) Metropolis replay possible.

pub mod chi2;
pub mod distribution;
pub mod sobol;

use glam::{Vec2, Vec3};
use rand_core::Rng;
use rand_pcg::Pcg32;
use std::f32::consts::{FRAC_1_PI, PI};

pub use distribution::{Distribution1D, Distribution2D};

/// SplitMix64 finaliser: a well-mixed 64-bit hash.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hash of several 64-bit words, order-sensitive.
#[inline]
pub fn hash_words(words: &[u64]) -> u64 {
    words.iter().fold(0x9e37_79b9_7f4a_7c15u64, |h, &w| mix64(h ^ mix64(w.wrapping_add(0x632b_e59b_d9b4_e019))))
}

/// Where a camera sample's random numbers come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SamplerKind {
    /// Independent streams, one per pixel and sample ([`Sampler`]).
    #[default]
    Independent,
    /// An Owen-scrambled Sobol sequence per pixel ([`sobol::SobolSampler`]; the path tracer's).
    Sobol,
}

/// The random numbers of camera sample `s` of a pixel, as the render loop makes them.
pub trait PixelSampler: Random {
    /// Sample `s` of the pixel whose numbers are keyed by `[seed, pixel]`.
    fn for_sample(seed: u64, pixel: u64, s: u32) -> Self;
}

impl PixelSampler for Sampler {
    #[inline]
    fn for_sample(seed: u64, pixel: u64, s: u32) -> Sampler {
        Sampler::new(&[seed, pixel, s as u64])
    }
}

impl PixelSampler for sobol::SobolSampler {
    #[inline]
    fn for_sample(seed: u64, pixel: u64, s: u32) -> sobol::SobolSampler {
        sobol::SobolSampler::new(&[seed, pixel], s)
    }
}

/// A source of uniform random numbers in `[0, 1)`: the independent [`Sampler`], or a
/// primary-sample-space state that Metropolis methods mutate.
pub trait Random {
    fn next_1d(&mut self) -> f32;
    /// Switches to numbered stream `k` from its start. Independent samplers ignore it;
    /// primary-sample-space samplers keep each stream's coordinates apart, so that the
    /// camera subpath, the light subpath and the connections each keep their coordinates
    /// when another part of the path changes length.
    #[inline]
    fn start_stream(&mut self, _k: u32) {}
    #[inline]
    fn next_2d(&mut self) -> Vec2 {
        let x = self.next_1d();
        Vec2::new(x, self.next_1d())
    }
}

impl Random for Sampler {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        Sampler::next_1d(self)
    }
    #[inline]
    fn next_2d(&mut self) -> Vec2 {
        Sampler::next_2d(self)
    }
}

/// The `independent` sampler: a PCG32 stream seeded from a hash of (seed, pass, pixel),
/// so every pixel sample is the same whatever thread renders it.
pub struct Sampler {
    rng: Pcg32,
}

impl Sampler {
    /// A sampler for one stream identified by `key` (e.g. `[seed, pass, pixel]`).
    pub fn new(key: &[u64]) -> Sampler {
        let h = hash_words(key);
        Sampler { rng: Pcg32::new(h, mix64(h ^ 0xda3e_39cb_94b9_5bdb)) }
    }

    /// A uniform number in `[0, 1)`.
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        // 24 random bits give every representable multiple of 2^-24 below 1.
        (self.rng.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let x = self.next_1d();
        Vec2::new(x, self.next_1d())
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        self.rng.next_u32()
    }
}

/// The largest `f32` below one: where a uniform number scaled into a cell is clamped.
pub const ONE_BELOW: f32 = 1.0 - f32::EPSILON / 2.0;

/// Uniform point on the unit disk (Shirley–Chiu concentric map).
pub fn square_to_uniform_disk_concentric(u: Vec2) -> Vec2 {
    let a = 2.0 * u - Vec2::ONE;
    if a == Vec2::ZERO {
        return Vec2::ZERO;
    }
    // Shirley and Chiu's map: the square's point at "radius" `r` and angle `θ = π/4 · q`
    // from the x axis (or `π/2 - π/4 · q` from it, measured from the y axis), `|q| <= 1`.
    let swap = a.x.abs() <= a.y.abs();
    let (r, q) = if swap { (a.y, a.x / a.y) } else { (a.x, a.y / a.x) };
    let (sin, cos) = crate::math::sin_cos_quarter(PI / 4.0 * q);
    if swap { Vec2::new(r * sin, r * cos) } else { Vec2::new(r * cos, r * sin) }
}

/// Cosine-weighted direction on the hemisphere around +z.
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_uniform_disk_concentric(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

#[inline]
pub fn square_to_cosine_hemisphere_pdf(v: Vec3) -> f32 {
    if v.z > 0.0 { v.z * FRAC_1_PI } else { 0.0 }
}

/// Uniform direction on the unit sphere.
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform direction in the cone of half-angle `acos(cos_max)` around +z.
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_t = 1.0 - u.y * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

#[inline]
pub fn square_to_uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// A direction about `+z` from the von Mises–Fisher distribution of concentration `kappa`
/// (density `∝ e^{κ cos θ}`; uniform for `κ = 0`): the direction perturbation of Manifold
/// Exploration (contract `memlt.md`, "Manifold perturbation", step 4). `cos θ` is inverted
/// from its CDF in the form `1 + ln(u + (1 - u) e^{-2κ}) / κ`, which stays finite for large `κ`.
pub fn square_to_von_mises_fisher(u: Vec2, kappa: f32) -> Vec3 {
    if kappa <= 0.0 {
        return square_to_uniform_sphere(u);
    }
    let (k, uy) = (kappa as f64, u.y as f64);
    let cos = (1.0 + (uy + (1.0 - uy) * (-2.0 * k).exp()).ln() / k).clamp(-1.0, 1.0) as f32;
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.x).sin_cos();
    Vec3::new(sin * c, sin * s, cos)
}

/// The solid-angle density of [`square_to_von_mises_fisher`]: `κ e^{κ (cos θ - 1)} / (2π (1 - e^{-2κ}))`.
pub fn square_to_von_mises_fisher_pdf(v: Vec3, kappa: f32) -> f32 {
    if kappa <= 0.0 {
        return UNIFORM_SPHERE_PDF;
    }
    let k = kappa as f64;
    (k * (k * (v.z as f64 - 1.0)).exp() / (2.0 * std::f64::consts::PI * -(-2.0 * k).exp_m1())) as f32
}

/// A point of the plane from an isotropic Gaussian of standard deviation `sigma` about the
/// origin (Box–Muller): the position perturbation of a path's end in Manifold Exploration
/// (contract `memlt.md`, "Manifold perturbation", step 4).
pub fn square_to_gaussian_2d(u: Vec2, sigma: f32) -> Vec2 {
    // 1 - u in (0, 1]: the radius stays finite.
    let r = sigma * (-2.0 * (1.0 - u.y).ln()).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.x).sin_cos();
    Vec2::new(r * c, r * s)
}

/// The density per unit area of [`square_to_gaussian_2d`]: `e^{-|p|² / 2σ²} / (2π σ²)`.
pub fn square_to_gaussian_2d_pdf(p: Vec2, sigma: f32) -> f32 {
    (-p.length_squared() / (2.0 * sigma * sigma)).exp() / (2.0 * PI * sigma * sigma)
}

/// Uniform barycentric coordinates `(b1, b2)` on a triangle.
pub fn square_to_uniform_triangle(u: Vec2) -> Vec2 {
    let t = (1.0 - u.x).max(0.0).sqrt();
    Vec2::new(1.0 - t, u.y * t)
}

/// The MIS heuristic of the integrators that weigh several strategies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Heuristic {
    /// β = 1.
    Balance,
    /// β = 2.
    #[default]
    Power,
}

/// Power heuristic (β = 2) weight of a strategy with density `a` against one with `b`.
#[inline]
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2.is_infinite() {
        1.0
    } else if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chi2::{Chi2Test, SphereDomain};

    #[test]
    fn sampler_is_reproducible_and_uniform() {
        let mut a = Sampler::new(&[1, 2, 3]);
        let mut b = Sampler::new(&[1, 2, 3]);
        let mut c = Sampler::new(&[1, 2, 4]);
        let (xs, ys, zs): (Vec<f32>, Vec<f32>, Vec<f32>) = (0..1000)
            .map(|_| (a.next_1d(), b.next_1d(), c.next_1d()))
            .fold((vec![], vec![], vec![]), |mut acc, (x, y, z)| {
                acc.0.push(x);
                acc.1.push(y);
                acc.2.push(z);
                acc
            });
        assert_eq!(xs, ys);
        assert_ne!(xs, zs);
        assert!(xs.iter().all(|x| (0.0..1.0).contains(x)));
        let mean: f32 = xs.iter().sum::<f32>() / 1000.0;
        assert!((mean - 0.5).abs() < 0.05);
    }

    #[test]
    fn cosine_hemisphere_chi2() {
        let t = Chi2Test::new(SphereDomain::default());
        t.run(square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf).assert_pass();
    }

    #[test]
    fn uniform_sphere_chi2() {
        let t = Chi2Test::new(SphereDomain::default());
        t.run(square_to_uniform_sphere, |_| UNIFORM_SPHERE_PDF).assert_pass();
    }

    #[test]
    fn uniform_cone_chi2() {
        let cos_max = 0.7f32;
        let t = Chi2Test::new(SphereDomain::default());
        t.run(
            |u| square_to_uniform_cone(u, cos_max),
            |v| {
                if v.z >= cos_max { square_to_uniform_cone_pdf(cos_max) } else { 0.0 }
            },
        )
        .assert_pass();
    }

    #[test]
    fn von_mises_fisher_chi2() {
        // From nearly uniform to a lobe a few degrees wide, and the uniform limit.
        for kappa in [0.0, 0.3, 4.0, 60.0] {
            let t = Chi2Test::new(SphereDomain::default());
            t.run(|u| square_to_von_mises_fisher(u, kappa), |v| square_to_von_mises_fisher_pdf(v, kappa)).assert_pass();
        }
        // Negative control: the density of a lobe 10% sharper than the one sampled.
        let t = Chi2Test::new(SphereDomain::default());
        let r = t.run(|u| square_to_von_mises_fisher(u, 4.0), |v| square_to_von_mises_fisher_pdf(v, 4.4));
        assert!(!r.passed(), "{r}");
        // Very sharp lobes stay finite and normalised.
        let v = square_to_von_mises_fisher(Vec2::new(0.3, 1e-30), 1e5);
        assert!(v.is_finite() && (v.length() - 1.0).abs() < 1e-5, "{v}");
        assert!(square_to_von_mises_fisher_pdf(Vec3::Z, 1e5).is_finite());
    }

    #[test]
    fn gaussian_2d_chi2() {
        // Cells of a 16 × 16 grid over ±3σ plus the outside, their expected counts from the
        // density integrated by the midpoint rule (8 × 8 points a cell).
        let counts_and_expected = |sigma_sampled: f32, sigma_claimed: f32| {
            let (n, cells, half) = (200_000usize, 16usize, 3.0f32);
            let cell = |p: Vec2| {
                let q = (p / sigma_sampled + Vec2::splat(half)) / (2.0 * half) * cells as f32;
                (q.cmpge(Vec2::ZERO).all() && q.cmplt(Vec2::splat(cells as f32)).all())
                    .then(|| q.y as usize * cells + q.x as usize)
            };
            let mut counts = vec![0u64; cells * cells + 1];
            let mut rng = Sampler::new(&[21]);
            for _ in 0..n {
                counts[cell(square_to_gaussian_2d(rng.next_2d(), sigma_sampled)).unwrap_or(cells * cells)] += 1;
            }
            let side = 2.0 * half * sigma_sampled / cells as f32;
            let mut expected = vec![0.0f64; cells * cells + 1];
            for (i, e) in expected.iter_mut().take(cells * cells).enumerate() {
                let origin =
                    Vec2::new((i % cells) as f32, (i / cells) as f32) * side - Vec2::splat(half * sigma_sampled);
                let mut sum = 0.0;
                for j in 0..64 {
                    let p = origin + Vec2::new((j % 8) as f32 + 0.5, (j / 8) as f32 + 0.5) * (side / 8.0);
                    sum += square_to_gaussian_2d_pdf(p, sigma_claimed) as f64;
                }
                *e = sum / 64.0 * (side * side) as f64 * n as f64;
            }
            let inside: f64 = expected.iter().sum();
            expected[cells * cells] = n as f64 - inside;
            (counts, expected)
        };
        let (counts, expected) = counts_and_expected(0.7, 0.7);
        assert!(crate::sampling::chi2::discrete_chi2(&counts, &expected).passed());
        // Negative control: a density 5% wider than what is sampled.
        let (counts, expected) = counts_and_expected(0.7, 0.735);
        assert!(!crate::sampling::chi2::discrete_chi2(&counts, &expected).passed());
        // The radius stays finite at the edge of the unit square.
        assert!(square_to_gaussian_2d(Vec2::new(0.2, 0.0), 1.0).is_finite());
        assert!(square_to_gaussian_2d(Vec2::new(0.2, 1.0 - f32::EPSILON), 1.0).is_finite());
    }

    #[test]
    fn chi2_rejects_a_wrong_pdf() {
        // Negative control: cosine-weighted samples tested against the uniform-hemisphere
        // pdf must be rejected, or the harness cannot tell a wrong sampler from a right one.
        let t = Chi2Test::new(SphereDomain::default());
        let r = t.run(square_to_cosine_hemisphere, |v| if v.z > 0.0 { 1.0 / (2.0 * PI) } else { 0.0 });
        assert!(!r.passed(), "{r}");
        // ... and a subtly wrong sampler (a cone slightly wider than its pdf says).
        let r = t.run(
            |u| square_to_uniform_cone(u, 0.69),
            |v| {
                if v.z >= 0.7 { square_to_uniform_cone_pdf(0.7) } else { 0.0 }
            },
        );
        assert!(!r.passed(), "{r}");
    }

    #[test]
    fn triangle_warp_is_uniform() {
        let mut s = Sampler::new(&[7]);
        let mut cells = [0u32; 4];
        for _ in 0..40000 {
            let b = square_to_uniform_triangle(s.next_2d());
            assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
            // The four sub-triangles of the midpoint subdivision have equal area.
            let idx = if b.x > 0.5 {
                0
            } else if b.y > 0.5 {
                1
            } else if b.x + b.y < 0.5 {
                2
            } else {
                3
            };
            cells[idx] += 1;
        }
        let chi: f64 = cells.iter().map(|&c| (c as f64 - 10000.0).powi(2) / 10000.0).sum();
        assert!(chi < 16.27, "chi2 {chi} for {cells:?}"); // p = 0.001 with 3 dof
    }
}
