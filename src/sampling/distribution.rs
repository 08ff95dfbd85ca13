//! Discrete distributions: sampling an index proportionally to non-negative weights.

/// A piecewise-constant distribution over `n` entries, sampled by inverting its CMF.
#[derive(Clone, Debug)]
pub struct Distribution1D {
    /// Each entry's CMF (the probability of it and the entries before it) beside its PMF, so
    /// that the cache line a search ends in also holds the probability it returns (an
    /// environment map's row is sampled at random: each separate array read is a miss).
    entries: Vec<Entry>,
    total: f64,
    /// For more than [`GUIDE_MIN`] entries, `guide[j]` is the number of entries whose CMF
    /// lies in a bucket below `j` (`g + 2` of them for `g` buckets, one bucket per
    /// [`GUIDE_STRIDE`] entries, see [`bucket`]): a sample counts CMF entries only within the
    /// bucket of `u` (about two adjacent cache lines, read at once) instead of a binary
    /// search over the whole CMF (one cache miss per halving), and finds the same index. The guide is small enough (256 bytes for a
    /// row of a 2048-pixel map) for all rows' guides to stay in cache. A near-uniform
    /// distribution needs none: its index is found by stepping from `⌊u · n⌋`.
    guide: Guide,
}

/// A guide table's entries, in 16 bits where the distribution is small enough; or none for a
/// near-uniform distribution (a tessellated disk's triangles, a constant row of a map), whose
/// index lies within an entry of `u · n`.
#[derive(Clone, Debug, PartialEq)]
enum Guide {
    None,
    Uniform,
    Short(Vec<u16>),
    Long(Vec<u32>),
}

impl Guide {
    /// The entries whose CMF may be the first above `u`, as a range `lo..hi`: those in the
    /// bucket `u` falls in (see [`bucket`]); `None` without a guide.
    #[inline]
    fn around(&self, u: f32) -> Option<(usize, usize)> {
        fn within(len: usize, at: impl Fn(usize) -> usize, u: f32) -> (usize, usize) {
            let k = bucket(u, len - 2);
            (at(k), at(k + 1))
        }
        match self {
            Guide::None | Guide::Uniform => None,
            Guide::Short(g) => Some(within(g.len(), |j| g[j] as usize, u)),
            Guide::Long(g) => Some(within(g.len(), |j| g[j] as usize, u)),
        }
    }
}

/// The guide bucket of a value `c` of `[0, 1]` among `g` buckets: `⌊c · g⌋` as `f32`
/// arithmetic gives it (`g` for `c = 1`). It never decreases as `c` grows (a product with a
/// positive constant and the floor are monotonic), so a CMF entry in a lower bucket than `u`
/// is below `u` and one in a higher bucket is above it: only the entries of `u`'s own bucket
/// need comparing, whatever the rounding.
#[inline]
fn bucket(c: f32, g: usize) -> usize {
    ((c * g as f32) as usize).min(g)
}

#[derive(Clone, Copy, Debug)]
struct Entry {
    cmf: f32,
    pmf: f32,
}

/// Distributions with more entries than this get a guide table.
const GUIDE_MIN: usize = 64;
/// Entries per guide bucket.
const GUIDE_STRIDE: usize = 16;
/// Up to this many CMF entries are counted one by one (branch-free, the loads independent)
/// rather than searched by halving.
const COUNT_MAX: usize = 64;

/// The guide table of a CMF of `n` entries.
fn guide_table(cmf: &[f32]) -> Guide {
    let n = cmf.len();
    if n <= GUIDE_MIN {
        return Guide::None;
    }
    // Every CMF entry within one entry's width of the uniform distribution's.
    if cmf.iter().enumerate().all(|(i, &c)| (c as f64 * n as f64 - (i + 1) as f64).abs() <= 1.0) {
        return Guide::Uniform;
    }
    let g = n.div_ceil(GUIDE_STRIDE);
    let counts = (0..=g + 1).map(|j| cmf.partition_point(|&c| bucket(c, g) < j));
    match u16::try_from(n) {
        Ok(_) => Guide::Short(counts.map(|c| c as u16).collect()),
        Err(_) => Guide::Long(counts.map(|c| c as u32).collect()),
    }
}

/// The number of entries whose CMF is at most `u` (the CMF is non-decreasing).
#[inline]
fn count_at_most(entries: &[Entry], u: f32) -> usize {
    if entries.len() <= COUNT_MAX {
        entries.iter().map(|e| (e.cmf <= u) as usize).sum()
    } else {
        entries.partition_point(|e| e.cmf <= u)
    }
}

