//! The film: reconstruction filters, per-tile image blocks and their deterministic merge.
//!
//! As in Mitsuba 3's `hdrfilm`, every sample is splatted with the filter's weight onto
//! each pixel whose centre lies within the filter radius, and a pixel's value is the
//! weighted average `Σ w L / Σ w`. Tiles render into their own [`ImageBlock`] (with a
//! border for the filter's reach) and blocks are merged in tile order, so a fixed seed
//! gives the same image whatever the number of threads.
//!
//! The sums are exact ([`ExactSum`]): a sample's weighted value `w L` (a product of two
//! `f32`, exact in `f64`) is added without rounding, so a pixel's sum does not depend on the
//! order or grouping of its samples. That is what lets a render cut into chunks of
//! iterations, each accumulated on its own and merged later, give the very image one
//! process gives.

use crate::math::{Rgb, floor_i32};
use glam::Vec2;

/// Mitsuba's reconstruction filters (`rfilter`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
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

/// Calls `f(x, y, w)` for every pixel whose centre lies within the filter's radius of the
/// film position `pos`, with the filter weight `w > 0`.
#[inline]
fn footprint(filter: &Filter, pos: Vec2, mut f: impl FnMut(i32, i32, f32)) {
    if let Filter::Box { radius } = *filter
        && radius <= 0.5
    {
        f(floor_i32(pos.x), floor_i32(pos.y), 1.0);
        return;
    }
    let r = filter.radius();
    let x_lo = (pos.x - 0.5 - r).ceil() as i32;
    let x_hi = floor_i32(pos.x - 0.5 + r);
    let y_lo = (pos.y - 0.5 - r).ceil() as i32;
    let y_hi = floor_i32(pos.y - 0.5 + r);
    let mut wx = [0.0f32; 16];
    let nx = ((x_hi - x_lo + 1).max(0) as usize).min(16);
    for (k, w) in wx.iter_mut().enumerate().take(nx) {
        *w = filter.eval(x_lo as f32 + k as f32 + 0.5 - pos.x);
    }
    for y in y_lo..=y_hi {
        let wy = filter.eval(y as f32 + 0.5 - pos.y);
        if wy == 0.0 {
            continue;
        }
        for (k, &wxk) in wx.iter().enumerate().take(nx) {
            let w = wxk * wy;
            if w != 0.0 {
                f(x_lo + k as i32, y, w);
            }
        }
    }
}

/// A light-tracing contribution landing at a film position, with its strategy's layer.
#[derive(Clone, Copy, Debug)]
pub struct Splat {
    pub pos: Vec2,
    pub value: Rgb,
    pub layer: u16,
}

impl Splat {
    /// A splat of strategy `(s,t)`, in its layer when per-strategy layers are kept.
    #[inline]
    pub fn of_strategy(s: usize, t: usize, pos: Vec2, value: Rgb, layers: bool) -> Splat {
        Splat { pos, value, layer: if layers { strategy_layer(s, t) as u16 } else { 0 } }
    }
}

/// Longest path (in segments) with an image of its own among the per-strategy images;
/// longer paths share one.
pub const STRATEGY_MAX_DEPTH: usize = 8;
/// Number of per-strategy layers: one per `(s,t)` with `1 <= s+t-1 <= STRATEGY_MAX_DEPTH`,
/// plus one for all longer paths.
pub const STRATEGY_LAYERS: usize = (STRATEGY_MAX_DEPTH - 1) * (STRATEGY_MAX_DEPTH + 2) / 2 + STRATEGY_MAX_DEPTH + 2;

/// The layer of strategy `(s,t)`.
#[inline]
pub fn strategy_layer(s: usize, t: usize) -> usize {
    let d = s + t - 1;
    if d > STRATEGY_MAX_DEPTH { STRATEGY_LAYERS - 1 } else { (d - 1) * (d + 2) / 2 + s }
}

/// The file name of a layer (`s2_t3`, or `longer`).
pub fn strategy_layer_name(layer: usize) -> String {
    if layer == STRATEGY_LAYERS - 1 {
        return format!("longer_than_{STRATEGY_MAX_DEPTH}");
    }
    for d in 1..=STRATEGY_MAX_DEPTH {
        for s in 0..=d {
            if strategy_layer(s, d + 1 - s) == layer {
                return format!("s{s}_t{}", d + 1 - s);
            }
        }
    }
    unreachable!("layer {layer} out of range")
}

