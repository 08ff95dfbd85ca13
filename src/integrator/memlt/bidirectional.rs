//! The bidirectional mutation of path-space Metropolis (Veach and Guibas 1997; contract
//! `memlt.md`, "Mutators"): delete a stretch of the current path, regenerate it from both
//! kept ends with a new length, join the ends.
//!
//! A path of `k` edges is seen as `k + 1` edges counting the choice of its light point (the
//! edge "before" `x_0`). A run of `kd` consecutive ones is deleted, starting at edge `a`:
//! `x_0 .. x_{a-1}` and `x_{a+kd-1} .. x_k` stay (the pinhole always does); `kd` is drawn with
//! probability `∝ 2^-kd` and `a` uniformly. `ka` new edges take their place, `∝ 2^-|ka-kd|`
//! within the lengths allowed, and the `ka - 1` new vertices are split uniformly into a
//! light-side and a camera-side walk. Regenerating the light point (`a = 0`) deletes and adds
//! at least two edges, and deleting one edge adds at least two (one would give the same path
//! back), so that every move has its reverse. The proposal density sums over
//! every split that could have produced the new stretch ([`stretch_density`]).

use super::path::{Measured, contribution, regenerate, stretch_density};
use crate::integrator::Counters;
use crate::integrator::bidir::Vertex;
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
}

impl Lengths {
    /// Whether path `x` is one of the chains' (its contribution is zero to them otherwise).
    #[inline]
    pub fn covers(&self, x: &[Vertex]) -> bool {
        let k = x.len().saturating_sub(1);
        (self.min..=self.max).contains(&k) && !(self.direct_separate && k == 2 && !x[1].delta)
    }
}

/// `2^-n`, exactly.
#[inline]
fn half_pow(n: usize) -> f64 {
    debug_assert!(n < 1023);
    f64::from_bits((1023 - n as u64) << 52)
}

/// The edges a deletion of `kd` edges may start at in a path of `k` edges: `kd = 1`
/// cannot start at `a = 0` (the light point's choice is not an edge one can re-join).
fn starts(k: usize, kd: usize) -> std::ops::Range<usize> {
    if kd == 1 { 1..k + 1 } else { 0..k + 2 - kd }
}

/// Probability of deleting `kd` edges (`1 ..= k + 1`, `∝ 2^-kd`, normalised by
/// `1 - 2^-(k+1)`) from edge `a` (uniform among [`starts`]) of a path of `k` edges.
pub fn deletion_pmf(k: usize, kd: usize, a: usize) -> f64 {
    if kd == 0 || kd > k + 1 || !starts(k, kd).contains(&a) {
        return 0.0;
    }
    half_pow(kd) / (1.0 - half_pow(k + 1)) / starts(k, kd).len() as f64
}

/// Every deletion `(kd, a)` of a path of `k` edges with its probability.
#[cfg(test)]
fn deletions(k: usize) -> impl Iterator<Item = (usize, usize, f64)> {
    (1..=k + 1).flat_map(move |kd| starts(k, kd).map(move |a| (kd, a, deletion_pmf(k, kd, a))))
}

/// The lengths `ka` may take after deleting `kd` edges from edge `a` of a path of `k`.
fn additions(k: usize, kd: usize, a: usize, lengths: Lengths) -> std::ops::RangeInclusive<usize> {
    // Regenerating the light point, or re-joining the ends of one deleted edge, adds two
    // edges or more: one would give the same path back.
    let lo = if a == 0 || kd == 1 { 2 } else { 1 };
    let lo = lo.max((lengths.min + kd).saturating_sub(k));
    let hi = lengths.max + kd - k;
    lo..=hi
}

/// Probability of `ka` new edges after deleting `kd` from edge `a` of a path of `k`.
pub fn addition_pmf(k: usize, kd: usize, a: usize, ka: usize, lengths: Lengths) -> f64 {
    let range = additions(k, kd, a, lengths);
    if !range.contains(&ka) {
        return 0.0;
    }
    half_pow(ka.abs_diff(kd)) / addition_norm(range, kd)
}

/// `Σ 2^-|n - kd|` over the lengths `n` of `range`.
fn addition_norm(range: std::ops::RangeInclusive<usize>, kd: usize) -> f64 {
    range.map(|n| half_pow(n.abs_diff(kd))).sum()
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
    deletion_pmf(k, kd, a) * addition_pmf(k, kd, a, ka, lengths) * stretch_density(scene, y, a, ka - 1)
}

