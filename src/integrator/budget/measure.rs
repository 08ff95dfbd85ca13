//! What the measured iterations of a budget record ([`super`]): each contribution's
//! luminance and MIS shares turned into every candidate's second moment and, for the
//! realized model, the camera sample as each candidate would weigh it.
//!
//! **Second moments.** A budget `b'` scales the counts of the connection strategies by
//! `a = N'/N` and those of light tracing by `c = L'/L`, and leaves the camera path's own
//! (`s = 0`, next-event estimation) as they are. Under the balance heuristic a sample's
//! weighted contribution is `v = f / Σ_k n_k p_k`, and with the MIS shares `u`, `k_c`, `l` of
//! its path (the weights of its strategies summed by kind, [`Shares`]) the combined density
//! under `b'` is `Σ_k n_k p_k · (u + a k_c + c l)`. So `Σ v² / (u + a k_c + c l)` over the
//! samples of a pixel estimates `∫ f² / Σ n'_k p_k`, the second moment of that pixel's
//! estimate under `b'`, from samples of the budget in use (Grittmann et al.'s estimator).
//! That needs each sample's shares relative to the density it was drawn with: a pool
//! connection's MIS counts (`harmonic`'s `N M P̄_t`) are not its draw's (`N M P(y | z)`), so
//! its shares are re-based on the draw ([`Shares::drawn`]); with the counts' shares a vertex
//! drawn `r` times less often than the counts assume weighs `r` times too much in every
//! candidate's moment, and most in path tracing's. For a candidate with connections the camera
//! path's own samples still divide by the counts' connection share (their path's draw is
//! not made), so only path tracing's prediction is exact in expectation. A
//! path no strategy of `b'` can make gives an infinite moment, so a budget that would lose
//! light (a caustic of a point light with no light tracing) is never chosen.
//!
//! **The realized model** (`--pc-budget-model realized`, [`Realized`]). A pixel's estimate
//! of an iteration is a sum `Y = Σ_i v_i`, and `Var Y = E[Σ v_i²] + E[Σ_{i≠j} v_i v_j] −
//! (E Y)²`. The moments above predict only the first term's change; but the squared mean
//! and the products of a camera path's contributions change with the weights too. Moving
//! weight from the paths a camera path samples well to light tracing or to more draws
//! lowers their second moment and their squared mean alike, which the moments count as a
//! gain: on a constructed estimator (`tests` below) they predict many times its variance.
//! The realized model keeps the diagonal from every strategy's samples (`q`) and takes
//! the rest from the camera samples re-weighted as the candidate would weigh them (the
//! cross terms of the camera path's own strategies scaled by how much of their heavy tail two
//! iterations miss), so it needs no independence factor. Its predictions against renders of
//! fixed plans, beside the moments', are in `docs/results/budget.md`.

use crate::integrator::bidir::Delivery;
use crate::integrator::bidir::mis::StrategyCounts;
use crate::integrator::bidir::{Sink, Vertex};
use crate::integrator::budget::Plan;
use crate::integrator::budget::shares::{Shares, delivered_shares};
use glam::Vec2;

/// How the measured contributions count for the candidates: each candidate's count scales
/// `(a, c)` against the plan in use, and the least density ratio whose moment counts in full
/// (the measured iterations over the samples per pixel planned for, [`typical`]).
#[derive(Clone, Debug, Default)]
pub(super) struct Weighing {
    pub scales: Vec<(f64, f64)>,
    pub floor: f64,
}

impl Weighing {
    /// The weighing of `candidates` measured under `from`.
    pub(super) fn new(from: &Plan, candidates: &[Plan], floor: f64) -> Weighing {
        let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
        let scales = candidates
            .iter()
            .map(|p| {
                (
                    ratio(p.connections as f64, from.connections as f64),
                    ratio(p.splat_paths as f64, from.splat_paths as f64),
                )
            })
            .collect();
        Weighing { scales, floor }
    }

    /// Candidates weighed.
    pub(super) fn len(&self) -> usize {
        self.scales.len()
    }
}

/// The camera path's own strategies' part of a contribution's second moment under a
/// candidate whose combined density is `d` times the plan in use's: `v² u / d²`, counted as
/// [`typical`] counts the whole moment, `v² u / (d max(d, floor))`.
#[inline]
pub(super) fn own_moment(v: f32, s: &Shares, d: f64, floor: f64) -> f64 {
    if d > 0.0 && v.is_finite() && v > 0.0 {
        (v as f64).powi(2) * s.unidirectional as f64 / (d * typical(d, floor))
    } else {
        0.0
    }
}

