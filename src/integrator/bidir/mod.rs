//! The bidirectional core shared by light tracing, BDPT, EORR, light-vertex-cache BDPT,
//! PCBPT, SPCBPT and the Metropolis integrators: path vertices with area-measure densities,
//! one random walk for both subpaths and the connections' shadow rays ([`walk`]), camera
//! walks that follow a guide ([`guide`]), the connection terms, and MIS weights by the ratio
//! walk ([`mis`]).
//!
//! Notation follows pbrt-v4 and the contract: light vertices `y_0..y_{s-1}` (`y_0` on an
//! emitter), camera vertices `z_0..z_{t-1}` (`z_0` the pinhole); strategy `(s,t)` joins
//! `y_{s-1}` and `z_{t-1}`. `pdf_fwd` is the area density with which a vertex was generated
//! by its own walk, `pdf_rev` the density had it been generated from the other end.

pub mod bdpt;
pub mod guide;
pub mod mis;
pub mod pool;
pub mod walk;
pub mod wavefront;

use crate::bsdf::TransportMode;
use crate::integrator::bidir::guide::Guide;
use crate::integrator::render_loop::PixelSink;
use crate::math::{Frame, Rgb};
use crate::scene::Scene;
use crate::scene::shape::SurfaceInteraction;
use glam::{Vec2, Vec3};

/// Longest subpath (in vertices) a walk builds, also with unlimited `max_depth`. Russian
/// roulette ends paths long before: a path of 48 bounces carries a negligible share.
pub const MAX_VERTICES: usize = 48;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VertexKind {
    /// The pinhole `z_0`.
    Camera,
    /// A point on an emitter that starts a light subpath (or was sampled for NEE).
    Light(u32),
    /// A surface point reached by a walk.
    Surface,
    /// Where a camera walk leaves the scene: every light at infinity (`constant`, `envmap`)
    /// seen in one direction.
    Sky,
    /// A scattering event in a participating medium ([`Vertex::medium`] says which): a
    /// point-like vertex (no normal, so no cosine in its area — here volume — densities)
    /// that scatters by the medium's phase function.
    Medium,
}

/// A path vertex.
///
/// Vertices at infinity (a light subpath's start on a `directional`, `constant` or `envmap`
/// light, a light sampled at infinity by next-event estimation, and [`VertexKind::Sky`]) keep
/// in `ng` the unit direction from the scene towards the light, and in `p` a point outside
/// the scene in that direction (the start of a light subpath's ray on the disk facing it).
/// Densities of generating a vertex at infinity are solid-angle densities, and the density of
/// the vertex a light at infinity generates is `|cos| / (π R²)` (a point on the disk of the
/// bounding sphere's radius `R`, then along the direction): pbrt-v4's measures.
#[derive(Clone, Copy, Debug)]
pub struct Vertex {
    pub kind: VertexKind,
    pub p: Vec3,
    /// Geometric normal (zero for point lights and the pinhole).
    pub ng: Vec3,
    /// Shading frame of a surface vertex (endpoints, which scatter nothing, keep the world
    /// axes).
    pub frame: Frame,
    pub uv: Vec2,
    /// The unperturbed shading normal in `frame` (see [`SurfaceInteraction::base_n`]).
    pub base_n: Vec3,
    /// Unit direction towards the previous vertex of its own walk (zero for endpoints).
    pub wo: Vec3,
    pub shape: u32,
    /// The BSDF of a surface vertex (an index into `scene.bsdfs`; `u32::MAX` for endpoints).
    pub bsdf: u32,
    /// Throughput of the subpath up to and including this vertex (over its densities).
    pub beta: Rgb,
    /// The medium the walk reached this vertex through (a medium vertex's own; the camera's
    /// for the pinhole; where the light is for a light vertex); `None` is vacuum.
    pub medium: Option<u32>,
    pub pdf_fwd: f32,
    pub pdf_rev: f32,
    /// Converts this vertex's solid-angle density towards its predecessor (in its own walk)
    /// into an area density there: the predecessor's `|cos|` towards this vertex over their
    /// squared distance (zero for endpoints, which have none).
    pub to_prev: f32,
    /// The walk left this vertex through a Dirac delta lobe.
    pub delta: bool,
    /// A deterministic connection can end here (not a purely specular surface).
    pub connectible: bool,
    /// The shading normal is the geometric normal (no shading-normal correction).
    pub flat: bool,
    /// The vertex lies at infinity (see above).
    pub infinite: bool,
    /// An integrator's label of the vertex, opaque to the core: a cache of a function of the
    /// vertex's position and shading normal that a [`pool::PoolSelection::label`] wrote and
    /// that the integrator's strategy counts read instead of recomputing it; `None` where
    /// none was written.
    pub label: Option<[u16; 4]>,
    /// The cell of the walk's [`guide::Guide`] holding a surface vertex (`u32::MAX` where
    /// the walk had no guide).
    pub cell: u32,
}

