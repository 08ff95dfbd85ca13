//! The shares of a path's MIS weights by kind of strategy (the camera path's own, pool
//! connections, light tracing): what the budget's efficiency estimate predicts another
//! budget's second moments from ([`measure`](super::measure)).

use crate::integrator::bidir::mis::{CAP, FullPath, StrategyCounts, count_table, path_pdfs, remap0};
use crate::integrator::bidir::pool::SplatRecorder;
use crate::integrator::bidir::{Connection, Delivery, Vertex};
use crate::math::{Rgb, luminance};
use crate::scene::Scene;
use glam::Vec2;

/// The kinds of strategies an integrator with a light pool can budget: the camera path's own
/// (`s = 0` and next-event estimation), pool connections (`s, t >= 2`) and light tracing
/// (`t = 1`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Shares {
    pub unidirectional: f32,
    pub connection: f32,
    pub light_trace: f32,
}

impl Shares {
    /// The class of strategy `(s, t)`: 0 unidirectional, 1 connection, 2 light tracing.
    #[inline]
    pub fn class(s: usize, t: usize) -> usize {
        match (s, t) {
            (_, 1) => 2,
            (0 | 1, _) => 0,
            _ => 1,
        }
    }

    /// The path's combined density under counts that scale the connections' by `a` and
    /// light tracing's by `c`, over its combined density now: `u + a k + c l`.
    #[inline]
    pub fn combined(&self, a: f64, c: f64) -> f64 {
        self.unidirectional as f64 + a * self.connection as f64 + c * self.light_trace as f64
    }

    /// The shares of a pool connection whose strategy's count in the MIS weights is `r`
    /// times the count its draw had (`n / n_drawn`: the count MIS gives the strategy, such
    /// as `harmonic`'s `N M P̄_t`, times the draw's factor `1 / (N M P(y | z))`), re-based on
    /// the density the sample was drawn with: the camera path's own and light tracing's
    /// shares times `r`. Whatever the counts, a sample of the weighted contribution `v` then
    /// estimates `∫ f² / Σ n'_k p_k` by `v² / combined(a, c)` (the counts `n'` of a budget
    /// with drawn counts, [`crate::integrator::budget::measure`]); with the MIS counts' shares it would
    /// estimate `r` times as much for a connection that drew its vertex `r` times less often
    /// than MIS assumed, which overrates path tracing's variance most (as with SPCBPT's
    /// harmonic counts, whose draws follow `Γ`, not the counts). `r = 1`
    /// (BDPT's connections, exact counts) leaves them as they are.
    pub fn drawn(self, r: f32) -> Shares {
        if !(r.is_finite() && r > 0.0) {
            return self;
        }
        Shares { unidirectional: self.unidirectional * r, light_trace: self.light_trace * r, ..self }
    }

    fn add(&mut self, class: usize, x: f32) {
        match class {
            0 => self.unidirectional += x,
            1 => self.connection += x,
            _ => self.light_trace += x,
        }
    }
}

/// The balance-heuristic weights of all strategies of the path that joins `light` and
/// `camera` (with the connection `conn`, `None` for `s = 0`), summed by [`Shares::class`]:
/// they sum to one. With other counts `n'` that scale each class's counts by `a_k`, the
/// path's combined density changes by `Σ_k a_k share_k`, which is what an efficiency
/// estimate needs to predict the second moment of another budget from this one's samples.
/// `drawn`, the factor of a connection drawn from a pool (`1 / (N M P(y | z))`), re-bases
/// them on the density it was drawn with ([`Shares::drawn`]); they then sum to one only
/// where the draw's count is the MIS count.
pub fn mis_shares_with(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    conn: Option<&Connection>,
    counts: &impl StrategyCounts,
    drawn: Option<f32>,
) -> Shares {
    let full = FullPath { light, camera };
    let (n, s) = (full.len(), light.len());
    let p = path_pdfs::<CAP>(scene, light, camera, conn);
    let table = count_table(&p, &full, counts);
    // The terms `n_i p_i / (n_s p_s)` of the balance heuristic's walk, by class.
    let nee = |i: usize| if i == 1 { p.nee_ratio } else { 1.0 };
    let n_s = table[s] * nee(s);
    let mut shares = Shares::default();
    if n_s.is_nan() || n_s <= 0.0 {
        return shares;
    }
    let term = |i: usize, r: f32| if p.valid(i) && table[i] > 0.0 { r * nee(i) * table[i] / n_s } else { 0.0 };
    let mut sum = 1.0f32;
    shares.add(Shares::class(s, n - s), 1.0);
    let mut r = 1.0f32;
    for i in (0..s).rev() {
        r *= remap0(p.pe[i]) / remap0(p.pl[i]);
        let x = term(i, r);
        sum += x;
        shares.add(Shares::class(i, n - i), x);
    }
    let mut r = 1.0f32;
    for i in s..n.saturating_sub(1) {
        r *= remap0(p.pl[i]) / remap0(p.pe[i]);
        let x = term(i + 1, r);
        sum += x;
        shares.add(Shares::class(i + 1, n - i - 1), x);
    }
    if !(sum.is_finite() && sum > 0.0) {
        return Shares::default();
    }
    let shares = Shares {
        unidirectional: shares.unidirectional / sum,
        connection: shares.connection / sum,
        light_trace: shares.light_trace / sum,
    };
    match drawn {
        Some(scale) => shares.drawn(table[s] * scale),
        None => shares,
    }
}

/// [`mis_shares_with`], evaluating the connection itself.
pub fn mis_shares(scene: &Scene, light: &[Vertex], camera: &[Vertex], counts: &impl StrategyCounts) -> Shares {
    let conn = match light.last() {
        Some(qs) => match Connection::new(scene, qs, &camera[camera.len() - 1]) {
            Some(c) => Some(c),
            None => return Shares::default(),
        },
        None => None,
    };
    mis_shares_with(scene, light, camera, conn.as_ref(), counts, None)
}

/// [`mis_shares_with`] of a delivered path.
#[inline]
pub fn delivered_shares<C: StrategyCounts>(d: &Delivery<'_, C>) -> Shares {
    mis_shares_with(d.scene, d.light, d.camera, d.conn, d.counts, d.drawn)
}

/// A light-tracing splat's luminance and MIS shares.
#[derive(Clone, Copy, Debug)]
pub struct SplatShares {
    pub pos: Vec2,
    pub value: f32,
    pub shares: Shares,
}

/// Records each splat of a pool's light tracing with its MIS shares.
pub struct ShareRecorder;

impl SplatRecorder for ShareRecorder {
    type Pending = Shares;
    type Record = SplatShares;

    fn observe<C: StrategyCounts>(&self, delivery: &Delivery<'_, C>) -> Shares {
        delivered_shares(delivery)
    }

    fn record(&self, shares: Shares, pos: Vec2, value: Rgb) -> SplatShares {
        SplatShares { pos, value: luminance(value), shares }
    }
}
