//! Vertex connection and merging (Georgiev, Křivánek, Davidovič and Slusallek 2012; the
//! same year's unified path sampling of Hachisuka et al.), and bidirectional photon mapping
//! as its merging-only case.
//!
//! Every iteration traces one light subpath per pixel into a pool ([`LightPool`]), splats
//! their light tracing (`t = 1`), and puts their rough surface vertices after the emitter
//! into a hashed grid ([`grid`]). The camera subpath of pixel `p` then takes at each vertex
//! BDPT's strategies with the light subpath `p` of the iteration (emission, next-event
//! estimation, connections to each of its vertices) and merges with every pool vertex
//! within the radius `r_i = r_1 i^((α - 1)/2)` of iteration `i` (from 1): a merge of camera
//! vertex `z` with light vertex `y` adds `β_z f_z(ω_z, ω_y) β_y / (M π r²)`, the density
//! estimate of the light arriving at `z` (`M` light paths). All strategies are weighed
//! together ([`crate::integrator::bidir::mis::merging`]: a merge's weight term is
//! `η pL(x_i) p_i` with `η = M π r²`).
//!
//! Merging is consistent, not unbiased: its bias (light blurred over the radius) fades as
//! the radius shrinks. Merges happen on surfaces only; in participating media the paths
//! through medium vertices come from the connections. `bpm` keeps the merges and the
//! camera subpath's own emission hits (the light seen directly or through Dirac lobes)
//! and drops every connection.

pub mod grid;

use crate::bsdf::TransportMode;
use crate::error::Error;
use crate::film::Tile;
use crate::integrator::bidir::bdpt::{Bdpt, Connector, Scratch};
use crate::integrator::bidir::mis::merging::merge_weight;
use crate::integrator::bidir::mis::{CAP, FullPath, Heuristic, SHORT, StrategyCounts};
use crate::integrator::bidir::pool::LightPool;
use crate::integrator::bidir::walk::camera_subpath;
use crate::integrator::bidir::{Sink, Vertex, VertexKind};
use crate::integrator::pool_base::PoolBase;
use crate::integrator::render_loop::{Ctx, Iterative, Prepared, TileResult, Work, sample_tile};
use crate::integrator::run::{Integrator, Iterations, Rendered, RunOptions};
use crate::integrator::stats::{Counters, Details, IntegratorStats, RenderStats};
use crate::math::Rgb;
use crate::sampling::Random;
use crate::scene::Scene;
use glam::Vec2;
use grid::HashGrid;
use serde::Serialize;
use std::ops::Range;

/// Options of vertex connection and merging (`--integrator vcm`) and of bidirectional
/// photon mapping (`--integrator bpm`).
#[derive(Clone, Debug, Serialize, clap::Args)]
pub struct VcmOptions {
    /// MIS heuristic.
    #[arg(long, value_enum, default_value_t = Heuristic::default())]
    pub heuristic: Heuristic,
    /// Merging radius of the first iteration, as a fraction of the radius of the scene's
    /// bounding sphere.
    #[arg(long = "vcm-radius", default_value_t = VcmOptions::default().radius)]
    pub radius: f32,
    /// The radius of iteration i is r_1 i^((alpha - 1) / 2): alpha in (0, 1] (1 keeps it).
    #[arg(long = "vcm-alpha", default_value_t = VcmOptions::default().alpha)]
    pub alpha: f32,
    /// Memory limit of the light pool, in MiB: settings whose pool would need more are refused.
    #[arg(long = "max-pool-mb", default_value_t = VcmOptions::default().max_pool_mb)]
    pub max_pool_mb: usize,
}

impl Default for VcmOptions {
    fn default() -> VcmOptions {
        VcmOptions { heuristic: Heuristic::default(), radius: 0.003, alpha: 0.75, max_pool_mb: 4096 }
    }
}

/// Options of bidirectional photon mapping (`--integrator bpm`): VCM's, its merges alone.
#[derive(Clone, Debug, Default, Serialize, clap::Args)]
pub struct BpmOptions {
    #[command(flatten)]
    pub vcm: VcmOptions,
}

impl VcmOptions {
    /// Checks the options.
    fn check(&self) -> Result<(), Error> {
        if !(self.radius > 0.0 && self.radius.is_finite()) {
            return Err(Error::Usage(format!("--vcm-radius must be positive (got {})", self.radius)));
        }
        if !(self.alpha > 0.0 && self.alpha <= 1.0) {
            return Err(Error::Usage(format!("--vcm-alpha must lie in (0, 1] (got {})", self.alpha)));
        }
        Ok(())
    }

    /// The merging radius of iteration `i` (from 0) in a scene whose bounding sphere has
    /// radius `scene_radius`.
    pub fn radius_at(&self, scene_radius: f32, i: u32) -> f32 {
        self.radius * scene_radius * ((i + 1) as f32).powf((self.alpha - 1.0) / 2.0)
    }
}

/// The strategy counts of an iteration: with `connections`, BDPT's strategies once each
/// (light tracing from `M` paths over the pixels, `M / (W·H)`), merges weighing `η`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VcmCounts {
    pub connections: bool,
    pub light_trace: f32,
    pub eta: f32,
}

