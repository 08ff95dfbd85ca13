//! The strategies of bidirectional path tracing on the shared core, and the per-sample
//! estimators built from them: light tracing (`t = 1` only) and BDPT (Veach 1997, contract
//! §2: every `(s,t)`), with a [`ConnectionPolicy`] deciding which connections are traced
//! (EORR's roulette is one, contract §4).

use crate::bsdf::TransportMode;
use crate::film::Tile;
use crate::integrator::bidir::guide::Guide;
use crate::integrator::bidir::mis::{Counts, Heuristic, StrategyCounts, mis_weight_with};
use crate::integrator::bidir::walk::{WalkLimits, camera_subpath, light_subpath, transmittance};
use crate::integrator::bidir::{Connection, Delivery, End, Sink, Vertex, VertexKind, light_origin_pdf};
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Work, sample_tile};
use crate::integrator::run::RunOptions;
use crate::integrator::run::{Integrator, Iterations, Rendered};
use crate::integrator::stats::Counters;
use crate::math::Rgb;
use crate::sampling::Random;
use crate::scene::Scene;
use glam::Vec2;
use std::ops::Range;
use std::slice::from_ref;

/// Which connections get their shadow ray traced: every one ([`Always`]), or those a
/// policy keeps, their contributions divided by the probability of keeping them (EORR's
/// roulette, [`crate::integrator::eorr`]).
pub trait ConnectionPolicy {
    /// Whether the policy judges connections at all: its [`ConnectionPolicy::keep`] then
    /// sees each connection's MIS-weighted contribution before its shadow ray is traced,
    /// and a connection of weight zero is not traced.
    fn judges(&self) -> bool;
    /// For the connection of MIS-weighted contribution `c` at film position `pos`:
    /// `Some(factor)` to trace it (its contribution multiplied by `factor`), `None` to
    /// leave it untraced.
    fn keep<R: Random>(&self, c: Rgb, pos: Vec2, rng: &mut R) -> Option<f32>;
}

/// Every connection traced, weighed after its shadow ray.
#[derive(Clone, Copy, Debug, Default)]
pub struct Always;

impl ConnectionPolicy for Always {
    #[inline(always)]
    fn judges(&self) -> bool {
        false
    }

    #[inline(always)]
    fn keep<R: Random>(&self, _: Rgb, _: Vec2, _: &mut R) -> Option<f32> {
        Some(1.0)
    }
}

/// Evaluates single strategies of a path and hands their weighted contributions to a sink.
pub struct Connector<'a, C, P = Always> {
    pub scene: &'a Scene,
    pub heuristic: Heuristic,
    pub counts: &'a C,
    pub policy: P,
    /// The guide the camera walks follow ([`crate::integrator::bidir::guide`]): the camera
    /// side's densities at the ends of connections are its.
    pub guide: Option<&'a dyn Guide>,
}

impl<'a, C: StrategyCounts> Connector<'a, C> {
    /// Strategies weighed with `counts`, every connection traced, no guide.
    pub fn new(scene: &'a Scene, heuristic: Heuristic, counts: &'a C) -> Connector<'a, C> {
        Connector { scene, heuristic, counts, policy: Always, guide: None }
    }

    /// The strategies of walks made with `limits` (their guide's densities at the ends).
    pub fn for_walks(
        scene: &'a Scene,
        heuristic: Heuristic,
        counts: &'a C,
        limits: &'a WalkLimits,
    ) -> Connector<'a, C> {
        Connector { guide: limits.guide(), ..Connector::new(scene, heuristic, counts) }
    }
}

