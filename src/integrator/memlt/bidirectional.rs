//! The bidirectional mutation of path-space Metropolis (Veach and Guibas 1997; contract
//! `memlt.md`, "Mutators"): delete a stretch of the current path, regenerate it from both
//! kept ends with a new length, join the ends.
//!
//! A path of `k` edges is seen as `k + 1` edges counting the choice of its light point (the
//! edge "before" `x_0`). A run of `kd` consecutive ones is deleted, starting at edge `a`:
//! `x_0 .. x_{a-1}` and `x_{a+kd-1} .. x_k` stay (the pinhole always does), and `ka` new
//! edges take their place. As in Mitsuba 0.6, the new length `k - kd + ka` is drawn first,
//! `∝ 2^-|Δk|` around the current one, then `kd` `∝ 2^-|kd - 2|` (a vertex replaced is the
//! most likely move) among the lengths that reach it, and `a` uniformly; the `ka - 1` new
//! vertices are split uniformly into a light-side and a camera-side walk. Regenerating the
//! light point (`a = 0`) deletes and adds at least two edges, and a move that keeps the
//! length deletes at least two (one would give the same path back), so that every move has
//! its reverse. The proposal density sums over every split that could have produced the
//! new stretch ([`stretch_density`]).

use crate::integrator::bidir::Vertex;
use crate::integrator::memlt::path::{Measured, contribution, regenerate, stretch_density};
use crate::integrator::metropolis::bootstrap::ChainPaths;
use crate::integrator::stats::Counters;
use crate::sampling::Random;
use crate::scene::Scene;

/// Path lengths (in edges) the chains may visit.
#[derive(Clone, Copy, Debug)]
pub struct Lengths {
    pub min: usize,
    pub max: usize,
    /// A direct-light pass renders the paths of one edge and the two-edge paths through a
    /// rough vertex: the chains' two-edge paths are those through a Dirac lobe alone.
    pub direct_separate: bool,
    /// A specular pass renders the paths whose every scattering vertex was left through a
    /// Dirac lobe ([`crate::integrator::memlt::specular_pass`]): the chains' paths have a rough vertex.
    pub specular_separate: bool,
}

impl Lengths {
    /// Whether path `x` is one of the chains' (its contribution is zero to them otherwise).
    #[inline]
    pub fn covers(&self, x: &[Vertex]) -> bool {
        let k = x.len().saturating_sub(1);
        (self.min..=self.max).contains(&k)
            && !(self.direct_separate && k == 2 && !x[1].delta)
            && !(self.specular_separate && k >= 2 && x[1..k].iter().all(|v| v.delta))
    }

    /// The paths the chains take, as the bootstrap's BDPT samples count them.
    pub(crate) fn chain_paths(&self) -> ChainPaths {
        ChainPaths {
            min_edges: self.min + usize::from(self.direct_separate),
            dirac_two_edges: self.direct_separate,
            dirac_only: !self.specular_separate,
        }
    }
}

/// `2^-n`, exactly.
#[inline]
fn half_pow(n: usize) -> f64 {
    debug_assert!(n < 1023);
    f64::from_bits((1023 - n as u64) << 52)
}

/// `2^-|n - centre|` normalised over `range`: a two-sided geometric distribution.
fn two_sided_pmf(n: usize, centre: usize, range: std::ops::RangeInclusive<usize>) -> f64 {
    if !range.contains(&n) {
        return 0.0;
    }
    half_pow(n.abs_diff(centre)) / range.map(|m| half_pow(m.abs_diff(centre))).sum::<f64>()
}

/// A draw from [`two_sided_pmf`] (`range` not empty).
fn two_sided_sample(u: f32, centre: usize, range: std::ops::RangeInclusive<usize>) -> usize {
    let u = u as f64 * range.clone().map(|m| half_pow(m.abs_diff(centre))).sum::<f64>();
    let mut acc = 0.0;
    let mut last = *range.start();
    for n in range {
        acc += half_pow(n.abs_diff(centre));
        last = n;
        if u < acc {
            break;
        }
    }
    last
}