/// What a contribution's second moment `v²` is divided by under a candidate whose combined
/// density is `d > 0` times the plan in use's: `d`, but at least `floor`, the measured
/// iterations over the samples per pixel the choice plans for (`--pc-budget-horizon`).
///
/// `v² / d` estimates the candidate's expected second moment, and a path the candidate
/// samples far less densely than the plan in use (`d` of 10⁻⁵: a path the connections find
/// that next-event estimation reaches only through a tiny solid angle) adds an expectation
/// made of a rare, huge sample. A render of `S` samples per pixel finds such a region of
/// paths with a chance of about `S d / T` (the `T` measured iterations found it about once),
/// and where that is below one its typical render misses the region's light, a squared error
/// of the region's squared mean: the expected `1 / d` weighed by `S d / T`, that is `S / T`.
/// So the moment is what the typical render at the horizon shows, not the expectation that
/// a few fireflies in a thousand renders carry. Without the floor a handful of pixels
/// whose connections found such paths can hold most of a candidate's predicted second
/// moment and make the path tracer look far worse than its renders are.
#[inline]
pub(super) fn typical(d: f64, floor: f64) -> f64 {
    d.max(floor)
}

/// Adds a contribution of luminance `v` and shares `s` to a pixel's moments: its value to
/// `x`, and `v² / (u + a k + c l)` ([`typical`]) for every candidate of `w` to `q`.
#[inline]
pub(super) fn accumulate(v: f32, s: &Shares, w: &Weighing, x: &mut f64, q: &mut [f64]) {
    if !(v.is_finite() && v > 0.0) {
        return;
    }
    let v = v as f64;
    *x += v;
    for (q, &(a, c)) in q.iter_mut().zip(&w.scales) {
        let d = s.combined(a, c);
        *q += if d > 0.0 { v * v / typical(d, w.floor) } else { f64::INFINITY };
    }
}

/// A measured pixel's largest contribution and its shares: the one sample whose moments
/// [`Top::rarity`] re-counts at the horizon when it is rare against the pixel's mean.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Top {
    pub v: f32,
    pub shares: Shares,
}

impl Top {
    /// Keeps `v` (with `shares`) when it is the largest so far.
    #[inline]
    pub(super) fn offer(&mut self, v: f32, shares: &Shares) {
        if v.is_finite() && v > self.v {
            *self = Top { v, shares: *shares };
        }
    }

    /// How much rarer than [`typical`] assumes this sample's region of paths is: its value
    /// over the `t` measured iterations' share of the pixel's mean `mean`, at least 1.
    ///
    /// [`typical`] counts each sample as a region the `t` measured iterations found about
    /// once. A region found with chance `ρ` per iteration has its paths' contributions `v`
    /// sum to about `ρ v` of the pixel's mean, so `ρ ≤ mean / v`, and where that is below
    /// `1 / t` a render at the horizon finds the region `t ρ` times as often as the floor
    /// assumes: the floor grows by `v / (t mean)`.
    pub(super) fn rarity(&self, mean: f64, t: f64) -> f64 {
        let v = self.v as f64;
        if v > 0.0 && mean > 0.0 { (v / (t * mean)).max(1.0) } else { 1.0 }
    }
}

/// How independent the pool connections of one camera vertex are, from their contributions
/// `v_1 … v_N` (the `N` draws of each camera vertex, those that found nothing counting as 0):
/// `raw` sums the second moment per draw, `Σ v_j² / N`, and `within` the unbiased variance
/// of the draws about their own camera vertex's mean, `(Σ v_j² − (Σ v_j)² / N) / (N − 1)`.
/// Given the camera vertex and the pool the draws are independent, so only `within` shrinks
/// with more draws; the moment estimator counts all of `raw` as if it did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Spread {
    pub raw: f64,
    pub within: f64,
}

impl Spread {
    fn add(&mut self, sum: f64, sum2: f64, draws: u32) {
        if draws < 2 {
            return;
        }
        let n = draws as f64;
        self.raw += sum2 / n;
        self.within += ((sum2 - sum * sum / n) / (n - 1.0)).max(0.0);
    }

    /// Adds `other`'s sums weighted by `k`.
    pub(super) fn add_weighted(&mut self, other: &Spread, k: f64) {
        self.raw += other.raw * k;
        self.within += other.within * k;
    }