/// A sum of `f64` values kept as an unevaluated pair `hi + lo` (Knuth's TwoSum moves each
/// addition's rounding error into `lo`).
///
/// Sums of the film's terms are exact, hence independent of the order of the additions, as
/// long as `lo` itself never rounds: its terms are multiples of the smallest term's last
/// bit and stay below a few units of `hi`'s last bit, which fits `lo`'s 53 bits while the
/// largest partial sum is less than about `2^50 / n` times the smallest term of `n` (for
/// `f32` radiance times `f32` filter weights, ratios of `10^13` at 1 000 samples a pixel).
/// Beyond that the result is still correct to `f64` precision, but two groupings may then
/// differ in the last bit of an `f32` pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExactSum {
    pub hi: f64,
    pub lo: f64,
}

impl ExactSum {
    /// Adds `x` (TwoSum: `hi + lo + x` is kept exactly while `lo` does not round).
    #[inline]
    pub fn add(&mut self, x: f64) {
        let s = self.hi + x;
        let b = s - self.hi;
        let err = (self.hi - (s - b)) + (x - b);
        self.hi = s;
        self.lo += err;
    }

    /// Adds another sum.
    #[inline]
    pub fn add_sum(&mut self, o: ExactSum) {
        self.add(o.hi);
        self.lo += o.lo;
    }

    /// The sum, rounded once.
    #[inline]
    pub fn value(&self) -> f64 {
        self.hi + self.lo
    }
}

/// Weighted sums `(Σ w r, Σ w g, Σ w b, Σ w)` for a tile plus a filter border.
pub struct ImageBlock {
    /// Pixel coordinates of the block's top-left entry (may be negative by the border).
    ox: i32,
    oy: i32,
    w: usize,
    h: usize,
    data: Vec<[ExactSum; 4]>,
    /// Per-strategy weighted sums `(Σ w r, Σ w g, Σ w b)`, layer after layer (empty unless
    /// per-strategy images are wanted).
    layers: Vec<[f32; 3]>,
    filter: Filter,
    /// Samples rejected because their value was NaN or infinite.
    pub invalid_samples: u64,
}

impl ImageBlock {
    pub fn new(tile: Tile, filter: Filter) -> ImageBlock {
        ImageBlock::with_layers(tile, filter, 0)
    }

    /// A block that also keeps `layers` per-strategy images.
    pub fn with_layers(tile: Tile, filter: Filter, layers: usize) -> ImageBlock {
        let b = (filter.radius() - 0.5).ceil().max(0.0) as i32;
        let (w, h) = (tile.width as usize + 2 * b as usize, tile.height as usize + 2 * b as usize);
        ImageBlock {
            ox: tile.x0 as i32 - b,
            oy: tile.y0 as i32 - b,
            w,
            h,
            data: vec![[ExactSum::default(); 4]; w * h],
            layers: vec![[0.0; 3]; layers * w * h],
            filter,
            invalid_samples: 0,
        }
    }

    #[inline]
    fn index(&self, x: i32, y: i32) -> Option<usize> {
        let (bx, by) = (x - self.ox, y - self.oy);
        (bx >= 0 && by >= 0 && (bx as usize) < self.w && (by as usize) < self.h)
            .then(|| by as usize * self.w + bx as usize)
    }

    /// Adds a radiance sample at a film position (pixel units). Non-finite values are
    /// dropped and counted.
    #[inline]
    pub fn put(&mut self, pos: Vec2, value: Rgb) {
        self.put_layers(pos, value, &[]);
    }

    /// Adds a sample and its per-strategy parts `(layer, value)`, which share its filter
    /// weights (so the layers sum to the image).
    pub fn put_layers(&mut self, pos: Vec2, value: Rgb, parts: &[(u16, Rgb)]) {
        if !value.is_finite() || parts.iter().any(|(_, v)| !v.is_finite()) {
            self.invalid_samples += 1;
            return;
        }
        let filter = self.filter;
        let plane = self.w * self.h;
        footprint(&filter, pos, |x, y, w| {
            if let Some(i) = self.index(x, y) {
                let e = &mut self.data[i];
                let w64 = w as f64;
                e[0].add(value.x as f64 * w64);
                e[1].add(value.y as f64 * w64);
                e[2].add(value.z as f64 * w64);
                e[3].add(w64);
                for (layer, v) in parts {
                    let e = &mut self.layers[*layer as usize * plane + i];
                    e[0] += v.x * w;
                    e[1] += v.y * w;
                    e[2] += v.z * w;
                }
            }
        });
    }
}