impl Vertex {
    pub fn camera(p: Vec3) -> Vertex {
        Vertex {
            kind: VertexKind::Camera,
            p,
            ng: Vec3::ZERO,
            frame: Frame::IDENTITY,
            uv: Vec2::ZERO,
            base_n: Vec3::Z,
            wo: Vec3::ZERO,
            shape: u32::MAX,
            bsdf: u32::MAX,
            beta: Rgb::ONE,
            medium: None,
            pdf_fwd: 1.0,
            pdf_rev: 0.0,
            to_prev: 0.0,
            delta: false,
            connectible: true,
            flat: true,
            infinite: false,
            label: None,
            cell: u32::MAX,
        }
    }

    pub fn light(light: usize, p: Vec3, n: Vec3, uv: Vec2, beta: Rgb, pdf_fwd: f32) -> Vertex {
        Vertex {
            kind: VertexKind::Light(light as u32),
            p,
            ng: n,
            frame: Frame::IDENTITY,
            uv,
            base_n: Vec3::Z,
            wo: Vec3::ZERO,
            shape: u32::MAX,
            bsdf: u32::MAX,
            beta,
            medium: None,
            pdf_fwd,
            pdf_rev: 0.0,
            to_prev: 0.0,
            delta: false,
            connectible: true,
            flat: true,
            infinite: false,
            label: None,
            cell: u32::MAX,
        }
    }

    /// The vertex where a camera walk leaves the scene at `p` in the unit direction `d`.
    pub fn sky(scene: &Scene, p: Vec3, d: Vec3, beta: Rgb) -> Vertex {
        let far = scene.bounds.beyond(p, d);
        Vertex {
            kind: VertexKind::Sky,
            connectible: false,
            infinite: true,
            ..Vertex::light(0, far, d, Vec2::ZERO, beta, 0.0)
        }
    }

    /// Whether the vertex lies at infinity (see [`Vertex`]).
    #[inline]
    pub fn at_infinity(&self) -> bool {
        self.infinite
    }

    /// Radiance (irradiance for a directional light) arriving from a vertex at infinity:
    /// for the sky and for any light at infinity that rays can hit, every such light seen in
    /// that direction (the strategies of one path must see one emitter).
    pub fn infinite_emission(&self, scene: &Scene) -> Rgb {
        if !self.infinite {
            return Rgb::ZERO;
        }
        match self.kind {
            VertexKind::Light(l)
                if let crate::light::Light::Directional { irradiance, .. } = &scene.lights[l as usize] =>
            {
                *irradiance
            }
            _ => scene.infinite_lights.iter().map(|&l| scene.lights[l].eval_infinite(self.ng)).sum(),
        }
    }

    /// A surface vertex with the BSDF `scene.bsdfs[bsdf]`; `connectible` is false for purely
    /// specular BSDFs.
    pub fn surface(si: &SurfaceInteraction, bsdf: u32, beta: Rgb, connectible: bool) -> Vertex {
        Vertex {
            kind: VertexKind::Surface,
            p: si.p,
            ng: si.ng,
            frame: si.shading,
            uv: si.uv,
            base_n: si.base_n,
            wo: si.wo,
            shape: si.shape,
            bsdf,
            beta,
            medium: None,
            pdf_fwd: 0.0,
            pdf_rev: 0.0,
            to_prev: 0.0,
            delta: false,
            connectible,
            flat: si.shading.n == si.ng,
            infinite: false,
            label: None,
            cell: u32::MAX,
        }
    }

