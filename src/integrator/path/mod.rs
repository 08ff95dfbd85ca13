//! Unidirectional path tracing (contract §1): next-event estimation with one light sample
//! per vertex, MIS by the power heuristic between BSDF and light sampling, Russian roulette
//! from `rr_depth` on, and Mitsuba's `max_depth` (segments from the camera; -1 unlimited).
//! In scenes with participating media or null surfaces, [`PathTracer::li_media`] (`media.rs`)
//! tracks the medium along the path.
//!
//! How a path continues at a surface is a hook, [`Continuation`]: it samples the next
//! direction, says with what density it samples a direction (next-event estimation's MIS
//! weight is taken against it) and sees the radiance the path gathers. The path tracer's own
//! is [`BsdfSampling`]; an integrator that samples from another distribution, or learns
//! from the paths, runs the same loop ([`PathTracer::li_with`]) with its own.

mod media;
mod wavefront;

use crate::accel::Ray;
use crate::bsdf::TransportMode;
use crate::bsdf::{Bsdf, BsdfSample};
use crate::film::Tile;
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Work, sample_tile_with};
use crate::integrator::run::RunOptions;
use crate::integrator::run::{Integrator, Iterations, Rendered};
use crate::integrator::stats::Counters;
use crate::math::{Rgb, max_component};
use crate::sampling::sobol::SobolSampler;
use crate::sampling::{PixelSampler, Random, Sampler, SamplerKind, power_heuristic};
use crate::scene::shape::SurfaceInteraction;
use crate::scene::{IntegratorSpec, Scene};
use glam::Vec3;
use std::ops::Range;

#[derive(Clone, Debug)]
pub struct PathTracer {
    /// Maximum number of segments; `u32::MAX` for unlimited.
    pub max_depth: u32,
    pub rr_depth: u32,
    pub hide_emitters: bool,
    /// Emission reached from a surface through a Dirac lobe counts (`true` but in MEMLT's
    /// direct-light pass, whose chains take those paths).
    pub dirac_emission: bool,
    /// Mitsuba 0.5/0.6's `strictNormals` ([`IntegratorSpec::strict_normals`]).
    pub strict_normals: bool,
    /// Where each camera sample's random numbers come from.
    pub sampler: SamplerKind,
    /// Trace the camera samples of a tile as a wavefront ([`wavefront`]) in scenes without
    /// media.
    pub wavefront: bool,
}

/// How a path continues at a surface vertex whose BSDF is `bsdf` (`wo` in the shading frame
/// of `si`): what samples the next direction and with what density, and what sees the
/// radiance the path gathers on its way to the camera.
pub(crate) trait Continuation {
    /// Samples the next direction: its weight `f |cos θ| / pdf`, its density `pdf` (solid
    /// angle) and whether it came from a Dirac lobe, as [`Bsdf::sample`] gives them.
    fn sample<R: Random>(
        &mut self,
        si: &SurfaceInteraction,
        bsdf: &Bsdf,
        wo: Vec3,
        sampler: &mut R,
    ) -> Option<BsdfSample>;

    /// The density (solid angle) with which [`Continuation::sample`] draws the non-Dirac
    /// direction `wi` (shading frame): what next-event estimation is weighed against.
    fn pdf(&self, si: &SurfaceInteraction, bsdf: &Bsdf, wo: Vec3, wi: Vec3) -> f32;

    /// The path went on from `si` along `wi` (world) with the sample `sample`, its
    /// throughput now `beta` (this vertex's weight included, before the roulette).
    #[inline(always)]
    fn continued(&mut self, _si: &SurfaceInteraction, _wi: Vec3, _sample: &BsdfSample, _beta: Rgb) {}

    /// Radiance `value` reached the camera (throughput and MIS weight included).
    #[inline(always)]
    fn gathered(&mut self, _value: Rgb) {}
}

/// The path tracer's continuation: the BSDF samples the next direction.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct BsdfSampling;

