//! The random walks of the bidirectional core: camera and light subpaths built vertex by
//! vertex (BSDF and phase-function sampling, free flights through media, null surfaces
//! crossed, Russian roulette), each vertex with its forward density and its predecessor's
//! reverse one, and the shadow rays of connections (their transmittance through media).

use crate::accel::Ray;
use crate::bsdf::TransportMode;
use crate::integrator::bidir::guide::Guide;
use crate::integrator::bidir::{MAX_VERTICES, Vertex, disk_pdf, shading_correction};
use crate::integrator::stats::Counters;
use crate::math::{Rgb, max_component, offset_origin};
use crate::sampling::Random;
use crate::scene::Scene;
use crate::scene::shape::SurfaceInteraction;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// How walks are made: how long they may be, when Russian roulette starts, and the guide
/// that camera walks follow, if any.
#[derive(Clone)]
pub struct WalkLimits {
    /// Most vertices of a camera subpath (camera included).
    pub camera_vertices: usize,
    /// Most vertices of a light subpath (emitter included).
    pub light_vertices: usize,
    /// Bounces after which Russian roulette may end a walk.
    pub rr_depth: u32,
    /// Where camera walks sample their directions ([`Guide`]; `None`: the BSDFs). Both
    /// walks write the camera side's densities as the guide's.
    pub guide: Option<Arc<dyn Guide>>,
}

impl std::fmt::Debug for WalkLimits {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WalkLimits")
            .field("camera_vertices", &self.camera_vertices)
            .field("light_vertices", &self.light_vertices)
            .field("rr_depth", &self.rr_depth)
            .field("guided", &self.guide.is_some())
            .finish()
    }
}

impl WalkLimits {
    /// Mitsuba's `max_depth` counts segments from the camera (`u32::MAX` = unlimited): a
    /// camera subpath has at most `max_depth + 1` vertices, a light subpath `max_depth`.
    pub fn new(max_depth: u32, rr_depth: u32) -> WalkLimits {
        let m = (max_depth as usize).min(MAX_VERTICES);
        WalkLimits { camera_vertices: (m + 1).min(MAX_VERTICES), light_vertices: m, rr_depth, guide: None }
    }

    /// The guide camera walks follow, if any.
    #[inline]
    pub fn guide(&self) -> Option<&dyn Guide> {
        self.guide.as_deref()
    }
}

/// A walk under way: the ray it traces next, the throughput it carries, and what its
/// Russian roulette and medium tracking keep between steps. [`random_walk`] traces its rays
/// one at a time; a wavefront asks for many walks' rays in one batch query and hands each
/// walk what its ray found ([`Walk::step`]).
#[derive(Clone, Debug)]
pub(crate) struct Walk {
    /// The ray the walk follows next.
    pub ray: Ray,
    beta: Rgb,
    /// Throughput of the scattering alone (what Russian roulette looks at).
    rr_beta: Rgb,
    bounces: u32,
    /// The medium the ray travels in, and the null surfaces it crossed.
    medium: Option<u32>,
    crossings: usize,
    mode: TransportMode,
    max_vertices: usize,
}

impl Walk {
    /// A walk leaving the last vertex of `path` along `ray` with throughput `beta`, to grow
    /// `path` to at most `max_vertices` vertices.
    fn new(scene: &Scene, ray: Ray, beta: Rgb, mode: TransportMode, max_vertices: usize, path: &[Vertex]) -> Walk {
        let medium = path[path.len() - 1].medium_towards(scene, ray.d);
        Walk { ray, beta, rr_beta: Rgb::ONE, bounces: 0, medium, crossings: 0, mode, max_vertices }
    }