    /// A scattering event at `p` in medium `medium`, reached from the direction `wo`.
    pub fn in_medium(p: Vec3, wo: Vec3, medium: u32, beta: Rgb) -> Vertex {
        Vertex {
            kind: VertexKind::Medium,
            wo,
            medium: Some(medium),
            connectible: true,
            ..Vertex::light(0, p, Vec3::ZERO, Vec2::ZERO, beta, 0.0)
        }
    }

    /// Whether the vertex scatters light (a surface or a medium vertex, not an endpoint).
    #[inline]
    pub fn scatters(&self) -> bool {
        matches!(self.kind, VertexKind::Surface | VertexKind::Medium)
    }

    /// The medium a ray leaving this vertex in direction `w` travels in: across a surface
    /// that bounds media, the one on `w`'s side; elsewhere the one the vertex was reached in.
    #[inline]
    pub fn medium_towards(&self, scene: &Scene, w: Vec3) -> Option<u32> {
        match self.kind {
            VertexKind::Surface => {
                scene.shapes[self.shape as usize].media.map_or(self.medium, |m| m.towards(self.ng, w))
            }
            _ => self.medium,
        }
    }

    /// The phase function of a medium vertex.
    #[inline]
    fn phase(&self, scene: &Scene) -> crate::medium::Phase {
        scene.media[self.medium.expect("a medium vertex has a medium") as usize].phase
    }

    /// Where the BSDF of a surface vertex is evaluated.
    #[inline]
    pub fn at(&self) -> crate::bsdf::At {
        crate::bsdf::At { uv: self.uv, base_n: self.base_n }
    }

