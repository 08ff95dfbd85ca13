//! SPCBPT's subspaces and its subspace sampling matrix (Su, Li and Wang 2022), the parts that
//! know nothing of the render loop:
//!
//! - [`SubspaceTree`]: a k-d tree over vertex features (position over the scene's bounding
//!   radius, normal) whose leaves are the subspaces, split at medians so that the vertices it
//!   was built from fill its leaves evenly;
//! - [`Matrix`]: `Γ`, one distribution over light subspaces per eye subspace, drawn by
//!   inverting its CDF through a guide table;
//! - [`Matrix::train`]: `Γ` fitted to the connections of earlier iterations by minimising the
//!   MIS-aware bound on the combined estimator's second moment (see there);
//! - [`LightSubspaces`]: a pool's connectible vertices by light subspace, and the draw of one
//!   vertex within a subspace from the subspace's alias table.

use crate::integrator::bidir::Vertex;
use crate::scene::Scene;
use glam::{Vec2, Vec3};

/// Length of a feature vector: position, then normal.
pub const FEATURES: usize = 6;
/// Weight of the normal against the position (over the bounding radius) in the features: a
/// normal that turns round moves a vertex as far as a quarter of the radius.
const NORMAL_WEIGHT: f32 = 0.25;

/// A vertex's features: its position relative to the scene's centre over the bounding radius,
/// and its shading normal turned to the side of direction `towards`.
pub fn features(scene: &Scene, v: &Vertex, towards: Vec3) -> [f32; FEATURES] {
    let b = &scene.bounds;
    let p = (v.p - b.center) / b.radius.max(f32::MIN_POSITIVE);
    let n = if v.frame.n.dot(towards) < 0.0 { -v.frame.n } else { v.frame.n } * NORMAL_WEIGHT;
    [p.x, p.y, p.z, n.x, n.y, n.z]
}

/// A node of a [`SubspaceTree`]: an inner node splits at `split` along `axis` (below goes to
/// `left`, the rest to `left + 1`); a leaf (`axis == LEAF`) is subspace `left`.
#[derive(Clone, Copy, Debug)]
struct Node {
    axis: u8,
    split: f32,
    left: u32,
}

const LEAF: u8 = u8::MAX;

/// A k-d tree whose leaves are subspaces.
#[derive(Clone, Debug)]
pub struct SubspaceTree {
    nodes: Vec<Node>,
    leaves: usize,
}

impl SubspaceTree {
    /// A tree of up to `leaves` subspaces over `points`: each node splits along its points'
    /// widest axis, at the quantile that gives its two children their share of the leaves. A
    /// node with one point, or whose points coincide, stays a leaf, so a tree can have fewer
    /// leaves than asked for (never fewer than one). The tree depends on the points' order
    /// only through ties.
    pub fn build(mut points: Vec<[f32; FEATURES]>, leaves: usize) -> SubspaceTree {
        let mut tree = SubspaceTree { nodes: vec![Node { axis: LEAF, split: 0.0, left: 0 }], leaves: 0 };
        tree.split(0, &mut points, leaves.max(1));
        tree
    }