    /// One step of the walk, given what its ray found (`hit`, the surface point or
    /// nothing): a vertex pushed onto `path` (a surface or, in a medium, a scattering event)
    /// unless a null surface was crossed, and the next ray sampled. `true` when the walk goes
    /// on along [`Walk::ray`]; `path` then has room for another vertex.
    ///
    /// The densities and each vertex's direction back (`wo`) are taken from the vertex
    /// positions, not from the ray that found the vertex: a ray leaves an offset origin, and
    /// where a segment is not much longer than that offset (in corners) the sampled
    /// direction and the direction between the two points differ. Every strategy of a path
    /// must see the same densities of the same points for the MIS weights to sum to one; the
    /// connections and the other strategies evaluate them from positions.
    ///
    /// With a guide in `limits`, every surface vertex keeps its cell, a camera walk samples
    /// from the guide where it guides, and the camera side's densities are the guide's.
    #[inline]
    pub fn step<R: Random>(
        &mut self,
        scene: &Scene,
        hit: Option<SurfaceInteraction>,
        limits: &WalkLimits,
        rng: &mut R,
        path: &mut Vec<Vertex>,
    ) -> bool {
        let (rr_depth, guide, mode) = (limits.rr_depth, limits.guide(), self.mode);
        let guided = guide.map(|g| (g, mode));
        let ray = self.ray;
        if let Some(m) = self.medium {
            let len = ray.d.length();
            let t_max = hit.as_ref().map_or(f32::INFINITY, |si| si.t * len);
            let flight = scene.media[m as usize].sample(ray.o, ray.d / len, t_max, rng);
            self.beta *= flight.weight;
            self.rr_beta *= flight.weight;
            if self.beta == Rgb::ZERO || !self.beta.is_finite() {
                return false;
            }
            if flight.scattered {
                let p = ray.o + ray.d * (flight.t / len);
                let Some(wi) = scatter_in_medium(scene, p, m, &ray, self.beta, self.max_vertices, guided, rng, path)
                else {
                    return false;
                };
                if !self.roulette(rr_depth, rng) {
                    return false;
                }
                self.ray = Ray::new(p, wi);
                return true;
            }
        }
        let Some(mut si) = hit else {
            // A camera walk that leaves the scene ends on the lights at infinity.
            if mode == TransportMode::Radiance && !scene.infinite_lights.is_empty() {
                let n = path.len();
                let prev = &path[n - 1];
                let mut v = Vertex::sky(scene, prev.p, ray.d, self.beta);
                if !prev.delta {
                    let (fwd, rev) = prev.densities_with(scene, &v, ray.d, 1.0, guided);
                    v.pdf_fwd = fwd;
                    if n >= 2 {
                        path[n - 2].pdf_rev = rev;
                    }
                }
                path.push(v);
            }
            return false;
        };
        let bsdf_index = scene.bsdf_index(&si);
        let bsdf = &scene.bsdfs[bsdf_index];
        if bsdf.is_null() {
            // A boundary between media: on into the medium behind it, no vertex.
            self.crossings += 1;
            if self.crossings > crate::scene::MAX_NULL_CROSSINGS {
                return false;
            }
            self.medium = scene.medium_after(&si, ray.d, self.medium);
            self.ray = si.spawn_ray(ray.d);
            return true;
        }
        let n = path.len();
        let prev = &path[n - 1];
        let back = prev.p - si.p;
        let dist = back.length();
        if dist == 0.0 || !dist.is_finite() {
            return false;
        }
        // Towards a light at infinity the direction is the light's, exactly. After a Dirac
        // delta (a mirror, glass) it is the ray's: no density of that step enters a weight, and
        // the direction between the two points can be far from the ray's on the short
        // segments inside thin glass, where it would bend what the glass shows.
        si.wo = if n == 1 && prev.at_infinity() {
            prev.ng
        } else if prev.delta {
            -ray.d.normalize()
        } else {
            back / dist
        };
        let mut v = Vertex::surface(&si, bsdf_index as u32, self.beta, !bsdf.is_delta());
        v.medium = self.medium;
        if let Some(g) = guide {
            v.cell = g.cell(v.p);
        }
        // After a light at infinity the density towards it stays a solid-angle density.
        v.to_prev = if n == 1 && prev.at_infinity() { 1.0 } else { prev.cos_area(si.wo) / (dist * dist) };
        // A vertex left through a delta lobe has no density (zero marks the delta).
        if !prev.delta {
            let (fwd, rev) = prev.densities_with(scene, &v, -si.wo, dist, guided);
            v.pdf_fwd = fwd;
            if n >= 2 {
                path[n - 2].pdf_rev = rev;
            }
        }
        path.push(v);
        if path.len() >= self.max_vertices {
            return false;
        }
        let wo = si.shading.to_local(si.wo);
        let sample = match guide {
            Some(g) if mode == TransportMode::Radiance && g.guides(&v, bsdf) => {
                let u = rng.next_1d();
                let (u2, u3) = (rng.next_2d(), rng.next_2d());
                g.sample(&v, bsdf, wo, u, u2, u3)
            }
            _ => {
                let u1 = rng.next_1d();
                let u2 = rng.next_2d();
                bsdf.sample(wo, si.at(), u1, u2, mode)
            }
        };
        let Some(bs) = sample else { return false };
        let wi = si.shading.to_world(bs.wi);
        let mut weight = bs.weight;
        if mode == TransportMode::Importance {
            weight *= shading_correction(si.ng, si.shading.n, si.wo, wi);
        }
        if bs.delta {
            let n = path.len();
            path[n - 1].delta = true;
        }
        self.beta *= weight;
        self.rr_beta *= weight;
        if self.beta == Rgb::ZERO || !self.beta.is_finite() {
            return false;
        }
        if !self.roulette(rr_depth, rng) {
            return false;
        }
        self.medium = scene.medium_after(&si, wi, self.medium);
        self.ray = si.spawn_ray(wi);
        true
    }

