//! The independent mutation of MEMLT: a whole new path from the bidirectional generator
//! ([`crate::integrator::memlt::independent_path`]: a length and a split into light and camera walks drawn from
//! [`Strategies`], every vertex new), proposed whatever the current path is. Not one of
//! Mitsuba 0.6's mutations (`--independent-mutation`): it is the path-space form of Kelemen's
//! large step, which lets a chain move between regions of the image that its local moves
//! join only rarely (a caustic seen directly and through a glass ball, say) in proportion to
//! their brightness. Its densities are the generator's: `T(x → y) = p(y)`, `T(y → x) =
//! p(x)`, with `p` the generator's density of a whole path ([`crate::integrator::memlt::whole_path_density`]),
//! the mixture over every length and split of its walks' densities.
//!
//! An independent proposal is accepted with probability `min(1, w(y) / w(x))`, `w = f / p`:
//! the closer `p` follows `f`, the more often. The start paths' generator draws a length
//! `∝ 2^-k` and a uniform split, most of which find nothing on a scene lit by a small light
//! through glass (a camera walk that must hit the light, say). The mutation's generator
//! draws them in proportion to what the start-path candidates found with each (their summed
//! `f / p`, each length and split with the share of the target it sampled), mixed with the
//! start paths' proportions (`--independent-defensive`, so that every strategy that can
//! find a path keeps a share and the proposal covers all the chains' paths).
//!
//! **Camera walks to the first light** (`--independent-camera-walks`, a share of the
//! draws). One camera walk that goes on until it finds a light makes a path of whatever
//! length that light is found at, as a path tracer's (or BDPT's `s = 0`) sample does; a
//! length and a split drawn first make only the paths of that length. The paths that only
//! such walks find (a floor's caustic seen in a glass ball at its rim: no edge of the path
//! takes a shadow ray) are proposed as often as BDPT samples them, where the split
//! generator proposes them at the rate of its one length's `s = 0` share. The mixture's
//! density adds the share times the walk's density (the camera-only split's, for a path with
//! no interior vertex on an emitter).

use crate::integrator::bidir::Vertex;
use crate::integrator::memlt::bidirectional::{Lengths, Proposal};
use crate::integrator::stats::Counters;
use crate::sampling::Random;
use crate::scene::Scene;

/// A path's length `k` in edges and its split `s` (the vertices walked from the light).
pub type Split = (usize, usize);

/// The generator's probabilities of a length `k` (in edges) and a split `s` (light-side
/// vertices walked, `0..=k`).
#[derive(Clone, Debug)]
pub struct Strategies {
    min: usize,
    /// The probability of each length from `min` on.
    length: Vec<f64>,
    /// For each length, the probability of each split given it; `None`: uniform over `0..=k`.
    split: Option<Vec<Vec<f64>>>,
    /// The share of draws that are camera walks to the first light ([`crate::integrator::memlt::path::camera_walk_to_light`]);
    /// the lengths and splits above share the rest.
    camera_walks: f64,
}

impl Strategies {
    /// Lengths `∝ 2^-(k - min)`, splits uniform: the start paths' generator.
    pub fn uniform(lengths: Lengths) -> Self {
        let length =
            (lengths.min..=lengths.max).map(|k| crate::integrator::memlt::seed_length_pmf(lengths, k)).collect();
        Strategies { min: lengths.min, length, split: None, camera_walks: 0.0 }
    }

    /// The same strategies with a share `camera_walks` (from 0 to 1) of the draws made camera
    /// walks to the first light.
    pub fn with_camera_walks(self, camera_walks: f64) -> Self {
        Strategies { camera_walks: camera_walks.clamp(0.0, 1.0), ..self }
    }

    /// The share of draws that are camera walks to the first light.
    pub fn camera_walks(&self) -> f64 {
        self.camera_walks
    }