impl Continuation for BsdfSampling {
    #[inline(always)]
    fn sample<R: Random>(
        &mut self,
        si: &SurfaceInteraction,
        bsdf: &Bsdf,
        wo: Vec3,
        sampler: &mut R,
    ) -> Option<BsdfSample> {
        let u_lobe = sampler.next_1d();
        let u_dir = sampler.next_2d();
        bsdf.sample(wo, si.at(), u_lobe, u_dir, TransportMode::Radiance)
    }

    #[inline(always)]
    fn pdf(&self, si: &SurfaceInteraction, bsdf: &Bsdf, wo: Vec3, wi: Vec3) -> f32 {
        bsdf.pdf(wo, wi, si.at(), TransportMode::Radiance)
    }
}

impl PathTracer {
    pub fn new(spec: &IntegratorSpec) -> PathTracer {
        PathTracer {
            max_depth: if spec.max_depth < 0 { u32::MAX } else { spec.max_depth as u32 },
            rr_depth: spec.rr_depth,
            hide_emitters: spec.hide_emitters,
            dirac_emission: true,
            strict_normals: spec.strict_normals,
            sampler: SamplerKind::Independent,
            wavefront: false,
        }
    }

    /// MIS weight of emission reached after `segments` earlier segments: seen directly by
    /// the camera (0), through a delta lobe (0 without `dirac_emission`), or by BSDF
    /// sampling against light sampling (whose density `pdf_light` is computed only when
    /// needed).
    #[inline]
    pub(crate) fn emission_weight(
        &self,
        segments: u32,
        prev_delta: bool,
        prev_pdf: f32,
        pdf_light: impl FnOnce() -> f32,
    ) -> f32 {
        if weighs_against_light_sampling(segments, prev_delta) {
            power_heuristic(prev_pdf, pdf_light())
        } else if segments == 0 {
            if self.hide_emitters { 0.0 } else { 1.0 }
        } else if self.dirac_emission {
            1.0
        } else {
            0.0
        }
    }

    /// Radiance arriving along a camera ray: [`PathTracer::li`], or
    /// [`PathTracer::li_media`] in a scene with media.
    #[inline]
    pub fn radiance<R: Random>(&self, scene: &Scene, ray: Ray, sampler: &mut R, counters: &mut Counters) -> Rgb {
        if scene.volumetric {
            self.li_media(scene, ray, sampler, counters)
        } else {
            self.li(scene, ray, sampler, counters)
        }
    }

    /// Radiance arriving along a camera ray in a scene without media.
    #[inline]
    pub fn li<R: Random>(&self, scene: &Scene, ray: Ray, sampler: &mut R, counters: &mut Counters) -> Rgb {
        self.li_with(scene, ray, sampler, counters, &mut BsdfSampling)
    }

    /// [`PathTracer::li`] with the path continued at each surface by `cont`.
    pub(crate) fn li_with<R: Random, C: Continuation>(
        &self,
        scene: &Scene,
        ray: Ray,
        sampler: &mut R,
        counters: &mut Counters,
        cont: &mut C,
    ) -> Rgb {
        let mut path = PathState::new(ray);
        if self.max_depth == 0 {
            return path.l;
        }
        loop {
            counters.extension_rays += 1;
            let Some(si) = scene.intersect(&path.ray) else {
                let d = path.ray.d.normalize();
                self.escaped(scene, &mut path, d, cont);
                break;
            };
            let Some(lit) = self.light_at(scene, &mut path, &si, sampler, counters, cont, |ray, _| {
                if scene.occluded(ray) { Rgb::ZERO } else { Rgb::ONE }
            }) else {
                break;
            };
            path.l += lit.direct;
            cont.gathered(lit.direct);
            if !self.go_on(&mut path, &si, &lit, sampler, cont) {
                break;
            }
        }
        path.l
    }