impl<C: StrategyCounts, P: ConnectionPolicy> Connector<'_, C, P> {
    /// Traces the shadow ray of a connection: the transmittance between its ends (zero when
    /// occluded).
    #[inline]
    fn trace(&self, a: &Vertex, b: &Vertex, counters: &mut Counters) -> Rgb {
        counters.connections += 1;
        let tr = transmittance(self.scene, a, b, counters);
        if tr == Rgb::ZERO {
            counters.connections_occluded += 1;
        }
        tr
    }

    /// `s = 0`: the camera subpath `z_0..z_{t-1}` ends on an emitter.
    pub fn emission(&self, camera: &[Vertex], sink: &mut impl Sink) {
        let t = camera.len();
        let pt = &camera[t - 1];
        let le = match pt.kind {
            VertexKind::Surface => {
                let Some(l) = self.scene.shapes[pt.shape as usize].light else { return };
                self.scene.lights[l].radiance(pt.ng, pt.uv, pt.wo)
            }
            VertexKind::Sky => pt.infinite_emission(self.scene),
            _ => return,
        };
        if le == Rgb::ZERO {
            return;
        }
        let w = mis_weight_with(self.scene, &[], camera, None, self.heuristic, self.counts);
        if sink.observes() {
            let (scene, counts) = (self.scene, self.counts);
            sink.observe(&Delivery { scene, light: &[], camera, conn: None, counts, drawn: None });
        }
        sink.add_emission(camera, pt.beta * le * w);
    }

    /// `s = 1`: next-event estimation from `z_{t-1}` to a fresh point on a light.
    pub fn next_event<R: Random>(
        &self,
        camera: &[Vertex],
        pos: Vec2,
        rng: &mut R,
        sink: &mut impl Sink,
        counters: &mut Counters,
    ) {
        let Some((y0, conn, c)) = self.light_sample(camera, rng) else { return };
        let t = camera.len();
        self.finish(from_ref(&y0), camera, &conn, c, None, pos, rng, sink, counters, |s, c, w| s.add(1, t, c * w));
    }

    /// The light sample of `s = 1` at `z_{t-1}`: the vertex `y_0` on the light, the
    /// connection and its unweighted contribution (`None` when it carries nothing).
    #[inline(always)]
    pub(crate) fn light_sample<R: Random>(&self, camera: &[Vertex], rng: &mut R) -> Option<(Vertex, Connection, Rgb)> {
        let scene = self.scene;
        let pt = &camera[camera.len() - 1];
        let u = rng.next_1d();
        let u1 = rng.next_1d();
        let u2 = rng.next_2d();
        if !pt.is_connectible() {
            return None;
        }
        let (l, pmf, _) = scene.light_sampler.sample(u)?;
        let ls = scene.lights[l].sample_li(&scene.shapes, &scene.bounds, pt.p, u1, u2)?;
        let camera_end = pt.end_with(scene, ls.wi, TransportMode::Radiance, self.guide);
        if camera_end.f == Rgb::ZERO {
            return None;
        }
        let c = pt.beta * camera_end.f * ls.li / (pmf * ls.pdf);
        let light = &scene.lights[l];
        Some(if light.at_infinity() {
            // A light at infinity: `y_0` is the direction, and `z_{t-1}`'s density from it
            // that of a point on the disk facing it (no distance term either way).
            let mut y0 = Vertex::light(l, ls.p, ls.wi, Vec2::ZERO, Rgb::ONE, 0.0);
            y0.infinite = true;
            y0.connectible = false;
            y0.pdf_fwd = y0.pdf_light_origin(scene);
            let light_end = End { f: Rgb::ZERO, pdf_fwd: crate::integrator::bidir::disk_pdf(scene), pdf_rev: 0.0 };
            (y0, Connection { w: -ls.wi, dist2: 1.0, inv_dist2: 1.0, light_end, camera_end }, c)
        } else {
            let y0 = Vertex::light(l, ls.p, ls.n, Vec2::ZERO, Rgb::ONE, light_origin_pdf(scene, l));
            let dist2 = (ls.p - pt.p).length_squared();
            // Only the emission density matters at a sampled light point.
            let light_end = End { f: Rgb::ZERO, pdf_fwd: light.pdf_emission_direction(ls.n, -ls.wi), pdf_rev: 0.0 };
            (y0, Connection { w: -ls.wi, dist2, inv_dist2: 1.0 / dist2, light_end, camera_end }, c)
        })
    }

    /// `t = 1`: `y_{s-1}` connects to the camera and splats onto the film.
    pub fn to_camera<R: Random>(&self, light: &[Vertex], rng: &mut R, sink: &mut impl Sink, counters: &mut Counters) {
        let Some((raster, conn, c)) = self.camera_connection(light) else { return };
        let s = light.len();
        let z0 = self.camera_vertex();
        self.finish(light, from_ref(&z0), &conn, c, None, raster, rng, sink, counters, |sk, c, w| {
            sk.splat(s, 1, raster, c * w)
        });
    }

    /// The camera's vertex `z_0`.
    #[inline]
    pub(crate) fn camera_vertex(&self) -> Vertex {
        Vertex { medium: self.scene.camera_medium, ..Vertex::camera(self.scene.camera.position) }
    }

    /// The connection of `t = 1` from `y_{s-1}`: where it lands on the film, the connection
    /// and its unweighted contribution (`None` when it carries nothing).
    #[inline(always)]
    pub(crate) fn camera_connection(&self, light: &[Vertex]) -> Option<(Vec2, Connection, Rgb)> {
        let scene = self.scene;
        let qs = &light[light.len() - 1];
        if !qs.is_connectible() {
            return None;
        }
        let k = scene.camera.connect(qs.p)?;
        let light_end = qs.end_with(scene, k.wi, TransportMode::Importance, self.guide);
        if light_end.f == Rgb::ZERO {
            return None;
        }
        let inv_dist2 = k.inv_dist2;
        // `We cos θ_camera` is the direction's density `k.pdf_dir`.
        let c = qs.beta * light_end.f * (k.pdf_dir * inv_dist2);
        let conn = Connection {
            w: k.wi,
            dist2: k.dist2,
            inv_dist2,
            light_end,
            // What `z0.end(scene, -k.wi, ..)` gives, without projecting the direction again.
            camera_end: End { f: Rgb::ZERO, pdf_fwd: k.pdf_dir, pdf_rev: 0.0 },
        };
        Some((k.raster, conn, c))
    }

    /// `s, t >= 2`: joins `y_{s-1}` and `z_{t-1}` with a shadow ray; `scale` multiplies the
    /// contribution (the pool connections' `1 / (N M PMF)`). `true` when the shadow ray
    /// was traced and found the two vertices visible to each other.
    #[allow(clippy::too_many_arguments)]
    pub fn connect<R: Random>(
        &self,
        light: &[Vertex],
        camera: &[Vertex],
        scale: f32,
        pos: Vec2,
        rng: &mut R,
        sink: &mut impl Sink,
        counters: &mut Counters,
    ) -> bool {
        let Some((conn, c)) = self.connection(light, camera, scale) else { return false };
        self.finish(light, camera, &conn, c, Some(scale), pos, rng, sink, counters, |sk, c, w| {
            sk.add_connection(light, camera, c, w)
        })
    }

    /// The connection of `y_{s-1}` and `z_{t-1}` and its unweighted contribution, `scale`
    /// included (`None` when it carries nothing).
    #[inline(always)]
    pub(crate) fn connection(&self, light: &[Vertex], camera: &[Vertex], scale: f32) -> Option<(Connection, Rgb)> {
        let (qs, pt) = (&light[light.len() - 1], &camera[camera.len() - 1]);
        if !qs.is_connectible() || !pt.is_connectible() {
            return None;
        }
        let conn = Connection::carrying(self.scene, qs, pt, self.guide)?;
        let f = conn.light_end.f * conn.camera_end.f;
        if f == Rgb::ZERO {
            return None;
        }
        Some((conn, qs.beta * f * pt.beta * (scale * conn.inv_dist2)))
    }

    /// Shows a sink that observes them the connection about to be delivered; `drawn` is
    /// the factor of a connection drawn from a pool.
    #[inline]
    fn observe(
        &self,
        light: &[Vertex],
        camera: &[Vertex],
        conn: &Connection,
        drawn: Option<f32>,
        sink: &mut impl Sink,
    ) {
        if sink.observes() {
            let (scene, counts) = (self.scene, self.counts);
            sink.observe(&Delivery { scene, light, camera, conn: Some(conn), counts, drawn });
        }
    }

    /// Weights an unweighted connection contribution, applies the connection policy, traces the shadow
    /// ray and delivers the result; `true` when the shadow ray was traced and unoccluded.
    /// `drawn` is the factor of a drawn connection.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn finish<R: Random, S: Sink>(
        &self,
        light: &[Vertex],
        camera: &[Vertex],
        conn: &Connection,
        c: Rgb,
        drawn: Option<f32>,
        pos: Vec2,
        rng: &mut R,
        sink: &mut S,
        counters: &mut Counters,
        deliver: impl FnOnce(&mut S, Rgb, f32),
    ) -> bool {
        let Some(weight) = self.judge(light, camera, conn, c, pos, rng) else { return false };
        let tr = self.trace(&light[light.len() - 1], &camera[camera.len() - 1], counters);
        if tr == Rgb::ZERO {
            return false;
        }
        self.deliver(light, camera, conn, c * tr, weight, drawn, sink, deliver);
        true
    }

    /// What the connection policy decides before a connection's shadow ray: `None` to leave
    /// it untraced, `Some(None)` to weigh it after the ray (the MIS weight is only computed
    /// for visible connections), `Some(Some(w))` for a policy that judges, whose weight
    /// (its factor included) comes first.
    #[inline(always)]
    pub(crate) fn judge<R: Random>(
        &self,
        light: &[Vertex],
        camera: &[Vertex],
        conn: &Connection,
        c: Rgb,
        pos: Vec2,
        rng: &mut R,
    ) -> Option<Option<f32>> {
        if !self.policy.judges() {
            return Some(None);
        }
        let w = mis_weight_with(self.scene, light, camera, Some(conn), self.heuristic, self.counts);
        if w == 0.0 {
            return None;
        }
        let k = self.policy.keep(c * w, pos, rng)?;
        Some(Some(w * k))
    }

    /// Delivers a visible connection's contribution `c` (the transmittance included) with
    /// its MIS weight, `weight` when [`Connector::judge`] gave it.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(crate) fn deliver<S: Sink>(
        &self,
        light: &[Vertex],
        camera: &[Vertex],
        conn: &Connection,
        c: Rgb,
        weight: Option<f32>,
        drawn: Option<f32>,
        sink: &mut S,
        deliver: impl FnOnce(&mut S, Rgb, f32),
    ) {
        let w = weight
            .unwrap_or_else(|| mis_weight_with(self.scene, light, camera, Some(conn), self.heuristic, self.counts));
        self.observe(light, camera, conn, drawn, sink);
        deliver(sink, c, w);
    }
}