    /// Counts a bounce and plays Russian roulette from `rr_depth` bounces on, on the
    /// throughput of the scattering alone: `false` when the walk ends.
    #[inline]
    fn roulette<R: Random>(&mut self, rr_depth: u32, rng: &mut R) -> bool {
        self.bounces += 1;
        if self.bounces >= rr_depth {
            let q = max_component(self.rr_beta).min(0.95);
            if rng.next_1d() >= q {
                return false;
            }
            self.beta /= q;
            self.rr_beta /= q;
        }
        true
    }
}

/// Runs `walk` to its end, its rays traced one at a time, each counted as an extension ray.
fn random_walk<R: Random>(
    scene: &Scene,
    mut walk: Walk,
    limits: &WalkLimits,
    rng: &mut R,
    path: &mut Vec<Vertex>,
    counters: &mut Counters,
) {
    while path.len() < walk.max_vertices {
        counters.extension_rays += 1;
        let hit = scene.intersect(&walk.ray);
        if !walk.step(scene, hit, limits, rng, path) {
            break;
        }
    }
}

/// A walk's scattering event at `p` in medium `m` (the ray `ray` led there): pushes the
/// medium vertex with its densities, as [`random_walk`] does for surfaces, and samples the
/// direction the walk leaves along (`None` when the walk is full); `guided` as in
/// [`Vertex::densities_with`].
#[allow(clippy::too_many_arguments)]
fn scatter_in_medium<R: Random>(
    scene: &Scene,
    p: Vec3,
    m: u32,
    ray: &Ray,
    beta: Rgb,
    max_vertices: usize,
    guided: Option<(&dyn Guide, TransportMode)>,
    rng: &mut R,
    path: &mut Vec<Vertex>,
) -> Option<Vec3> {
    let n = path.len();
    let prev = &path[n - 1];
    let back = prev.p - p;
    let dist = back.length();
    if dist == 0.0 || !dist.is_finite() {
        return None;
    }
    let from_infinity = n == 1 && prev.at_infinity();
    let wo = if from_infinity {
        prev.ng
    } else if prev.delta {
        -ray.d.normalize()
    } else {
        back / dist
    };
    let mut v = Vertex::in_medium(p, wo, m, beta);
    v.to_prev = if from_infinity { 1.0 } else { prev.cos_area(wo) / (dist * dist) };
    if !prev.delta {
        let (fwd, rev) = prev.densities_with(scene, &v, -wo, dist, guided);
        v.pdf_fwd = fwd;
        if n >= 2 {
            path[n - 2].pdf_rev = rev;
        }
    }
    path.push(v);
    if path.len() >= max_vertices {
        return None;
    }
    // The phase function is sampled exactly: the throughput is unchanged.
    Some(scene.media[m as usize].phase.sample(wo, rng.next_2d()).0)
}

