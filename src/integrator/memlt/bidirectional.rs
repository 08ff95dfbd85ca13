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
}

/// `(kd, a)` with their probabilities for a path of `k` edges: every deletion with its
/// probability. `kd = 1` cannot start at `a = 0`.
fn deletions(k: usize) -> impl Iterator<Item = (usize, usize, f64)> {
    let starts = move |kd: usize| if kd == 1 { k } else { k + 2 - kd };
    let norm: f64 = (1..=k + 1).filter(|&kd| starts(kd) > 0).map(|kd| 0.5f64.powi(kd as i32)).sum();
    (1..=k + 1).flat_map(move |kd| {
        let n = starts(kd);
        let first = usize::from(kd == 1);
        (first..first + n).map(move |a| (kd, a, 0.5f64.powi(kd as i32) / norm / n as f64))
    })
}

/// Probability of deleting `kd` edges from edge `a` of a path of `k` edges.
pub fn deletion_pmf(k: usize, kd: usize, a: usize) -> f64 {
    if kd == 0 || kd > k + 1 || a + kd > k + 1 || (a == 0 && kd == 1) {
        return 0.0;
    }
    deletions(k).find(|&(d, s, _)| d == kd && s == a).map_or(0.0, |(_, _, p)| p)
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
    let w = |n: usize| 0.5f64.powi(n.abs_diff(kd) as i32);
    w(ka) / range.map(w).sum::<f64>()
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
    let u = rng.next_1d() as f64;
    let mut acc = 0.0;
    let mut pick = None;
    for (kd, a, p) in deletions(k) {
        acc += p;
        pick = Some((kd, a));
        if u < acc {
            break;
        }
    }
    let (kd, a) = pick?;
    let u = rng.next_1d() as f64;
    let mut acc = 0.0;
    let mut ka = 0;
    for n in additions(k, kd, a, lengths) {
        acc += addition_pmf(k, kd, a, n, lengths);
        ka = n;
        if u < acc {
            break;
        }
    }
    if ka == 0 {
        return None;
    }
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
        let lengths = Lengths { min: 2, max: 7 };
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