/// The number of entries whose CMF is at most `u`, walking from entry `⌊u · n⌋` (where a
/// near-uniform CMF puts it, give or take one entry) to the first CMF above `u`.
#[inline]
fn count_from_uniform(entries: &[Entry], u: f32) -> usize {
    let n = entries.len();
    let mut i = ((u * n as f32) as usize).min(n);
    while i < n && entries[i].cmf <= u {
        i += 1;
    }
    while i > 0 && entries[i - 1].cmf > u {
        i -= 1;
    }
    i
}

impl Distribution1D {
    /// Builds from non-negative weights. When they sum to zero (or are not finite), the
    /// distribution falls back to uniform.
    pub fn new(weights: &[f32]) -> Distribution1D {
        let mut sum = 0.0f64;
        let mut cmf = Vec::with_capacity(weights.len());
        for &w in weights {
            sum += if w.is_finite() && w > 0.0 { w as f64 } else { 0.0 };
            cmf.push(sum);
        }
        let n = weights.len();
        let (pmf, cmf, total): (Vec<f32>, Vec<f32>, f64) = if sum > 0.0 && sum.is_finite() {
            let pmf =
                weights.iter().map(|&w| if w.is_finite() && w > 0.0 { (w as f64 / sum) as f32 } else { 0.0 }).collect();
            (pmf, cmf.iter().map(|&c| (c / sum) as f32).collect(), sum)
        } else {
            (vec![1.0 / n.max(1) as f32; n], (1..=n).map(|i| i as f32 / n as f32).collect(), 0.0)
        };
        let guide = guide_table(&cmf);
        let entries = cmf.iter().zip(&pmf).map(|(&cmf, &pmf)| Entry { cmf, pmf }).collect();
        Distribution1D { entries, total, guide }
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Sum of the weights the distribution was built from.
    pub fn total(&self) -> f64 {
        self.total
    }

    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.entries[i].pmf
    }

    /// The probability of entries `0..=i`.
    #[inline]
    pub fn cmf(&self, i: usize) -> f32 {
        self.entries[i].cmf
    }

    /// Samples an index for `u` in `[0,1)`; returns the index and `u` rescaled to `[0,1)`
    /// within the chosen entry (so one number can be reused).
    #[inline]
    pub fn sample(&self, u: f32) -> (usize, f32) {
        let n = self.entries.len();
        if n == 1 {
            // One entry (of probability one): what the search below returns.
            return (0, u.clamp(0.0, 1.0 - f32::EPSILON));
        }
        // The number of CMF entries at or below `u`, counted within the guide's buckets
        // around `u` for many entries.
        let i = match (&self.guide, self.guide.around(u)) {
            (Guide::Uniform, _) => count_from_uniform(&self.entries, u),
            (_, None) => count_at_most(&self.entries[..n - 1], u),
            (_, Some((lo, hi))) => lo + count_at_most(&self.entries[lo..hi.min(n)], u),
        }
        .min(n - 1);
        // Skip zero-probability entries that a CMF plateau could land on.
        let mut i = i;
        while self.entries[i].pmf == 0.0 && i + 1 < n {
            i += 1;
        }
        let lo = if i == 0 { 0.0 } else { self.entries[i - 1].cmf };
        let p = self.entries[i].pmf;
        let rescaled = if p > 0.0 { ((u - lo) / p).clamp(0.0, 1.0 - f32::EPSILON) } else { 0.0 };
        (i, rescaled)
    }
}

/// A piecewise-constant distribution over a `width × height` grid (rows then columns),
/// sampled by a marginal over rows and a conditional per row.
#[derive(Clone, Debug)]
pub struct Distribution2D {
    pub width: usize,
    pub height: usize,
    rows: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// `weights` in row-major order, `width × height` of them.
    pub fn new(weights: &[f32], width: usize, height: usize) -> Distribution2D {
        let rows: Vec<Distribution1D> = weights.chunks(width).map(Distribution1D::new).collect();
        let sums: Vec<f32> = rows.iter().map(|r| r.total() as f32).collect();
        Distribution2D { width, height, rows, marginal: Distribution1D::new(&sums) }
    }

    /// Samples a continuous point of `[0,1)²` (x along a row, y across rows) and returns it
    /// with its density with respect to the unit square.
    pub fn sample(&self, u: glam::Vec2) -> (glam::Vec2, f32) {
        let (y, uy) = self.marginal.sample(u.y);
        let (x, ux) = self.rows[y].sample(u.x);
        let p = glam::Vec2::new((x as f32 + ux) / self.width as f32, (y as f32 + uy) / self.height as f32);
        (p, self.pdf_cell(x, y))
    }

