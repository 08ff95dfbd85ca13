//! MEMLT's specular pass: the paths that scatter through Dirac lobes alone, from the camera
//! to a light (a small light seen in a mirror or through a glass ball), rendered beside the
//! chains by camera walks, with `--specular-samples` positions per pixel in stratified cells.
//!
//! Only a camera walk that hits the light finds such a path: no connection can end at a
//! Dirac vertex. A chain enters these paths only by a whole-path move that happens to do that
//! walk, and a light reflected in a ball is hundreds of times the image's mean radiance in a
//! few pixels, so the chains' share of it comes in rare, long visits (and the chains' fixed
//! total spreads what they miss over the rest of the image). Here each pixel estimates it
//! directly; the pixel's cells make its share of a reflection it covers in part nearly
//! exact. The chains' paths are the rest ([`crate::integrator::memlt::bidirectional::Lengths::covers`]).

use crate::accel::Ray;
use crate::bsdf::TransportMode;
use crate::film::Tile;
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Work, sample_tile_in};
use crate::integrator::stats::Counters;
use crate::math::Rgb;
use crate::sampling::Random;
use crate::scene::Scene;
use crate::scene::shape::SurfaceInteraction;
use std::ops::Range;

/// Camera walks through Dirac lobes alone.
#[derive(Clone, Debug)]
pub struct SpecularPass {
    /// The longest path, in edges.
    pub max_edges: u32,
}

impl SpecularPass {
    /// The light arriving along a camera ray by paths of two edges or more (at most
    /// `max_edges`) whose every scattering was through a Dirac lobe: the walk follows the
    /// lobe each BSDF sample picks and ends at the first rough one (that path is the chains').
    /// In media the path takes each edge's transmittance (its scattering events are the
    /// chains').
    pub fn li<R: Random>(&self, scene: &Scene, mut ray: Ray, sampler: &mut R, counters: &mut Counters) -> Rgb {
        let mut l = Rgb::ZERO;
        let mut beta = Rgb::ONE;
        let mut medium = scene.camera_medium;
        // Edges traced so far.
        let mut edges = 0u32;
        while edges < self.max_edges {
            let Some(si) = next_surface(scene, &mut ray, &mut medium, &mut beta, counters) else {
                // The ray leaves the scene: a light at infinity ends the path, after at least
                // one scattering.
                if edges > 0 {
                    let d = ray.d.normalize();
                    for &light_index in &scene.infinite_lights {
                        l += beta * scene.lights[light_index].eval_infinite(d);
                    }
                }
                break;
            };
            edges += 1;
            if edges >= 2
                && let Some((_, light)) = scene.area_light(&si)
            {
                l += beta * light.radiance(si.ng, si.uv, si.wo);
            }
            if edges >= self.max_edges {
                break;
            }
            let bsdf = scene.bsdf(&si);
            let wo = si.shading.to_local(si.wo);
            let (u_lobe, u_dir) = (sampler.next_1d(), sampler.next_2d());
            let Some(bs) = bsdf.sample(wo, si.at(), u_lobe, u_dir, TransportMode::Radiance) else {
                break;
            };
            if !bs.delta {
                break;
            }
            beta *= bs.weight;
            if beta == Rgb::ZERO {
                break;
            }
            let wi = si.shading.to_world(bs.wi);
            medium = scene.medium_after(&si, wi, medium);
            ray = si.spawn_ray(wi);
        }
        l
    }
}

/// The first surface along `ray` that is not a null one (`None` when the ray leaves the
/// scene), `beta` taking the transmittance of the media crossed up to it (or out of the
/// scene) and `medium` the medium it is reached in.
fn next_surface(
    scene: &Scene,
    ray: &mut Ray,
    medium: &mut Option<u32>,
    beta: &mut Rgb,
    counters: &mut Counters,
) -> Option<SurfaceInteraction> {
    for _ in 0..crate::scene::MAX_NULL_CROSSINGS {
        counters.extension_rays += 1;
        let hit = scene.intersect(ray);
        if let Some(m) = *medium {
            let d = hit.as_ref().map_or(f32::INFINITY, |si| si.t * ray.d.length());
            *beta *= crate::integrator::memlt::media::homogeneous(scene, m).transmittance(d);
        }
        let si = hit?;
        if !scene.bsdf(&si).is_null() {
            return Some(si);
        }
        *medium = scene.medium_after(&si, ray.d, *medium);
        *ray = si.spawn_ray(ray.d);
    }
    *beta = Rgb::ZERO;
    None
}

/// The pass in the render loop: no state between iterations, positions in the pixel's cells
/// when the render has a sample count.
impl Iterative for SpecularPass {
    type Pass = ();
    type TileData = ();

    fn prepare(&self, _: &Ctx, _: u32, _: bool, _: &mut Work) -> Prepared<()> {
        Prepared::only(())
    }

    fn render_tile(&self, ctx: &Ctx, _: &(), tile: Tile, first: u32, count: u32) -> TileResult {
        sample_tile_in(ctx, tile, (first, count), ctx.planned_spp, |pos, sampler, sink, counters| {
            let ray = ctx.scene.camera.generate_ray(pos);
            sink.l = counters.camera_path(|c| self.li(ctx.scene, ray, sampler, c));
            true
        })
    }

    fn finish(&mut self, _: &Ctx, _: (), _: Range<u32>, _: &[TileResult]) {}
}