/// The per-sample estimator of light tracing, BDPT and EORR.
#[derive(Clone, Debug)]
pub struct Bdpt {
    pub limits: WalkLimits,
    /// Longest path in segments (`u32::MAX` = unlimited).
    pub max_depth: u32,
    pub hide_emitters: bool,
    /// Light tracing only: no camera subpath, every path splats through `t = 1`.
    pub light_only: bool,
}

/// Reusable subpath storage (one per worker).
#[derive(Default)]
pub struct Scratch {
    pub camera: Vec<Vertex>,
    pub light: Vec<Vertex>,
    /// The pool draws of one camera vertex: index, contribution factor (summed over
    /// repeats) and how many draws chose it.
    pub draws: Vec<(usize, f32, u32)>,
}

impl Bdpt {
    /// Whether strategy `(s,t)` builds a path that the integrator renders.
    #[inline]
    pub fn allowed(&self, s: usize, t: usize) -> bool {
        s + t >= 2 && s + t - 1 <= self.max_depth as usize && !(self.hide_emitters && s + t == 2)
    }

    /// The light-subpath lengths `s <= s_max` with `(s, t)` allowed, as one range.
    #[inline]
    pub fn allowed_light_lengths(&self, t: usize, s_max: usize) -> std::ops::Range<usize> {
        // `s + t >= 2`, or `>= 3` with emitters hidden; at most `max_depth` segments.
        let lo = (if self.hide_emitters { 3usize } else { 2 }).saturating_sub(t);
        let hi = (self.max_depth as usize).saturating_add(2).saturating_sub(t).min(s_max + 1);
        lo..hi.max(lo)
    }

