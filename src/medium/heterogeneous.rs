//! Mitsuba's `heterogeneous` medium: an extinction coefficient that varies over space, read
//! from a grid ([`Grid`], one channel, times the medium's `scale`), and an albedo that is a
//! constant or a grid too. The medium fills its extinction grid's box; outside it light
//! travels freely.
//!
//! Free flights are sampled by delta tracking (Woodcock tracking): tentative collisions at
//! the rate of the majorant μ (the grid's largest value times `scale`), each a real one with
//! probability σt(x)/μ; a real collision scatters with the weight of the albedo there, a
//! flight that reaches the segment's end keeps its throughput. Transmittance is estimated by
//! ratio tracking: the product of `1 − σt(x)/μ` over the tentative collisions. Both are
//! unbiased for trilinear (or nearest) lookups, which never exceed the grid's largest value.

use super::MediumSample;
use super::grid::{Grid, Volume};
use crate::math::Rgb;
use crate::sampling::Random;
use glam::Vec3;

/// A heterogeneous medium.
#[derive(Clone, Debug)]
pub struct Heterogeneous {
    /// The extinction's grid (its first channel), before `scale`.
    sigma_t: Grid,
    scale: f32,
    albedo: Volume,
    /// The largest extinction: the grid's largest value times `scale`.
    majorant: f32,
}

/// The part of a ray inside the medium's box: the local ray and the stretch `[t0, t1]`.
struct Span {
    o: Vec3,
    d: Vec3,
    t0: f32,
    t1: f32,
}

impl Heterogeneous {
    /// A medium whose extinction is `scale` times the first channel of `sigma_t`.
    pub fn new(sigma_t: Grid, scale: f32, albedo: Volume) -> Heterogeneous {
        let majorant = sigma_t.max() * scale;
        Heterogeneous { sigma_t, scale, albedo, majorant }
    }

    /// The largest extinction in the medium.
    pub fn majorant(&self) -> f32 {
        self.majorant
    }

    /// Whether light scatters in the medium (otherwise it only absorbs).
    pub fn scatters(&self) -> bool {
        match &self.albedo {
            Volume::Constant(a) => a.max_element() > 0.0,
            Volume::Grid(g) => g.max() > 0.0,
        }
    }

    /// The part of the segment from `o` along the unit direction `d` to the distance `t_max`
    /// that crosses the medium, if any and if anything there slows light.
    fn span(&self, o: Vec3, d: Vec3, t_max: f32) -> Option<Span> {
        if self.majorant <= 0.0 {
            return None;
        }
        let (o, d) = self.sigma_t.local_ray(o, d);
        let (t0, t1) = Grid::clip(o, d)?;
        let (t0, t1) = (t0.max(0.0), t1.min(t_max));
        (t0 < t1).then_some(Span { o, d, t0, t1 })
    }

    /// The next tentative collision after `t`, at the majorant's rate.
    #[inline]
    fn step<R: Random>(&self, t: f32, rng: &mut R) -> f32 {
        t - (1.0 - rng.next_1d()).ln() / self.majorant
    }

    /// The extinction at distance `t` along the local ray of `span`.
    #[inline]
    fn density(&self, span: &Span, t: f32) -> f32 {
        self.sigma_t.scalar_local(span.o + span.d * t) * self.scale
    }

    /// An unbiased estimate of the fraction of light that crosses the segment from `o`
    /// along the unit direction `d` to the distance `t_max` (ratio tracking).
    pub fn transmittance<R: Random>(&self, o: Vec3, d: Vec3, t_max: f32, rng: &mut R) -> f32 {
        let Some(span) = self.span(o, d, t_max) else { return 1.0 };
        let mut tr = 1.0;
        let mut t = span.t0;
        loop {
            t = self.step(t, rng);
            if t >= span.t1 {
                return tr;
            }
            tr *= 1.0 - (self.density(&span, t) / self.majorant).min(1.0);
            if tr <= 0.0 {
                return 0.0;
            }
        }
    }