    fn split(&mut self, node: usize, points: &mut [[f32; FEATURES]], leaves: usize) {
        let widest = (0..FEATURES)
            .map(|a| {
                let (lo, hi) = points.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| (lo.min(p[a]), hi.max(p[a])));
                (a, hi - lo)
            })
            .fold((0, 0.0f32), |best, (a, w)| if w > best.1 { (a, w) } else { best });
        if leaves <= 1 || points.len() <= 1 || widest.1 <= 0.0 {
            self.nodes[node] = Node { axis: LEAF, split: 0.0, left: self.leaves as u32 };
            self.leaves += 1;
            return;
        }
        let axis = widest.0;
        let left_leaves = leaves / 2;
        let mid = (points.len() * left_leaves / leaves).clamp(1, points.len() - 1);
        points.select_nth_unstable_by(mid, |a, b| a[axis].total_cmp(&b[axis]));
        let split = points[mid][axis];
        // Points equal to the split value go right, as the classification sends them.
        let (l, r) = partition(points, |p| p[axis] < split);
        if l.is_empty() {
            // Every point at or above the median value: no split separates them along it.
            self.nodes[node] = Node { axis: LEAF, split: 0.0, left: self.leaves as u32 };
            self.leaves += 1;
            return;
        }
        let left = self.nodes.len();
        self.nodes.push(Node { axis: LEAF, split: 0.0, left: 0 });
        self.nodes.push(Node { axis: LEAF, split: 0.0, left: 0 });
        self.nodes[node] = Node { axis: axis as u8, split, left: left as u32 };
        self.split(left, l, left_leaves);
        self.split(left + 1, r, leaves - left_leaves);
    }

    /// Subspaces (leaves).
    pub fn len(&self) -> usize {
        self.leaves
    }

    pub fn is_empty(&self) -> bool {
        self.leaves == 0
    }

    /// The subspace of a feature vector.
    #[inline]
    pub fn classify(&self, f: &[f32; FEATURES]) -> usize {
        let mut node = self.nodes[0];
        while node.axis != LEAF {
            let i = node.left as usize + (f[node.axis as usize] >= node.split) as usize;
            node = self.nodes[i];
        }
        node.left as usize
    }

    /// Bytes the tree takes.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node>()
    }
}

/// Splits `points` in place into those that satisfy `below` and the rest.
fn partition<T>(points: &mut [T], below: impl Fn(&T) -> bool) -> (&mut [T], &mut [T]) {
    let mut k = 0;
    for i in 0..points.len() {
        if below(&points[i]) {
            points.swap(i, k);
            k += 1;
        }
    }
    points.split_at_mut(k)
}

/// A connection of a training iteration: eye subspace `eye`, light subspace `light`, the
/// matrix entry `gamma` it was drawn with, the square of its unweighted contribution's
/// luminance (`F²`, `F` divided by the density of its draw) and its MIS weight `w`.
#[derive(Clone, Copy, Debug)]
pub struct TrainingSample {
    pub eye: u32,
    pub light: u32,
    pub gamma: f32,
    pub f2: f32,
    pub w: f32,
}

/// The subspace sampling matrix `Γ`: row `i` is the distribution of light subspaces a camera
/// vertex of eye subspace `i` draws from.
#[derive(Clone, Debug)]
pub struct Matrix {
    pub eye: usize,
    pub light: usize,
    /// `eye × light` probabilities, row after row.
    gamma: Vec<f32>,
    /// `eye × light` running sums of the rows (the last entry of a row is 1).
    cdf: Vec<f32>,
    /// Per row, the [`Guide`] of its running sums, `light.next_power_of_two()` entries.
    guide: Vec<u32>,
    /// Rows fitted to training samples (the others are uniform).
    pub trained_rows: usize,
}

/// Fixed-point steps of [`Matrix::train`].
const TRAINING_STEPS: usize = 12;

impl Matrix {
    /// Every row uniform over the light subspaces.
    pub fn uniform(eye: usize, light: usize) -> Matrix {
        Matrix::from_rows(eye, light, vec![1.0 / light as f32; eye * light], 0)
    }

    fn from_rows(eye: usize, light: usize, gamma: Vec<f32>, trained_rows: usize) -> Matrix {
        let mut cdf = vec![0.0f32; eye * light];
        for (row, out) in gamma.chunks_exact(light).zip(cdf.chunks_exact_mut(light)) {
            let mut sum = 0.0f64;
            for (g, c) in row.iter().zip(out.iter_mut()) {
                sum += *g as f64;
                *c = sum as f32;
            }
            // The sums run to one; the last entry is set so that every draw lands in a row.
            out[light - 1] = 1.0;
        }
        let mut guide = Vec::with_capacity(eye * light.next_power_of_two());
        for row in cdf.chunks_exact(light) {
            Guide::build(row, &mut guide);
        }
        Matrix { eye, light, gamma, cdf, guide, trained_rows }
    }