impl StrategyCounts for VcmCounts {
    #[inline]
    fn count(&self, _: &FullPath, s: usize, t: usize) -> f32 {
        match (s, t) {
            (0, _) => 1.0,
            _ if !self.connections => 0.0,
            (_, 1) => self.light_trace,
            _ => 1.0,
        }
    }

    fn merging(&self) -> Option<f32> {
        Some(self.eta)
    }
}

/// What the tiles of an iteration share: its light pool, the grid of its merging vertices
/// and its radius.
pub struct VcmPass {
    pool: LightPool,
    grid: HashGrid,
    radius: f32,
    counts: VcmCounts,
}

/// VCM (or BPM, without `connections`) in the render loop: one iteration per pass.
pub struct VcmRender {
    base: PoolBase,
    options: VcmOptions,
    connections: bool,
    stats: VcmStats,
}

/// What a VCM render reports.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct VcmStats {
    /// The radius of the first and of the last iteration, in scene units.
    pub radius: (f32, f32),
    /// Light paths per iteration.
    pub light_paths: usize,
    /// Merging vertices in the last iteration's grid.
    pub merging_vertices: usize,
    /// Camera vertices that looked for light vertices, and the merges they found.
    pub lookups: u64,
    pub merges: u64,
}

impl IntegratorStats for VcmStats {
    fn lines(&self, _: &RenderStats) -> Vec<String> {
        let per = if self.lookups > 0 { self.merges as f64 / self.lookups as f64 } else { 0.0 };
        vec![format!(
            "  merging: radius {:.4e} → {:.4e}, {} light paths per iteration, {} merging vertices (the last \
             iteration's); {} camera vertices merged, {per:.2} light vertices each",
            self.radius.0, self.radius.1, self.light_paths, self.merging_vertices, self.lookups
        )]
    }
}

impl VcmRender {
    fn counts(&self, scene: &Scene, radius: f32) -> VcmCounts {
        let pixels = scene.film.width as f32 * scene.film.height as f32;
        let m = self.base.light_paths as f32;
        VcmCounts {
            connections: self.connections,
            light_trace: m / pixels,
            eta: m * std::f32::consts::PI * radius * radius,
        }
    }
}

/// The pool's merging vertices: rough surface points after the emitter.
fn merging_vertices(pool: &LightPool) -> Vec<(u32, glam::Vec3)> {
    pool.connectible
        .iter()
        .map(|&g| (g, pool.vertices[g as usize].p))
        .filter(|&(g, _)| pool.vertices[g as usize].kind == VertexKind::Surface)
        .collect()
}

impl Iterative for VcmRender {
    type Pass = VcmPass;
    type TileData = (u64, u64);

    fn begin(&mut self, ctx: &Ctx) -> Result<(), Error> {
        self.base.pilot(ctx, 0)?;
        self.stats.light_paths = self.base.light_paths;
        Ok(())
    }

    fn pass_end(&self, first: u32, _: u32) -> u32 {
        first + 1
    }

    fn prepare(&self, ctx: &Ctx, first: u32, keep: bool, work: &mut Work) -> Prepared<VcmPass> {
        let radius = self.options.radius_at(ctx.scene.bounds.radius, first);
        let counts = self.counts(ctx.scene, radius);
        let conn = Connector::new(ctx.scene, self.options.heuristic, &counts);
        // Without connections there is no light tracing to splat.
        let traced = self.base.trace(ctx, &conn, None, first, keep && self.connections, work);
        let grid = HashGrid::new(&merging_vertices(&traced.pool), radius);
        let pass = VcmPass { pool: traced.pool, grid, radius, counts };
        Prepared { pass, splats: traced.splats, counters: traced.counters, splat_paths: None }
    }

    fn render_tile(&self, ctx: &Ctx, pass: &VcmPass, tile: Tile, first: u32, count: u32) -> TileResult<(u64, u64)> {
        let conn = Connector::new(ctx.scene, self.options.heuristic, &pass.counts);
        let mut scratch = Scratch::default();
        let mut found = (0u64, 0u64);
        let result = sample_tile(ctx, tile, first, count, |pos, rng, sink, counters| {
            self.sample(&conn, pass, pos, rng, &mut scratch, sink, counters, &mut found);
            true
        });
        result.map(|()| found)
    }

    fn finish(&mut self, ctx: &Ctx, pass: VcmPass, iterations: Range<u32>, results: &[TileResult<(u64, u64)>]) {
        if self.stats.radius.0 == 0.0 {
            self.stats.radius.0 = pass.radius;
        }
        self.stats.radius.1 = pass.radius;
        self.stats.merging_vertices = merging_vertices(&pass.pool).len();
        if iterations.start >= ctx.start {
            for r in results {
                self.stats.lookups += r.data.0;
                self.stats.merges += r.data.1;
            }
        }
    }

    fn details(&self) -> Details {
        Details::of(self.stats)
    }
}