    /// A path's ray left the scene along the unit direction `d`: the light of the lights
    /// at infinity along it.
    #[inline(always)]
    fn escaped<C: Continuation>(&self, scene: &Scene, path: &mut PathState, d: Vec3, cont: &mut C) {
        for &light_index in &scene.infinite_lights {
            let light = &scene.lights[light_index];
            // The density only where the weight needs it.
            let (le, pdf) = if weighs_against_light_sampling(path.depth, path.prev_delta) {
                light.eval_pdf_infinite(d)
            } else {
                (light.eval_infinite(d), 0.0)
            };
            if le == Rgb::ZERO {
                continue;
            }
            let w = self.emission_weight(path.depth, path.prev_delta, path.prev_pdf, || {
                scene.light_sampler.pmf(light_index) * pdf
            });
            path.l += path.beta * le * w;
            cont.gathered(path.beta * le * w);
        }
    }

    /// A path's ray reached the surface point `si`: its emission (added to `path.l`) and
    /// next-event estimation there (the shadow ray's transmittance from `transmittance`, as
    /// in [`PathTracer::surface_nee`]), whose contribution is returned, not added. `None`
    /// where the path ends at `si` (its last segment, or strict normals).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn light_at<'s, R: Random, C: Continuation>(
        &self,
        scene: &'s Scene,
        path: &mut PathState,
        si: &SurfaceInteraction,
        sampler: &mut R,
        counters: &mut Counters,
        cont: &mut C,
        transmittance: impl FnOnce(&Ray, bool) -> Rgb,
    ) -> Option<Lit<'s>> {
        path.depth += 1;
        if let Some((light_index, light)) = scene.area_light(si) {
            let le = light.radiance(si.ng, si.uv, si.wo);
            if le != Rgb::ZERO {
                let w = self.emission_weight(path.depth - 1, path.prev_delta, path.prev_pdf, || {
                    scene.light_sampler.pmf(light_index) * light.pdf_li(&scene.shapes, path.prev_p, si)
                });
                path.l += path.beta * le * w;
                cont.gathered(path.beta * le * w);
            }
        }
        if path.depth >= self.max_depth {
            return None;
        }
        let bsdf = scene.bsdf(si);
        let wo = si.shading.to_local(si.wo);
        if !self.sides_agree(si, si.wo, wo.z) {
            return None;
        }
        let direct = self.surface_nee(scene, si, bsdf, wo, path.beta, sampler, counters, &*cont, transmittance);
        Some(Lit { direct, bsdf, wo })
    }

    /// After [`PathTracer::light_at`] (and the light sample's contribution gathered): the
    /// next direction, the throughput, the roulette and the next ray (in `path.ray`);
    /// `false` where the path ends.
    #[inline(always)]
    fn go_on<R: Random, C: Continuation>(
        &self,
        path: &mut PathState,
        si: &SurfaceInteraction,
        lit: &Lit,
        sampler: &mut R,
        cont: &mut C,
    ) -> bool {
        let Some((bs, wi_world)) = self.sample_next(si, lit.bsdf, lit.wo, sampler, cont) else { return false };
        path.beta *= bs.weight;
        if path.beta == Rgb::ZERO {
            return false;
        }
        path.prev_pdf = bs.pdf;
        path.prev_delta = bs.delta;
        path.prev_p = si.p;
        cont.continued(si, wi_world, &bs, path.beta);
        if !self.roulette(path, sampler) {
            return false;
        }
        path.ray = si.spawn_ray(wi_world);
        true
    }

    /// Russian roulette from `rr_depth` on: `false` when the path ends (or carries nothing).
    #[inline(always)]
    fn roulette<R: Random>(&self, path: &mut PathState, sampler: &mut R) -> bool {
        if path.beta == Rgb::ZERO {
            return false;
        }
        if path.depth >= self.rr_depth {
            let q = max_component(path.beta).min(0.95);
            if sampler.next_1d() >= q {
                return false;
            }
            path.beta /= q;
        }
        true
    }
}