    /// `Γ_ij`.
    #[inline]
    pub fn gamma(&self, eye: usize, light: usize) -> f32 {
        self.gamma[eye * self.light + light]
    }

    /// Draws a light subspace for eye subspace `eye` with `u` in `[0, 1)`; returns it and
    /// the probability with which it is drawn (`Γ_ij`, as the CDF's step gives it).
    #[inline]
    pub fn draw(&self, eye: usize, u: f32) -> (usize, f32) {
        let row = &self.cdf[eye * self.light..(eye + 1) * self.light];
        let k = self.light.next_power_of_two();
        let j = Guide::find(row, &self.guide[eye * k..(eye + 1) * k], u);
        (j, self.gamma[eye * self.light + j])
    }

    /// Bytes the matrix takes.
    pub fn bytes(&self) -> usize {
        (self.gamma.len() + self.cdf.len()) * std::mem::size_of::<f32>() + self.guide.len() * std::mem::size_of::<u32>()
    }

    /// `Γ` fitted to `samples`, mixed with the uniform distribution in proportion `uniform`.
    ///
    /// The objective (after Su, Li and Wang's MIS-aware bound): with the balance heuristic,
    /// the second moment of the combined estimator is bounded by `∫ f² / Σ_k n_k p_k`, where
    /// the pool connections' term is `N M Γ_ij P(y | j) p(x)`. A training connection, drawn
    /// with `Γ'_ij` and weighted `w'`, estimates this integrand over its own density as
    /// `F² / (r + Γ_ij / Γ'_ij)` with `r = (1 - w') / w'` (the other strategies' share,
    /// fixed), so each row minimises `L_i(Γ) = Σ F² / (r + Γ_ij / Γ'_ij)` over `Σ_j Γ_ij = 1`.
    /// Its optimum has `-∂L/∂Γ_ij` equal for every entry in use, and the fixed point
    /// `Γ_ij ← Γ_ij (-∂L/∂Γ_ij)^½`, normalised, reaches it: without the other strategies
    /// (`r = 0`) one step gives the closed form `Γ_ij ∝ (Σ F² Γ'_ij)^½`; where they already
    /// carry a connection's paths, its entry loses weight. Rows without samples stay
    /// uniform; entries without samples keep only the uniform share, which keeps every
    /// light subspace reachable.
    pub fn train(eye: usize, light: usize, samples: &[TrainingSample], uniform: f32) -> Matrix {
        let mut gamma = vec![0.0f64; eye * light];
        let mut rows = vec![false; eye];
        for s in samples {
            rows[s.eye as usize] = true;
        }
        for (i, row) in gamma.chunks_exact_mut(light).enumerate() {
            if rows[i] {
                row.fill(1.0 / light as f64);
            }
        }
        // Samples with a positive weight and contribution.
        let used: Vec<&TrainingSample> =
            samples.iter().filter(|s| s.w > 0.0 && s.f2 > 0.0 && s.gamma > 0.0 && s.f2.is_finite()).collect();
        let mut grad = vec![0.0f64; eye * light];
        for _ in 0..TRAINING_STEPS {
            grad.fill(0.0);
            for s in &used {
                let k = s.eye as usize * light + s.light as usize;
                let r = (1.0 - s.w as f64) / s.w as f64;
                let d = r + gamma[k] / s.gamma as f64;
                grad[k] += s.f2 as f64 / (s.gamma as f64 * d * d);
            }
            for (i, (row, g)) in gamma.chunks_exact_mut(light).zip(grad.chunks_exact(light)).enumerate() {
                if !rows[i] {
                    continue;
                }
                let mut sum = 0.0;
                for (x, &gk) in row.iter_mut().zip(g) {
                    *x *= gk.sqrt();
                    sum += *x;
                }
                if sum > 0.0 && sum.is_finite() {
                    row.iter_mut().for_each(|x| *x /= sum);
                } else {
                    row.fill(1.0 / light as f64);
                }
            }
        }
        let u = uniform.clamp(0.0, 1.0) as f64;
        let trained_rows = rows.iter().filter(|&&r| r).count();
        let out = gamma
            .chunks_exact(light)
            .zip(&rows)
            .flat_map(|(row, &trained)| {
                row.iter()
                    .map(move |&g| if trained { ((1.0 - u) * g + u / light as f64) as f32 } else { 1.0 / light as f32 })
            })
            .collect();
        Matrix::from_rows(eye, light, out, trained_rows)
    }
}

