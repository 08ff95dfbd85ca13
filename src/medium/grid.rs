//! Volumes: values over space that a heterogeneous medium reads its extinction and albedo
//! from. Mitsuba's `gridvolume` (a [`crate::scene::vol`] grid placed by a transform and
//! looked up trilinearly or at the nearest cell) and a constant (`constvolume`, or a plain
//! value).
//!
//! A grid fills the unit cube of its local space. Mitsuba 3 places cell `i`'s value at
//! `(i + ½) / res` and clamps lookups beyond the outer cell centres; Mitsuba 0.6 placed
//! the first and last values on the cube's faces (`i / (res − 1)`). Outside the cube a
//! grid reads as zero for a medium's extinction (the medium ends there) and as its clamped
//! border for the albedo.

use crate::math::Rgb;
use glam::{Affine3A, Vec3};

/// Where a grid's values sit in its unit cube.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Samples {
    /// Mitsuba 3: at the cells' centres.
    CellCentred,
    /// Mitsuba 0.6: on a lattice whose outer values lie on the cube's faces.
    Corners,
}

/// A grid of values placed in the scene.
#[derive(Clone, Debug)]
pub struct Grid {
    res: [usize; 3],
    channels: usize,
    data: Vec<f32>,
    /// World space to the grid's unit cube.
    to_local: Affine3A,
    samples: Samples,
    nearest: bool,
    max: f32,
}

impl Grid {
    /// A grid of `res` cells of `channels` values (`data` x fastest, channels interleaved),
    /// whose unit cube `to_local` maps world space onto.
    pub fn new(
        res: [usize; 3],
        channels: usize,
        data: Vec<f32>,
        to_local: Affine3A,
        samples: Samples,
        nearest: bool,
    ) -> Grid {
        assert_eq!(data.len(), res.iter().product::<usize>() * channels);
        let max = data.iter().copied().fold(0.0f32, f32::max);
        Grid { res, channels, data, to_local, samples, nearest, max }
    }

    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The largest value: no lookup (each an average of values) exceeds it.
    pub fn max(&self) -> f32 {
        self.max
    }

    /// The values themselves.
    pub fn values(&self) -> &[f32] {
        &self.data
    }

    /// A ray from `o` along the unit direction `d`, in the grid's local space (distances
    /// along it stay the world's).
    #[inline]
    pub fn local_ray(&self, o: Vec3, d: Vec3) -> (Vec3, Vec3) {
        (self.to_local.transform_point3(o), self.to_local.transform_vector3(d))
    }

    /// The stretch `[t0, t1]` of the local ray `(o, d)` inside the unit cube, if any.
    pub fn clip(o: Vec3, d: Vec3) -> Option<(f32, f32)> {
        let inv = d.recip();
        let (a, b) = (-o * inv, (Vec3::ONE - o) * inv);
        // An axis the ray runs parallel to gives NaN from 0 · ∞: it bounds nothing when the
        // ray lies between that axis' faces, and excludes everything otherwise.
        let mut t0 = f32::NEG_INFINITY;
        let mut t1 = f32::INFINITY;
        for i in 0..3 {
            if d[i] == 0.0 {
                if !(0.0..=1.0).contains(&o[i]) {
                    return None;
                }
                continue;
            }
            t0 = t0.max(a[i].min(b[i]));
            t1 = t1.min(a[i].max(b[i]));
        }
        (t0 <= t1).then_some((t0, t1))
    }

    /// Whether the local point lies in the unit cube.
    #[inline]
    pub fn contains(p: Vec3) -> bool {
        p.cmpge(Vec3::ZERO).all() && p.cmple(Vec3::ONE).all()
    }

    /// The first channel at the local point `p` (zero outside the cube).
    #[inline]
    pub fn scalar_local(&self, p: Vec3) -> f32 {
        if !Grid::contains(p) {
            return 0.0;
        }
        self.lookup(p, 0)
    }

    /// The colour at the world point `p`, the border's beyond the cube (a one-channel grid
    /// is grey).
    pub fn rgb_at(&self, p: Vec3) -> Rgb {
        let l = self.to_local.transform_point3(p).clamp(Vec3::ZERO, Vec3::ONE);
        if self.channels == 1 {
            Rgb::splat(self.lookup(l, 0))
        } else {
            Rgb::new(self.lookup(l, 0), self.lookup(l, 1), self.lookup(l, 2))
        }
    }

