//! The correction of pool connections' counts for their correlation (`--pc-mis
//! correlated`), a [`StrategyCounts::density_factors`] of PCBPT's and SPCBPT's counts.
//!
//! [`StrategyCounts::density_factors`]: crate::integrator::bidir::mis::StrategyCounts::density_factors

/// The correction of pool connections' counts for correlation (`--pc-mis correlated`; the
/// idea of Grittmann, Georgiev and Slusallek, "Correlation-aware multiple importance sampling
/// for bidirectional rendering algorithms", CGF 2021, there for next-event estimation with
/// several shadow rays): the `N` connections made from one camera vertex share its camera
/// prefix, so where that prefix carries the randomness they are worth fewer than `N`
/// independent samples. Each strategy `s' ≥ 2, t' ≥ 2` has its count multiplied by
///
/// `c = max(P_E / (P_E + P_L - P_E P_L), 1/N)`,
///
/// where `P_E = Π min(A pE(x_i), 1)` over the camera prefix's vertices beyond the primary
/// hit, `P_L = Π min(A pL(x_i), 1) / N` over the light prefix, and `A` the area of the
/// pixel's footprint at the primary hit, `1 / (W·H pE(x_{n-2}))`: `P` is how likely the
/// prefix lands again within a footprint of where it is, 1 for a fully determined one
/// (Dirac vertices count as determined). A fully determined camera prefix keeps `N`; a
/// random camera prefix joined to a nearly determined light prefix counts as one sample.
/// `c` is a function of the path's densities alone, the same whichever strategy sampled it,
/// so the weights still sum to one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Correlation {
    /// `W·H`.
    pub pixels: f32,
    /// `N`.
    pub connections: f32,
}

impl Correlation {
    /// The factors `c` of the strategies `0..n` of a path of `n` vertices whose densities
    /// are `pl(i)`, `pe(i)`, into `out` (1 where a strategy is no pool connection).
    pub fn factors(&self, n: usize, pl: impl Fn(usize) -> f32, pe: impl Fn(usize) -> f32, out: &mut [f32]) {
        out[..n].fill(1.0);
        if n < 4 {
            return;
        }
        let area = 1.0 / (self.pixels * pe(n - 2));
        if !(area.is_finite() && area > 0.0) {
            return;
        }
        let prob = |p: f32| if p <= 0.0 { 1.0 } else { (area * p).min(1.0) };
        // P_E of strategy s', over x_{s'}..x_{n-3}, from the camera end.
        let mut p_e = 1.0f32;
        for s in (2..=n - 2).rev() {
            if s <= n - 3 {
                p_e *= prob(pe(s));
            }
            out[s] = p_e;
        }
        // P_L of strategy s', over x_0..x_{s'-1}, from the light end; `out[s']` holds P_E.
        let mut p_l = prob(pl(0));
        for (s, o) in out.iter_mut().enumerate().take(n - 1).skip(2) {
            p_l *= prob(pl(s - 1));
            let (p_e, p_l) = (*o, p_l / self.connections);
            let denom = p_e + p_l - p_e * p_l;
            let c = if denom > 0.0 { p_e / denom } else { 1.0 };
            *o = c.max(1.0 / self.connections);
        }
    }
}