/// What a path tracer's path carries from one vertex to the next.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PathState {
    /// The ray to trace next.
    pub ray: Ray,
    /// The radiance gathered so far.
    pub l: Rgb,
    /// The throughput.
    pub beta: Rgb,
    /// The vertices reached so far (segments traced).
    pub depth: u32,
    /// The last BSDF sample's density (solid angle) and whether it was a delta lobe.
    pub prev_pdf: f32,
    pub prev_delta: bool,
    /// Where the last ray started.
    pub prev_p: Vec3,
    /// The medium the ray travels in (`None` in a scene without media).
    pub medium: Option<u32>,
}

impl PathState {
    #[inline(always)]
    pub fn new(ray: Ray) -> PathState {
        PathState {
            ray,
            l: Rgb::ZERO,
            beta: Rgb::ONE,
            depth: 0,
            prev_pdf: 0.0,
            prev_delta: true,
            prev_p: ray.o,
            medium: None,
        }
    }
}

/// A surface vertex's light, from [`PathTracer::light_at`]: the light sample's contribution
/// (its shadow ray answered or not), and the BSDF and direction the path goes on with.
pub(crate) struct Lit<'s> {
    pub direct: Rgb,
    bsdf: &'s Bsdf,
    wo: Vec3,
}

impl PathTracer {
    /// With strict normals a direction (world `w`, `local_z` its shading-frame cosine)
    /// counts only where the geometric and the shading normal put it on the same side.
    #[inline(always)]
    fn sides_agree(&self, si: &SurfaceInteraction, w: Vec3, local_z: f32) -> bool {
        !self.strict_normals || w.dot(si.ng) * local_z > 0.0
    }

    /// The path's next direction at `si` (`wo` in its shading frame), sampled by `cont`:
    /// the sample and its world direction, or `None` where sampling fails or strict normals
    /// refuse the direction.
    #[inline(always)]
    fn sample_next<R: Random, C: Continuation>(
        &self,
        si: &SurfaceInteraction,
        bsdf: &Bsdf,
        wo: Vec3,
        sampler: &mut R,
        cont: &mut C,
    ) -> Option<(BsdfSample, Vec3)> {
        let bs = cont.sample(si, bsdf, wo, sampler)?;
        let wi_world = si.shading.to_world(bs.wi);
        self.sides_agree(si, wi_world, bs.wi.z).then_some((bs, wi_world))
    }

    /// Next-event estimation from the surface point `si` (its BSDF `bsdf`, `wo` in its shading
    /// frame) for a path of throughput `beta`: one light sample weighed by the power heuristic
    /// against the continuation `cont`'s sampling (none from a Dirac BSDF). `transmittance` gives the fraction of
    /// the light that reaches `si` along the shadow ray, for a light at infinity or not
    /// (zero when something blocks it). Draws four numbers whether it samples or not.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn surface_nee<R: Random>(
        &self,
        scene: &Scene,
        si: &SurfaceInteraction,
        bsdf: &Bsdf,
        wo: Vec3,
        beta: Rgb,
        sampler: &mut R,
        counters: &mut Counters,
        cont: &impl Continuation,
        transmittance: impl FnOnce(&Ray, bool) -> Rgb,
    ) -> Rgb {
        let u_light = sampler.next_1d();
        let u_light1 = sampler.next_1d();
        let u_light2 = sampler.next_2d();
        if bsdf.is_delta() {
            return Rgb::ZERO;
        }
        let Some((light_index, pmf, _)) = scene.light_sampler.sample(u_light) else { return Rgb::ZERO };
        let light = &scene.lights[light_index];
        let Some(ls) = light.sample_li(&scene.shapes, &scene.bounds, si.p, u_light1, u_light2) else {
            return Rgb::ZERO;
        };
        let wi = si.shading.to_local(ls.wi);
        let f = bsdf.eval(wo, wi, si.at(), TransportMode::Radiance) * wi.z.abs();
        if f == Rgb::ZERO || !self.sides_agree(si, ls.wi, wi.z) {
            return Rgb::ZERO;
        }
        counters.shadow_rays += 1;
        let tr = transmittance(&si.spawn_ray_to(ls.p), light.is_infinite());
        if tr == Rgb::ZERO {
            return Rgb::ZERO;
        }
        let pdf_light = pmf * ls.pdf;
        let w = if ls.delta { 1.0 } else { light_sampling_weight(pdf_light, cont.pdf(si, bsdf, wo, wi)) };
        beta * f * tr * ls.li * (w / pdf_light)
    }
}

