//! Two-stage Metropolis (Mitsuba 0.6's `twoStage` of `pssmlt` and `mlt`): a first stage
//! estimates the image's luminance at a reduced resolution; the chains of the second stage
//! then sample paths in proportion to `f(x) / I(x)`, their luminance over the first stage's
//! at their film position, so that each pixel gets about the same share of the mutations
//! instead of a share proportional to its brightness, and each splat carries
//! `b' I(x) f(x) / |f(x)|`, with `b'` the mean of `f / I` over the image (estimated by
//! bootstrap samples independent of the map, so the image stays consistent whatever the map).
//! Any positive map gives the same image in expectation; a good one spreads relative error
//! evenly. Contract §6 leaves the chains' target function to the implementation: this is
//! the option Mitsuba 0.6 offers.
//!
//! The map is built from BDPT samples at uniformly random film positions, their luminance
//! summed over cells of `reduction`² pixels, interpolated bilinearly between the cells'
//! centres to every pixel, and kept at least [`FLOOR`] times the image's mean so that no
//! pixel's target grows without bound where the first stage saw little light.

use glam::Vec2;

/// The smallest value of the map, as a fraction of its mean: where the first stage found
/// (almost) no light, the chains give a pixel at most `1 / FLOOR` times the mutations its
/// brightness alone would.
pub const FLOOR: f32 = 0.02;

/// The coarse grid of the first stage: `cols × rows` cells of `cell` pixels square over a
/// `width × height` film (the last row and column may be cut short).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Grid {
    pub width: u32,
    pub height: u32,
    pub cell: u32,
    pub cols: u32,
    pub rows: u32,
}

impl Grid {
    pub fn new(width: u32, height: u32, cell: u32) -> Grid {
        let cell = cell.max(1);
        Grid { width, height, cell, cols: width.div_ceil(cell).max(1), rows: height.div_ceil(cell).max(1) }
    }

    pub fn len(&self) -> usize {
        (self.cols * self.rows) as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The cell holding film position `pos` (clamped to the film).
    pub fn cell_of(&self, pos: Vec2) -> usize {
        let x = ((pos.x.max(0.0) as u32) / self.cell).min(self.cols - 1);
        let y = ((pos.y.max(0.0) as u32) / self.cell).min(self.rows - 1);
        (y * self.cols + x) as usize
    }

    /// Pixels of the film inside cell `(cx, cy)`.
    fn area(&self, cx: u32, cy: u32) -> f64 {
        let w = (self.width - cx * self.cell).min(self.cell);
        let h = (self.height - cy * self.cell).min(self.cell);
        (w * h) as f64
    }
}

/// The first stage's luminance per pixel: what the chains' target divides by.
#[derive(Clone, Debug)]
pub struct Importance {
    width: u32,
    height: u32,
    values: Vec<f32>,
}

impl Importance {
    /// The map from the first stage's luminance `sums` per cell of `grid` over `samples`
    /// samples, each at a uniformly random film position: a cell's mean luminance per pixel
    /// is its sum times the film's pixel count over the samples and the cell's area. `None`
    /// when the first stage found no light at all.
    pub fn from_cells(grid: Grid, sums: &[f64], samples: u64) -> Option<Importance> {
        assert_eq!(sums.len(), grid.len());
        let pixels = grid.width as f64 * grid.height as f64;
        let means: Vec<f64> = (0..grid.rows)
            .flat_map(|cy| (0..grid.cols).map(move |cx| (cx, cy)))
            .zip(sums)
            .map(|((cx, cy), &s)| {
                let v = s.max(0.0) * pixels / (samples.max(1) as f64 * grid.area(cx, cy));
                if v.is_finite() { v } else { 0.0 }
            })
            .collect();
        // Bilinear interpolation between cell centres, clamped at the film's edges.
        let at = |cx: i64, cy: i64| {
            means[(cy.clamp(0, grid.rows as i64 - 1) * grid.cols as i64 + cx.clamp(0, grid.cols as i64 - 1)) as usize]
        };
        let c = grid.cell as f64;
        let mut values = Vec::with_capacity((grid.width * grid.height) as usize);
        for y in 0..grid.height {
            let fy = (y as f64 + 0.5) / c - 0.5;
            let (y0, ty) = (fy.floor() as i64, fy - fy.floor());
            for x in 0..grid.width {
                let fx = (x as f64 + 0.5) / c - 0.5;
                let (x0, tx) = (fx.floor() as i64, fx - fx.floor());
                let v = (1.0 - ty) * ((1.0 - tx) * at(x0, y0) + tx * at(x0 + 1, y0))
                    + ty * ((1.0 - tx) * at(x0, y0 + 1) + tx * at(x0 + 1, y0 + 1));
                values.push(v as f32);
            }
        }
        let mean = values.iter().map(|&v| v as f64).sum::<f64>() / values.len() as f64;
        if !(mean > 0.0 && mean.is_finite()) {
            return None;
        }
        let floor = FLOOR * mean as f32;
        for v in &mut values {
            *v = v.max(floor);
        }
        Some(Importance { width: grid.width, height: grid.height, values })
    }

