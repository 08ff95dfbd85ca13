//! The light MEMLT renders beside its chains (contract `memlt.md`: the direct light handled
//! as Mitsuba 0.6 does, by a separate estimate): the direct-light pass by the path tracer
//! (`--direct-samples`: paths of one edge, and of two through a rough vertex; those through a
//! Dirac lobe, a small light's reflection in glass say, are the specular pass's, or the
//! chains' without one), the specular pass ([`crate::integrator::memlt::specular_pass`], `--specular-samples`),
//! and the film the chains splat into over them. Under a time budget with
//! `--direct-balance` the direct pass runs twice, from two streams, so that its noise can be
//! measured, and goes on later for the share of the time [`crate::integrator::memlt::direct_balance`] gives it.

use crate::error::Error;
use crate::film::Film;
use crate::integrator::memlt::specular_pass::SpecularPass;
use crate::integrator::metropolis::bootstrap::Keys;
use crate::integrator::path::PathTracer;
use crate::integrator::render_loop;
use crate::integrator::run::{Budget, RunOptions};
use crate::integrator::stats::Counters;
use crate::math::Rgb;
use crate::scene::Scene;
use std::time::Instant;

const DIRECT_STREAM: u64 = 0x6469_7265;
const SPECULAR_STREAM: u64 = 0x7370_6563;

/// The passes' light.
pub struct SeparateLight {
    /// Every direct-pass sample, merged.
    direct: Film,
    /// The first two passes' images, where the balance measures the direct light's noise.
    pub halves: Option<(Vec<Rgb>, Vec<Rgb>)>,
    /// The direct pass's samples per pixel and seconds, in all.
    pub samples: u32,
    pub seconds: f64,
    /// The direct passes run so far (each has its own stream).
    passes: u64,
    specular: Option<Vec<Rgb>>,
}

impl SeparateLight {
    /// The passes before the chains: `direct` samples per pixel of the direct light (none
    /// where it is not positive), twice with `balance`, and `specular` samples per pixel of
    /// the specular pass. Also their work.
    pub fn render(
        scene: &Scene,
        opts: &RunOptions,
        key: Keys,
        direct: i32,
        balance: bool,
        specular: Option<u32>,
    ) -> Result<(SeparateLight, Counters), Error> {
        let (w, h) = (scene.film.width, scene.film.height);
        let mut light = SeparateLight {
            direct: Film::new(w, h, scene.film.filter),
            halves: None,
            samples: 0,
            seconds: 0.0,
            passes: 0,
            specular: None,
        };
        let mut counters = Counters::default();
        if direct > 0 {
            let (a, c) = light.more_direct(scene, opts, key, direct as u32)?;
            counters += c;
            if balance {
                let (b, c) = light.more_direct(scene, opts, key, direct as u32)?;
                counters += c;
                light.halves = Some((a.develop(), b.develop()));
            }
        }
        if let Some(n) = specular {
            // Its own sample count: its image adds to the direct pass's.
            let spec = &scene.integrator;
            let max_edges =
                if spec.max_depth < 0 { crate::integrator::memlt::MAX_EDGES as u32 } else { spec.max_depth as u32 };
            let out =
                render_loop::run(scene, &pass(opts, key, n, SPECULAR_STREAM), SpecularPass { max_edges }, false, None)?;
            counters += out.stats.counters;
            light.specular = out.film.map(|f| f.develop());
        }
        Ok((light, counters))
    }

    /// Another direct pass of `spp` samples per pixel, from a stream of its own, merged
    /// into the light: its film and work.
    pub fn more_direct(
        &mut self,
        scene: &Scene,
        opts: &RunOptions,
        key: Keys,
        spp: u32,
    ) -> Result<(Film, Counters), Error> {
        let started = Instant::now();
        let spec = &scene.integrator;
        let max_depth = if spec.max_depth < 0 { 2 } else { (spec.max_depth as u32).min(2) };
        let pt = PathTracer { max_depth, dirac_emission: false, ..PathTracer::new(spec) };
        // The first pass keeps the stream it always had.
        let stream = DIRECT_STREAM ^ self.passes;
        let out = render_loop::run(scene, &pass(opts, key, spp, stream), pt, false, None)?;
        let film = out.film.unwrap_or_else(|| Film::new(scene.film.width, scene.film.height, scene.film.filter));
        self.direct.merge_film(&film);
        self.passes += 1;
        self.samples += spp;
        self.seconds += started.elapsed().as_secs_f64();
        Ok((film, out.stats.counters))
    }

    /// The film the chains splat into: the passes' light.
    pub fn film(&self) -> Film {
        let mut f = self.direct.clone();
        if let Some(image) = &self.specular {
            f.add_to_mean(image);
        }
        f
    }
}

/// A pass's options: its sample count and its own stream.
fn pass(opts: &RunOptions, key: Keys, spp: u32, stream: u64) -> RunOptions {
    let mut o = opts.clone();
    o.budget = Budget::Spp(spp);
    o.seed = crate::sampling::hash_words(&key(stream, 0));
    o.checkpoints.clear();
    // The preview shows the whole render's image (the chains' rounds), not a pass's part.
    o.preview = None;
    o.progress = false;
    o.aovs.clear();
    o.noise_threshold = None;
    o
}