/// The accumulated image: filtered camera samples (`Σ w L / Σ w`) plus light-tracing splats
/// (`Σ h L / ∫h`, scaled by pixels per light path). Camera samples lie inside the image, so a
/// border pixel's weighted mean covers only the part of its filter inside the image; the
/// splats' `∫h` is taken over the same part, so both estimate the same pixel value.
#[derive(Clone)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    pub filter: Filter,
    data: Vec<[ExactSum; 4]>,
    splats: Vec<[ExactSum; 3]>,
    /// Per-strategy images: camera parts and splat parts, layer after layer.
    layers: usize,
    layer_data: Vec<[f64; 3]>,
    layer_splats: Vec<[f64; 3]>,
    /// `1 / ∫ filter` over the image, per column and per row (the filters are separable).
    col_norm: Vec<f32>,
    row_norm: Vec<f32>,
    /// Light paths whose splats are in the film (the splat estimator's sample count).
    pub light_paths: u64,
    /// Samples dropped for non-finite values.
    pub invalid_samples: u64,
}

impl Film {
    pub fn new(width: u32, height: u32, filter: Filter) -> Film {
        Film::with_layers(width, height, filter, 0)
    }

    pub fn with_layers(width: u32, height: u32, filter: Filter, layers: usize) -> Film {
        let n = width as usize * height as usize;
        Film {
            width,
            height,
            filter,
            data: vec![[ExactSum::default(); 4]; n],
            splats: Vec::new(),
            layers,
            layer_data: vec![[0.0; 3]; layers * n],
            layer_splats: Vec::new(),
            col_norm: inside_norms(&filter, width),
            row_norm: inside_norms(&filter, height),
            light_paths: 0,
            invalid_samples: 0,
        }
    }