    /// The share of the connections' second moment that more or fewer draws change:
    /// `within / raw`, in `[0, 1]`; `None` with nothing measured.
    pub fn independence(&self) -> Option<f64> {
        (self.raw > 0.0).then(|| (self.within / self.raw).clamp(0.0, 1.0))
    }
}

/// The moments of one tile's measured pixels in one iteration.
pub struct TileMoments {
    weighing: Weighing,
    /// Measured-pixel index of each entry.
    pub(super) ids: Vec<u32>,
    pub(super) x: Vec<f64>,
    /// `q` of entry `e` at `[e * C .. (e + 1) * C]`.
    pub(super) q: Vec<f64>,
    /// Per entry: the pool connections' second moment per draw and their variance within
    /// camera vertices, summed over the entry's camera vertices ([`Spread`]).
    pub(super) spread: Vec<Spread>,
    /// Per entry and candidate (like `q`): the camera sample as the candidate would weigh
    /// it, and its connections' correction for the candidate's number of draws ([`Realized`]).
    pub(super) realized: Vec<Realized>,
    /// Per entry: its largest contribution and that contribution's shares ([`Top`]).
    pub(super) top: Vec<Top>,
    /// Connections each camera vertex draws under the plan in use.
    draws: u32,
    /// The camera vertex whose connections are being summed: its depth, `Σ v`, `Σ v²`.
    vertex: (usize, f64, f64),
    /// The same per candidate, of its weights' draws `v / (u + a k + c l)`.
    vertex_realized: Vec<(f64, f64)>,
}

impl TileMoments {
    /// No entries yet, with room for `entries`, for the candidates of `weighing` and
    /// `draws` connections per camera vertex.
    pub(super) fn new(weighing: Weighing, draws: u32, entries: usize) -> TileMoments {
        let c = weighing.len();
        TileMoments {
            weighing,
            ids: Vec::with_capacity(entries),
            x: Vec::with_capacity(entries),
            q: Vec::with_capacity(entries * c),
            spread: Vec::with_capacity(entries),
            realized: Vec::with_capacity(entries * c),
            top: Vec::with_capacity(entries),
            draws,
            vertex: (0, 0.0, 0.0),
            vertex_realized: vec![(0.0, 0.0); c],
        }
    }

    /// Starts the entry of measured pixel `id`.
    pub fn begin(&mut self, id: usize) {
        self.end_vertex();
        self.ids.push(id as u32);
        self.x.push(0.0);
        self.q.extend(std::iter::repeat_n(0.0, self.weighing.len()));
        self.realized.extend(std::iter::repeat_n(Realized::default(), self.weighing.len()));
        self.spread.push(Spread::default());
        self.top.push(Top::default());
    }

    /// Adds a pool connection's contribution `v` (shares `s`) from the camera vertex at
    /// depth `t`. A camera vertex's draws arrive together; those that found nothing add
    /// nothing.
    fn connection(&mut self, t: usize, v: f32, s: &Shares) {
        if !(v.is_finite() && v > 0.0) {
            return;
        }
        if t != self.vertex.0 {
            self.end_vertex();
            self.vertex.0 = t;
        }
        let v = v as f64;
        self.vertex.1 += v;
        self.vertex.2 += v * v;
        for (acc, &(a, c)) in self.vertex_realized.iter_mut().zip(&self.weighing.scales) {
            let d = s.combined(a, c);
            if d > 0.0 {
                acc.0 += v / d;
                acc.1 += (v / d) * (v / d);
            }
        }
    }

    /// Adds the camera vertex being summed to the entry's [`Spread`] and, per candidate, its
    /// draws' correction to the entry's [`Realized`].
    pub fn end_vertex(&mut self) {
        let (_, sum, sum2) = std::mem::take(&mut self.vertex);
        let c = self.weighing.len();
        if let (Some(spread), true) = (self.spread.last_mut(), sum2 > 0.0) {
            spread.add(sum, sum2, self.draws);
            let at = self.realized.len() - c;
            for ((r, acc), &(a, _)) in
                self.realized[at..].iter_mut().zip(&mut self.vertex_realized).zip(&self.weighing.scales)
            {
                r.add_pairs(std::mem::take(acc), a, self.draws);
            }
        }
        self.vertex_realized.iter_mut().for_each(|acc| *acc = (0.0, 0.0));
    }