    /// One camera sample at film position `pos`: a camera subpath (unless light tracing),
    /// one light subpath, and every strategy joining them.
    #[allow(clippy::too_many_arguments)]
    pub fn sample<R: Random, C: StrategyCounts, P: ConnectionPolicy>(
        &self,
        conn: &Connector<C, P>,
        pos: Vec2,
        rng: &mut R,
        scratch: &mut Scratch,
        sink: &mut impl Sink,
        counters: &mut Counters,
    ) {
        let scene = conn.scene;
        if self.light_only {
            scratch.camera.clear();
            scratch.camera.push(Vertex { medium: scene.camera_medium, ..Vertex::camera(scene.camera.position) });
            if !scene.infinite_lights.is_empty() && self.allowed(0, 2) {
                // No light path reaches the pinhole from infinity: the camera ray finds the
                // sky seen directly.
                let ray = scene.camera.generate_ray(pos);
                counters.camera_rays += 1;
                if scene.intersect(&ray).is_none() {
                    let mut sky = Vertex::sky(scene, ray.o, ray.d, Rgb::ONE);
                    sky.pdf_fwd = scene.camera.pdf_direction(ray.d);
                    scratch.camera.push(sky);
                    conn.emission(&scratch.camera, sink);
                    scratch.camera.truncate(1);
                }
            }
        } else {
            camera_subpath(scene, pos, &self.limits, rng, &mut scratch.camera, counters);
        }
        rng.start_stream(1);
        light_subpath(scene, &self.limits, rng, &mut scratch.light, counters);
        counters.light_paths += 1;
        rng.start_stream(2);
        let (camera, light) = (&scratch.camera, &scratch.light);
        for t in 1..=camera.len() {
            for s in self.allowed_light_lengths(t, light.len()) {
                match (s, t) {
                    (0, _) => conn.emission(&camera[..t], sink),
                    (_, 1) => conn.to_camera(&light[..s], rng, sink, counters),
                    (1, _) => conn.next_event(&camera[..t], pos, rng, sink, counters),
                    _ => {
                        conn.connect(&light[..s], &camera[..t], 1.0, pos, rng, sink, counters);
                    }
                }
            }
        }
    }
}