    /// Adds a block (the caller merges blocks in a fixed order).
    pub fn merge(&mut self, block: &ImageBlock) {
        self.invalid_samples += block.invalid_samples;
        let n = self.width as usize * self.height as usize;
        let plane = block.w * block.h;
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
                let bi = by * block.w + bx;
                let fi = y as usize * self.width as usize + x as usize;
                let s = block.data[bi];
                let d = &mut self.data[fi];
                for c in 0..4 {
                    d[c].add_sum(s[c]);
                }
                for layer in 0..self.layers.min(block.layers.len() / plane.max(1)) {
                    let s = block.layers[layer * plane + bi];
                    let d = &mut self.layer_data[layer * n + fi];
                    for c in 0..3 {
                        d[c] += s[c] as f64;
                    }
                }
            }
        }
    }

    /// Adds light-tracing splats (the caller adds them in a fixed order).
    pub fn add_splats(&mut self, splats: &[Splat]) {
        let n = self.width as usize * self.height as usize;
        if self.splats.is_empty() {
            self.splats = vec![[ExactSum::default(); 3]; n];
            self.layer_splats = vec![[0.0; 3]; self.layers * n];
        }
        let (w, h, filter) = (self.width as i32, self.height as i32, self.filter);
        let (cols, rows) = (&self.col_norm, &self.row_norm);
        for sp in splats {
            if !sp.value.is_finite() {
                self.invalid_samples += 1;
                continue;
            }
            footprint(&filter, sp.pos, |x, y, wt| {
                if x >= 0 && y >= 0 && x < w && y < h {
                    let i = y as usize * w as usize + x as usize;
                    let v = sp.value * (wt * cols[x as usize] * rows[y as usize]);
                    let d = &mut self.splats[i];
                    d[0].add(v.x as f64);
                    d[1].add(v.y as f64);
                    d[2].add(v.z as f64);
                    if self.layers > 0 {
                        let d = &mut self.layer_splats[sp.layer as usize * n + i];
                        d[0] += v.x as f64;
                        d[1] += v.y as f64;
                        d[2] += v.z as f64;
                    }
                }
            });
        }
    }

    /// Adds another film's splats (exactly, so the order of the films does not matter).
    pub fn add_film_splats(&mut self, other: &Film) {
        self.combine_splats(other, |d, s| d.add_sum(s));
    }

    /// Adds the splats and dropped samples of other films (a Markov-chain render's worker
    /// films; exact, so their order does not matter).
    pub fn add_splat_films(&mut self, others: &[Film]) {
        for f in others {
            self.add_film_splats(f);
            self.invalid_samples += f.invalid_samples;
        }
    }

    /// Adds each of `other`'s splat sums into this film's with `add` (creating this film's
    /// splats when it has none).
    fn combine_splats(&mut self, other: &Film, add: impl Fn(&mut ExactSum, ExactSum)) {
        if other.splats.is_empty() {
            return;
        }
        if self.splats.is_empty() {
            self.splats = vec![[ExactSum::default(); 3]; self.width as usize * self.height as usize];
        }
        for (d, s) in self.splats.iter_mut().zip(&other.splats) {
            for c in 0..3 {
                add(&mut d[c], s[c]);
            }
        }
    }

    /// Adds another film of the same size: its camera sums, splats, light paths and dropped
    /// samples (sums are exact, so the order of the films does not matter).
    pub fn merge_film(&mut self, other: &Film) {
        assert_eq!((self.width, self.height), (other.width, other.height), "films of one image");
        for (d, s) in self.data.iter_mut().zip(&other.data) {
            for c in 0..4 {
                d[c].add_sum(s[c]);
            }
        }
        self.add_film_splats(other);
        self.light_paths += other.light_paths;
        self.invalid_samples += other.invalid_samples;
    }

    /// Adds `image` to what the camera samples' weighted mean develops to: each pixel's
    /// weighted sums grow by the image's value times the pixel's weight sum (a pixel without
    /// samples gets the value with weight one). Another pass's estimate of other paths, at
    /// whatever sample count, then adds to this film's, and films merged later keep the sum.
    pub fn add_to_mean(&mut self, image: &[Rgb]) {
        assert_eq!(image.len(), self.data.len(), "one value per pixel");
        for (d, v) in self.data.iter_mut().zip(image) {
            let mut w = d[3].value();
            if w <= 0.0 {
                (d[3], w) = (ExactSum { hi: 1.0, lo: 0.0 }, 1.0);
            }
            for (c, x) in [v.x, v.y, v.z].into_iter().enumerate() {
                d[c].add(x as f64 * w);
            }
        }
    }

    /// The exact sums of every pixel: the camera samples' `(Σ w r, Σ w g, Σ w b, Σ w)`, then
    /// the splats' `(r, g, b)` (zero without splats). Strategy layers are not included.
    pub fn sums(&self) -> Vec<[ExactSum; 7]> {
        let zero = [ExactSum::default(); 3];
        (0..self.data.len())
            .map(|i| {
                let (c, s) = (self.data[i], self.splats.get(i).unwrap_or(&zero));
                [c[0], c[1], c[2], c[3], s[0], s[1], s[2]]
            })
            .collect()
    }

    /// A film from the sums [`Film::sums`] gives, and its light paths and dropped samples.
    pub fn from_sums(
        width: u32,
        height: u32,
        filter: Filter,
        sums: &[[ExactSum; 7]],
        light_paths: u64,
        invalid_samples: u64,
    ) -> Film {
        let mut film = Film::new(width, height, filter);
        assert_eq!(sums.len(), film.data.len(), "one entry per pixel");
        film.data = sums.iter().map(|s| [s[0], s[1], s[2], s[3]]).collect();
        if sums.iter().any(|s| s[4..].iter().any(|x| *x != ExactSum::default())) {
            film.splats = sums.iter().map(|s| [s[4], s[5], s[6]]).collect();
        }
        film.light_paths = light_paths;
        film.invalid_samples = invalid_samples;
        film
    }

    /// Adds another film's splats times `scale` (films whose splats carry different
    /// normalisations; the result is rounded, not exact).
    pub fn add_scaled_splats(&mut self, other: &Film, scale: f64) {
        self.combine_splats(other, |d, s| d.add(s.value() * scale));
    }

    /// Pixels per light path: the factor that turns summed splats into pixel values.
    fn splat_scale(&self) -> f64 {
        if self.light_paths == 0 { 0.0 } else { (self.width as f64 * self.height as f64) / self.light_paths as f64 }
    }

    fn develop_with(&self, camera: impl Fn(usize) -> [f64; 3], splats: impl Fn(usize) -> Option<[f64; 3]>) -> Vec<Rgb> {
        let scale = self.splat_scale();
        (0..self.data.len())
            .map(|i| {
                let wsum = self.data[i][3].value();
                let mut v = [0.0f64; 3];
                if wsum > 0.0 {
                    v = camera(i).map(|x| x / wsum);
                }
                if let Some(sp) = splats(i) {
                    for c in 0..3 {
                        v[c] += sp[c] * scale;
                    }
                }
                Rgb::new(v[0] as f32, v[1] as f32, v[2] as f32)
            })
            .collect()
    }

    /// The developed image: linear RGB, row-major from the top-left.
    pub fn develop(&self) -> Vec<Rgb> {
        self.develop_with(
            |i| [self.data[i][0].value(), self.data[i][1].value(), self.data[i][2].value()],
            |i| self.splats.get(i).map(|s| s.map(|c| c.value())),
        )
    }

    /// The developed image of what this film holds beyond `part`, a film of the same size
    /// that received some of the same passes (the even iterations of a render whose odd
    /// ones `part` holds): camera sums, splats and light paths minus `part`'s.
    pub fn develop_without(&self, part: &Film) -> Vec<Rgb> {
        assert_eq!((self.width, self.height), (part.width, part.height), "films of one image");
        let lp = self.light_paths.saturating_sub(part.light_paths);
        let scale = if lp == 0 { 0.0 } else { (self.width as f64 * self.height as f64) / lp as f64 };
        (0..self.data.len())
            .map(|i| {
                let (a, b) = (&self.data[i], &part.data[i]);
                let wsum = a[3].value() - b[3].value();
                let mut v = [0.0f64; 3];
                if wsum > 0.0 {
                    v = [0, 1, 2].map(|c| (a[c].value() - b[c].value()) / wsum);
                }
                if let Some(sa) = self.splats.get(i) {
                    let sb = part.splats.get(i);
                    for c in 0..3 {
                        v[c] += (sa[c].value() - sb.map_or(0.0, |s| s[c].value())) * scale;
                    }
                }
                Rgb::new(v[0] as f32, v[1] as f32, v[2] as f32)
            })
            .collect()
    }

    /// The developed image of one strategy layer (they sum to [`Film::develop`]).
    pub fn develop_layer(&self, layer: usize) -> Vec<Rgb> {
        let n = self.width as usize * self.height as usize;
        let splats =
            if self.layer_splats.is_empty() { &[][..] } else { &self.layer_splats[layer * n..(layer + 1) * n] };
        self.develop_with(|i| self.layer_data[layer * n + i], |i| splats.get(i).copied())
    }

    pub fn layers(&self) -> usize {
        self.layers
    }
}