    /// Adds a contribution of luminance `v` and shares `shares` made by a strategy of
    /// [`Shares::class`] `class` of the camera sample.
    fn record(&mut self, v: f32, shares: &Shares, class: usize) {
        let c = self.weighing.len();
        let (Some(x), true) = (self.x.last_mut(), self.q.len() >= c) else { return };
        if !(v.is_finite() && v > 0.0) {
            return;
        }
        let at = self.q.len() - c;
        if let Some(top) = self.top.last_mut() {
            top.offer(v, shares);
        }
        let (v, floor) = (v as f64, self.weighing.floor);
        *x += v;
        // `accumulate`'s moments and the candidate's weighing of the sample, with each
        // candidate's combined density computed once.
        for ((q, r), &(a, l)) in self.q[at..].iter_mut().zip(&mut self.realized[at..]).zip(&self.weighing.scales) {
            let d = shares.combined(a, l);
            if d <= 0.0 {
                *q = f64::INFINITY;
                continue;
            }
            let typical = typical(d, floor);
            *q += v * v / typical;
            let own = if class == 1 { a } else { 1.0 };
            if own > 0.0 {
                let w = v * own / d;
                r.sample += w;
                r.diagonal += w * w;
                if class == 0 {
                    r.own_sample += w;
                    r.own_diagonal += w * w;
                }
            }
            r.own_moment += v * v * shares.unidirectional as f64 / (d * typical);
        }
    }
}

/// A camera sample as a candidate would weigh it (`--pc-budget-model realized`). Under a
/// budget that scales the connection counts by `a` and light tracing's by `c`, a contribution
/// `v` of the camera path's own strategies weighs `v' = v / (u + a k + c l)` and a
/// connection's `a v'` (the `N' = a N` draws estimated from the `N` made), so `sample` is the
/// candidate's estimate from the same camera path. A pixel's variance under the candidate is
/// `E[Σ_i v_i²] + E[Σ_{i≠j} v_i v_j] − (E Y)²`: the first, the diagonal, is the second moment
/// `Σ v² / (u + a k + c l)` that every strategy's samples estimate (light tracing's
/// included); the others come from the realized samples, `sample² − diagonal` over the
/// iterations and the product of different iterations' `sample`s. Given the camera vertex
/// the draws are independent, so their pairs' products, `N (N − 1)` of them made and
/// `N' (N' − 1)` wanted, are rescaled (`pairs`). Unlike the change of second moments alone
/// this keeps the squared means and the correlation of a camera path's contributions
/// (depths, draws of one vertex, the shared prefix): moving weight from the well-sampled
/// paths of the camera path to light tracing or to more draws lowers their second moment and
/// their squared mean as much, which the moments took for a gain.
///
/// The realized samples see the paths that the camera path's own strategies sample rarely
/// only as rarely, so in two iterations their sums miss much of a heavy tail. The diagonal
/// is taken from every strategy's samples for that reason; the cross terms cannot be, and
/// those with a contribution of the camera path's own strategies ([`Realized::cross`]) are
/// scaled by how much the realized samples miss of those strategies' diagonal (`own_moment`,
/// from every strategy's samples, over `own_diagonal`, realized; summed over the pixels as
/// relMSE weighs them: [`crate::integrator::budget::BudgetStats::missed`]): without it the
/// model underrates path tracing's variance where the realized samples miss much of that
/// tail. The connections' cross terms are not scaled: they have no such tail, and scaling
/// them too overrates the gain of more connections.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Realized {
    pub sample: f64,
    pub diagonal: f64,
    pub pairs: f64,
    /// The camera path's own strategies' share of `sample`, of `diagonal`, and of `q`
    /// (their second moment `Σ v² u / (u + a k + c l)²` from every strategy's samples).
    pub own_sample: f64,
    pub own_diagonal: f64,
    pub own_moment: f64,
}

impl Realized {
    /// The cross terms `sample² − diagonal` (draws' pairs rescaled), split into those with
    /// a contribution of the camera path's own strategies and the others (connections with
    /// connections).
    pub(super) fn cross(&self) -> (f64, f64) {
        let (own, other) = (self.own_sample, self.sample - self.own_sample);
        let with_own = own * own - self.own_diagonal + 2.0 * own * other;
        (with_own, other * other - (self.diagonal - self.own_diagonal) + self.pairs)
    }
}