    /// The BSDF of a surface vertex.
    #[inline]
    pub fn bsdf<'a>(&self, scene: &'a Scene) -> &'a crate::bsdf::Bsdf {
        &scene.bsdfs[self.bsdf as usize]
    }

    /// The emitter this vertex lies on: a light endpoint, or a surface of an area light.
    #[inline]
    pub fn light_index(&self, scene: &Scene) -> Option<usize> {
        match self.kind {
            VertexKind::Light(l) => Some(l as usize),
            VertexKind::Surface => scene.shapes[self.shape as usize].light,
            VertexKind::Camera | VertexKind::Sky | VertexKind::Medium => None,
        }
    }

    /// Whether a deterministic connection can end at this vertex (not a purely specular
    /// surface).
    #[inline]
    pub fn is_connectible(&self) -> bool {
        self.connectible
    }

    /// `|cos|` between the geometric normal and `w` for points on surfaces; 1 for point-like
    /// vertices. Converts solid-angle densities to area densities at this vertex.
    #[inline]
    pub fn cos_area(&self, w: Vec3) -> f32 {
        if self.ng == Vec3::ZERO { 1.0 } else { self.ng.dot(w).abs() }
    }

    /// What a connection needs from this vertex as one of its ends, towards the unit
    /// direction `w` of the other end: the BSDF (or emission) times the cosine at this vertex
    /// for light travelling between it and `w`, with the adjoint shading-normal correction in
    /// importance mode; the solid-angle density of generating the other end; and that of
    /// generating this vertex's own predecessor given the other end — one BSDF lookup for all
    /// three.
    #[inline(always)]
    pub fn end(&self, scene: &Scene, w: Vec3, mode: TransportMode) -> End {
        self.end_with(scene, w, mode, None)
    }

    /// [`Vertex::end`] where camera walks follow `guide`: the camera side's density at a
    /// surface vertex (generating the other end from a camera end, the predecessor from a
    /// light end) is the guide's.
    #[inline(always)]
    pub fn end_with(&self, scene: &Scene, w: Vec3, mode: TransportMode, guide: Option<&dyn Guide>) -> End {
        match self.kind {
            VertexKind::Surface => {
                let bsdf = self.bsdf(scene);
                let (lo, li) = bsdf.to_local(&self.frame, self.wo, w);
                let (f, mut pdf_fwd, mut pdf_rev) = bsdf.eval_pdfs(lo, li, self.at(), mode);
                let mut f = f * li.z.abs();
                if mode == TransportMode::Importance && !self.flat && f != Rgb::ZERO {
                    // `lo.z` and `li.z` are the cosines with the shading normal.
                    f *= shading_correction_cos(lo.z, w.dot(self.ng), self.wo.dot(self.ng), li.z);
                }
                if let Some(g) = guide {
                    match mode {
                        TransportMode::Radiance => pdf_fwd = g.pdf(self, bsdf, w, pdf_fwd),
                        TransportMode::Importance => pdf_rev = g.pdf(self, bsdf, self.wo, pdf_rev),
                    }
                }
                End { f, pdf_fwd, pdf_rev }
            }
            VertexKind::Light(l) => {
                let light = &scene.lights[l as usize];
                End {
                    f: light.emitted(self.ng, self.uv, w) * self.cos_area(w),
                    pdf_fwd: light.pdf_emission_direction(self.ng, w),
                    pdf_rev: 0.0,
                }
            }
            VertexKind::Camera => End { f: Rgb::ZERO, pdf_fwd: scene.camera.pdf_direction(w), pdf_rev: 0.0 },
            VertexKind::Sky => End { f: self.infinite_emission(scene), pdf_fwd: 0.0, pdf_rev: 0.0 },
            VertexKind::Medium => {
                // Phase functions are symmetric and sampled exactly: value and both densities.
                let p = self.phase(scene).eval(self.wo, w);
                End { f: Rgb::splat(p), pdf_fwd: p, pdf_rev: p }
            }
        }
    }

    /// The BSDF of a surface vertex times the shading cosine towards `wi`, for light
    /// travelling between the unit world directions `wo` (its own side) and `wi`, with the
    /// adjoint shading-normal correction in importance mode.
    #[inline]
    pub fn scatter(&self, scene: &Scene, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        if self.kind == VertexKind::Medium {
            return Rgb::splat(self.phase(scene).eval(wo, wi));
        }
        let (lo, li) = (self.frame.to_local(wo), self.frame.to_local(wi));
        self.scatter_local(self.bsdf(scene), wo, wi, lo, li, mode)
    }

    /// [`Vertex::scatter`] with `bsdf` looked up and the directions also given in the shading
    /// frame (`lo`, `li`), for callers that need them for densities too.
    #[inline]
    pub fn scatter_local(
        &self,
        bsdf: &crate::bsdf::Bsdf,
        wo: Vec3,
        wi: Vec3,
        lo: Vec3,
        li: Vec3,
        mode: TransportMode,
    ) -> Rgb {
        let mut f = bsdf.eval(lo, li, self.at(), mode) * li.z.abs();
        if mode == TransportMode::Importance {
            f *= shading_correction(self.ng, self.frame.n, wo, wi);
        }
        f
    }

    /// Area density at `next` of this vertex generating it, given the vertex `prev` before
    /// this one (surfaces need it for their BSDF; endpoints ignore it).
    pub fn pdf(&self, scene: &Scene, prev: Option<&Vertex>, next: &Vertex) -> f32 {
        self.pdf_with(scene, prev, next, None)
    }

    /// [`Vertex::pdf`] of the camera side when camera walks follow `guide` (at a surface
    /// vertex, the guide's density).
    pub fn pdf_with(&self, scene: &Scene, prev: Option<&Vertex>, next: &Vertex, guide: Option<&dyn Guide>) -> f32 {
        if self.at_infinity() {
            return self.pdf_light(scene, next);
        }
        let d = next.p - self.p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return 0.0;
        }
        let w = if next.at_infinity() { next.ng } else { d / dist2.sqrt() };
        let solid = match self.kind {
            VertexKind::Camera => scene.camera.pdf_direction(w),
            VertexKind::Light(l) => scene.lights[l as usize].pdf_emission_direction(self.ng, w),
            VertexKind::Sky => 0.0,
            VertexKind::Surface | VertexKind::Medium => {
                let Some(prev) = prev else { return 0.0 };
                let wo = if prev.at_infinity() { prev.ng } else { (prev.p - self.p).normalize_or_zero() };
                if self.kind == VertexKind::Medium {
                    return self.phase(scene).eval(wo, w)
                        * if next.at_infinity() { 1.0 } else { next.cos_area(-w) / dist2 };
                }
                let bsdf = self.bsdf(scene);
                let p = bsdf.pdf(self.frame.to_local(wo), self.frame.to_local(w), self.at(), TransportMode::Radiance);
                guide.map_or(p, |g| g.pdf(self, bsdf, w, p))
            }
        };
        if next.at_infinity() { solid } else { solid * next.cos_area(-w) / dist2 }
    }

    /// The densities of this vertex scattering between its predecessor and `next` (unit
    /// direction `w`, distance `dist`), in area measure: of generating `next`, and of
    /// generating the predecessor given `next` (zero for endpoints, which have no
    /// predecessor). One BSDF lookup for both; the values of two calls of [`Vertex::pdf`].
    #[inline(always)]
    pub fn densities(&self, scene: &Scene, next: &Vertex, w: Vec3, dist: f32) -> (f32, f32) {
        self.densities_with(scene, next, w, dist, None)
    }

    /// [`Vertex::densities`] in a walk whose camera side follows a guide: `Some((guide,
    /// mode))`, the walk's transport mode saying which of the two densities is the camera
    /// side's (the forward one in a camera walk, the reverse one in a light walk).
    #[inline(always)]
    pub fn densities_with(
        &self,
        scene: &Scene,
        next: &Vertex,
        w: Vec3,
        dist: f32,
        guide: Option<(&dyn Guide, TransportMode)>,
    ) -> (f32, f32) {
        let to_next = if next.infinite { 1.0 } else { next.cos_area(-w) / (dist * dist) };
        match self.kind {
            VertexKind::Camera => (scene.camera.pdf_direction(w) * to_next, 0.0),
            VertexKind::Light(_) if self.infinite => (self.pdf_light(scene, next), 0.0),
            VertexKind::Light(l) => (scene.lights[l as usize].pdf_emission_direction(self.ng, w) * to_next, 0.0),
            VertexKind::Sky => (0.0, 0.0),
            VertexKind::Medium => {
                let p = self.phase(scene).eval(self.wo, w);
                (p * to_next, p * self.to_prev)
            }
            VertexKind::Surface => {
                let bsdf = self.bsdf(scene);
                let (lo, li) = bsdf.to_local(&self.frame, self.wo, w);
                let (mut fwd, mut rev) = bsdf.pdf_pair(lo, li, self.at(), TransportMode::Radiance);
                match guide {
                    Some((g, TransportMode::Radiance)) => fwd = g.pdf(self, bsdf, w, fwd),
                    Some((g, TransportMode::Importance)) => rev = g.pdf(self, bsdf, self.wo, rev),
                    None => {}
                }
                (fwd * to_next, rev * self.to_prev)
            }
        }
    }

    /// Area density at `next` of this vertex, taken as a light, emitting towards it.
    pub fn pdf_light(&self, scene: &Scene, next: &Vertex) -> f32 {
        if self.at_infinity() {
            // A point on the disk facing the light, then along the light's direction.
            return next.cos_area(-self.ng) * disk_pdf(scene);
        }
        let Some(l) = self.light_index(scene) else { return 0.0 };
        let d = next.p - self.p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return 0.0;
        }
        let w = d / dist2.sqrt();
        scene.lights[l].pdf_emission_direction(self.ng, w) * next.cos_area(-w) / dist2
    }

    /// Density of a light subpath starting at this point: light choice times position. For
    /// a vertex at infinity, the density of its direction over every light at infinity
    /// ([`infinite_light_density`]; a directional light's, a delta, counts as its choice).
    pub fn pdf_light_origin(&self, scene: &Scene) -> f32 {
        match self.kind {
            VertexKind::Light(l) if self.infinite && scene.lights[l as usize].is_unreachable() => {
                scene.light_sampler.pmf(l as usize)
            }
            _ if self.infinite => infinite_light_density(scene, self.ng),
            _ => {
                let Some(l) = self.light_index(scene) else { return 0.0 };
                light_origin_pdf(scene, l)
            }
        }
    }
}