/// The deletion lengths allowed when a path of `k` edges is to become one of `k2`: enough
/// to reach `k2`, and at least two when the length stays (deleting one edge and adding one
/// back gives the same path), up to all `k + 1`.
fn deletions(k: usize, k2: usize) -> std::ops::RangeInclusive<usize> {
    let least = if k == k2 { 2 } else { 1 };
    least.max((k + 1).saturating_sub(k2))..=k + 1
}

/// The edges a deletion of `kd` edges, replaced by `ka`, may start at in a path of `k`
/// edges. The light point's choice (`a = 0`) is not an edge one can re-join (`kd = 1`), and
/// regenerating it needs a new vertex on each side of the join (`ka ≥ 2`).
fn starts(k: usize, kd: usize, ka: usize) -> std::ops::Range<usize> {
    let first = usize::from(kd == 1 || ka == 1);
    first..(k + 2).saturating_sub(kd).max(first)
}

/// Probability of the move `(kd, a, ka)` of a path of `k` edges: the new length
/// `k2 = k - kd + ka` drawn `∝ 2^-|k2 - k|` among the lengths allowed, the deletion length
/// `kd` `∝ 2^-|kd - 2|` among [`deletions`], its start `a` uniformly among [`starts`].
pub fn move_pmf(k: usize, kd: usize, a: usize, ka: usize, lengths: Lengths) -> f64 {
    if ka == 0 || kd == 0 || kd > k + 1 {
        return 0.0;
    }
    let k2 = k - kd + ka;
    let range = starts(k, kd, ka);
    if !range.contains(&a) {
        return 0.0;
    }
    two_sided_pmf(k2, k, lengths.min..=lengths.max) * two_sided_pmf(kd, 2, deletions(k, k2)) / range.len() as f64
}

/// Every move `(kd, a, ka)` of a path of `k` edges with its probability.
#[cfg(test)]
fn moves(k: usize, lengths: Lengths) -> Vec<(usize, usize, usize, f64)> {
    let mut all = Vec::new();
    for k2 in lengths.min..=lengths.max {
        for kd in deletions(k, k2) {
            let ka = k2 + kd - k;
            for a in starts(k, kd, ka) {
                all.push((kd, a, ka, move_pmf(k, kd, a, ka, lengths)));
            }
        }
    }
    all
}

/// A proposal with the densities of both directions.
pub struct Proposal {
    pub path: Vec<Vertex>,
    pub measured: Measured,
    /// `T(x → y)` and `T(y → x)`.
    pub forward: f64,
    pub backward: f64,
}

/// `T(x → y)` of a bidirectional mutation of `x` (`k` edges) that deleted `kd` edges from
/// edge `a` and put `ka` in their place, giving `y`.
pub fn density(scene: &Scene, k: usize, y: &[Vertex], kd: usize, a: usize, ka: usize, lengths: Lengths) -> f64 {
    move_pmf(k, kd, a, ka, lengths) * stretch_density(scene, y, a, ka - 1)
}

/// Draws a move `(kd, a, ka)` for a path of `k` edges with probability [`move_pmf`];
/// `None` when the deletion leaves no edge to start at (which would take a new length of 0).
fn draw_move<R: Random>(k: usize, lengths: Lengths, rng: &mut R) -> Option<(usize, usize, usize)> {
    let k2 = two_sided_sample(rng.next_1d(), k, lengths.min..=lengths.max);
    let kd = two_sided_sample(rng.next_1d(), 2, deletions(k, k2));
    let ka = k2 + kd - k;
    let range = starts(k, kd, ka);
    if range.is_empty() {
        return None;
    }
    let a = range.start + ((rng.next_1d() * range.len() as f32) as usize).min(range.len() - 1);
    Some((kd, a, ka))
}