    /// Lengths and splits in proportion to `found[k - min][s]` (what the uniform generator's
    /// paths of length `k` and split `s` contributed, their summed `f / p`), mixed with the
    /// uniform generator's probabilities with weight `defensive`. The uniform generator
    /// alone when nothing was found.
    pub fn learned(lengths: Lengths, found: &[Vec<f64>], defensive: f64) -> Self {
        let uniform = Self::uniform(lengths);
        let total: f64 = found.iter().flatten().sum();
        if !(total > 0.0 && total.is_finite()) || defensive >= 1.0 {
            return uniform;
        }
        let d = defensive.clamp(0.0, 1.0);
        let joint: Vec<Vec<f64>> = (lengths.min..=lengths.max)
            .map(|k| {
                let row = found.get(k - lengths.min);
                (0..=k)
                    .map(|s| {
                        let w = row.and_then(|r| r.get(s)).copied().unwrap_or(0.0);
                        (1.0 - d) * w / total + d * uniform.probability(k, s)
                    })
                    .collect()
            })
            .collect();
        let length: Vec<f64> = joint.iter().map(|r| r.iter().sum()).collect();
        let split = joint
            .into_iter()
            .zip(&length)
            .map(|(r, &l)| r.into_iter().map(|p| if l > 0.0 { p / l } else { 0.0 }).collect())
            .collect();
        Strategies { min: lengths.min, length, split: Some(split), camera_walks: 0.0 }
    }

    /// [`Strategies::learned`] from candidates of the start paths' generator: each one's
    /// weight `f / p` (0 where it found nothing) with the length and split it drew.
    pub fn from_candidates(lengths: Lengths, candidates: &[(f32, Split)], defensive: f64) -> Self {
        let mut found = vec![Vec::new(); lengths.max + 1 - lengths.min];
        for &(w, (k, s)) in candidates {
            if w > 0.0 {
                let row: &mut Vec<f64> = &mut found[k - lengths.min];
                row.resize(row.len().max(k + 1), 0.0);
                row[s] += w as f64;
            }
        }
        Self::learned(lengths, &found, defensive)
    }

    /// The probability of length `k` (0 outside the generator's lengths).
    pub fn length(&self, k: usize) -> f64 {
        k.checked_sub(self.min).and_then(|i| self.length.get(i)).copied().unwrap_or(0.0)
    }

    /// The probability of split `s` given length `k`.
    pub fn split(&self, k: usize, s: usize) -> f64 {
        if s > k {
            return 0.0;
        }
        match &self.split {
            None => 1.0 / (k + 1) as f64,
            Some(t) => k.checked_sub(self.min).and_then(|i| t.get(i)).and_then(|r| r.get(s)).copied().unwrap_or(0.0),
        }
    }

    /// The mixture of a path's split densities `d` (of length `k`, split 0 first) by the
    /// splits' probabilities.
    pub fn over_splits(&self, k: usize, d: impl Iterator<Item = f64>) -> f64 {
        match &self.split {
            None => d.sum::<f64>() / (k + 1) as f64,
            Some(_) => d.enumerate().map(|(s, p)| self.split(k, s) * p).sum(),
        }
    }

    /// The probability of length `k` and split `s`.
    pub fn probability(&self, k: usize, s: usize) -> f64 {
        self.length(k) * self.split(k, s)
    }

    /// A length and a split from two uniform numbers.
    pub fn sample(&self, u: f64, v: f32) -> Split {
        let mut acc = 0.0;
        let mut k = self.min;
        for (i, p) in self.length.iter().enumerate() {
            acc += p;
            k = self.min + i;
            if u < acc && *p > 0.0 {
                break;
            }
        }
        let s = match &self.split {
            None => ((v * (k + 1) as f32) as usize).min(k),
            Some(t) => {
                let row = &t[k - self.min];
                let mut acc = 0.0;
                let mut pick = row.iter().rposition(|&p| p > 0.0).unwrap_or(k);
                for (s, &p) in row.iter().enumerate() {
                    acc += p;
                    if (v as f64) < acc && p > 0.0 {
                        pick = s;
                        break;
                    }
                }
                pick
            }
        };
        (k, s)
    }
}

/// Proposes a path independent of `x` from the generator `strategies` (with `lengths`);
/// `None` when the generator fails.
pub fn propose(
    scene: &Scene,
    x: &[Vertex],
    lengths: Lengths,
    strategies: &Strategies,
    rng: &mut impl Random,
    c: &mut Counters,
) -> Option<Proposal> {
    let (path, measured, forward) = crate::integrator::memlt::independent_path(scene, lengths, strategies, rng, c)?;
    Some(Proposal {
        path,
        measured,
        forward,
        backward: crate::integrator::memlt::whole_path_density(scene, strategies, x),
    })
}
