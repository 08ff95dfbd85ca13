//! What a Metropolis render's pixels rest on (PSSMLT and MEMLT alike): the longest stay of
//! any chain's current state around one pixel (within one pixel of it, a 3×3 block). A
//! chain that enters a region of its space its moves seldom leave (in `glass-caustic`, the
//! floor's caustic reflected in the ball) stays there for many steps and splats them all
//! into a few pixels; the render is still right on average, but those pixels' values rest
//! on one visit. The stay, set against the light in its block in the finished image, tells
//! a user so.

use crate::film::Splat;
use crate::math::{Rgb, luminance};
use glam::Vec2;
use serde::Serialize;

/// A stretch of consecutive steps in which a chain's current state stayed within one pixel
/// of `pixel` (where the stay began): its length and the weight (in units of the luminance
/// a step splats in all) that its steps put into the 3×3 block around `pixel`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Stay {
    pub pixel: (i32, i32),
    pub steps: u64,
    pub weight: f64,
}

/// A chain's current stay and its longest so far.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Stays {
    pub current: Stay,
    pub longest: Stay,
}

impl Stays {
    /// One step whose current state lies in `pixel`, splatting `weight(centre)` into the
    /// block around the stay's centre (this pixel when a new stay begins).
    pub fn record(&mut self, pixel: (i32, i32), weight: impl FnOnce((i32, i32)) -> f64) {
        if self.current.steps == 0 || !near(pixel, self.current.pixel) {
            self.current = Stay { pixel, steps: 0, weight: 0.0 };
        }
        self.current.steps += 1;
        self.current.weight += weight(self.current.pixel);
        if self.current.steps > self.longest.steps {
            self.longest = self.current;
        }
    }
}

/// Whether pixel `p` lies in the 3×3 block around `centre`.
pub(crate) fn near(p: (i32, i32), centre: (i32, i32)) -> bool {
    (p.0 - centre.0).abs() <= 1 && (p.1 - centre.1).abs() <= 1
}

/// The pixel that holds a film position.
pub(crate) fn pixel_of(raster: Vec2) -> (i32, i32) {
    (raster.x.floor() as i32, raster.y.floor() as i32)
}

/// The share of the luminance of `splats` that lands in the 3×3 block around `centre`.
pub(crate) fn share_in(splats: &[Splat], centre: (i32, i32)) -> f64 {
    let lum = |s: &Splat| luminance(s.value).max(0.0) as f64;
    let all: f64 = splats.iter().map(lum).sum();
    if all > 0.0 && all.is_finite() {
        splats.iter().filter(|s| near(pixel_of(s.pos), centre)).map(lum).sum::<f64>() / all
    } else {
        0.0
    }
}

/// The longest stay of any chain's current state around one pixel (the first chain's where
/// several are as long): how many consecutive mutations, around which pixel, and the share
/// of the light in that pixel and its eight neighbours that the stay put there. A share
/// above one half means those pixels' values rest on one visit of one chain: a longer
/// render or another seed averages it out.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LongestStay {
    pub mutations: u64,
    pub pixel: [i32; 2],
    pub share: f64,
}

impl LongestStay {
    /// The summary's line on the stay and, when that stay carries most of the light in the
    /// pixels around it, a warning (`integrator` names the render's integrator).
    pub fn lines(&self, integrator: &str) -> Vec<String> {
        let [x, y] = self.pixel;
        let mut lines = vec![format!(
            "  longest stay of a chain around one pixel: {} mutations within a pixel of ({x}, {y}), {:.0}% of the light in those 3×3 pixels",
            self.mutations,
            self.share * 100.0
        )];
        if self.dominates() {
            lines.push(format!(
                "warning: {integrator}: one chain stayed {} mutations within a pixel of ({x}, {y}) and put {:.0}% of the light \
                 in those 3×3 pixels there: their values rest on a single visit (a longer render, or another --seed, averages it out)",
                self.mutations,
                self.share * 100.0
            ));
        }
        lines
    }

    /// Shorter stays are not reported as a pixel resting on one visit: in a short render
    /// every pixel's value comes from a few.
    pub const MIN_MUTATIONS: u64 = 1000;

    /// Whether the stay carries more than half the light around its pixel.
    pub fn dominates(&self) -> bool {
        self.mutations >= Self::MIN_MUTATIONS && self.share > 0.5
    }