impl Realized {
    /// Adds one camera vertex's draws under a candidate, `Σ v'` and `Σ v'²` over its `n`
    /// draws, for `a n` draws: the products of pairs, `(Σ v')² − Σ v'²` of them made with
    /// weight `a²` in `sample²`, count `a n (a n − 1) / (n (n − 1))`.
    fn add_pairs(&mut self, (sum, sum2): (f64, f64), a: f64, n: u32) {
        if n < 2 || a == 1.0 {
            return;
        }
        let n = n as f64;
        self.pairs += (a * (a * n - 1.0) / (n - 1.0) - a * a) * (sum * sum - sum2);
    }
}

/// A measured pixel's realized samples under one candidate ([`Realized`]), summed over the
/// measured iterations: what the realized model predicts the candidate's variance from.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct RealizedSums {
    /// `Σ sample` and `Σ sample²` over the iterations.
    pub sample: f64,
    pub square: f64,
    /// The cross terms ([`Realized::cross`]): with a contribution of the camera path's own
    /// strategies, and the others.
    pub with_own: f64,
    pub other: f64,
    /// The camera path's own strategies' diagonal as realized, and their second moment from
    /// every strategy's samples (light tracing's splats included, [`own_moment`]).
    pub own_diagonal: f64,
    pub own_moment: f64,
}

impl RealizedSums {
    /// Adds an iteration's realized camera sample of the pixel.
    pub(super) fn add(&mut self, r: &Realized) {
        let (with_own, other) = r.cross();
        self.sample += r.sample;
        self.square += r.sample * r.sample;
        self.with_own += with_own;
        self.other += other;
        self.own_diagonal += r.own_diagonal;
        self.own_moment += r.own_moment;
    }

    /// The variance of the pixel's estimate of an iteration under the candidate, from `t`
    /// iterations: the diagonal `q` (its second moment from every strategy's samples), the
    /// cross terms with the camera path's own strategies scaled by `missed` (how much of
    /// their heavy tail the realized samples miss), less the squared mean (the products of
    /// different iterations' samples).
    pub(super) fn variance(&self, q: f64, missed: f64, t: f64) -> f64 {
        (q + missed * self.with_own + self.other) / t
            - (self.sample * self.sample - self.square) / (t * (t - 1.0)).max(1.0)
    }
}

/// Wraps a camera sample's sink: passes everything on, and records each contribution's
/// luminance and shares into the tile's moments.
pub struct BudgetSink<'a, S> {
    pub inner: &'a mut S,
    pub moments: &'a mut TileMoments,
    pub pending: Shares,
}