/// One end of a connection (see [`Vertex::end`]).
#[derive(Clone, Copy, Debug)]
pub struct End {
    pub f: Rgb,
    pub pdf_fwd: f32,
    pub pdf_rev: f32,
}

/// A connection between `y_{s-1}` and `z_{t-1}`: the unit direction from the light end to
/// the camera end, the squared distance and its reciprocal, and both ends' terms.
#[derive(Clone, Copy, Debug)]
pub struct Connection {
    pub w: Vec3,
    pub dist2: f32,
    pub inv_dist2: f32,
    pub light_end: End,
    pub camera_end: End,
}

impl Connection {
    /// Evaluates the connection of two vertices (`None` when they coincide).
    #[inline]
    pub fn new(scene: &Scene, qs: &Vertex, pt: &Vertex) -> Option<Connection> {
        Connection::evaluate(scene, qs, pt, false, None)
    }

    /// [`Connection::new`] for a connection that is only wanted if it carries light: `None`
    /// also when an end's BSDF (or emission) value is zero, found before the other end is
    /// evaluated. Where camera walks follow `guide`, the ends' camera-side densities are its
    /// ([`Vertex::end_with`]).
    #[inline]
    pub fn carrying(scene: &Scene, qs: &Vertex, pt: &Vertex, guide: Option<&dyn Guide>) -> Option<Connection> {
        Connection::evaluate(scene, qs, pt, true, guide)
    }