    /// Samples a free flight along the segment from `o` along the unit direction `d` to the
    /// distance `t_max` (delta tracking). A medium that does not scatter is crossed with
    /// ratio tracking's estimate of its transmittance.
    pub fn sample<R: Random>(&self, o: Vec3, d: Vec3, t_max: f32, rng: &mut R) -> MediumSample {
        let pass = |weight| MediumSample { t: t_max, scattered: false, weight };
        if !self.scatters() {
            return pass(Rgb::splat(self.transmittance(o, d, t_max, rng)));
        }
        let Some(span) = self.span(o, d, t_max) else { return pass(Rgb::ONE) };
        let mut t = span.t0;
        loop {
            t = self.step(t, rng);
            if t >= span.t1 {
                return pass(Rgb::ONE);
            }
            if rng.next_1d() * self.majorant < self.density(&span, t) {
                return MediumSample { t, scattered: true, weight: self.albedo.rgb_at(o + d * t) };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::grid::Samples;
    use crate::sampling::Sampler;
    use crate::sampling::chi2::discrete_chi2;
    use glam::Affine3A;

    const A: f32 = 0.4;
    const B: f32 = 2.6;

    /// Extinction rising linearly from `a` at x = 0 to `b` at x = `len` (a two-value grid
    /// with values on the box's faces), scaled by `scale`, in the box [0, len] × [0, 1]².
    fn ramp(a: f32, b: f32, len: f32, scale: f32, albedo: Rgb) -> Heterogeneous {
        let to_local = Affine3A::from_scale(Vec3::new(1.0 / len, 1.0, 1.0));
        let grid = Grid::new([2, 1, 1], 1, vec![a, b], to_local, Samples::Corners, false);
        Heterogeneous::new(grid, scale, Volume::Constant(albedo))
    }

    /// The optical depth from x = 0 to x = t of the ramp from `a` to `b` over [0, 1].
    fn depth(a: f32, b: f32, t: f32) -> f64 {
        let (a, b, t) = (a as f64, b as f64, t as f64);
        a * t + (b - a) * t * t / 2.0
    }

    /// Ratio tracking's mean through a ramp (stretched to length 2, scaled by 0.5: the same
    /// optical depth) against `exp(-∫σt)`, within four standard errors; and the estimate of
    /// a segment ending halfway.
    #[test]
    fn ratio_tracking_gives_the_ramps_transmittance() {
        let m = ramp(A, B, 2.0, 0.5, Rgb::ONE);
        let mut rng = Sampler::new(&[21]);
        for (from, to, exact) in
            [(-1.0f32, 5.0f32, (-depth(A, B, 1.0)).exp()), (-1.0, 1.0, (-depth(A, B, 0.5)).exp()), (0.7, 0.7, 1.0)]
        {
            let o = Vec3::new(from, 0.5, 0.5);
            let n = 200_000;
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for _ in 0..n {
                let t = m.transmittance(o, Vec3::X, to - from, &mut rng) as f64;
                sum += t;
                sum2 += t * t;
            }
            let mean = sum / n as f64;
            let err = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
            assert!((mean - exact).abs() <= 4.0 * err + 1e-6, "{from}..{to}: {mean} ± {err} against {exact}");
        }
        // A ray beside the box crosses nothing.
        assert_eq!(m.transmittance(Vec3::new(-1.0, 1.5, 0.5), Vec3::X, 10.0, &mut rng), 1.0);
    }

    /// The histogram of delta tracking's collision distances through the ramp (plus the
    /// flights that pass) against `σt(t) exp(-τ(t))`, by a χ² test; the control (the
    /// reversed ramp's distribution, of the same optical depth) must fail.
    #[test]
    fn delta_tracking_samples_the_collision_distances_of_the_ramp() {
        let m = ramp(A, B, 1.0, 1.0, Rgb::splat(0.5));
        let bins = 24;
        let n = 200_000;
        let mut counts = vec![0u64; bins + 1];
        let mut rng = Sampler::new(&[22]);
        for _ in 0..n {
            let s = m.sample(Vec3::new(-0.5, 0.5, 0.5), Vec3::X, 1.5, &mut rng);
            if s.scattered {
                assert_eq!(s.weight, Rgb::splat(0.5));
                let x = s.t - 0.5;
                counts[((x * bins as f32) as usize).min(bins - 1)] += 1;
            } else {
                assert_eq!((s.t, s.weight), (1.5, Rgb::ONE));
                counts[bins] += 1;
            }
        }
        let expected = |a: f32, b: f32| -> Vec<f64> {
            let mut e: Vec<f64> = (0..bins)
                .map(|i| {
                    let (x0, x1) = (i as f32 / bins as f32, (i + 1) as f32 / bins as f32);
                    n as f64 * ((-depth(a, b, x0)).exp() - (-depth(a, b, x1)).exp())
                })
                .collect();
            e.push(n as f64 * (-depth(a, b, 1.0)).exp());
            e
        };
        discrete_chi2(&counts, &expected(A, B)).assert_pass();
        assert!(!discrete_chi2(&counts, &expected(B, A)).passed(), "the reversed ramp passed too");
    }

    /// A grid of one value is a homogeneous medium: delta tracking's pass rate and ratio
    /// tracking's mean are `exp(-σt d)`.
    #[test]
    fn a_constant_grid_is_a_homogeneous_medium() {
        let grid = Grid::new([3, 3, 3], 1, vec![0.8; 27], Affine3A::IDENTITY, Samples::CellCentred, false);
        let m = Heterogeneous::new(grid, 1.5, Volume::Constant(Rgb::ONE));
        let exact = (-1.2f64).exp();
        let mut rng = Sampler::new(&[23]);
        let n = 100_000;
        let o = Vec3::new(0.3, -2.0, 0.6);
        let passed = (0..n).filter(|_| !m.sample(o, Vec3::Y, 10.0, &mut rng).scattered).count();
        let p = passed as f64 / n as f64;
        assert!((p - exact).abs() < 4.0 * (exact * (1.0 - exact) / n as f64).sqrt(), "{p} against {exact}");
        let mean = (0..n).map(|_| m.transmittance(o, Vec3::Y, 10.0, &mut rng) as f64).sum::<f64>() / n as f64;
        assert!((mean - exact).abs() < 4.0 * (exact * (1.0 - exact) / n as f64).sqrt(), "{mean} against {exact}");
    }
}