    /// The stay `longest` measured against the finished `image` (`width × height`), whose
    /// `done` mutations each put luminance `b` into it (the film scales splats by pixels
    /// over mutations). `None` when no chain ran.
    pub(crate) fn measure(longest: Stay, image: &[Rgb], (w, h): (u32, u32), b: f64, done: u64) -> Option<LongestStay> {
        if longest.steps == 0 || done == 0 {
            return None;
        }
        let (px, py) = longest.pixel;
        let around: f64 = (py - 1..=py + 1)
            .flat_map(|y| (px - 1..=px + 1).map(move |x| (x, y)))
            .filter(|&(x, y)| x >= 0 && y >= 0 && (x as u32) < w && (y as u32) < h)
            .map(|(x, y)| luminance(image[y as usize * w as usize + x as usize]) as f64)
            .sum();
        let stay = longest.weight * b * (w as u64 * h as u64) as f64 / done as f64;
        Some(LongestStay {
            mutations: longest.steps,
            pixel: [px, py],
            share: if around > 0.0 { stay / around } else { 0.0 },
        })
    }
}

/// The longest of the chains' longest stays (the first chain's where several are as long).
pub(crate) fn longest<'a>(stays: impl Iterator<Item = &'a Stays>) -> Stay {
    stays.map(|s| s.longest).fold(Stay::default(), |a, s| if s.steps > a.steps { s } else { a })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_longest_stay_in_one_pixel_is_kept() {
        let mut s = Stays::default();
        // A stay goes on while the state is within one pixel of where it began.
        for (pixel, w) in [((3, 4), 1.0), ((2, 5), 0.5), ((6, 4), 1.0), ((7, 3), 0.25), ((5, 4), 1.0), ((3, 4), 1.0)] {
            s.record(pixel, |_| w);
        }
        assert_eq!(s.longest, Stay { pixel: (6, 4), steps: 3, weight: 2.25 });
        assert_eq!(s.current, Stay { pixel: (3, 4), steps: 1, weight: 1.0 });
        // A stay as long as the longest does not replace it.
        s.record((4, 4), |_| 1.0);
        s.record((3, 3), |_| 1.0);
        assert_eq!(s.longest.pixel, (6, 4));
        // The weight is asked for around the stay's centre.
        s.record((2, 5), |c| if c == (3, 4) { 1.0 } else { 9.0 });
        assert_eq!(s.longest, Stay { pixel: (3, 4), steps: 4, weight: 4.0 });
        assert_eq!(pixel_of(Vec2::new(2.99, 0.0)), (2, 0));
        assert!(!LongestStay { mutations: 999, pixel: [0, 0], share: 0.9 }.dominates());
        assert!(LongestStay { mutations: 1000, pixel: [0, 0], share: 0.51 }.dominates());
        assert!(!LongestStay { mutations: 100_000, pixel: [0, 0], share: 0.5 }.dominates());
    }

    #[test]
    fn a_stay_is_measured_against_the_light_around_its_pixel() {
        // A 4×3 image of luminance 1 everywhere, 1200 mutations of luminance b = 0.5 in all:
        // a stay that put weight 100 into pixel (0, 0) gave it 100 · 0.5 · 12 / 1200 = 0.5,
        // of the 4 around it (the corner has three neighbours).
        let image = vec![Rgb::ONE; 12];
        let stay = Stay { pixel: (0, 0), steps: 100, weight: 100.0 };
        let m = LongestStay::measure(stay, &image, (4, 3), 0.5, 1200).unwrap();
        assert!((m.share - 0.125).abs() < 1e-12, "{m:?}");
        assert_eq!(LongestStay::measure(Stay::default(), &image, (4, 3), 0.5, 1200), None);
        let splats = [
            Splat { pos: Vec2::new(0.5, 0.5), value: Rgb::splat(3.0), layer: 0 },
            Splat { pos: Vec2::new(2.5, 0.5), value: Rgb::splat(1.0), layer: 0 },
        ];
        assert!((share_in(&splats, (0, 0)) - 0.75).abs() < 1e-12);
        assert!((share_in(&splats, (1, 1)) - 1.0).abs() < 1e-12);
    }
}