    /// Channel `c` at the local point `p` of the unit cube.
    fn lookup(&self, p: Vec3, c: usize) -> f32 {
        let res = Vec3::new(self.res[0] as f32, self.res[1] as f32, self.res[2] as f32);
        let top = res - Vec3::ONE;
        if self.nearest {
            let x = match self.samples {
                Samples::CellCentred => (p * res).floor(),
                Samples::Corners => (p * top).round(),
            };
            let i = x.clamp(Vec3::ZERO, top);
            return self.at([i.x as usize, i.y as usize, i.z as usize], c);
        }
        let x = match self.samples {
            Samples::CellCentred => p * res - Vec3::splat(0.5),
            Samples::Corners => p * top,
        }
        .clamp(Vec3::ZERO, top);
        let i0 = x.floor();
        let f = x - i0;
        let i0 = [i0.x as usize, i0.y as usize, i0.z as usize];
        let i1 = [0, 1, 2].map(|a| (i0[a] + 1).min(self.res[a] - 1));
        let mut v = 0.0;
        for corner in 0..8 {
            let pick = |a: usize| corner >> a & 1 == 1;
            let w = (0..3).map(|a| if pick(a) { f[a] } else { 1.0 - f[a] }).product::<f32>();
            if w > 0.0 {
                v += w * self.at([0, 1, 2].map(|a| if pick(a) { i1[a] } else { i0[a] }), c);
            }
        }
        v
    }

    #[inline]
    fn at(&self, i: [usize; 3], c: usize) -> f32 {
        self.data[((i[2] * self.res[1] + i[1]) * self.res[0] + i[0]) * self.channels + c]
    }
}

/// A value over space: a constant or a grid.
#[derive(Clone, Debug)]
pub enum Volume {
    Constant(Rgb),
    Grid(Grid),
}

impl Volume {
    /// The colour at the world point `p`.
    #[inline]
    pub fn rgb_at(&self, p: Vec3) -> Rgb {
        match self {
            Volume::Constant(v) => *v,
            Volume::Grid(g) => g.rgb_at(p),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(samples: Samples, nearest: bool) -> Grid {
        // Values 0, 1, 2, 3 along x, the same along y and z.
        let data = (0..4 * 2 * 2).map(|i| (i % 4) as f32).collect();
        Grid::new([4, 2, 2], 1, data, Affine3A::IDENTITY, samples, nearest)
    }

    #[test]
    fn trilinear_lookups_interpolate_between_cell_centres() {
        let g = ramp(Samples::CellCentred, false);
        // Cell i's centre is at (i + ½) / 4; beyond the outer centres the border holds.
        for (x, v) in [(0.125, 0.0), (0.375, 1.0), (0.25, 0.5), (0.5, 1.5), (0.0, 0.0), (1.0, 3.0), (0.9, 3.0)] {
            assert!((g.scalar_local(Vec3::new(x, 0.3, 0.7)) - v).abs() < 1e-5, "at {x}");
        }
        let c = ramp(Samples::Corners, false);
        for (x, v) in [(0.0, 0.0), (1.0 / 3.0, 1.0), (0.5, 1.5), (1.0, 3.0)] {
            assert!((c.scalar_local(Vec3::new(x, 0.3, 0.7)) - v).abs() < 1e-5, "at {x}");
        }
        assert_eq!(g.scalar_local(Vec3::new(1.01, 0.5, 0.5)), 0.0);
        assert_eq!(g.max(), 3.0);
    }

    #[test]
    fn nearest_lookups_take_one_cell() {
        let g = ramp(Samples::CellCentred, true);
        assert_eq!(g.scalar_local(Vec3::new(0.49, 0.5, 0.5)), 1.0);
        assert_eq!(g.scalar_local(Vec3::new(0.51, 0.5, 0.5)), 2.0);
        assert_eq!(g.scalar_local(Vec3::new(1.0, 0.5, 0.5)), 3.0);
    }

    #[test]
    fn rays_are_clipped_to_the_unit_cube() {
        let (t0, t1) = Grid::clip(Vec3::new(-1.0, 0.5, 0.5), Vec3::X).unwrap();
        assert!((t0 - 1.0).abs() < 1e-6 && (t1 - 2.0).abs() < 1e-6);
        assert_eq!(Grid::clip(Vec3::new(-1.0, 1.5, 0.5), Vec3::X), None);
        let (t0, t1) = Grid::clip(Vec3::splat(0.5), Vec3::new(0.0, 0.0, -1.0)).unwrap();
        assert!((t0 + 0.5).abs() < 1e-6 && (t1 - 0.5).abs() < 1e-6);
    }
}