/// Proposes a bidirectional mutation of `x`; `None` when it fails (the proposal then has no
/// contribution and is rejected).
pub fn propose<R: Random>(
    scene: &Scene,
    x: &[Vertex],
    lengths: Lengths,
    rng: &mut R,
    counters: &mut Counters,
) -> Option<Proposal> {
    let k = x.len() - 1;
    let (kd, a, ka) = draw_move(k, lengths, rng)?;
    let s = ((rng.next_1d() * ka as f32) as usize).min(ka - 1);
    let c = a + kd - 1;
    let y = regenerate(scene, &x[..a], &x[c..], s, ka - 1 - s, rng, counters)?;
    let measured = contribution(scene, &y)?;
    let forward = density(scene, k, &y, kd, a, ka, lengths);
    let backward = density(scene, y.len() - 1, x, ka, a, kd, lengths);
    Some(Proposal { path: y, measured, forward, backward })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts of `draw_move`'s moves for a path of `k` edges against `n` times their
    /// probabilities as `pmf` gives them (one cell per move, one for failed draws).
    fn draw_counts(
        k: usize,
        lengths: Lengths,
        n: usize,
        pmf: impl Fn(usize, usize, usize) -> f64,
    ) -> (Vec<u64>, Vec<f64>) {
        let all: Vec<(usize, usize, usize)> = moves(k, lengths).into_iter().map(|(kd, a, ka, _)| (kd, a, ka)).collect();
        let mut counts = vec![0u64; all.len() + 1];
        let mut rng = crate::sampling::Sampler::new(&[5, k as u64]);
        for _ in 0..n {
            match draw_move(k, lengths, &mut rng) {
                Some(m) => counts[all.iter().position(|&x| x == m).expect("a move of the list")] += 1,
                None => counts[all.len()] += 1,
            }
        }
        let mut expected: Vec<f64> = all.iter().map(|&(kd, a, ka)| n as f64 * pmf(kd, a, ka)).collect();
        expected.push(n as f64 - expected.iter().sum::<f64>());
        (counts, expected)
    }

    #[test]
    fn moves_are_drawn_with_their_probabilities() {
        use crate::sampling::chi2::discrete_chi2;
        let lengths = Lengths { min: 2, max: 7, direct_separate: false, specular_separate: false };
        let n = 400_000;
        for k in [2, 4, 7] {
            let (counts, expected) = draw_counts(k, lengths, n, |kd, a, ka| move_pmf(k, kd, a, ka, lengths));
            let r = discrete_chi2(&counts, &expected);
            assert!(r.passed(), "k = {k}: p = {} {:?}", r.p_value, r.message);
        }
        // Negative control: the 2-edge deletions' share claimed 3% lower, the 3-edge ones'
        // (which are half as likely) 6% higher.
        let k = 4;
        let skewed = |kd: usize, a: usize, ka: usize| {
            let f = match kd {
                2 => 0.97,
                3 => 1.06,
                _ => 1.0,
            };
            f * move_pmf(k, kd, a, ka, lengths)
        };
        let (counts, expected) = draw_counts(k, lengths, n, skewed);
        assert!(!discrete_chi2(&counts, &expected).passed(), "a skewed deletion pmf was not caught");
    }

    #[test]
    fn moves_sum_to_one_and_every_move_has_its_reverse() {
        let lengths = Lengths { min: 2, max: 7, direct_separate: false, specular_separate: false };
        for k in lengths.min..=lengths.max {
            let all = moves(k, lengths);
            let total: f64 = all.iter().map(|m| m.3).sum();
            // No draw fails: a start is left unless every edge is deleted and one added,
            // which would leave no edge at all.
            assert!((total - 1.0).abs() < 1e-12, "k = {k}: {total}");
            for &(kd, a, ka, p) in &all {
                assert!(p > 0.0, "k {k} kd {kd} a {a} ka {ka}");
                assert!(a + kd <= k + 1 && !(a == 0 && (kd == 1 || ka == 1)));
                let k2 = k - kd + ka;
                assert!((lengths.min..=lengths.max).contains(&k2));
                assert!(k2 != k || kd >= 2, "a move that gives the path back");
                // The reverse move deletes `ka` from the same edge and adds `kd`.
                assert!(move_pmf(k2, ka, a, kd, lengths) > 0.0, "k {k} kd {kd} a {a} ka {ka}");
            }
            assert_eq!(move_pmf(k, 1, 0, 2, lengths), 0.0);
            assert_eq!(move_pmf(k, 2, 0, 1, lengths), 0.0);
            assert_eq!(move_pmf(k, k + 2, 0, 2, lengths), 0.0);
        }
    }
}