/// Traces a camera subpath through film position `pos` (pixel units) into `path`.
pub fn camera_subpath<R: Random>(
    scene: &Scene,
    pos: Vec2,
    limits: &WalkLimits,
    rng: &mut R,
    path: &mut Vec<Vertex>,
    counters: &mut Counters,
) {
    let Some(walk) = camera_start(scene, pos, limits, path) else { return };
    // The walk's first ray is the camera ray.
    counters.camera_path(|c| random_walk(scene, walk, limits, rng, path, c));
}

/// The start of a camera subpath through film position `pos`: `path` cleared to the camera
/// vertex, and the walk from it along the camera ray (`None` when the subpath has no room
/// for another vertex).
pub(crate) fn camera_start(scene: &Scene, pos: Vec2, limits: &WalkLimits, path: &mut Vec<Vertex>) -> Option<Walk> {
    path.clear();
    let ray = scene.camera.generate_ray(pos);
    path.push(Vertex { medium: scene.camera_medium, ..Vertex::camera(ray.o) });
    (limits.camera_vertices > 1)
        .then(|| Walk::new(scene, ray, Rgb::ONE, TransportMode::Radiance, limits.camera_vertices, path))
}

/// Traces a light subpath into `path`: a light chosen by power, a point and direction of
/// emission, then BSDF sampling in importance mode.
pub fn light_subpath<R: Random>(
    scene: &Scene,
    limits: &WalkLimits,
    rng: &mut R,
    path: &mut Vec<Vertex>,
    counters: &mut Counters,
) {
    if let Some(walk) = light_start(scene, limits, rng, path) {
        random_walk(scene, walk, limits, rng, path, counters);
    }
}

/// The start of a light subpath: `path` cleared to the vertex on the light (or nothing,
/// when no light emits), and the walk from it (`None` when the subpath ends there).
pub(crate) fn light_start<R: Random>(
    scene: &Scene,
    limits: &WalkLimits,
    rng: &mut R,
    path: &mut Vec<Vertex>,
) -> Option<Walk> {
    path.clear();
    let u_light = rng.next_1d();
    let u1 = rng.next_1d();
    let u_pos = rng.next_2d();
    let u_dir = rng.next_2d();
    if limits.light_vertices == 0 {
        return None;
    }
    let (l, pmf, _) = scene.light_sampler.sample(u_light)?;
    let light = &scene.lights[l];
    // The first vertex, the ray the walk leaves it along, and the throughput it carries.
    let (y0, ray, beta) = if light.at_infinity() {
        infinite_light_start(scene, l, pmf, u_pos, u_dir)?
    } else {
        let es = light.sample_emission(&scene.shapes, u1, u_pos, u_dir)?;
        let origin = pmf * es.pdf_pos;
        if origin <= 0.0 || es.pdf_dir <= 0.0 {
            return None;
        }
        let y0 = Vertex::light(l, es.p, es.n, es.uv, Rgb::splat(1.0 / origin), origin);
        // What `y0.end(scene, es.d, ..).f` gives, without its direction density.
        let le = light.emitted(es.n, es.uv, es.d) * y0.cos_area(es.d);
        let o = if es.n == Vec3::ZERO { es.p } else { offset_origin(es.p, es.n, es.d) };
        (y0, Ray::new(o, es.d), le / (origin * es.pdf_dir))
    };
    let mut y0 = y0;
    let mut beta = beta;
    if scene.volumetric {
        y0.medium = light_medium(scene, l, &y0, ray.d);
        // Light from infinity crosses all of a medium that nothing bounds.
        if let (true, Some(m)) = (y0.infinite, y0.medium) {
            beta *= scene.media[m as usize].transmittance(ray.o, -ray.d.normalize(), f32::INFINITY);
        }
    }
    path.push(y0);
    if limits.light_vertices <= 1 || beta == Rgb::ZERO || !beta.is_finite() {
        return None;
    }
    Some(Walk::new(scene, ray, beta, TransportMode::Importance, limits.light_vertices, path))
}

