//! The film: reconstruction filters, per-tile image blocks and their deterministic merge.
//!
//! As in Mitsuba 3's `hdrfilm`, every sample is splatted with the filter's weight onto
//! each pixel whose centre lies within the filter radius, and a pixel's value is the
//! weighted average `Σ w L / Σ w`. Tiles render into their own [`ImageBlock`] (with a
//! border for the filter's reach) and blocks are merged in tile order, so a fixed seed
//! gives the same image whatever the number of threads.

use crate::math::Rgb;
use glam::Vec2;

/// Mitsuba's reconstruction filters (`rfilter`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Filter {
    /// Radius 0.5 by default: each sample belongs to its pixel.
    Box { radius: f32 },
    /// Radius 1 by default.
    Tent { radius: f32 },
    /// Truncated at 4 standard deviations, minus the value there (Mitsuba 3).
    Gaussian { stddev: f32 },
}

impl Filter {
    pub fn radius(&self) -> f32 {
        match *self {
            Filter::Box { radius } | Filter::Tent { radius } => radius,
            Filter::Gaussian { stddev } => 4.0 * stddev,
        }
    }

    /// One-dimensional filter weight at offset `x`.
    #[inline]
    pub fn eval(&self, x: f32) -> f32 {
        let x = x.abs();
        match *self {
            Filter::Box { radius } => {
                if x <= radius {
                    1.0
                } else {
                    0.0
                }
            }
            Filter::Tent { radius } => (1.0 - x / radius).max(0.0),
            Filter::Gaussian { stddev } => {
                let alpha = -1.0 / (2.0 * stddev * stddev);
                let r = 4.0 * stddev;
                ((alpha * x * x).exp() - (alpha * r * r).exp()).max(0.0)
            }
        }
    }
}

/// An axis-aligned rectangle of pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tile {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
}

/// Splits a `width × height` image into tiles of at most `size × size`, row by row.
pub fn tiles(width: u32, height: u32, size: u32) -> Vec<Tile> {
    let mut out = Vec::new();
    for y0 in (0..height).step_by(size as usize) {
        for x0 in (0..width).step_by(size as usize) {
            out.push(Tile { x0, y0, width: size.min(width - x0), height: size.min(height - y0) });
        }
    }
    out
}

/// Weighted sums `(Σ w r, Σ w g, Σ w b, Σ w)` for a tile plus a filter border.
pub struct ImageBlock {
    /// Pixel coordinates of the block's top-left entry (may be negative by the border).
    ox: i32,
    oy: i32,
    w: usize,
    h: usize,
    data: Vec<[f32; 4]>,
    filter: Filter,
    /// Samples rejected because their value was NaN or infinite.
    pub invalid_samples: u64,
}

impl ImageBlock {
    pub fn new(tile: Tile, filter: Filter) -> ImageBlock {
        let b = (filter.radius() - 0.5).ceil().max(0.0) as i32;
        let (w, h) = (tile.width as usize + 2 * b as usize, tile.height as usize + 2 * b as usize);
        ImageBlock {
            ox: tile.x0 as i32 - b,
            oy: tile.y0 as i32 - b,
            w,
            h,
            data: vec![[0.0; 4]; w * h],
            filter,
            invalid_samples: 0,
        }
    }

    /// Adds a radiance sample at a film position (pixel units). Non-finite values are
    /// dropped and counted.
    #[inline]
    pub fn put(&mut self, pos: Vec2, value: Rgb) {
        if !value.is_finite() {
            self.invalid_samples += 1;
            return;
        }
        let r = self.filter.radius();
        if let Filter::Box { radius } = self.filter
            && radius <= 0.5
        {
            let (px, py) = (pos.x.floor() as i32 - self.ox, pos.y.floor() as i32 - self.oy);
            if px >= 0 && py >= 0 && (px as usize) < self.w && (py as usize) < self.h {
                let e = &mut self.data[py as usize * self.w + px as usize];
                e[0] += value.x;
                e[1] += value.y;
                e[2] += value.z;
                e[3] += 1.0;
            }
            return;
        }
        // Pixels whose centre (i + 0.5) lies within the radius of the sample.
        let x_lo = (pos.x - 0.5 - r).ceil() as i32;
        let x_hi = (pos.x - 0.5 + r).floor() as i32;
        let y_lo = (pos.y - 0.5 - r).ceil() as i32;
        let y_hi = (pos.y - 0.5 + r).floor() as i32;
        let mut wx = [0.0f32; 16];
        let nx = ((x_hi - x_lo + 1).max(0) as usize).min(16);
        for (k, w) in wx.iter_mut().enumerate().take(nx) {
            *w = self.filter.eval(x_lo as f32 + k as f32 + 0.5 - pos.x);
        }
        for y in y_lo..=y_hi {
            let by = y - self.oy;
            if by < 0 || by as usize >= self.h {
                continue;
            }
            let wy = self.filter.eval(y as f32 + 0.5 - pos.y);
            if wy == 0.0 {
                continue;
            }
            for (k, &wxk) in wx.iter().enumerate().take(nx) {
                let bx = x_lo + k as i32 - self.ox;
                if bx < 0 || bx as usize >= self.w {
                    continue;
                }
                let w = wxk * wy;
                if w == 0.0 {
                    continue;
                }
                let e = &mut self.data[by as usize * self.w + bx as usize];
                e[0] += value.x * w;
                e[1] += value.y * w;
                e[2] += value.z * w;
                e[3] += w;
            }
        }
    }
}