/// A pool's connectible vertices sorted by light subspace, with what the draw within a
/// subspace needs: vertex `y` of subspace `j` is drawn with probability
/// `P(y | j) = (1 - δ) q(y) / Q_j + δ / V_j`, `q` its flux (the luminance of its light
/// throughput), `Q_j` and `V_j` the subspace's total flux and vertex count, `δ` =
/// [`WITHIN_UNIFORM`]. The uniform share reaches vertices whose flux is not known from their
/// positions (behind a specular bounce).
#[derive(Clone, Debug, Default)]
pub struct LightSubspaces {
    /// `light + 1` offsets into `columns`: subspace `j`'s members (connectible pool
    /// indices, sorted by subspace) are `offsets[j]..offsets[j + 1]`.
    offsets: Vec<u32>,
    /// Per member, its column of its subspace's alias table ([`Column`]).
    columns: Vec<Column>,
    /// `q` of each connectible pool index.
    pub flux: Vec<f32>,
    /// `Q_j`.
    pub totals: Vec<f64>,
}

/// One column of a subspace's alias table (Walker's method, built by Vose's): a draw picks
/// the column of member `m` of the subspace's `V_j` uniformly, then keeps `m` with
/// probability `keep` and takes member `other` otherwise, so member `m` is drawn with
/// probability `(keep_m + Σ_{other_c = m} (1 - keep_c)) / V_j`, which the table makes
/// `P(y | j)`.
#[derive(Clone, Copy, Debug, Default)]
struct Alias {
    keep: f32,
    /// The member taken otherwise (its position in the sorted members).
    other: u32,
}

/// What a draw reads of a column, in one load of 32 aligned bytes: the two pool vertices it
/// may take (the column's own member and its alias), their `P(y | j)`, and the share that
/// keeps the first. The choice between them is an index, not a branch. (Inverting running
/// sums instead took a guide lookup, a scan whose length the random number set, and the
/// flux's division, on a path every connection takes.)
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
struct Column {
    p: [f64; 2],
    y: [u32; 2],
    keep: f32,
}

impl Alias {
    /// The alias table of probabilities `p` (summing to one) over members `base..base +
    /// p.len()`, appended to `out`.
    fn build(p: &[f64], base: u32, out: &mut Vec<Alias>) {
        let n = p.len();
        let start = out.len();
        let mut scaled: Vec<f64> = p.iter().map(|&x| x * n as f64).collect();
        out.extend((0..n).map(|m| Alias { keep: 1.0, other: base + m as u32 }));
        let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&m| scaled[m] < 1.0);
        while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
            small.pop();
            out[start + s] = Alias { keep: scaled[s] as f32, other: base + l as u32 };
            scaled[l] -= 1.0 - scaled[s];
            if scaled[l] < 1.0 {
                large.pop();
                small.push(l);
            }
        }
        // What is left is one up to rounding: kept whole.
    }
}

/// Guide tables (the cutpoint method of Chen and Asau) for inverting a running sum (a row
/// of `Γ`, whose draws for one camera vertex are stratified, which the inversion keeps): with
/// `K` a power of two at least the sum's length, entry `k` is the first index whose sum
/// exceeds `k / K`, so a draw `u` starts its search at entry `⌊u K⌋` and steps on at most a
/// few indices. `u K` and `k / K` are exact in floating point (`K` is a power of two), so the
/// index found is the one a binary search finds, bit for bit; the draws cost a load or two
/// where the search took one dependent load per halving, twice in every draw.
struct Guide;