/// The medium light leaving light `l` at its vertex `y0` in direction `d` travels in: the
/// side of its shape's medium boundary that `d` leaves to, or the medium at its position.
pub fn light_medium(scene: &Scene, l: usize, y0: &Vertex, d: Vec3) -> Option<u32> {
    if let crate::light::Light::Area { shape, .. } = &scene.lights[l]
        && let Some(m) = scene.shapes[*shape].media
    {
        return m.towards(y0.ng, d);
    }
    let p = if y0.ng == Vec3::ZERO { y0.p } else { offset_origin(y0.p, y0.ng, d) };
    scene.medium_at(p)
}

/// The start of a light subpath from light `l` at infinity (chosen with probability `pmf`):
/// a direction from the light's distribution and a point on the disk of the bounding sphere
/// facing it; the vertex (its density in the measures of [`Vertex`]), the ray into the
/// scene and the throughput.
fn infinite_light_start(scene: &Scene, l: usize, pmf: f32, u_pos: Vec2, u_dir: Vec2) -> Option<(Vertex, Ray, Rgb)> {
    let (wi, pdf_dir, li) = scene.lights[l].sample_infinite_direction(u_dir)?;
    let p = crate::light::disk_point(&scene.bounds, wi, u_pos);
    let beta = li / (pmf * pdf_dir * disk_pdf(scene));
    let mut y0 = Vertex::light(l, p, wi, Vec2::ZERO, beta, 0.0);
    y0.infinite = true;
    y0.connectible = false;
    y0.pdf_fwd = y0.pdf_light_origin(scene);
    Some((y0, Ray::new(p, -wi), beta))
}

/// A shadow ray between two vertices, offset at both ends along their geometric normals.
#[inline]
pub fn visible(scene: &Scene, a: &Vertex, b: &Vertex, counters: &mut Counters) -> bool {
    transmittance(scene, a, b, counters) != Rgb::ZERO
}

/// The fraction of light that travels between the light-side vertex `a` and the
/// camera-side vertex `b` of a connection: zero when something blocks the segment, else the
/// transmittance of the media along it ([`Scene::transmittance`]). The segment is traced
/// from the end whose medium its walk knows: `b`, unless `b` lies at infinity.
#[inline(always)]
pub fn transmittance(scene: &Scene, a: &Vertex, b: &Vertex, counters: &mut Counters) -> Rgb {
    counters.shadow_rays += 1;
    if !scene.volumetric {
        // Without media a plain occlusion query, inlined where connections are made.
        return if scene.occluded(&shadow_segment(a, b).0) { Rgb::ZERO } else { Rgb::ONE };
    }
    transmittance_in_media(scene, a, b)
}

/// [`transmittance`] in a scene with media or null surfaces.
#[inline(never)]
fn transmittance_in_media(scene: &Scene, a: &Vertex, b: &Vertex) -> Rgb {
    let (a, b) = if !b.infinite { (b, a) } else { (a, b) };
    let (segment, from, to) = shadow_segment(a, b);
    scene.transmittance_to(&segment, from.medium_towards(scene, to.p - from.p), to.infinite)
}

/// The shadow ray between `a` and `b`, from the finite one when the other lies at infinity,
/// with the vertices it starts from and ends at.
#[inline(always)]
pub(crate) fn shadow_segment<'v>(a: &'v Vertex, b: &'v Vertex) -> (Ray, &'v Vertex, &'v Vertex) {
    // The segment stops `SHADOW_EPSILON` of its length short of its far end. A vertex at
    // infinity is a point beyond the scene, some scene diameters away: the ray starts at the
    // finite vertex, so that margin lies outside the scene rather than in front of the
    // surface (from the far point it left centimetres before the surface untested, and
    // light leaked past the edges of whatever stood there).
    let (a, b) = if a.infinite && !b.infinite { (b, a) } else { (a, b) };
    let d = b.p - a.p;
    let o = if a.ng == Vec3::ZERO { a.p } else { offset_origin(a.p, a.ng, d) };
    let e = if b.ng == Vec3::ZERO { b.p } else { offset_origin(b.p, b.ng, -d) };
    (Ray::segment(o, e - o, 1.0 - crate::math::SHADOW_EPSILON), a, b)
}