/// Draws a move for a path of `k` edges: `(kd, a, ka)` with probability
/// `deletion_pmf(k, kd, a) · addition_pmf(k, kd, a, ka)`; `None` when no length is left to
/// add.
fn draw_move<R: Random>(k: usize, lengths: Lengths, rng: &mut R) -> Option<(usize, usize, usize)> {
    // `kd` by its marginal `2^-kd / (1 - 2^-(k+1))`, then its start uniformly.
    let u = rng.next_1d() as f64 * (1.0 - half_pow(k + 1));
    let mut acc = 0.0;
    let mut kd = k + 1;
    for n in 1..=k + 1 {
        acc += half_pow(n);
        if u < acc {
            kd = n;
            break;
        }
    }
    let range = starts(k, kd);
    let a = range.start + ((rng.next_1d() * range.len() as f32) as usize).min(range.len() - 1);
    let range = additions(k, kd, a, lengths);
    let u = rng.next_1d() as f64 * addition_norm(range.clone(), kd);
    let mut acc = 0.0;
    let mut ka = 0;
    for n in range {
        acc += half_pow(n.abs_diff(kd));
        ka = n;
        if u < acc {
            break;
        }
    }
    (ka > 0).then_some((kd, a, ka))
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
        let moves: Vec<(usize, usize, usize)> =
            deletions(k).flat_map(|(kd, a, _)| additions(k, kd, a, lengths).map(move |ka| (kd, a, ka))).collect();
        let mut counts = vec![0u64; moves.len() + 1];
        let mut rng = crate::sampling::Sampler::new(&[5, k as u64]);
        for _ in 0..n {
            match draw_move(k, lengths, &mut rng) {
                Some(m) => counts[moves.iter().position(|&x| x == m).expect("a move of the list")] += 1,
                None => counts[moves.len()] += 1,
            }
        }
        let mut expected: Vec<f64> = moves.iter().map(|&(kd, a, ka)| n as f64 * pmf(kd, a, ka)).collect();
        expected.push(n as f64 - expected.iter().sum::<f64>());
        (counts, expected)
    }

    #[test]
    fn moves_are_drawn_with_their_probabilities() {
        use crate::sampling::chi2::discrete_chi2;
        let lengths = Lengths { min: 2, max: 7, direct_separate: false };
        let n = 400_000;
        for k in [2, 4, 7] {
            let (counts, expected) =
                draw_counts(k, lengths, n, |kd, a, ka| deletion_pmf(k, kd, a) * addition_pmf(k, kd, a, ka, lengths));
            let r = discrete_chi2(&counts, &expected);
            assert!(r.passed(), "k = {k}: p = {} {:?}", r.p_value, r.message);
        }
        // Negative control: deletion lengths claimed `∝ 2^-kd` with the 1-edge deletions'
        // share moved by 3% onto the 2-edge ones (which are half as likely).
        let k = 4;
        let skewed = |kd: usize, a: usize, ka: usize| {
            let f = match kd {
                1 => 0.97,
                2 => 1.06,
                _ => 1.0,
            };
            f * deletion_pmf(k, kd, a) * addition_pmf(k, kd, a, ka, lengths)
        };
        let (counts, expected) = draw_counts(k, lengths, n, skewed);
        assert!(!discrete_chi2(&counts, &expected).passed(), "a skewed deletion pmf was not caught");
    }

    #[test]
    fn deletions_sum_to_one_and_match_their_pmf() {
        for k in 1..12 {
            let all: Vec<_> = deletions(k).collect();
            let total: f64 = all.iter().map(|d| d.2).sum();
            assert!((total - 1.0).abs() < 1e-12, "k = {k}: {total}");
            for &(kd, a, p) in &all {
                assert_eq!(deletion_pmf(k, kd, a), p);
                assert!(a + kd <= k + 1 && !(a == 0 && kd == 1));
            }
            assert_eq!(deletion_pmf(k, 1, 0), 0.0);
            assert_eq!(deletion_pmf(k, k + 2, 0), 0.0);
        }
    }

    #[test]
    fn additions_sum_to_one_and_every_move_has_its_reverse() {
        let lengths = Lengths { min: 2, max: 7, direct_separate: false };
        for k in lengths.min..=lengths.max {
            for (kd, a, _) in deletions(k) {
                // Deleting one edge of a path at the longest length leaves no length to
                // add (such proposals fail).
                if additions(k, kd, a, lengths).is_empty() {
                    assert!(kd == 1 && k == lengths.max);
                    continue;
                }
                let total: f64 = additions(k, kd, a, lengths).map(|ka| addition_pmf(k, kd, a, ka, lengths)).sum();
                assert!((total - 1.0).abs() < 1e-12, "k {k} kd {kd} a {a}: {total}");
                for ka in additions(k, kd, a, lengths) {
                    let k2 = k - kd + ka;
                    assert!((lengths.min..=lengths.max).contains(&k2));
                    // The reverse move deletes `ka` from the same edge and adds `kd`.
                    assert!(deletion_pmf(k2, ka, a) > 0.0, "k {k} kd {kd} a {a} ka {ka}");
                    assert!(addition_pmf(k2, ka, a, kd, lengths) > 0.0, "k {k} kd {kd} a {a} ka {ka}");
                }
            }
        }
    }
}