    /// The map at film position `pos` (its pixel's value, clamped to the film).
    #[inline]
    pub fn at(&self, pos: Vec2) -> f32 {
        let x = (pos.x.max(0.0) as u32).min(self.width - 1);
        let y = (pos.y.max(0.0) as u32).min(self.height - 1);
        self.values[(y * self.width + x) as usize]
    }

    /// The map's value in pixel `(x, y)` (clamped to the film).
    pub fn pixel(&self, (x, y): (i32, i32)) -> f32 {
        self.at(Vec2::new(x as f32 + 0.5, y as f32 + 0.5))
    }

    pub fn values(&self) -> &[f32] {
        &self.values
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_uniform_image_gives_a_flat_map() {
        // Sums proportional to each cell's area: the same luminance everywhere.
        let g = Grid::new(40, 25, 16);
        assert_eq!((g.cols, g.rows), (3, 2));
        let sums: Vec<f64> = (0..g.rows)
            .flat_map(|cy| (0..g.cols).map(move |cx| (cx, cy)))
            .map(|(cx, cy)| 0.5 * g.area(cx, cy) * 1000.0 / (40.0 * 25.0))
            .collect();
        let m = Importance::from_cells(g, &sums, 1000).unwrap();
        for &v in m.values() {
            assert!((v - 0.5).abs() < 1e-5, "{v}");
        }
    }

    #[test]
    fn the_map_interpolates_between_cells_and_keeps_its_floor() {
        let g = Grid::new(32, 16, 16);
        // Left cell bright, right cell black.
        let area = 256.0;
        let m = Importance::from_cells(g, &[2.0 * area * 100.0 / 512.0, 0.0], 100).unwrap();
        // The left cell's centre keeps its mean, the right one's the floor, and between
        // them the map falls linearly.
        let mean = m.values().iter().map(|&v| v as f64).sum::<f64>() / 512.0;
        assert!((m.at(Vec2::new(7.9, 8.0)) - 2.0).abs() < 0.07);
        assert!((m.pixel((0, 3)) - 2.0).abs() < 1e-5);
        assert!((m.pixel((31, 3)) as f64 - FLOOR as f64 * mean).abs() < 1e-3);
        let mid = m.pixel((15, 3));
        assert!(mid > 0.9 && mid < 1.1, "{mid}");
        for w in m.values()[..32].windows(2) {
            assert!(w[1] <= w[0] + 1e-6);
        }
    }

    #[test]
    fn no_light_gives_no_map() {
        let g = Grid::new(8, 8, 4);
        assert!(Importance::from_cells(g, &[0.0; 4], 10).is_none());
    }

    #[test]
    fn positions_fall_in_their_cells() {
        let g = Grid::new(40, 25, 16);
        assert_eq!(g.cell_of(Vec2::new(0.0, 0.0)), 0);
        assert_eq!(g.cell_of(Vec2::new(39.99, 24.99)), 5);
        assert_eq!(g.cell_of(Vec2::new(16.0, 15.99)), 1);
        assert_eq!(g.cell_of(Vec2::new(-1.0, 100.0)), 3);
    }
}
