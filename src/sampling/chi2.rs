//! χ² goodness-of-fit harness: does a sampling routine draw what its pdf says?
//!
//! The sphere of directions is cut into cells of equal solid angle (uniform in `cos θ` and
//! `φ`); samples are histogrammed, the pdf is integrated over each cell by Simpson's rule,
//! cells with small expected counts are pooled, and Pearson's statistic is compared with
//! the χ² distribution. The pdf's total over the sphere is checked too (it must not exceed
//! one, and must match the fraction of samples that succeeded). Every user of the harness
//! has a negative control in the tests: a deliberately wrong pdf must be rejected.

use glam::{Vec2, Vec3};
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::f64::consts::PI;
use std::fmt;

use super::Sampler;

/// The sphere of directions, binned `res_z × res_phi` uniformly in `θ` and `φ` (so cells
/// near the poles are small and peaked lobes there are resolved).
#[derive(Clone, Copy, Debug)]
pub struct SphereDomain {
    pub res_z: usize,
    pub res_phi: usize,
}

impl Default for SphereDomain {
    fn default() -> Self {
        SphereDomain { res_z: 24, res_phi: 48 }
    }
}

impl SphereDomain {
    fn cell(&self, v: Vec3) -> Option<usize> {
        let v = v.as_dvec3();
        let len = v.length();
        if !(len.is_finite() && (len - 1.0).abs() < 1e-3) {
            return None;
        }
        let v = v / len;
        let theta = v.z.clamp(-1.0, 1.0).acos();
        let mut phi = v.y.atan2(v.x);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let iz = ((theta / PI * self.res_z as f64) as usize).min(self.res_z - 1);
        let ip = ((phi / (2.0 * PI) * self.res_phi as f64) as usize).min(self.res_phi - 1);
        Some(iz * self.res_phi + ip)
    }

    fn direction(theta: f64, phi: f64) -> Vec3 {
        let (s, c) = theta.sin_cos();
        Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32)
    }

    /// ∫ pdf sin θ dθ dφ over each cell, by adaptive Simpson quadrature: a cell is split
    /// in four until the Simpson estimate agrees with the sum over its quarters, so
    /// discontinuities (the edge of a light, of a cone) and narrow lobes are resolved.
    fn integrate(&self, pdf: &mut dyn FnMut(Vec3) -> f32) -> Vec<f64> {
        let dz = PI / self.res_z as f64;
        let dp = 2.0 * PI / self.res_phi as f64;
        let mut out = vec![0.0; self.res_z * self.res_phi];
        let mut f = |t: f64, p: f64| pdf(Self::direction(t, p)) as f64 * t.sin();
        for iz in 0..self.res_z {
            for ip in 0..self.res_phi {
                let (z0, p0) = (iz as f64 * dz, ip as f64 * dp);
                out[iz * self.res_phi + ip] = adaptive(&mut f, z0, z0 + dz, p0, p0 + dp, 0);
            }
        }
        out
    }
}

/// Simpson's rule on a rectangle from its 3×3 grid of values.
fn simpson(v: &[[f64; 3]; 3], area: f64) -> f64 {
    let w = [1.0, 4.0, 1.0];
    let mut s = 0.0;
    for a in 0..3 {
        for b in 0..3 {
            s += w[a] * w[b] * v[a][b];
        }
    }
    s * area / 36.0
}

fn grid(f: &mut dyn FnMut(f64, f64) -> f64, z0: f64, z1: f64, p0: f64, p1: f64) -> [[f64; 3]; 3] {
    // Sample a hair inside the rectangle so values on shared edges belong to it.
    let e = 1e-7;
    let zs = [z0 + e * (z1 - z0), 0.5 * (z0 + z1), z1 - e * (z1 - z0)];
    let ps = [p0 + e * (p1 - p0), 0.5 * (p0 + p1), p1 - e * (p1 - p0)];
    let mut v = [[0.0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            v[a][b] = f(zs[a], ps[b]);
        }
    }
    v
}

fn adaptive(f: &mut dyn FnMut(f64, f64) -> f64, z0: f64, z1: f64, p0: f64, p1: f64, depth: u32) -> f64 {
    const MIN_DEPTH: u32 = 2;
    const MAX_DEPTH: u32 = 7;
    let area = (z1 - z0) * (p1 - p0);
    let whole = simpson(&grid(f, z0, z1, p0, p1), area);
    let (zm, pm) = (0.5 * (z0 + z1), 0.5 * (p0 + p1));
    let quarters = [(z0, zm, p0, pm), (z0, zm, pm, p1), (zm, z1, p0, pm), (zm, z1, pm, p1)];
    let parts: Vec<f64> = quarters.iter().map(|&(a, b, c, d)| simpson(&grid(f, a, b, c, d), area / 4.0)).collect();
    let sum: f64 = parts.iter().sum();
    if depth >= MAX_DEPTH || (depth >= MIN_DEPTH && (sum - whole).abs() <= 1e-6 + 1e-4 * sum.abs()) {
        return sum;
    }
    quarters.iter().map(|&(a, b, c, d)| adaptive(f, a, b, c, d, depth + 1)).sum()
}

/// The outcome of one χ² test.
#[derive(Clone, Debug)]
pub struct Chi2Result {
    pub statistic: f64,
    pub dof: usize,
    pub p_value: f64,
    pub significance: f64,
    /// ∫ pdf over the sphere.
    pub pdf_integral: f64,
    /// Fraction of samples that produced a direction.
    pub success_fraction: f64,
    pub message: Option<String>,
}