/// `∫ filter(t) dt` over `[lo, hi]`, by the midpoint rule.
fn filter_integral(filter: &Filter, lo: f32, hi: f32) -> f64 {
    let n = 4096;
    let h = (hi - lo) / n as f32;
    (0..n).map(|i| filter.eval(lo + (i as f32 + 0.5) * h) as f64 * h as f64).sum()
}

/// For each pixel of a row (or column) of `n` pixels, `1 / ∫ filter` over the part of the
/// filter centred on the pixel that lies inside the image (the whole filter away from the
/// edges).
fn inside_norms(filter: &Filter, n: u32) -> Vec<f32> {
    let r = filter.radius();
    let full = filter_integral(filter, -r, r);
    (0..n)
        .map(|i| {
            let c = i as f32 + 0.5;
            let (lo, hi) = ((-c).max(-r), (n as f32 - c).min(r));
            let part = if lo <= -r && hi >= r { full } else { filter_integral(filter, lo, hi) };
            if part > 0.0 { (1.0 / part) as f32 } else { 0.0 }
        })
        .collect()
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

    /// Light arriving evenly over the image, splatted, develops to itself in every pixel,
    /// border pixels included (their filter reaches outside the image, where no light lands).
    #[test]
    fn even_splats_develop_to_themselves_up_to_the_borders() {
        let value = Rgb::new(0.25, 0.5, 2.0);
        for filter in [Filter::Box { radius: 0.5 }, Filter::Tent { radius: 1.0 }, Filter::Gaussian { stddev: 0.5 }] {
            let (w, h, k) = (9u32, 7u32, 32u32);
            let mut film = Film::new(w, h, filter);
            let splats: Vec<Splat> = (0..h * k)
                .flat_map(|j| (0..w * k).map(move |i| (i, j)))
                .map(|(i, j)| Splat {
                    pos: Vec2::new((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32),
                    value,
                    layer: 0,
                })
                .collect();
            film.add_splats(&splats);
            film.light_paths = splats.len() as u64;
            for (p, v) in film.develop().into_iter().enumerate() {
                assert!((v / value - Rgb::ONE).abs().max_element() < 2e-3, "{filter:?}: pixel {p}: {v}");
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

    /// Sums do not depend on how samples are grouped into blocks and films: one film of all
    /// samples equals the sum of films of uneven groups, bit for bit, over six decades of
    /// sample values. Plain `f32` block sums (as a negative control) do depend on it.
    #[test]
    fn films_of_any_grouping_add_up_to_the_same_bits() {
        let filter = Filter::Gaussian { stddev: 0.5 };
        let tile = Tile { x0: 0, y0: 0, width: 4, height: 3 };
        let mut s = crate::sampling::Sampler::new(&[9]);
        let samples: Vec<(Vec2, Rgb, Splat)> = (0..3000)
            .map(|_| {
                let pos = Vec2::new(s.next_1d() * 4.0, s.next_1d() * 3.0);
                let scale = 10f32.powf(s.next_1d() * 6.0 - 3.0);
                let v = Rgb::new(s.next_1d(), s.next_1d(), s.next_1d()) * scale;
                (pos, v, Splat { pos: Vec2::new(s.next_1d() * 4.0, s.next_1d() * 3.0), value: v * 0.1, layer: 0 })
            })
            .collect();
        let film_of = |cuts: &[usize]| {
            let mut total = Film::new(4, 3, filter);
            let mut bounds = vec![0];
            bounds.extend_from_slice(cuts);
            bounds.push(samples.len());
            for g in bounds.windows(2) {
                let mut part = Film::new(4, 3, filter);
                let mut block = ImageBlock::new(tile, filter);
                for (pos, v, _) in &samples[g[0]..g[1]] {
                    block.put(*pos, *v);
                }
                part.merge(&block);
                part.add_splats(&samples[g[0]..g[1]].iter().map(|x| x.2).collect::<Vec<_>>());
                total.merge_film(&part);
            }
            total.light_paths = 1000;
            total.develop().iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>()
        };
        let one = film_of(&[]);
        assert_eq!(one, film_of(&[1]));
        assert_eq!(one, film_of(&[17, 1000, 1001, 2999]));
        assert_eq!(one, film_of(&[1500]));
        // Negative control: f32 running sums of the same values in two groupings differ.
        let f32_sum = |cut: usize| {
            let (a, b) = samples.split_at(cut);
            let part = |xs: &[(Vec2, Rgb, Splat)]| xs.iter().fold(0.0f32, |acc, x| acc + x.1.x);
            (part(a) + part(b)).to_bits()
        };
        assert!((1..samples.len()).any(|c| f32_sum(c) != f32_sum(0)), "the control must differ");
    }

    /// A film of two parts, without one of them, develops to the other part's image:
    /// camera sums, weights, splats and light paths all subtracted.
    #[test]
    fn a_film_without_a_part_develops_to_the_rest() {
        let filter = Filter::Tent { radius: 1.0 };
        let tile = Tile { x0: 0, y0: 0, width: 5, height: 4 };
        let mut s = crate::sampling::Sampler::new(&[3]);
        let mut part = |n: usize, light_paths: u64| {
            let mut film = Film::new(5, 4, filter);
            let mut block = ImageBlock::new(tile, filter);
            let mut splats = Vec::new();
            for _ in 0..n {
                let pos = Vec2::new(s.next_1d() * 5.0, s.next_1d() * 4.0);
                block.put(pos, Rgb::new(s.next_1d(), s.next_1d(), 2.0 * s.next_1d()));
                splats.push(Splat { pos, value: Rgb::splat(s.next_1d()), layer: 0 });
            }
            film.merge(&block);
            film.add_splats(&splats);
            film.light_paths = light_paths;
            film
        };
        let (a, b) = (part(200, 30), part(150, 20));
        let mut both = a.clone();
        both.merge_film(&b);
        for (x, y) in both.develop_without(&b).iter().zip(a.develop()) {
            assert!((*x - y).abs().max_element() < 1e-5, "{x} against {y}");
        }
        assert_ne!(both.develop(), a.develop(), "the control: the whole film is not the part");
    }

    #[test]
    fn tiles_cover_the_image_once() {
        let ts = tiles(70, 33, 16);
        let covered: u32 = ts.iter().map(|t| t.width * t.height).sum();
        assert_eq!(covered, 70 * 33);
    }
}