impl Guide {
    /// Appends the guide of `cdf` (non-empty, non-decreasing) to `out`.
    fn build(cdf: &[f32], out: &mut Vec<u32>) {
        let n = cdf.len();
        let k = n.next_power_of_two();
        let mut i = 0;
        for e in 0..k {
            let at = e as f32 / k as f32;
            while i < n - 1 && cdf[i] <= at {
                i += 1;
            }
            out.push(i as u32);
        }
    }

    /// The first index of `cdf` whose sum exceeds `u` (the last when none does), from its
    /// `guide`.
    #[inline]
    fn find(cdf: &[f32], guide: &[u32], u: f32) -> usize {
        let e = ((u * guide.len() as f32) as usize).min(guide.len() - 1);
        let mut i = guide[e] as usize;
        while i < cdf.len() - 1 && cdf[i] <= u {
            i += 1;
        }
        i
    }
}

/// The uniform share `δ` of the draw within a light subspace.
pub const WITHIN_UNIFORM: f32 = 0.1;

impl LightSubspaces {
    /// Sorts connectible pool vertices `0..subspace.len()` (of subspace `subspace[k]` and
    /// flux `flux[k]`) into `light` subspaces.
    pub fn new(light: usize, subspace: &[u32], flux: Vec<f32>) -> LightSubspaces {
        let mut offsets = vec![0u32; light + 1];
        for &j in subspace {
            offsets[j as usize + 1] += 1;
        }
        for j in 0..light {
            offsets[j + 1] += offsets[j];
        }
        let mut fill = offsets.clone();
        let mut members = vec![0u32; subspace.len()];
        for (k, &j) in subspace.iter().enumerate() {
            members[fill[j as usize] as usize] = k as u32;
            fill[j as usize] += 1;
        }
        let mut totals = vec![0.0f64; light];
        let mut within = vec![0.0f64; members.len()];
        let mut alias = Vec::with_capacity(members.len());
        for j in 0..light {
            let range = offsets[j] as usize..offsets[j + 1] as usize;
            let total: f64 = members[range.clone()].iter().map(|&k| flux[k as usize] as f64).sum();
            totals[j] = total;
            let count = range.len() as f64;
            for m in range.clone() {
                within[m] = within_probability(flux[members[m] as usize] as f64, total, count);
            }
            Alias::build(&within[range.clone()], range.start as u32, &mut alias);
        }
        let columns = alias
            .iter()
            .enumerate()
            .map(|(m, a)| {
                let o = a.other as usize;
                Column { p: [within[m], within[o]], y: [members[m], members[o]], keep: a.keep }
            })
            .collect();
        LightSubspaces { offsets, columns, flux, totals }
    }

    /// `V_j`.
    #[inline]
    pub fn count(&self, j: usize) -> usize {
        (self.offsets[j + 1] - self.offsets[j]) as usize
    }

    /// Non-empty light subspaces.
    pub fn used(&self) -> usize {
        (0..self.totals.len()).filter(|&j| self.count(j) > 0).count()
    }

    /// `P(y | j)` of connectible pool index `k` in subspace `j`.
    #[inline]
    pub fn within(&self, j: usize, k: usize) -> f64 {
        within_probability(self.flux[k] as f64, self.totals[j], self.count(j) as f64)
    }

    /// Draws a vertex of subspace `j` with `u` in `[0, 1)²` (the column, then the alias):
    /// its connectible pool index and `P(y | j)`; `None` when the subspace is empty.
    #[inline]
    pub fn draw(&self, j: usize, u: Vec2) -> Option<(usize, f64)> {
        let (a, b) = (self.offsets[j] as usize, self.offsets[j + 1] as usize);
        if a == b {
            return None;
        }
        let c = &self.columns[a + ((u.x * (b - a) as f32) as usize).min(b - a - 1)];
        let pick = usize::from(u.y >= c.keep);
        Some((c.y[pick] as usize, c.p[pick]))
    }
}