/// The accumulated image.
#[derive(Clone)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    pub filter: Filter,
    data: Vec<[f64; 4]>,
    /// Samples dropped for non-finite values.
    pub invalid_samples: u64,
}

impl Film {
    pub fn new(width: u32, height: u32, filter: Filter) -> Film {
        Film { width, height, filter, data: vec![[0.0; 4]; width as usize * height as usize], invalid_samples: 0 }
    }

    /// Adds a block (the caller merges blocks in a fixed order).
    pub fn merge(&mut self, block: &ImageBlock) {
        self.invalid_samples += block.invalid_samples;
        for by in 0..block.h {
            let y = by as i32 + block.oy;
            if y < 0 || y >= self.height as i32 {
                continue;
            }
            for bx in 0..block.w {
                let x = bx as i32 + block.ox;
                if x < 0 || x >= self.width as i32 {
                    continue;
                }
                let s = block.data[by * block.w + bx];
                let d = &mut self.data[y as usize * self.width as usize + x as usize];
                for c in 0..4 {
                    d[c] += s[c] as f64;
                }
            }
        }
    }

    /// The developed image: linear RGB, row-major from the top-left.
    pub fn develop(&self) -> Vec<Rgb> {
        self.data
            .iter()
            .map(|d| {
                if d[3] > 0.0 {
                    Rgb::new((d[0] / d[3]) as f32, (d[1] / d[3]) as f32, (d[2] / d[3]) as f32)
                } else {
                    Rgb::ZERO
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_signal_develops_to_itself_with_every_filter() {
        for filter in [Filter::Box { radius: 0.5 }, Filter::Tent { radius: 1.0 }, Filter::Gaussian { stddev: 0.5 }] {
            let mut film = Film::new(9, 7, filter);
            let mut s = crate::sampling::Sampler::new(&[1]);
            for t in tiles(9, 7, 4) {
                let mut b = ImageBlock::new(t, filter);
                for y in t.y0..t.y0 + t.height {
                    for x in t.x0..t.x0 + t.width {
                        for _ in 0..4 {
                            b.put(Vec2::new(x as f32, y as f32) + s.next_2d(), Rgb::new(0.25, 0.5, 2.0));
                        }
                    }
                }
                film.merge(&b);
            }
            for v in film.develop() {
                assert!((v - Rgb::new(0.25, 0.5, 2.0)).abs().max_element() < 1e-5, "{filter:?}: {v}");
            }
        }
    }

    #[test]
    fn non_finite_samples_are_dropped_and_counted() {
        let t = Tile { x0: 0, y0: 0, width: 2, height: 2 };
        let mut b = ImageBlock::new(t, Filter::Box { radius: 0.5 });
        b.put(Vec2::new(0.5, 0.5), Rgb::new(f32::NAN, 0.0, 0.0));
        b.put(Vec2::new(0.5, 0.5), Rgb::new(f32::INFINITY, 0.0, 0.0));
        b.put(Vec2::new(0.5, 0.5), Rgb::ONE);
        let mut f = Film::new(2, 2, Filter::Box { radius: 0.5 });
        f.merge(&b);
        assert_eq!(f.invalid_samples, 2);
        assert_eq!(f.develop()[0], Rgb::ONE);
    }

    #[test]
    fn tiles_cover_the_image_once() {
        let ts = tiles(70, 33, 16);
        let covered: u32 = ts.iter().map(|t| t.width * t.height).sum();
        assert_eq!(covered, 70 * 33);
    }
}