impl<S: Sink> Sink for BudgetSink<'_, S> {
    #[inline]
    fn add(&mut self, s: usize, t: usize, value: crate::math::Rgb) {
        self.moments.record(crate::math::luminance(value), &self.pending, Shares::class(s, t));
        self.inner.add(s, t, value);
    }

    fn splat(&mut self, s: usize, t: usize, pos: Vec2, value: crate::math::Rgb) {
        // Camera passes of the pool integrators do not splat; their light tracing is the
        // pool's, measured through `SplatShares`.
        self.inner.splat(s, t, pos, value);
    }

    fn add_emission(&mut self, camera: &[Vertex], value: crate::math::Rgb) {
        self.moments.record(crate::math::luminance(value), &self.pending, 0);
        self.inner.add_emission(camera, value);
    }

    fn add_connection(&mut self, light: &[Vertex], camera: &[Vertex], c: crate::math::Rgb, w: f32) {
        let v = crate::math::luminance(c * w);
        let class = Shares::class(light.len(), camera.len());
        self.moments.record(v, &self.pending, class);
        if class == 1 {
            self.moments.connection(camera.len(), v, &self.pending);
        }
        self.inner.add_connection(light, camera, c, w);
    }

    fn observes(&self) -> bool {
        true
    }

    fn observe<C: StrategyCounts>(&mut self, delivery: &Delivery<'_, C>) {
        self.pending = delivered_shares(delivery);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The estimator of another budget's second moment is exact for a path sampled by two
    /// strategies with known densities: the balance-heuristic samples of budget `n` predict
    /// `∫ f² / Σ n' p` for budget `n'`.
    #[test]
    fn moments_of_another_budget_match_their_integral() {
        // On [0, 1]: f(x) = 1 + x; "unidirectional" samples uniform (p_u = 1, count 1),
        // "connections" with density p_k(x) = 2x (count n = 2).
        let f = |x: f64| 1.0 + x;
        let (pu, pk) = (|_x: f64| 1.0, |x: f64| 2.0 * x);
        let n = 2.0;
        let mut rng = crate::sampling::Sampler::new(&[5]);
        let scales = [(0.0, 0.0), (0.5, 0.0), (1.0, 0.0), (4.0, 0.0)];
        let w = Weighing { scales: scales.to_vec(), floor: 0.0 };
        let mut q = [0.0f64; 4];
        let mut x = 0.0;
        let runs = 200_000;
        let shares = |y: f64| {
            let total = pu(y) + n * pk(y);
            Shares { unidirectional: (pu(y) / total) as f32, connection: (n * pk(y) / total) as f32, light_trace: 0.0 }
        };
        for _ in 0..runs {
            // One unidirectional sample and `n` connection samples per run.
            let y = rng.next_1d() as f64;
            let v = f(y) / (pu(y) + n * pk(y));
            accumulate(v as f32, &shares(y), &w, &mut x, &mut q);
            for _ in 0..n as usize {
                let y = (rng.next_1d() as f64).sqrt();
                let v = f(y) / (pu(y) + n * pk(y));
                accumulate(v as f32, &shares(y), &w, &mut x, &mut q);
            }
        }
        assert!((x / runs as f64 - 1.5).abs() < 0.01, "mean {}", x / runs as f64);
        for (k, &(a, _)) in scales.iter().enumerate() {
            // ∫ (1+x)² / (1 + a n 2x) dx by the midpoint rule.
            let m = 100_000;
            let exact: f64 = (0..m)
                .map(|i| {
                    let y = (i as f64 + 0.5) / m as f64;
                    f(y) * f(y) / (pu(y) + a * n * pk(y))
                })
                .sum::<f64>()
                / m as f64;
            let est = q[k] / runs as f64;
            assert!((est / exact - 1.0).abs() < 0.01, "scale {a}: {est} against {exact}");
        }
    }

    /// A connection drawn with another density than the MIS counts assume (PCBPT's and
    /// SPCBPT's `harmonic` counts against their draws' PMFs): its shares re-based on the draw
    /// ([`Shares::drawn`]) estimate the path tracer's second moment `∫ f² / p_u` exactly, and
    /// the shares of the MIS counts alone miss it.
    #[test]
    fn drawn_shares_give_the_path_tracer_s_moment_whatever_the_counts() {
        let f = |x: f64| 1.0 + x;
        // Draws with density 2x; the MIS counts assume a uniform density.
        let (pu, drawn, assumed) = (|_x: f64| 1.0, |x: f64| 2.0 * x, |_x: f64| 1.0);
        let n = 2.0;
        let mut rng = crate::sampling::Sampler::new(&[7]);
        let w = Weighing { scales: vec![(0.0, 0.0)], floor: 0.0 };
        let (mut rebased, mut plain, mut x) = ([0.0f64], [0.0f64], 0.0);
        let runs = 400_000;
        // The MIS weights' combined density and shares, from the assumed counts.
        let total = |y: f64| pu(y) + n * assumed(y);
        let shares = |y: f64| Shares {
            unidirectional: (pu(y) / total(y)) as f32,
            connection: (n * assumed(y) / total(y)) as f32,
            light_trace: 0.0,
        };
        for _ in 0..runs {
            let y = rng.next_1d() as f64;
            let v = (f(y) / total(y)) as f32;
            accumulate(v, &shares(y), &w, &mut x, &mut rebased);
            accumulate(v, &shares(y), &w, &mut x, &mut plain);
            for _ in 0..n as usize {
                let y = (rng.next_1d() as f64).max(1e-12).sqrt();
                let shares = shares(y);
                // The MIS weight of the assumed counts over the density drawn with.
                let v = (n * assumed(y) / total(y) * f(y) / (n * drawn(y))) as f32;
                accumulate(v, &shares.drawn((assumed(y) / drawn(y)) as f32), &w, &mut x, &mut rebased);
                accumulate(v, &shares, &w, &mut x, &mut plain);
            }
        }
        // Both halves of `x` estimate ∫ f = 1.5 (each sample was added twice).
        assert!((x / 2.0 / runs as f64 - 1.5).abs() < 0.01, "mean {}", x / 2.0 / runs as f64);
        // ∫ (1 + x)² dx = 7/3.
        let exact = 7.0 / 3.0;
        let (est, miss) = (rebased[0] / runs as f64, plain[0] / runs as f64);
        assert!((est / exact - 1.0).abs() < 0.01, "re-based: {est} against {exact}");
        assert!((miss / exact - 1.0).abs() > 0.05, "the MIS counts' shares should miss: {miss} against {exact}");
        // A draw as MIS assumed it (and a ratio that is no number) leaves the shares.
        let s = Shares { unidirectional: 0.25, connection: 0.5, light_trace: 0.25 };
        assert_eq!(s.drawn(1.0), s);
        assert_eq!(s.drawn(f32::NAN), s);
        assert_eq!(s.drawn(2.0), Shares { unidirectional: 0.5, connection: 0.5, light_trace: 0.5 });
    }

    /// The realized model predicts another budget's variance where the change of second
    /// moments does not: a camera sample of one "unidirectional" sample and `N` independent
    /// "connection" draws, with the balance heuristic, re-weighted for `N' = a N` draws,
    /// against the exact variance of the `N'`-draw estimator. The moments leave out the
    /// squared means, which change with the weights: they must miss by more.
    #[test]
    fn realized_variance_of_another_budget_matches_its_integral() {
        let f = |x: f64| 1.0 + x;
        let (pu, pk) = (|_x: f64| 1.0, |x: f64| 2.0 * x);
        let n = 4u32;
        let scales = vec![(1.0, 0.0), (0.0, 0.0), (0.25, 0.0), (0.5, 0.0), (2.0, 0.0)];
        let c = scales.len();
        let mut rng = crate::sampling::Sampler::new(&[11]);
        let runs = 2_000_000;
        let shares = |y: f64, draws: f64| {
            let total = pu(y) + draws * pk(y);
            Shares {
                unidirectional: (pu(y) / total) as f32,
                connection: (draws * pk(y) / total) as f32,
                light_trace: 0.0,
            }
        };
        let (mut sums, mut x1, mut x2, mut q) = (vec![RealizedSums::default(); c], 0.0, 0.0, vec![0.0; c]);
        let w = Weighing { scales: scales.clone(), floor: 0.0 };
        let mut m = TileMoments::new(w.clone(), n, 0);
        for run in 0..runs {
            if run % 10_000 == 0 {
                m = TileMoments::new(w.clone(), n, 0);
            }
            m.begin(0);
            let y = rng.next_1d() as f64;
            m.record((f(y) / (pu(y) + n as f64 * pk(y))) as f32, &shares(y, n as f64), 0);
            for _ in 0..n {
                let y = (rng.next_1d() as f64).sqrt();
                let v = (f(y) / (pu(y) + n as f64 * pk(y))) as f32;
                m.record(v, &shares(y, n as f64), 1);
                m.connection(2, v, &shares(y, n as f64));
            }
            m.end_vertex();
            let e = m.ids.len() - 1;
            x1 += m.x[e];
            x2 += m.x[e] * m.x[e];
            for k in 0..c {
                let r = m.realized[e * c + k];
                let (with_own, other) = r.cross();
                assert!((with_own + other - (r.sample * r.sample - r.diagonal + r.pairs)).abs() < 1e-9);
                sums[k].add(&r);
                q[k] += m.q[e * c + k];
            }
        }
        let t = runs as f64;
        let variance = |s1: f64, s2: f64| (s2 - s1 * s1 / t) / (t - 1.0);
        let measured = variance(x1, x2);
        let integral = |g: &dyn Fn(f64) -> f64| {
            let m = 100_000;
            (0..m).map(|i| g((i as f64 + 0.5) / m as f64)).sum::<f64>() / m as f64
        };
        for (k, &(a, _)) in scales.iter().enumerate() {
            let n2 = a * n as f64;
            let g = |x: f64| f(x) / (pu(x) + n2 * pk(x));
            let var_u = integral(&|x| g(x) * g(x)) - integral(&g).powi(2);
            let var_k = integral(&|x| g(x) * g(x) * pk(x)) - integral(&|x| g(x) * pk(x)).powi(2);
            let exact = var_u + n2 * var_k;
            let missed = sums[k].own_moment / sums[k].own_diagonal;
            assert!((missed - 1.0).abs() < 0.02, "a = {a}: the realized samples missed {missed}");
            let realized = sums[k].variance(q[k], missed, t);
            let moments = measured + (q[k] - q[0]) / t;
            assert!((realized / exact - 1.0).abs() < 0.03, "a = {a}: realized {realized} against {exact}");
            if a != 1.0 {
                assert!((moments / exact - 1.0).abs() > 0.1, "a = {a}: moments {moments} close to {exact}");
            }
        }
    }

    /// A path the candidate samples at a density ratio `d` under the floor counts `v² / floor`
    /// (its expected `v² / d` times its chance `d / floor` of being found at the horizon),
    /// one at or above it `v² / d`, and one that no strategy of the candidate makes stays
    /// infinite whatever the floor; with no floor every path counts its expectation.
    #[test]
    fn rarely_sampled_paths_count_as_often_as_the_horizon_finds_them() {
        let u = 1e-5f32;
        let s = Shares { unidirectional: u, connection: 1.0 - u, light_trace: 0.0 };
        // The plan in use, path tracing, half the connections.
        let scales = [(1.0, 0.0), (0.0, 0.0), (0.5, 0.0)];
        let half = u as f64 + 0.5 * (1.0 - u as f64);
        let floor = 1.0 / 64.0;
        let (mut x, mut q) = (0.0, [0.0; 3]);
        accumulate(2.0, &s, &Weighing { scales: scales.to_vec(), floor }, &mut x, &mut q);
        assert_eq!(x, 2.0);
        let close = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-6;
        assert!(close(q[0], 4.0) && close(q[1], 4.0 / floor) && close(q[2], 4.0 / half), "{q:?}");
        // The camera path's own share of it, likewise.
        let own = own_moment(2.0, &s, s.combined(0.0, 0.0), floor);
        assert!(close(own, 4.0 / floor), "{own}");
        assert!(close(own_moment(2.0, &s, half, floor), 4.0 * u as f64 / (half * half)));
        let mut none = [0.0; 3];
        accumulate(2.0, &s, &Weighing { scales: scales.to_vec(), floor: 0.0 }, &mut x, &mut none);
        assert!(close(none[1], 4.0 / u as f64), "{none:?}");
        let light = Shares { unidirectional: 0.0, connection: 0.0, light_trace: 1.0 };
        let mut q = [0.0; 2];
        accumulate(1.0, &light, &Weighing { scales: vec![(1.0, 1.0), (1.0, 0.0)], floor: 0.5 }, &mut x, &mut q);
        assert!(q[0] == 1.0 && q[1].is_infinite(), "{q:?}");
    }

    /// A budget without the only strategy that makes a path predicts an infinite moment.
    #[test]
    fn losing_a_paths_only_strategy_costs_an_infinite_moment() {
        let mut x = 0.0;
        let mut q = [0.0; 2];
        let s = Shares { unidirectional: 0.0, connection: 0.0, light_trace: 1.0 };
        accumulate(1.0, &s, &Weighing { scales: vec![(1.0, 1.0), (1.0, 0.0)], floor: 0.0 }, &mut x, &mut q);
        assert_eq!(q[0], 1.0);
        assert!(q[1].is_infinite());
    }

    #[test]
    fn spread_separates_camera_vertices_and_counts_draws_that_found_nothing() {
        let mut m = TileMoments::new(Weighing { scales: vec![(1.0, 1.0)], floor: 0.0 }, 4, 0);
        // Pixel 0: a camera vertex whose four draws agree (no spread at all).
        m.begin(0);
        for _ in 0..4 {
            m.connection(2, 0.5, &Shares::default());
        }
        // Pixel 1: one draw of four finds light at depth 2, two of four at depth 3.
        m.begin(1);
        m.connection(2, 2.0, &Shares::default());
        m.connection(3, 1.0, &Shares::default());
        m.connection(3, 1.0, &Shares::default());
        m.end_vertex();
        assert_eq!(m.spread[0], Spread { raw: 0.25, within: 0.0 });
        assert_eq!(m.spread[0].independence(), Some(0.0));
        // Depth 2: Σv² = 4, Σv = 2: raw 1, within (4 − 1) / 3 = 1. Depth 3: Σv² = 2, Σv = 2:
        // raw 0.5, within (2 − 1) / 3.
        let s = m.spread[1];
        assert!((s.raw - 1.5).abs() < 1e-12 && (s.within - (1.0 + 1.0 / 3.0)).abs() < 1e-12, "{s:?}");
        assert!((s.independence().unwrap() - 8.0 / 9.0).abs() < 1e-12);
        // Nothing measured, or one draw per vertex: no estimate.
        assert_eq!(Spread::default().independence(), None);
        let mut one = Spread::default();
        one.add(1.0, 1.0, 1);
        assert_eq!(one.independence(), None);
    }
}