/// MIS weight of a light sample of density `pdf_light` against the continuation's sampling
/// of the same direction with density `pdf_continuation` (power heuristic).
#[inline(always)]
pub(crate) fn light_sampling_weight(pdf_light: f32, pdf_continuation: f32) -> f32 {
    power_heuristic(pdf_light, pdf_continuation)
}

/// Whether emission reached after `segments` earlier segments, the last one sampled from a
/// Dirac lobe or not, is weighted against light sampling (which needs the light's density):
/// not when seen directly by the camera, nor through a Dirac lobe.
#[inline]
fn weighs_against_light_sampling(segments: u32, prev_delta: bool) -> bool {
    segments > 0 && !prev_delta
}

impl PathTracer {
    /// A tile's camera samples with their random numbers from `S`.
    fn tile_with<S: PixelSampler>(&self, ctx: &Ctx, tile: Tile, first: u32, count: u32) -> TileResult {
        sample_tile_with::<S>(ctx, tile, (first, count), None, |pos, sampler, sink, counters| {
            let ray = ctx.scene.camera.generate_ray(pos);
            sink.l = counters.camera_path(|c| self.radiance(ctx.scene, ray, sampler, c));
            true
        })
    }
}

/// The path tracer in the render loop: no state between iterations.
impl Iterative for PathTracer {
    type Pass = ();
    type TileData = ();

    fn prepare(&self, _: &Ctx, _: u32, _: bool, _: &mut Work) -> Prepared<()> {
        Prepared::only(())
    }

    fn render_tile(&self, ctx: &Ctx, _: &(), tile: Tile, first: u32, count: u32) -> TileResult {
        let wavefront = self.wavefront && !ctx.scene.volumetric;
        match (self.sampler, wavefront) {
            (SamplerKind::Independent, false) => self.tile_with::<Sampler>(ctx, tile, first, count),
            (SamplerKind::Sobol, false) => self.tile_with::<SobolSampler>(ctx, tile, first, count),
            (SamplerKind::Independent, true) => self.tile_wavefront::<Sampler>(ctx, tile, first, count),
            (SamplerKind::Sobol, true) => self.tile_wavefront::<SobolSampler>(ctx, tile, first, count),
        }
    }

    fn finish(&mut self, _: &Ctx, _: (), _: Range<u32>, _: &[TileResult]) {}
}

/// Options of the path tracer (`--integrator path`; its depths are the scene's and the
/// command line's `--max-depth`, `--rr-depth`).
#[derive(Clone, Debug, serde::Serialize, clap::Args)]
pub struct PathOptions {
    /// Trace each tile's paths as a wavefront, bounce by bounce, with batched ray queries
    /// (false: one path at a time; the same image). Scenes with media are traced one path
    /// at a time either way.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub wavefront: bool,
}

impl Default for PathOptions {
    fn default() -> PathOptions {
        PathOptions { wavefront: true }
    }
}

impl Integrator for PathOptions {
    const BIDIRECTIONAL: bool = false;
    const MEDIA: bool = true;

    fn render(&self, scene: &Scene, opts: &RunOptions, iterations: Iterations) -> Rendered {
        let pt =
            PathTracer { sampler: scene.sampler.kind, wavefront: self.wavefront, ..PathTracer::new(&scene.integrator) };
        crate::integrator::render_loop::run(scene, opts, pt, false, iterations)
    }
}
