//! AOVs (arbitrary output variables): channels written beside the image, with pbrt-v4's
//! `gbuffer` film's names, for denoisers and analysis.
//!
//! | AOV | channels | what |
//! |---|---|---|
//! | `albedo` | `Albedo.R/G/B` | the directional albedo at the first non-Dirac surface |
//! | `normal` | `Ns.X/Y/Z` | its shading normal, in world space |
//! | `depth` | `Z` | the first hit's depth along the camera's view axis |
//! | `position` | `P.X/Y/Z` | the first hit's position, in world space |
//! | `variance` | `Variance.R/G/B` | the image's per-pixel variance ([`crate::integrator::noise`]) |
//!
//! All but the variance come from a pass of their own over the camera's first hits, after
//! the render and the same for every integrator: [`FIRST_HIT_SPP`] camera rays per pixel,
//! stratified in the pixel, each added to the film with the reconstruction filter's weights
//! as the image's samples are, so the channels are filtered the way the image is. Albedo
//! and normal follow Dirac chains as denoisers expect: through a mirror or smooth glass to
//! the first surface with a non-Dirac lobe, the chain's weights multiplying the albedo found
//! there. The albedo is estimated as pbrt-v4 does (`BSDF::rho`): the weight `f cos / pdf` of
//! one BSDF sample per ray, whose mean is the surface's directional albedo — exactly the
//! reflectance for a diffuse surface, and for any other model its reflectance and
//! transmittance integrated over directions, with no per-model approximation to keep.
//! Depth and position belong to the first hit itself. A ray that leaves the scene (or a
//! chain that does) adds zeros: the channels of a pixel half on the background are
//! partly zero, as a filtered image's are.

use crate::bsdf::TransportMode;
use crate::error::Error;
use crate::film::{Film, ImageBlock, Tile, tiles};
use crate::image_io::Channels;
use crate::math::Rgb;
use crate::sampling::Sampler;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// The AOVs `--aov` names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Aov {
    Albedo,
    Normal,
    Depth,
    Position,
    Variance,
}

impl Aov {
    pub const ALL: [Aov; 5] = [Aov::Albedo, Aov::Normal, Aov::Depth, Aov::Position, Aov::Variance];

    /// The name `--aov` takes.
    pub fn name(self) -> &'static str {
        match self {
            Aov::Albedo => "albedo",
            Aov::Normal => "normal",
            Aov::Depth => "depth",
            Aov::Position => "position",
            Aov::Variance => "variance",
        }
    }

    /// Its channels in the EXR file (pbrt-v4's names).
    pub fn channels(self) -> &'static [&'static str] {
        match self {
            Aov::Albedo => &["Albedo.R", "Albedo.G", "Albedo.B"],
            Aov::Normal => &["Ns.X", "Ns.Y", "Ns.Z"],
            Aov::Depth => &["Z"],
            Aov::Position => &["P.X", "P.Y", "P.Z"],
            Aov::Variance => &["Variance.R", "Variance.G", "Variance.B"],
        }
    }

    /// Whether the first-hit pass computes it (all but the variance, which the render
    /// loop's half-images give).
    pub fn is_first_hit(self) -> bool {
        self != Aov::Variance
    }
}

/// Parses a comma-separated list of AOV names (each kept once, in the order given).
pub fn parse_list(s: &str) -> Result<Vec<Aov>, String> {
    let mut out = Vec::new();
    for name in s.split(',').map(str::trim) {
        let aov = Aov::ALL.into_iter().find(|a| a.name() == name).ok_or_else(|| {
            let names: Vec<&str> = Aov::ALL.iter().map(|a| a.name()).collect();
            format!("unknown AOV \"{name}\" (expected a comma-separated list of {})", names.join(", "))
        })?;
        if !out.contains(&aov) {
            out.push(aov);
        }
    }
    Ok(out)
}

/// Camera rays per pixel of the first-hit pass (a 4 × 4 grid of jittered cells).
pub const FIRST_HIT_SPP: u32 = 16;

/// Dirac bounces the albedo and normal follow at most.
const MAX_CHAIN: u32 = 32;

/// What one camera ray finds.
#[derive(Clone, Copy, Default)]
struct FirstHit {
    albedo: Rgb,
    normal: Vec3,
    depth: f32,
    position: Vec3,
}