/// Checks that the scene has a light to start light paths from.
pub fn check_lights(scene: &Scene, integrator: &str) -> Result<(), String> {
    if scene.lights.is_empty() {
        return Err(format!(
            "{}: the scene has no emitter (the {integrator} integrator needs one)",
            scene.path.display()
        ));
    }
    Ok(())
}

/// Options of BDPT (`--integrator bdpt`).
#[derive(Clone, Debug, serde::Serialize, clap::Args)]
pub struct BdptOptions {
    /// MIS heuristic.
    #[arg(long, value_enum, default_value_t = Heuristic::default())]
    pub heuristic: Heuristic,
    /// Trace each tile's samples as a wavefront, their walks bounce by bounce and their
    /// connections together, with batched ray queries (false: one sample at a time; the
    /// same image). Scenes with media are traced one sample at a time either way.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub wavefront: bool,
}

impl Default for BdptOptions {
    fn default() -> BdptOptions {
        BdptOptions { heuristic: Heuristic::default(), wavefront: true }
    }
}

/// Options of light tracing (`--integrator lighttrace`): none of its own.
#[derive(Clone, Debug, Default, serde::Serialize, clap::Args)]
pub struct LighttraceOptions {}

/// BDPT (or light tracing, `light_only`) in the render loop: no state between iterations.
pub struct BdptRender {
    pub bdpt: Bdpt,
    pub heuristic: Heuristic,
    /// Trace BDPT's tiles as a wavefront ([`crate::integrator::bidir::wavefront`]) in scenes
    /// without media.
    pub wavefront: bool,
}

impl Iterative for BdptRender {
    type Pass = ();
    type TileData = ();

