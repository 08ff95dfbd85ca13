//! A point of primary sample space mutated lazily (Kelemen et al. 2002; contract §6): the
//! random numbers PSSMLT's chains and the Metropolis integrators' bootstrap draw.

use crate::sampling::{Random, Sampler};

/// Kelemen's small-step perturbation of one coordinate: an offset of size
/// `s2 · exp(-ln(s2/s1) · v)`, `v` uniform, in a random direction, wrapped to `[0, 1)`.
#[inline]
pub fn perturb(x: f32, u: f32) -> f32 {
    const S1: f32 = 1.0 / 1024.0;
    const S2: f32 = 1.0 / 64.0;
    let (up, v) = if u < 0.5 { (true, u * 2.0) } else { (false, (u - 0.5) * 2.0) };
    let dv = S2 * (-(S2 / S1).ln() * v).exp();
    let mut y = if up { x + dv } else { x - dv };
    if y >= 1.0 {
        y -= 1.0;
    }
    if y < 0.0 {
        y += 1.0;
    }
    if y >= 1.0 { 0.0 } else { y }
}

#[derive(Clone, Copy, Debug, Default)]
struct Coordinate {
    value: f32,
    modified: u64,
    backup_value: f32,
    backup_modified: u64,
}

/// Number of interleaved streams (camera, light, connections).
const STREAMS: usize = 3;

/// A point of primary sample space with lazy mutation (Kelemen et al. 2002).
pub struct PrimarySampler {
    rng: Sampler,
    coords: Vec<Coordinate>,
    iteration: u64,
    last_large_step: u64,
    large_step: bool,
    large_step_prob: f32,
    stream: usize,
    index: usize,
}

impl PrimarySampler {
    pub fn new(key: &[u64], large_step_prob: f32) -> PrimarySampler {
        PrimarySampler {
            rng: Sampler::new(key),
            coords: Vec::new(),
            iteration: 0,
            last_large_step: 0,
            large_step: true,
            large_step_prob,
            stream: 0,
            index: 0,
        }
    }

    /// Draws the mutations' numbers from the stream `key` from now on (the state's
    /// coordinates are kept).
    pub fn reseed(&mut self, key: &[u64]) {
        self.rng = Sampler::new(key);
    }

    /// Begins a proposal: a large step with probability `large_step_prob` (or when forced).
    pub fn start_iteration(&mut self, force_large: bool) {
        self.iteration += 1;
        self.large_step = force_large || self.rng.next_1d() < self.large_step_prob;
        self.stream = 0;
        self.index = 0;
    }

    pub fn is_large_step(&self) -> bool {
        self.large_step
    }

    pub fn accept(&mut self) {
        if self.large_step {
            self.last_large_step = self.iteration;
        }
    }

    pub fn reject(&mut self) {
        for c in &mut self.coords {
            if c.modified == self.iteration {
                c.value = c.backup_value;
                c.modified = c.backup_modified;
            }
        }
        self.iteration -= 1;
    }

    fn ensure_ready(&mut self, i: usize) {
        if i >= self.coords.len() {
            self.coords.resize(i + 1, Coordinate::default());
        }
        let rng = &mut self.rng;
        let c = &mut self.coords[i];
        // A coordinate untouched since before the last accepted large step takes that
        // step's fresh value first.
        if c.modified < self.last_large_step {
            c.value = rng.next_1d();
            c.modified = self.last_large_step;
        }
        c.backup_value = c.value;
        c.backup_modified = c.modified;
        if self.large_step {
            c.value = rng.next_1d();
        } else {
            for _ in c.modified..self.iteration {
                c.value = perturb(c.value, rng.next_1d());
            }
        }
        c.modified = self.iteration;
    }
}

impl Random for PrimarySampler {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        let i = self.index * STREAMS + self.stream;
        self.index += 1;
        self.ensure_ready(i);
        self.coords[i].value
    }

    #[inline]
    fn start_stream(&mut self, k: u32) {
        self.stream = k as usize % STREAMS;
        self.index = 0;
    }
}
