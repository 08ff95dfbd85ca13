//! Mitsuba's `homogeneous` medium: the same absorption and scattering coefficients
//! everywhere, so transmittance is analytic (`exp(-σt d)` per colour channel).
//!
//! Distances are sampled as Mitsuba 0.6's `balance` strategy does: a colour channel picked
//! uniformly, then an exponential distance with that channel's σt; the density is the
//! average over the channels (one-sample MIS between them), so no channel's weight is
//! unbounded. A medium that does not scatter (σs = 0) is never sampled: its transmittance
//! is applied analytically.

use super::MediumSample;
use crate::math::Rgb;
use glam::Vec3;

/// A homogeneous medium's coefficients (per unit length of the scene).
#[derive(Clone, Debug)]
pub struct Homogeneous {
    pub sigma_a: Rgb,
    pub sigma_s: Rgb,
    pub sigma_t: Rgb,
}

impl Homogeneous {
    pub fn new(sigma_a: Rgb, sigma_s: Rgb) -> Homogeneous {
        Homogeneous { sigma_a, sigma_s, sigma_t: sigma_a + sigma_s }
    }

    /// Whether light scatters in the medium (otherwise it only absorbs).
    #[inline]
    pub fn scatters(&self) -> bool {
        self.sigma_s.max_element() > 0.0
    }

    /// The fraction of light that crosses a distance `d`.
    #[inline]
    pub fn transmittance(&self, d: f32) -> Rgb {
        let t = (-self.sigma_t * d).exp();
        // exp(-0 · ∞) is NaN: a clear channel over an endless distance keeps everything.
        Vec3::select(self.sigma_t.cmpeq(Vec3::ZERO), Vec3::ONE, t)
    }

    /// Samples a free flight along a segment of length `t_max` (infinite for a ray that
    /// leaves the scene) from the uniform numbers `u_channel` and `u`.
    pub fn sample(&self, t_max: f32, u_channel: f32, u: f32) -> MediumSample {
        if !self.scatters() {
            return MediumSample { t: t_max, scattered: false, weight: self.transmittance(t_max) };
        }
        let channel = ((u_channel * 3.0) as usize).min(2);
        let density = self.sigma_t[channel];
        let t = if density > 0.0 { -(1.0 - u).ln() / density } else { f32::INFINITY };
        let scattered = t < t_max;
        let t = if scattered { t } else { t_max };
        let tr = self.transmittance(t);
        let (pdf, weight) = if scattered {
            let pdf = (self.sigma_t * tr).element_sum() / 3.0;
            (pdf, self.sigma_s * tr)
        } else {
            (tr.element_sum() / 3.0, tr)
        };
        let weight = if pdf > 0.0 { weight / pdf } else { Rgb::ZERO };
        MediumSample { t, scattered, weight }
    }

    /// The density of sampling a scattering event at `t` (per unit length), and the
    /// probability of flying past `t` (what [`Homogeneous::sample`] gives its two outcomes).
    pub fn densities(&self, t: f32) -> (f32, f32) {
        if !self.scatters() {
            return (0.0, 1.0);
        }
        let tr = self.transmittance(t);
        ((self.sigma_t * tr).element_sum() / 3.0, tr.element_sum() / 3.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    fn fog() -> Homogeneous {
        Homogeneous::new(Rgb::new(0.1, 0.3, 0.0), Rgb::new(0.5, 0.2, 0.9))
    }

    /// The expected weight of flying past `t_max` plus the integral of the scattering
    /// weights equals what the path's throughput must keep: `T(t_max)` for the flights that
    /// pass, and `∫ σs T(t) f(t) dt` for the events, estimated for a test function `f`.
    #[test]
    fn free_flights_are_unbiased() {
        let m = fog();
        let t_max = 2.5f32;
        let f = |t: f32| 1.0 + t * t;
        let mut rng = Sampler::new(&[11]);
        let n = 400_000;
        let (mut passed, mut scattered) = (Rgb::ZERO, Rgb::ZERO);
        let (mut passed2, mut scattered2) = (Rgb::ZERO, Rgb::ZERO);
        for _ in 0..n {
            let s = m.sample(t_max, rng.next_1d(), rng.next_1d());
            if s.scattered {
                let v = s.weight * f(s.t);
                scattered += v;
                scattered2 += v * v;
            } else {
                assert_eq!(s.t, t_max);
                passed += s.weight;
                passed2 += s.weight * s.weight;
            }
        }
        let n = n as f32;
        // ∫0^tmax σs e^{-σt t} (1 + t²) dt, per channel, by the midpoint rule.
        let steps = 20_000;
        let mut exact = Rgb::ZERO;
        for i in 0..steps {
            let t = (i as f32 + 0.5) * t_max / steps as f32;
            exact += m.sigma_s * m.transmittance(t) * f(t) * (t_max / steps as f32);
        }
        for c in 0..3 {
            let (mean, var) = (scattered[c] / n, scattered2[c] / n - (scattered[c] / n).powi(2));
            assert!((mean - exact[c]).abs() < 4.0 * (var / n).sqrt() + 1e-4, "events {c}: {mean} vs {}", exact[c]);
            let (mean, var) = (passed[c] / n, passed2[c] / n - (passed[c] / n).powi(2));
            let tr = m.transmittance(t_max)[c];
            assert!((mean - tr).abs() < 4.0 * (var / n).sqrt() + 1e-4, "passes {c}: {mean} vs {tr}");
        }
    }

    #[test]
    fn weights_are_the_ratios_of_the_densities() {
        let m = fog();
        let mut rng = Sampler::new(&[12]);
        for _ in 0..1000 {
            let s = m.sample(1.7, rng.next_1d(), rng.next_1d());
            let (p_event, p_pass) = m.densities(s.t);
            let tr = m.transmittance(s.t);
            let expected = if s.scattered { m.sigma_s * tr / p_event } else { tr / p_pass };
            assert!((s.weight - expected).abs().max_element() <= 1e-4 * expected.max_element());
        }
    }

    #[test]
    fn absorbing_media_are_never_sampled() {
        let m = Homogeneous::new(Rgb::new(1.0, 2.0, 0.0), Rgb::ZERO);
        let s = m.sample(0.5, 0.3, 0.999);
        assert!(!s.scattered);
        assert_eq!(s.weight, Rgb::new((-0.5f32).exp(), (-1.0f32).exp(), 1.0));
        assert_eq!(m.transmittance(f32::INFINITY), Rgb::new(0.0, 0.0, 1.0));
    }
}