/// What one camera ray through film position `pos` finds, with `sampler`'s numbers for the
/// BSDF samples.
fn first_hit(scene: &Scene, pos: Vec2, sampler: &mut Sampler) -> FirstHit {
    let camera = &scene.camera;
    let mut ray = camera.generate_ray(pos);
    let Some(mut si) = scene.intersect(&ray) else { return FirstHit::default() };
    let forward = camera.to_world.vector(Vec3::Z).normalize();
    let mut hit = FirstHit { depth: (si.p - camera.position).dot(forward), position: si.p, ..FirstHit::default() };
    let mut throughput = Rgb::ONE;
    for _ in 0..MAX_CHAIN {
        let bsdf = scene.bsdf(&si);
        hit.normal = si.shading.n;
        let (u1, u2) = (sampler.next_1d(), sampler.next_2d());
        let sample = bsdf.sample(si.shading.to_local(si.wo), si.at(), u1, u2, TransportMode::Radiance);
        if !bsdf.is_delta() {
            hit.albedo = throughput * sample.map_or(Rgb::ZERO, |s| s.weight);
            return hit;
        }
        let Some(s) = sample else { return hit };
        throughput *= s.weight;
        ray = si.spawn_ray(si.shading.to_world(s.wi));
        match scene.intersect(&ray) {
            Some(next) => si = next,
            None => return hit,
        }
    }
    hit
}

/// The first-hit AOVs among `aovs`, as `(channel name, one value per pixel)`, in the order
/// asked for: [`FIRST_HIT_SPP`] rays per pixel with the random streams of `seed`, on
/// `threads` worker threads (0 = all cores).
pub fn first_hits(scene: &Scene, aovs: &[Aov], seed: u64, threads: usize) -> Result<Channels, Error> {
    let wanted: Vec<Aov> = aovs.iter().copied().filter(|a| a.is_first_hit()).collect();
    if wanted.is_empty() {
        return Ok(Vec::new());
    }
    let (w, h) = (scene.film.width, scene.film.height);
    let filter = scene.film.filter;
    let pool = crate::workers::render_pool(threads)?;
    let blocks: Vec<Vec<ImageBlock>> =
        pool.install(|| tiles(w, h, 32).par_iter().map(|&t| tile_blocks(scene, &wanted, seed, t)).collect());
    let mut films: Vec<Film> = wanted.iter().map(|_| Film::new(w, h, filter)).collect();
    for tile in &blocks {
        for (film, block) in films.iter_mut().zip(tile) {
            film.merge(block);
        }
    }
    let mut out = Vec::new();
    for (aov, film) in wanted.iter().zip(&films) {
        let image = film.develop();
        for (c, name) in aov.channels().iter().enumerate() {
            out.push((name.to_string(), image.iter().map(|p| p[c]).collect()));
        }
    }
    Ok(out)
}

/// One image block per wanted AOV for the pixels of `tile`.
fn tile_blocks(scene: &Scene, wanted: &[Aov], seed: u64, tile: Tile) -> Vec<ImageBlock> {
    let mut blocks: Vec<ImageBlock> = wanted.iter().map(|_| ImageBlock::new(tile, scene.film.filter)).collect();
    let n = (FIRST_HIT_SPP as f32).sqrt() as u32;
    for y in tile.y0..tile.y0 + tile.height {
        for x in tile.x0..tile.x0 + tile.width {
            let pixel = y as u64 * scene.film.width as u64 + x as u64;
            for s in 0..FIRST_HIT_SPP {
                let mut sampler = Sampler::new(&[seed, AOV_STREAM, pixel, s as u64]);
                let cell = Vec2::new((s % n) as f32, (s / n) as f32);
                let offset = ((cell + sampler.next_2d()) / n as f32).min(Vec2::splat(1.0f32.next_down()));
                let pos = Vec2::new(x as f32, y as f32) + offset;
                let hit = first_hit(scene, pos, &mut sampler);
                for (block, aov) in blocks.iter_mut().zip(wanted) {
                    let value = match aov {
                        Aov::Albedo => hit.albedo,
                        Aov::Normal => hit.normal,
                        Aov::Depth => Vec3::new(hit.depth, 0.0, 0.0),
                        Aov::Position => hit.position,
                        Aov::Variance => unreachable!("not a first-hit AOV"),
                    };
                    block.put(pos, value);
                }
            }
        }
    }
    blocks
}

/// The key that keeps the first-hit pass's random streams apart from the render's.
const AOV_STREAM: u64 = 0x414f_565f_6869_7473;

/// The variance AOV's channels.
pub fn variance_channels(variance: &[Rgb]) -> Channels {
    Aov::Variance
        .channels()
        .iter()
        .enumerate()
        .map(|(c, name)| (name.to_string(), variance.iter().map(|p| p[c]).collect()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_parse_in_order_once_each_and_unknown_names_are_named() {
        assert_eq!(parse_list("depth,albedo, depth").unwrap(), vec![Aov::Depth, Aov::Albedo]);
        let e = parse_list("albedo,colour").unwrap_err();
        assert!(e.contains("\"colour\"") && e.contains("albedo, normal, depth, position, variance"), "{e}");
        assert!(parse_list("").is_err());
    }
}