impl Chi2Result {
    pub fn passed(&self) -> bool {
        self.message.is_none() && self.p_value >= self.significance
    }

    pub fn assert_pass(&self) {
        assert!(self.passed(), "χ² test failed: {self}");
    }
}

impl fmt::Display for Chi2Result {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "χ² = {:.1} with {} dof, p = {:.3e} (significance {:.1e}), ∫pdf = {:.4}, {:.4} of samples valid",
            self.statistic, self.dof, self.p_value, self.significance, self.pdf_integral, self.success_fraction
        )?;
        if let Some(m) = &self.message {
            write!(f, "; {m}")?;
        }
        Ok(())
    }
}

/// A configured χ² test over a domain.
pub struct Chi2Test {
    pub domain: SphereDomain,
    pub samples: usize,
    pub seed: u64,
    /// Significance level before the Šidák correction for `tests` repeated tests.
    pub significance: f64,
    pub tests: usize,
}

impl Chi2Test {
    pub fn new(domain: SphereDomain) -> Chi2Test {
        Chi2Test { domain, samples: 400_000, seed: 1, significance: 0.01, tests: 1 }
    }

    /// Runs the test: `sample` maps a uniform point of the unit square to a direction (or
    /// `None` when sampling fails), `pdf` is the density it claims, per unit solid angle.
    pub fn run<S: Into<Option<Vec3>>>(
        &self,
        mut sample: impl FnMut(Vec2) -> S,
        mut pdf: impl FnMut(Vec3) -> f32,
    ) -> Chi2Result {
        let cells = self.domain.res_z * self.domain.res_phi;
        let mut counts = vec![0u64; cells];
        let mut rng = Sampler::new(&[self.seed, 0xc412]);
        let mut ok = 0usize;
        let mut outside = 0usize;
        for _ in 0..self.samples {
            if let Some(v) = sample(rng.next_2d()).into() {
                match self.domain.cell(v) {
                    Some(c) => {
                        counts[c] += 1;
                        ok += 1;
                    }
                    None => outside += 1,
                }
            }
        }
        let integral = self.domain.integrate(&mut pdf);
        let pdf_integral: f64 = integral.iter().sum();
        let success_fraction = ok as f64 / self.samples as f64;
        let expected: Vec<f64> = integral.iter().map(|p| p * self.samples as f64).collect();
        let mut r = pearson(&counts, &expected, self.significance, self.tests);
        r.pdf_integral = pdf_integral;
        r.success_fraction = success_fraction;
        if outside > 0 {
            r.message = Some(format!("{outside} samples were not unit vectors"));
        } else if pdf_integral > 1.0 + 1e-3 {
            r.message = Some(format!("the pdf integrates to {pdf_integral:.4} > 1"));
        } else if (pdf_integral - success_fraction).abs() > 2e-3 + 5.0 / (self.samples as f64).sqrt() {
            r.message = Some(format!(
                "the pdf integrates to {pdf_integral:.4} but {success_fraction:.4} of the samples succeeded"
            ));
        }
        r
    }
}

/// Pearson's χ² test of observed counts against expected counts, pooling cells whose
/// expectation is below 5 (a cell expected empty that received samples fails outright).
fn pearson(counts: &[u64], expected: &[f64], significance: f64, tests: usize) -> Chi2Result {
    let mut order: Vec<usize> = (0..counts.len()).collect();
    order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]));
    let mut stat = 0.0;
    let mut dof = 0usize;
    let (mut pool_obs, mut pool_exp) = (0.0, 0.0);
    let mut message = None;
    for &i in &order {
        let (o, e) = (counts[i] as f64, expected[i]);
        if e <= 0.0 && o > 0.0 {
            message = Some(format!("cell {i} received {o} samples where the pdf is zero"));
        }
        if e < 5.0 {
            pool_obs += o;
            pool_exp += e;
            if pool_exp >= 5.0 {
                stat += (pool_obs - pool_exp).powi(2) / pool_exp;
                dof += 1;
                pool_obs = 0.0;
                pool_exp = 0.0;
            }
        } else {
            stat += (o - e).powi(2) / e;
            dof += 1;
        }
    }
    if pool_exp > 0.0 {
        stat += (pool_obs - pool_exp).powi(2) / pool_exp;
        dof += 1;
    } else if pool_obs > 0.0 {
        message = Some(format!("{pool_obs} samples fell where the pdf is zero"));
    }
    let dof = dof.saturating_sub(1).max(1);
    let p_value = match ChiSquared::new(dof as f64) {
        Ok(d) => 1.0 - d.cdf(stat),
        Err(_) => 0.0,
    };
    // Šidák correction for `tests` independent tests at the same level.
    let significance = 1.0 - (1.0 - significance).powf(1.0 / tests.max(1) as f64);
    Chi2Result {
        statistic: stat,
        dof,
        p_value,
        significance,
        pdf_integral: f64::NAN,
        success_fraction: f64::NAN,
        message,
    }
}

/// χ² test of counts of a discrete distribution against expected counts, at 1%.
pub fn discrete_chi2(counts: &[u64], expected: &[f64]) -> Chi2Result {
    pearson(counts, expected, 0.01, 1)
}

/// [`discrete_chi2`] as one of `tests` independent tests at 1% together (Šidák).
pub fn discrete_chi2_of(counts: &[u64], expected: &[f64], tests: usize) -> Chi2Result {
    pearson(counts, expected, 0.01, tests)
}