/// `P(y | j) = (1 - δ) q / Q + δ / V` (uniform `1 / V` where the subspace has no flux),
/// from a vertex's flux `q` and its subspace's total flux `Q` and vertex count `V`.
#[inline]
pub fn within_probability(q: f64, total: f64, count: f64) -> f64 {
    if count <= 0.0 {
        0.0
    } else if total <= 0.0 {
        1.0 / count
    } else {
        (1.0 - WITHIN_UNIFORM as f64) * q / total + WITHIN_UNIFORM as f64 / count
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(state: &mut u64) -> f32 {
        *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*state >> 40) as f32 / (1u64 << 24) as f32
    }

    #[test]
    fn tree_leaves_share_the_points_evenly_and_classify_them_where_they_were_put() {
        let mut s = 3u64;
        let points: Vec<[f32; FEATURES]> = (0..4000).map(|_| std::array::from_fn(|_| lcg(&mut s))).collect();
        let tree = SubspaceTree::build(points.clone(), 64);
        assert_eq!(tree.len(), 64);
        let mut counts = vec![0usize; 64];
        for p in &points {
            counts[tree.classify(p)] += 1;
        }
        let (lo, hi) = (counts.iter().min().unwrap(), counts.iter().max().unwrap());
        assert!(*lo >= 55 && *hi <= 70, "leaf sizes {lo}..{hi}");
        // Coincident points cannot be split: one leaf.
        let same = SubspaceTree::build(vec![[0.5; FEATURES]; 100], 16);
        assert_eq!(same.len(), 1);
        assert_eq!(same.classify(&[0.1; FEATURES]), 0);
    }

    #[test]
    fn training_without_other_strategies_gives_the_closed_form() {
        // One row, four light subspaces, drawn uniformly (Γ' = 1/4), w = 1: the optimum is
        // Γ_j ∝ (Σ F² Γ')^½.
        let f2 = [4.0f32, 1.0, 0.0, 9.0];
        let samples: Vec<TrainingSample> = f2
            .iter()
            .enumerate()
            .map(|(j, &f2)| TrainingSample { eye: 0, light: j as u32, gamma: 0.25, f2, w: 1.0 })
            .collect();
        let m = Matrix::train(2, 4, &samples, 0.0);
        let want = [2.0f32 / 6.0, 1.0 / 6.0, 0.0, 3.0 / 6.0];
        for (j, w) in want.iter().enumerate() {
            assert!((m.gamma(0, j) - w).abs() < 1e-5, "Γ_0{j} = {} ≠ {w}", m.gamma(0, j));
        }
        // The row without samples stays uniform, and the uniform share is mixed in.
        assert!((0..4).all(|j| m.gamma(1, j) == 0.25));
        let m = Matrix::train(2, 4, &samples, 0.2);
        assert!((m.gamma(0, 2) - 0.05).abs() < 1e-6 && (m.gamma(0, 3) - (0.8 * 0.5 + 0.05)).abs() < 1e-6);
        assert_eq!(m.trained_rows, 1);
    }

    #[test]
    fn training_moves_weight_away_from_what_other_strategies_carry() {
        // Two subspaces with the same contributions, drawn with Γ' = ½ each; the other
        // strategies carry subspace 0's paths as well as its connections do (w' = ½, r = 1).
        // L = 1/(1 + 2Γ_0) + 1/(2Γ_1): -∂L/∂Γ equal in both entries at Γ_0 = ¼.
        let mk = |light, w| TrainingSample { eye: 0, light, gamma: 0.5, f2: 1.0, w };
        let m = Matrix::train(1, 2, &[mk(0, 0.5), mk(1, 1.0)], 0.0);
        assert!((m.gamma(0, 0) - 0.25).abs() < 2e-3, "Γ = {} {}", m.gamma(0, 0), m.gamma(0, 1));
        // Carried nine times better by the others (w' = 0.1): the optimum is on the boundary.
        let m = Matrix::train(1, 2, &[mk(0, 0.1), mk(1, 1.0)], 0.0);
        assert!(m.gamma(0, 0) < 0.05, "Γ = {} {}", m.gamma(0, 0), m.gamma(0, 1));
    }

    /// `Γ` with uneven rows: a matrix trained on samples of random contributions.
    fn uneven_matrix(eye: usize, light: usize) -> Matrix {
        let mut s = 11u64;
        let samples: Vec<TrainingSample> = (0..eye * light * 3)
            .map(|k| {
                let f = lcg(&mut s);
                TrainingSample {
                    eye: (k % eye) as u32,
                    light: (k / eye % light) as u32,
                    gamma: 1.0 / light as f32,
                    f2: f * f * f * f,
                    w: 0.2 + 0.8 * lcg(&mut s),
                }
            })
            .collect();
        Matrix::train(eye, light, &samples, 0.1)
    }

    /// The guide finds the index a binary search finds, for running sums with flat stretches,
    /// steps at the guide's own boundaries, a last entry short of one, and draws on and
    /// between the boundaries.
    #[test]
    fn guide_tables_find_what_the_binary_search_finds() {
        let mut s = 9u64;
        let mut sums: Vec<Vec<f32>> = vec![
            vec![1.0],
            vec![0.0, 0.0, 1.0],
            vec![0.25, 0.5, 0.75, 1.0],
            vec![0.125, 0.125, 0.5, 0.5, 0.999_999_9],
            vec![0.0, 0.3, 0.3, 0.3, 0.7, 1.0, 1.0],
        ];
        for n in [2usize, 3, 17, 60, 64, 65, 300] {
            let w: Vec<f64> = (0..n).map(|_| if lcg(&mut s) < 0.3 { 0.0 } else { lcg(&mut s) as f64 }).collect();
            let total: f64 = w.iter().sum::<f64>().max(1e-9);
            let mut sum = 0.0;
            sums.push(
                w.iter()
                    .map(|x| {
                        sum += x;
                        (sum / total) as f32
                    })
                    .collect(),
            );
        }
        for cdf in &sums {
            let mut guide = Vec::new();
            Guide::build(cdf, &mut guide);
            let k = cdf.len().next_power_of_two();
            assert_eq!(guide.len(), k);
            let mut us: Vec<f32> = (0..4 * k).map(|e| e as f32 / (4 * k) as f32).collect();
            us.extend(cdf.iter().copied().filter(|&c| c < 1.0));
            us.extend(cdf.iter().map(|&c| (c - f32::EPSILON).max(0.0)));
            us.extend((0..2000).map(|_| lcg(&mut s)));
            us.push(1.0 - f32::EPSILON / 2.0);
            for u in us {
                let want = cdf.partition_point(|&c| c <= u).min(cdf.len() - 1);
                assert_eq!(Guide::find(cdf, &guide, u), want, "sums {cdf:?}, u {u}");
            }
        }
    }

    #[test]
    fn subspace_draws_follow_gamma_chi2() {
        use crate::sampling::chi2::discrete_chi2;
        let (eye, light) = (5, 40);
        let m = uneven_matrix(eye, light);
        let mut s = 5u64;
        for i in 0..eye {
            let row: Vec<f64> = (0..light).map(|j| m.gamma(i, j) as f64).collect();
            assert!((row.iter().sum::<f64>() - 1.0).abs() < 1e-5);
            let (lo, hi) = row.iter().fold((1.0f64, 0.0f64), |(a, b), &g| (a.min(g), b.max(g)));
            assert!(hi > 4.0 * lo, "row {i} is nearly uniform: {lo}..{hi}");
            let n = 100_000u64;
            let mut counts = vec![0u64; light];
            for _ in 0..n {
                let (j, p) = m.draw(i, lcg(&mut s));
                assert_eq!(p, m.gamma(i, j));
                counts[j] += 1;
            }
            let expected: Vec<f64> = row.iter().map(|g| g * n as f64).collect();
            discrete_chi2(&counts, &expected).assert_pass();
            // Negative control: the uniform rows the matrix started from are rejected.
            let uniform = vec![n as f64 / light as f64; light];
            assert!(!discrete_chi2(&counts, &uniform).passed(), "row {i}: uniform rows were not rejected");
        }
    }

    #[test]
    fn draws_within_a_subspace_have_the_probability_they_report() {
        let subspace = [0u32, 1, 0, 0, 1, 2];
        let flux = vec![1.0f32, 2.0, 3.0, 0.0, 0.0, 0.0];
        let l = LightSubspaces::new(4, &subspace, flux);
        assert_eq!((l.count(0), l.count(1), l.count(2), l.count(3)), (3, 2, 1, 0));
        assert_eq!(l.used(), 3);
        assert!(l.draw(3, Vec2::splat(0.5)).is_none());
        // A stratified grid over the two numbers.
        let side = 500;
        let n = side * side;
        let mut hits = [0usize; 6];
        for k in 0..n {
            let u = Vec2::new((k % side) as f32 + 0.5, (k / side) as f32 + 0.5) / side as f32;
            let (i, p) = l.draw(0, u).unwrap();
            hits[i] += 1;
            assert!((p - l.within(0, i)).abs() < 1e-12);
        }
        for i in [0usize, 2, 3] {
            let want = l.within(0, i);
            assert!(
                (hits[i] as f64 / n as f64 - want).abs() < 1e-3,
                "vertex {i}: {} vs {want}",
                hits[i] as f64 / n as f64
            );
        }
        // Vertex 3 has no flux: only the uniform share reaches it.
        assert!((l.within(0, 3) - WITHIN_UNIFORM as f64 / 3.0).abs() < 1e-9);
        // A subspace without flux draws uniformly.
        assert!((l.within(2, 5) - 1.0).abs() < 1e-12);
    }

    /// The probabilities an alias table implies (each column's kept share, plus what the
    /// columns aliased to a member give it) are the ones it was built from, for flat,
    /// skewed and tiny-entry distributions; a table with one column's alias moved (the
    /// negative control) fails the same check.
    #[test]
    fn alias_tables_imply_the_probabilities_they_were_built_from() {
        let matches = |table: &[Alias], base: u32, p: &[f64]| {
            let n = table.len() as f64;
            let mut got = vec![0.0f64; table.len()];
            for (c, a) in table.iter().enumerate() {
                got[c] += a.keep as f64 / n;
                got[(a.other - base) as usize] += (1.0 - a.keep as f64) / n;
            }
            got.iter().zip(p).all(|(&g, &want)| (g - want).abs() <= 1e-6 * want + 1e-12)
        };
        let mut s = 3u64;
        let mut cases: Vec<Vec<f64>> =
            vec![vec![1.0], vec![0.5, 0.5], vec![0.9, 0.05, 0.05], vec![1e-6, 1.0 - 2e-6, 1e-6]];
        for n in [3usize, 17, 64, 500, 2000] {
            let w: Vec<f64> = (0..n)
                .map(|_| if lcg(&mut s) < 0.2 { 1e-4 * lcg(&mut s) as f64 } else { lcg(&mut s) as f64 })
                .collect();
            let total: f64 = w.iter().sum();
            cases.push(w.iter().map(|x| x / total).collect());
        }
        for p in &cases {
            let mut table = vec![Alias::default(); 3];
            Alias::build(p, 7, &mut table);
            assert_eq!(table.len(), 3 + p.len());
            assert!(matches(&table[3..], 7, p), "a table of {} members", p.len());
            // Negative control: a column that gives part of its share away aliased to the
            // wrong member.
            if let Some(c) = table[3..].iter().position(|a| a.keep < 0.99) {
                let mut wrong = table[3..].to_vec();
                wrong[c].other = 7 + ((wrong[c].other - 7 + 1) % p.len() as u32);
                assert!(!matches(&wrong, 7, p), "a moved alias was not caught ({} members)", p.len());
            }
        }
    }
}