    fn prepare(&self, _: &Ctx, _: u32, _: bool, _: &mut Work) -> Prepared<()> {
        Prepared::only(())
    }

    fn render_tile(&self, ctx: &Ctx, _: &(), tile: Tile, first: u32, count: u32) -> TileResult {
        let counts = if self.bdpt.light_only { Counts::LightTrace } else { Counts::Bdpt };
        let conn = Connector::new(ctx.scene, self.heuristic, &counts);
        self.bdpt.render_tile(ctx, &conn, tile, first, count, self.wavefront)
    }

    fn finish(&mut self, _: &Ctx, _: (), _: Range<u32>, _: &[TileResult]) {}
}

impl Bdpt {
    /// Iterations `first..first + count` of a tile, each camera sample's strategies
    /// evaluated by `conn`: as a wavefront ([`crate::integrator::bidir::wavefront`]) when
    /// `wavefront` is set, but for light tracing alone and in scenes with media, which are
    /// traced one sample at a time.
    pub(crate) fn render_tile<C: StrategyCounts, P: ConnectionPolicy>(
        &self,
        ctx: &Ctx,
        conn: &Connector<C, P>,
        tile: Tile,
        first: u32,
        count: u32,
        wavefront: bool,
    ) -> TileResult {
        if wavefront && !self.light_only && !ctx.scene.volumetric {
            return self.tile_wavefront(ctx, conn, tile, first, count);
        }
        let mut scratch = Scratch::default();
        // Light tracing only splats, but for the sky seen directly.
        let camera_samples = !self.light_only || !ctx.scene.infinite_lights.is_empty();
        sample_tile(ctx, tile, first, count, |pos, rng, sink, counters| {
            self.sample(conn, pos, rng, &mut scratch, sink, counters);
            camera_samples
        })
    }

    /// The bidirectional estimator with the scene's depth limits and emitter visibility
    /// (light tracing alone with `light_only`).
    pub fn for_scene(scene: &Scene, light_only: bool) -> Bdpt {
        let spec = &scene.integrator;
        let max_depth = if spec.max_depth < 0 { u32::MAX } else { spec.max_depth as u32 };
        Bdpt {
            limits: WalkLimits::new(max_depth, spec.rr_depth),
            max_depth,
            hide_emitters: spec.hide_emitters,
            light_only,
        }
    }
}

impl Integrator for LighttraceOptions {
    const BIDIRECTIONAL: bool = true;
    const MEDIA: bool = true;

    fn render(&self, scene: &Scene, opts: &RunOptions, iterations: Iterations) -> Rendered {
        let method = BdptRender { bdpt: Bdpt::for_scene(scene, true), heuristic: Default::default(), wavefront: false };
        crate::integrator::render_loop::run(scene, opts, method, true, iterations)
    }
}

impl Integrator for BdptOptions {
    const BIDIRECTIONAL: bool = true;
    const MEDIA: bool = true;

    fn render(&self, scene: &Scene, opts: &RunOptions, iterations: Iterations) -> Rendered {
        let bdpt = Bdpt::for_scene(scene, false);
        let method = BdptRender { bdpt, heuristic: self.heuristic, wavefront: self.wavefront };
        crate::integrator::render_loop::run(scene, opts, method, true, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
        Some(&mut self.heuristic)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allowed_light_lengths_are_the_allowed_strategies() {
        for max_depth in [0, 1, 2, 3, 5, 8, u32::MAX] {
            for hide_emitters in [false, true] {
                let b = Bdpt { limits: WalkLimits::new(max_depth, 3), max_depth, hide_emitters, light_only: false };
                for t in 1..=12 {
                    for s_max in 0..=12 {
                        let want: Vec<usize> = (0..=s_max).filter(|&s| b.allowed(s, t)).collect();
                        let got: Vec<usize> = b.allowed_light_lengths(t, s_max).collect();
                        assert_eq!(got, want, "max_depth {max_depth}, hide {hide_emitters}, t {t}, s_max {s_max}");
                    }
                }
            }
        }
    }
}