    #[inline(always)]
    fn evaluate(
        scene: &Scene,
        qs: &Vertex,
        pt: &Vertex,
        nonzero: bool,
        guide: Option<&dyn Guide>,
    ) -> Option<Connection> {
        if qs.infinite {
            // From a light at infinity, along its direction, with no distance term: the
            // density of `pt` is that of a point on the disk facing the light.
            let w = -qs.ng;
            let light_end = End { f: qs.infinite_emission(scene), pdf_fwd: disk_pdf(scene), pdf_rev: 0.0 };
            if nonzero && light_end.f == Rgb::ZERO {
                return None;
            }
            let camera_end = pt.end_with(scene, -w, TransportMode::Radiance, guide);
            return Some(Connection { w, dist2: 1.0, inv_dist2: 1.0, light_end, camera_end });
        }
        let d = pt.p - qs.p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 || !dist2.is_finite() {
            return None;
        }
        let w = d / dist2.sqrt();
        let light_end = qs.end_with(scene, w, TransportMode::Importance, guide);
        if nonzero && light_end.f == Rgb::ZERO {
            return None;
        }
        let camera_end = pt.end_with(scene, -w, TransportMode::Radiance, guide);
        Some(Connection { w, dist2, inv_dist2: 1.0 / dist2, light_end, camera_end })
    }
}

/// Density of the direction `wi` (towards the light) over the lights at infinity that rays
/// can hit, each chosen with its light-selection probability: how a light subpath, next-event
/// estimation, or (as the density of its far end) an escaped camera ray sees the sky.
pub fn infinite_light_density(scene: &Scene, wi: Vec3) -> f32 {
    scene.infinite_lights.iter().map(|&l| scene.light_sampler.pmf(l) * scene.lights[l].pdf_infinite(wi)).sum()
}

/// `1 / (π R²)`: the density of a point on the disk a light at infinity starts its paths on.
#[inline]
pub fn disk_pdf(scene: &Scene) -> f32 {
    let r = scene.bounds.radius;
    1.0 / (std::f32::consts::PI * r * r)
}

/// Light-selection probability times the area density of the start point.
#[inline]
pub fn light_origin_pdf(scene: &Scene, light: usize) -> f32 {
    let pos = match &scene.lights[light] {
        crate::light::Light::Area { shape, .. } => 1.0 / scene.shapes[*shape].area(),
        _ => 1.0,
    };
    scene.light_sampler.pmf(light) * pos
}

