//! A hashed uniform grid over points, for the fixed-radius queries of vertex merging: cells
//! of side `2r` (a ball of radius `r` lies in the 2 × 2 × 2 cells nearest its centre), hashed
//! into as many buckets as there are points, the points sorted by bucket. Rebuilt every
//! iteration (the radius shrinks); a query allocates nothing.
//!
//! Light vertices on a wall share one coordinate by the thousand, which the kd-tree crate
//! the renderer uses elsewhere cannot bucket; a grid does not care.

use glam::{IVec3, Vec3};

/// The points of one iteration, by bucket.
pub struct HashGrid {
    inv_cell: f32,
    r2: f32,
    /// `start[b]..start[b + 1]` indexes `items` for bucket `b`.
    start: Vec<u32>,
    /// The points' ids and positions, bucket after bucket.
    items: Vec<(u32, Vec3)>,
}

impl HashGrid {
    /// The grid of `points` (id, position) for queries of radius `r`.
    pub fn new(points: &[(u32, Vec3)], r: f32) -> HashGrid {
        let inv_cell = 1.0 / (2.0 * r);
        let buckets = points.len().max(1);
        let mut start = vec![0u32; buckets + 1];
        let bucket_of = |p: Vec3| bucket(cell(p, inv_cell), buckets);
        for &(_, p) in points {
            start[bucket_of(p) + 1] += 1;
        }
        for b in 0..buckets {
            start[b + 1] += start[b];
        }
        let mut next = start.clone();
        let mut items = vec![(0u32, Vec3::ZERO); points.len()];
        for &(id, p) in points {
            let b = bucket_of(p);
            items[next[b] as usize] = (id, p);
            next[b] += 1;
        }
        HashGrid { inv_cell, r2: r * r, start, items }
    }

    /// Calls `found(id, squared distance)` for every point within `r` of `p`, in an order
    /// that depends only on the points.
    pub fn query(&self, p: Vec3, mut found: impl FnMut(u32, f32)) {
        let buckets = self.start.len() - 1;
        // The lower corner of the 2 × 2 × 2 cells around `p`.
        let base = cell(p - Vec3::splat(0.5 / self.inv_cell), self.inv_cell);
        let mut seen = [usize::MAX; 8];
        for k in 0..8 {
            let c = base + IVec3::new(k & 1, (k >> 1) & 1, (k >> 2) & 1);
            let b = bucket(c, buckets);
            // Two cells may share a bucket: each bucket once.
            if seen[..k as usize].contains(&b) {
                continue;
            }
            seen[k as usize] = b;
            for &(id, q) in &self.items[self.start[b] as usize..self.start[b + 1] as usize] {
                let d2 = (q - p).length_squared();
                if d2 <= self.r2 {
                    found(id, d2);
                }
            }
        }
    }
}

/// The cell of `p`.
#[inline]
fn cell(p: Vec3, inv_cell: f32) -> IVec3 {
    (p * inv_cell).floor().as_ivec3()
}

/// The bucket of cell `c` among `n`.
#[inline]
fn bucket(c: IVec3, n: usize) -> usize {
    let h = (c.x as u32).wrapping_mul(73_856_093)
        ^ (c.y as u32).wrapping_mul(19_349_663)
        ^ (c.z as u32).wrapping_mul(83_492_791);
    h as usize % n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    #[test]
    fn queries_find_exactly_the_points_within_the_radius() {
        // Points on a plane (one coordinate shared) and in a box, against a linear scan.
        let mut rng = Sampler::new(&[3]);
        let mut points: Vec<(u32, Vec3)> = (0..4000)
            .map(|i| {
                let u = rng.next_2d();
                let z = if i % 2 == 0 { 0.0 } else { rng.next_1d() };
                (i, Vec3::new(u.x, u.y, z))
            })
            .collect();
        points.push((9999, Vec3::new(0.5, 0.5, 0.0)));
        let r = 0.03;
        let grid = HashGrid::new(&points, r);
        for q in 0..300 {
            let u = rng.next_2d();
            let p = Vec3::new(u.x, u.y, if q % 3 == 0 { 0.0 } else { rng.next_1d() });
            let mut got = Vec::new();
            grid.query(p, |id, _| got.push(id));
            got.sort_unstable();
            let mut want: Vec<u32> =
                points.iter().filter(|(_, x)| (*x - p).length_squared() <= r * r).map(|(id, _)| *id).collect();
            want.sort_unstable();
            assert_eq!(got, want, "query {q} at {p}");
        }
    }
}