impl VcmRender {
    /// One camera sample at film position `pos`: at each camera vertex, BDPT's strategies
    /// with the pixel's light subpath (with connections) and the merges; `found` counts the
    /// vertices that merged and their merges.
    #[allow(clippy::too_many_arguments)]
    fn sample<R: Random>(
        &self,
        conn: &Connector<VcmCounts>,
        pass: &VcmPass,
        pos: Vec2,
        rng: &mut R,
        scratch: &mut Scratch,
        sink: &mut impl Sink,
        counters: &mut Counters,
        found: &mut (u64, u64),
    ) {
        let (scene, bdpt) = (conn.scene, &self.base.bdpt);
        camera_subpath(scene, pos, &bdpt.limits, rng, &mut scratch.camera, counters);
        let camera = &scratch.camera;
        let light = pass.pool.path(pixel_index(scene, pos).min(pass.pool.paths.saturating_sub(1)));
        for t in 2..=camera.len() {
            if bdpt.allowed(0, t) {
                conn.emission(&camera[..t], sink);
            }
            if self.connections {
                if bdpt.allowed(1, t) {
                    conn.next_event(&camera[..t], pos, rng, sink, counters);
                }
                for s in bdpt.allowed_light_lengths(t, light.len()).filter(|&s| s >= 2) {
                    conn.connect(&light[..s], &camera[..t], 1.0, pos, rng, sink, counters);
                }
            }
            let merged = self.merge(conn, pass, &camera[..t], sink);
            found.0 += u64::from(merged.is_some());
            found.1 += merged.unwrap_or(0);
        }
    }

    /// The merges of camera vertex `z_{t-1}` (the last of `camera`) with the light vertices
    /// within the radius; how many it found, `None` when it does not merge.
    fn merge(
        &self,
        conn: &Connector<VcmCounts>,
        pass: &VcmPass,
        camera: &[Vertex],
        sink: &mut impl Sink,
    ) -> Option<u64> {
        let (scene, bdpt) = (conn.scene, &self.base.bdpt);
        let t = camera.len();
        let z = &camera[t - 1];
        if z.kind != VertexKind::Surface || !z.is_connectible() {
            return None;
        }
        let bsdf = z.bsdf(scene);
        let norm = 1.0 / (pass.pool.paths as f32 * std::f32::consts::PI * pass.radius * pass.radius);
        let mut n = 0;
        pass.grid.query(z.p, |g, _| {
            let g = g as usize;
            let light = &pass.pool.vertices[pass.pool.path_start[g] as usize..=g];
            let i = light.len() - 1;
            if !bdpt.allowed(i, t) {
                return;
            }
            n += 1;
            let y = &light[i];
            let (lo, li) = bsdf.to_local(&z.frame, z.wo, y.wo);
            let f = bsdf.eval(lo, li, z.at(), TransportMode::Radiance);
            let c = z.beta * f * y.beta * norm;
            if c == Rgb::ZERO {
                return;
            }
            let w = if i + t <= SHORT {
                merge_weight::<SHORT>(scene, light, camera, conn.heuristic, conn.counts)
            } else {
                merge_weight::<CAP>(scene, light, camera, conn.heuristic, conn.counts)
            };
            sink.add(i, t, c * w);
        });
        Some(n)
    }
}

/// The index of the pixel at film position `pos`, row after row.
#[inline]
fn pixel_index(scene: &Scene, pos: Vec2) -> usize {
    let (w, h) = (scene.film.width, scene.film.height);
    let x = (pos.x.max(0.0) as u32).min(w - 1);
    let y = (pos.y.max(0.0) as u32).min(h - 1);
    (y * w + x) as usize
}

/// Renders with VCM (`connections`) or BPM.
fn render(
    scene: &Scene,
    run: &RunOptions,
    options: &VcmOptions,
    connections: bool,
    iterations: Iterations,
) -> Rendered {
    options.check()?;
    let pixels = scene.film.width as usize * scene.film.height as usize;
    let base = PoolBase::new(Bdpt::for_scene(scene, false), options.heuristic, options.max_pool_mb, pixels);
    let method = VcmRender { base, options: options.clone(), connections, stats: VcmStats::default() };
    crate::integrator::render_loop::run(scene, run, method, true, iterations)
}

impl Integrator for VcmOptions {
    const BIDIRECTIONAL: bool = true;
    const MEDIA: bool = true;

    fn render(&self, scene: &Scene, run: &RunOptions, iterations: Iterations) -> Rendered {
        render(scene, run, self, true, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
        Some(&mut self.heuristic)
    }
}

/// Merging alone cannot render the light a medium scatters from a point light (a medium
/// vertex does not merge): BPM refuses media.
impl Integrator for BpmOptions {
    const BIDIRECTIONAL: bool = true;

    fn render(&self, scene: &Scene, run: &RunOptions, iterations: Iterations) -> Rendered {
        render(scene, run, &self.vcm, false, iterations)
    }

    fn heuristic_mut(&mut self) -> Option<&mut Heuristic> {
        Some(&mut self.vcm.heuristic)
    }
}