/// Ratio of the area density with which next-event estimation from `from` produces the
/// light point `x0` to the density of a light subpath starting there. Both choose the light
/// by power; they differ where NEE samples the cone a sphere subtends instead of its area.
pub fn nee_ratio(scene: &Scene, x0: &Vertex, from: Vec3) -> f32 {
    if !scene.light_sampler.any_sphere_light() {
        return 1.0;
    }
    let Some(l) = x0.light_index(scene) else { return 1.0 };
    match &scene.lights[l] {
        crate::light::Light::Area { shape, .. } => {
            let s = &scene.shapes[*shape];
            // Meshes are sampled by area both ways: the ratio is exactly one.
            if !matches!(s.geometry, crate::scene::shape::ShapeGeometry::Sphere { .. }) {
                return 1.0;
            }
            let d = x0.p - from;
            let dist2 = d.length_squared();
            if dist2 == 0.0 {
                return 1.0;
            }
            let solid = s.pdf_direction(from, x0.p, x0.ng);
            let r = solid * x0.cos_area(d / dist2.sqrt()) / dist2 * s.area();
            if r.is_finite() && r > 0.0 { r } else { 1.0 }
        }
        _ => 1.0,
    }
}

/// The factor that makes BSDF sampling with shading normals adjoint in importance mode
/// (Veach 1997, §5.3): `|wo·ns| |wi·ng| / (|wo·ng| |wi·ns|)`.
#[inline]
pub fn shading_correction(ng: Vec3, ns: Vec3, wo: Vec3, wi: Vec3) -> f32 {
    shading_correction_cos(wo.dot(ns), wi.dot(ng), wo.dot(ng), wi.dot(ns))
}

/// [`shading_correction`] from the four cosines `wo·ns`, `wi·ng`, `wo·ng`, `wi·ns`.
#[inline]
pub fn shading_correction_cos(wo_ns: f32, wi_ng: f32, wo_ng: f32, wi_ns: f32) -> f32 {
    let num = wo_ns.abs() * wi_ng.abs();
    let den = wo_ng.abs() * wi_ns.abs();
    if den == 0.0 { 0.0 } else { num / den }
}

/// Where a strategy's contribution goes: onto the pixel being sampled (`add`) or, for
/// `t = 1`, splatted at a film position (`splat`).
pub trait Sink {
    fn add(&mut self, s: usize, t: usize, value: Rgb);
    fn splat(&mut self, s: usize, t: usize, pos: Vec2, value: Rgb);
    /// `s = 0`: the camera subpath `camera` ends on an emitter (by default
    /// `add(0, camera.len(), value)`; a sink that sorts paths by their vertices looks at them).
    #[inline]
    fn add_emission(&mut self, camera: &[Vertex], value: Rgb) {
        self.add(0, camera.len(), value);
    }
    /// `s, t >= 2`: the connection of `light` and `camera`, its unweighted contribution `c`
    /// and MIS weight `w` (by default `add(s, t, c * w)`; a sink that learns from the
    /// connections looks at them).
    #[inline]
    fn add_connection(&mut self, light: &[Vertex], camera: &[Vertex], c: Rgb, w: f32) {
        self.add(light.len(), camera.len(), c * w);
    }
    /// Whether the sink looks at the paths of the contributions it receives (an
    /// efficiency estimate does): each then comes through [`Sink::observe`] right before it.
    #[inline]
    fn observes(&self) -> bool {
        false
    }
    /// The path of the contribution delivered next, with what weighs it.
    #[inline]
    fn observe<C: mis::StrategyCounts>(&mut self, _delivery: &Delivery<'_, C>) {}
}

/// A camera sample's pixel in the render loop receives the strategies' contributions.
impl Sink for PixelSink<'_> {
    #[inline]
    fn add(&mut self, s: usize, t: usize, value: Rgb) {
        PixelSink::add(self, s, t, value)
    }

    #[inline]
    fn splat(&mut self, s: usize, t: usize, pos: Vec2, value: Rgb) {
        PixelSink::splat(self, s, t, pos, value)
    }
}

/// The path of a strategy about to be delivered to a sink, with what weighs it
/// ([`Sink::observe`]).
pub struct Delivery<'a, C> {
    pub scene: &'a Scene,
    pub light: &'a [Vertex],
    pub camera: &'a [Vertex],
    /// The connection's evaluation (`None` for `s = 0`, where the camera subpath ends on an
    /// emitter).
    pub conn: Option<&'a Connection>,
    /// The strategy counts of the weights.
    pub counts: &'a C,
    /// The contribution factor of a connection drawn from a pool (`1 / (N M P(y | z))`).
    pub drawn: Option<f32>,
}