    fn pdf_cell(&self, x: usize, y: usize) -> f32 {
        self.marginal.pmf(y) * self.rows[y].pmf(x) * (self.width * self.height) as f32
    }

    /// Density at a point of the unit square.
    pub fn pdf(&self, p: glam::Vec2) -> f32 {
        let x = ((p.x * self.width as f32) as usize).min(self.width - 1);
        let y = ((p.y * self.height as f32) as usize).min(self.height - 1);
        self.pdf_cell(x, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::chi2::discrete_chi2;

    #[test]
    fn samples_follow_weights() {
        let w = [1.0, 0.0, 3.0, 0.5, 5.5];
        let d = Distribution1D::new(&w);
        let mut s = crate::sampling::Sampler::new(&[3]);
        let n = 100_000;
        let mut counts = vec![0u64; w.len()];
        for _ in 0..n {
            counts[d.sample(s.next_1d()).0] += 1;
        }
        assert_eq!(counts[1], 0);
        let expected: Vec<f64> = (0..w.len()).map(|i| d.pmf(i) as f64 * n as f64).collect();
        assert!(discrete_chi2(&counts, &expected).passed());
        // Negative control: the same samples against uniform expectations are rejected.
        let uniform = vec![n as f64 / w.len() as f64; w.len()];
        assert!(!discrete_chi2(&counts, &uniform).passed());
    }

    #[test]
    fn small_and_large_distributions_pick_the_binary_search_index() {
        // The index counted (up to 64 entries, or within guide buckets) or searched within
        // the buckets must be the full binary search's, also at `u` exactly on a CMF entry and
        // one ulp either side, and on zero-weight plateaus.
        let mut s = crate::sampling::Sampler::new(&[5]);
        for n in (1..=12).chain([63, 64, 65, 66, 71, 72, 73, 100, 1000, 2048, 4096, 70_000]) {
            for trial in 0..20 {
                // Every fifth trial one entry outweighs the rest by far (a sun in a sky map):
                // many entries then share one guide bucket. Two in five are uniform or
                // nearly so (a tessellated disk's triangles), with no guide table.
                let w: Vec<f32> = (0..n)
                    .map(|i| match () {
                        _ if trial % 5 == 2 => 1.0,
                        _ if trial % 5 == 3 => 1.0 + s.next_1d() * 1e-3,
                        _ if (i + trial) % 4 == 1 => 0.0,
                        _ if trial % 5 == 0 && i == n / 2 => 1e6,
                        _ => 0.1 + s.next_1d() * 3.0,
                    })
                    .collect();
                let d = Distribution1D::new(&w);
                let near_uniform = matches!(trial % 5, 2 | 3);
                assert_eq!(d.guide == Guide::Uniform, near_uniform && n > GUIDE_MIN, "n = {n}, trial {trial}");
                let mut us: Vec<f32> = (0..50).map(|_| s.next_1d()).collect();
                let cmf: Vec<f32> = (0..n).map(|i| d.cmf(i)).collect();
                for &c in &cmf {
                    us.extend([c, c.next_down(), c.next_up()].iter().filter(|u| (0.0..1.0).contains(*u)));
                }
                us.push(0.0);
                for u in us {
                    let mut i = cmf.partition_point(|&c| c <= u).min(n - 1);
                    while d.pmf(i) == 0.0 && i + 1 < n {
                        i += 1;
                    }
                    let (j, r) = d.sample(u);
                    assert_eq!(j, i, "n = {n}, u = {u}, cmf = {cmf:?}");
                    assert!(d.pmf(j) > 0.0 && (0.0..1.0).contains(&r));
                }
            }
        }
    }

    #[test]
    fn two_dimensional_density_integrates_to_one_and_matches_samples() {
        let w: Vec<f32> = (0..12).map(|i| ((i * 7) % 5) as f32).collect();
        let d = Distribution2D::new(&w, 4, 3);
        let mut total = 0.0;
        for y in 0..3 {
            for x in 0..4 {
                total += d.pdf(glam::Vec2::new((x as f32 + 0.5) / 4.0, (y as f32 + 0.5) / 3.0)) / 12.0;
            }
        }
        assert!((total - 1.0).abs() < 1e-5);
        let mut s = crate::sampling::Sampler::new(&[4]);
        for _ in 0..1000 {
            let (p, pdf) = d.sample(s.next_2d());
            assert!((d.pdf(p) - pdf).abs() < 1e-5 && pdf > 0.0);
        }
    }

    #[test]
    fn zero_weights_fall_back_to_uniform() {
        let d = Distribution1D::new(&[0.0, 0.0, 0.0, 0.0]);
        assert_eq!(d.pmf(2), 0.25);
        assert_eq!(d.sample(0.6).0, 2);
    }
}
