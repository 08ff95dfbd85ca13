//! Paths of path space, as Manifold Exploration's Markov chains hold them (contract
//! `memlt.md`, "The chain"): every vertex of one full path from a point on a light (`x_0`:
//! on an area light, or the position of a point or spot light) to the pinhole (`x_k`), its
//! measurement contribution `f(x)`, the area densities with which a walk from either end
//! generates each of its vertices, and the walks that regenerate a stretch of a path
//! between two kept ends.
//!
//! A point or spot light's position is a Dirac distribution: its paths' `f` and densities
//! take the position by its discrete probability (the light's, chosen by power), and no
//! walk from the camera can reach it (its camera-side density is zero).
//!
//! Light from infinity (`constant`, `envmap`, sky, sun, `directional`) arrives along a direction: such a
//! path's `x_0` is a vertex at infinity (`Vertex::infinite`) whose geometric normal is the
//! unit direction from `x_1` towards the light, and whose position is kept on that line,
//! beyond the scene ([`settle_sky`]), so that a shadow ray and the directions between
//! positions find it. In the measures of the bidirectional core (pbrt-v4's): its edge to
//! `x_1` has no distance and no cosine at `x_0` (`G = |cos θ_1|`), the light walk's density
//! of `x_0` is the solid-angle density of its direction over every light at infinity that
//! rays can hit, each chosen by power (the radiance it carries is theirs summed; a
//! directional light's direction is a Dirac one, taken by its light's probability as a point
//! light's position is), and that of `x_1` given
//! `x_0` is the disk's `1 / (π R²)` times `|cos θ_1|` ([`disk_pdf`]); a camera walk whose
//! last ray leaves the scene reaches it with the solid-angle density of that ray.
//!
//! A path scatters at a vertex either through a Dirac lobe (`Vertex::delta`: a mirror, glass,
//! a smooth coating's reflection) or through the rest of its BSDF. Both `f` and the densities
//! take a Dirac lobe by its coefficient and its discrete probability: the delta functions a
//! path's contribution and its densities share cancel in every ratio the chains use.
//!
//! Contributions are in the units of a pixel's value: the pinhole's factor is
//! `We cos θ = 1 / (A cos³θ)` (the density of its direction over the image), so the mean of
//! `f / p` over paths sampled through uniform film positions is the image's mean.

use crate::accel::Ray;
use crate::bsdf::{At, Bsdf, BsdfSample, TransportMode};
use crate::integrator::bidir::walk::visible;
use crate::integrator::bidir::{Vertex, VertexKind, disk_pdf, light_origin_pdf};
use crate::integrator::memlt::media::{self, Stop};
use crate::integrator::stats::Counters;
use crate::math::{Rgb, offset_origin};
use crate::sampling::Random;
use crate::scene::Scene;
use glam::{Vec2, Vec3};

/// Unit direction from `a` to `b` and their squared distance; towards or from a vertex at
/// infinity its direction, and a distance of one (its edge's geometric factor has none).
#[inline]
fn towards(a: &Vertex, b: &Vertex) -> (Vec3, f32) {
    if b.infinite {
        return (b.ng, 1.0);
    }
    if a.infinite {
        return (-a.ng, 1.0);
    }
    let d = b.p - a.p;
    let d2 = d.length_squared();
    (d / d2.sqrt(), d2)
}

/// A sample of the Dirac lobe of `bsdf` that takes `lo` to the reflected side (or the
/// transmitted one) in `mode`.
fn delta_sample(bsdf: &Bsdf, lo: Vec3, at: At, reflection: bool, mode: TransportMode) -> Option<BsdfSample> {
    // The lobe is chosen by `u1` alone; these values reach every lobe a model has.
    [0.0, 0.26, 0.51, 0.76, 0.999_999].into_iter().find_map(|u1| {
        bsdf.sample(lo, at, u1, Vec2::splat(0.5), mode).filter(|s| s.delta && (s.wi.z * lo.z > 0.0) == reflection)
    })
}

/// The Dirac lobe of `bsdf` that takes `lo` to the side of `li` (reflection or
/// transmission): its coefficient and its discrete probability when sampled in `mode`.
pub fn delta_lobe(bsdf: &Bsdf, lo: Vec3, li: Vec3, at: At, mode: TransportMode) -> Option<(Rgb, f32)> {
    delta_sample(bsdf, lo, at, lo.z * li.z > 0.0, mode).map(|s| (s.f, s.pdf))
}

/// The direction a Dirac lobe of `bsdf` takes `lo` to, reflecting or transmitting as asked.
pub fn delta_direction(bsdf: &Bsdf, lo: Vec3, at: At, reflection: bool) -> Option<Vec3> {
    delta_sample(bsdf, lo, at, reflection, TransportMode::Radiance).map(|s| s.wi)
}

/// A light vertex at infinity in the unit direction `d` (towards the light) from `from`:
/// of light `l` when that is a directional light (a Dirac direction of its own), else of
/// the scene's first light that rays leaving the scene find (a path sees all of those
/// along `d`, and its densities are their mixture, so the index only marks the vertex as a
/// light). `None` when the scene has no such light.
pub fn sky_vertex(scene: &Scene, l: Option<usize>, from: Vec3, d: Vec3) -> Option<Vertex> {
    let l = match l {
        Some(l) if scene.lights[l].is_unreachable() => l,
        _ => *scene.infinite_lights.first()?,
    };
    let mut v = Vertex::light(l, scene.bounds.beyond(from, d), d, Vec2::ZERO, Rgb::ONE, 0.0);
    v.infinite = true;
    if scene.volumetric {
        // Where a light walk from it starts: a point beyond the scene.
        v.medium = scene.medium_at(v.p);
    }
    Some(v)
}

/// Puts the position of a path's light vertex at infinity back on the line from `x_1`
/// along its direction, after `x_1` moved.
#[inline]
pub fn settle_sky(scene: &Scene, v: &mut [Vertex]) {
    if v.len() >= 2 && v[0].infinite {
        v[0].p = scene.bounds.beyond(v[1].p, v[0].ng);
    }
}

/// Whether a deterministic connection can end at vertex `v` of a path: the light, the
/// pinhole, a medium's scattering event, or a surface scattering through a non-Dirac part
/// of its BSDF.
#[inline]
pub fn connectible(scene: &Scene, v: &Vertex) -> bool {
    match v.kind {
        VertexKind::Surface => !v.delta && !v.bsdf(scene).is_delta(),
        _ => true,
    }
}

/// The BSDF value of interior vertex `i` for light arriving from `x_{i-1}` and leaving
/// towards `x_{i+1}`, times `|cos|` with the shading normal over `|cos|` with the geometric
/// one on the light's side (radiance transport's shading-normal factor).
fn scatter(scene: &Scene, v: &[Vertex], i: usize) -> Rgb {
    let x = &v[i];
    let (to_camera, _) = towards(x, &v[i + 1]);
    let (to_light, _) = towards(x, &v[i - 1]);
    if x.kind == VertexKind::Medium {
        let sigma_s = media::homogeneous(scene, medium_of(x) as u32).sigma_s;
        return sigma_s * scene.media[medium_of(x)].phase.eval(to_camera, to_light);
    }
    let bsdf = x.bsdf(scene);
    let (lo, li) = (x.frame.to_local(to_camera), x.frame.to_local(to_light));
    let f = if x.delta {
        delta_lobe(bsdf, lo, li, x.at(), TransportMode::Radiance).map_or(Rgb::ZERO, |(f, _)| f)
    } else {
        bsdf.eval(lo, li, x.at(), TransportMode::Radiance)
    };
    let cos_g = x.ng.dot(to_light).abs();
    if cos_g == 0.0 { Rgb::ZERO } else { f * (li.z.abs() / cos_g) }
}

/// A path's contribution and where on the film it lands.
#[derive(Clone, Copy, Debug)]
pub struct Measured {
    pub f: Rgb,
    /// Film position in pixel units.
    pub raster: Vec2,
}

/// The medium of a medium vertex.
#[inline]
fn medium_of(x: &Vertex) -> usize {
    x.medium.expect("a medium vertex has a medium") as usize
}

/// The measurement contribution `f(x)` of a path whose edges are known to be unoccluded,
/// and its film position; `None` when it is zero or off the image. In a scene with media,
/// each edge's transmittance is traced (`None` when a surface blocks one).
pub fn contribution(scene: &Scene, v: &[Vertex]) -> Option<Measured> {
    let k = v.len().checked_sub(1)?;
    if k < 1 {
        return None;
    }
    let VertexKind::Light(l) = v[0].kind else { return None };
    let conn = scene.camera.connect(v[k - 1].p)?;
    let (w, _) = towards(&v[0], &v[1]);
    let le = if v[0].infinite {
        v[0].infinite_emission(scene)
    } else {
        scene.lights[l as usize].emitted(v[0].ng, v[0].uv, w)
    };
    let mut f = le * conn.pdf_dir;
    let mut g = 1.0f64;
    for i in 0..k {
        let (w, d2) = towards(&v[i], &v[i + 1]);
        g *= (cos_at(&v[i], w) * v[i + 1].cos_area(w)) as f64 / d2 as f64;
    }
    for i in 1..k {
        if f == Rgb::ZERO {
            return None;
        }
        f *= scatter(scene, v, i);
    }
    let f = f * g as f32 * media::path_transmittance(scene, v)?;
    (f != Rgb::ZERO && f.is_finite()).then_some(Measured { f, raster: conn.raster })
}

/// `|cos|` at a path's vertex towards `w`: 1 at infinity (no cosine on that side of its edge).
#[inline]
fn cos_at(x: &Vertex, w: Vec3) -> f32 {
    if x.infinite { 1.0 } else { x.cos_area(w) }
}

/// Solid-angle density of `x` scattering from `wo` (its own side) into `wi`, in `mode`,
/// through the part of its BSDF the path uses there.
pub fn lobe_pdf(scene: &Scene, x: &Vertex, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
    if x.kind == VertexKind::Medium {
        // Phase functions are sampled exactly, and symmetric.
        return scene.media[medium_of(x)].phase.eval(wo, wi);
    }
    let bsdf = x.bsdf(scene);
    let (lo, li) = (x.frame.to_local(wo), x.frame.to_local(wi));
    if x.delta {
        delta_lobe(bsdf, lo, li, x.at(), mode).map_or(0.0, |(_, p)| p)
    } else {
        bsdf.pdf(lo, li, x.at(), mode)
    }
}

/// Solid-angle density of interior vertex `x_i` scattering from `x_{i+1}` towards
/// `x_{i-1}` in a walk from the camera (a Dirac lobe's discrete probability where the path
/// scatters through one).
pub fn pdf_from_lobe(scene: &Scene, v: &[Vertex], i: usize) -> f64 {
    let x = &v[i];
    lobe_pdf(scene, x, towards(x, &v[i + 1]).0, towards(x, &v[i - 1]).0, TransportMode::Radiance) as f64
}

/// The area density of `v[j]` per unit solid angle at its neighbour `v[from]`: `|cos θ| / d²`.
/// At a specular vertex the cosine is the one towards its camera-side neighbour, whichever
/// walk reaches it: `f` (radiance transport) keeps that cosine of a Dirac lobe's, and a
/// light walk's own density of the vertex, with the light-side cosine, goes with importance
/// transport's coefficients instead. Refractions make the two cosines differ; with this
/// convention every density of a path is in the measure `f` is.
pub fn area_factor(v: &[Vertex], j: usize, from: usize) -> f64 {
    let (w, d2) = towards(&v[from], &v[j]);
    let x = &v[j];
    let cos = if x.kind == VertexKind::Surface && x.delta && j + 1 < v.len() {
        x.cos_area(towards(x, &v[j + 1]).0)
    } else {
        cos_at(x, w)
    };
    cos as f64 / d2 as f64
}

/// Area density of `x_j` generated by a walk from the light: for `j = 0` a light chosen by
/// power and a point on it (at infinity: a direction), else from `x_{j-1}` (emission, a
/// point on the disk facing a light at infinity, or importance-mode BSDF sampling, given
/// `x_{j-2}`). Without the free flights of media ([`split_densities`] takes them).
pub fn pdf_from_light(scene: &Scene, v: &[Vertex], j: usize) -> f64 {
    if j == 0 {
        return match v[0].kind {
            VertexKind::Light(_) if v[0].infinite => v[0].pdf_light_origin(scene) as f64,
            VertexKind::Light(l) => light_origin_pdf(scene, l as usize) as f64,
            _ => 0.0,
        };
    }
    let x = &v[j - 1];
    let (w, _) = towards(x, &v[j]);
    let solid = match x.kind {
        VertexKind::Light(_) if x.infinite => disk_pdf(scene),
        VertexKind::Light(l) => scene.lights[l as usize].pdf_emission_direction(x.ng, w),
        VertexKind::Surface | VertexKind::Medium => {
            lobe_pdf(scene, x, towards(x, &v[j - 2]).0, w, TransportMode::Importance)
        }
        _ => 0.0,
    };
    solid as f64 * area_factor(v, j, j - 1)
}

/// Whether a ray can find the light vertex `x`: not at a point or spot light's position,
/// nor in a directional light's direction.
#[inline]
pub fn hittable_light(scene: &Scene, x: &Vertex) -> bool {
    match x.kind {
        VertexKind::Light(l) => !scene.lights[l as usize].is_unreachable(),
        _ => false,
    }
}

/// Area density of `x_j` generated by a walk from the pinhole: from `x_{j+1}` (a uniform
/// film position, or radiance-mode BSDF sampling given `x_{j+2}`). Zero for the position
/// of a point or spot light and a directional light's direction, which no ray finds.
/// Without the free flights of media ([`split_densities`] takes them).
pub fn pdf_from_camera(scene: &Scene, v: &[Vertex], j: usize) -> f64 {
    if j == 0 && !hittable_light(scene, &v[0]) {
        return 0.0;
    }
    let x = &v[j + 1];
    let (w, _) = towards(x, &v[j]);
    let solid = match x.kind {
        VertexKind::Camera => scene.camera.pdf_direction(w),
        VertexKind::Surface | VertexKind::Medium => {
            lobe_pdf(scene, x, towards(x, &v[j + 2]).0, w, TransportMode::Radiance)
        }
        _ => 0.0,
    };
    solid as f64 * area_factor(v, j, j + 1)
}

/// Traces `n` vertices from `ray` into `out`, sampling each one's BSDF (or phase function)
/// in `mode` (from the direction the walk arrived along) for the next ray, all but the
/// last; `out` ends with the vertex the ray leaves, and in a medium the walk samples free
/// flights ([`media::advance`]). With `to_sky`, a last ray that leaves the scene ends the
/// walk at the lights at infinity (a vertex there; `to_sky` is for a camera walk that is to
/// end on a light). `false` when a ray leaves the scene otherwise, or a BSDF gives no
/// direction.
#[allow(clippy::too_many_arguments)]
pub fn walk<R: Random>(
    scene: &Scene,
    mut ray: Ray,
    n: usize,
    mode: TransportMode,
    to_sky: bool,
    rng: &mut R,
    out: &mut Vec<Vertex>,
    counters: &mut Counters,
) -> bool {
    let mut medium = out.last().and_then(|v| v.medium_towards(scene, ray.d));
    for i in 0..n {
        let mut v = match media::advance(scene, &mut ray, &mut medium, rng, counters) {
            Stop::Surface(si) => Found::Surface(si),
            Stop::Medium(p, m) => Found::Medium(p, m),
            Stop::Escaped => {
                // Placed on the line from the walk's last vertex, as `settle_sky` places it.
                let from = out.last().map_or(ray.o, |v| v.p);
                if to_sky
                    && i + 1 == n
                    && let Some(v) = sky_vertex(scene, None, from, ray.d)
                {
                    out.push(v);
                    return true;
                }
                return false;
            }
            Stop::Lost => return false,
        }
        .vertex(scene, &ray, medium);
        if i + 1 < n {
            let Some(next) = scatter_on(scene, &mut v, &ray, mode, rng) else { return false };
            medium = v.medium_towards(scene, next.d);
            ray = next;
        }
        out.push(v);
    }
    true
}

/// What a walk's ray found: a surface, or a scattering event in a medium.
enum Found {
    Surface(crate::scene::shape::SurfaceInteraction),
    Medium(Vec3, u32),
}

impl Found {
    /// The path vertex, reached along `ray` travelling in `medium`.
    fn vertex(&self, scene: &Scene, ray: &Ray, medium: Option<u32>) -> Vertex {
        match self {
            Found::Surface(si) => {
                let mut v = surface_vertex(scene, si, false);
                v.medium = medium;
                v
            }
            Found::Medium(p, m) => Vertex::in_medium(*p, -ray.d.normalize(), *m, Rgb::ONE),
        }
    }
}

/// The ray a walk's vertex `v`, reached along `ray`, sends on by sampling its BSDF in
/// `mode` (setting whether it left through a Dirac lobe) or its phase function; `None` when
/// the BSDF gives no direction.
fn scatter_on<R: Random>(scene: &Scene, v: &mut Vertex, ray: &Ray, mode: TransportMode, rng: &mut R) -> Option<Ray> {
    let u1 = rng.next_1d();
    let u2 = rng.next_2d();
    if v.kind == VertexKind::Medium {
        let d = scene.media[medium_of(v)].phase.sample(-ray.d.normalize(), u2).0;
        return Some(Ray::new(v.p, d));
    }
    let s = v.bsdf(scene).sample(v.frame.to_local(-ray.d), v.at(), u1, u2, mode)?;
    v.delta = s.delta;
    let d = v.frame.to_world(s.wi);
    Some(Ray::new(offset_origin(v.p, v.ng, d), d))
}

/// A camera walk that stops at the first light it finds: a uniform film position, then
/// radiance-mode BSDF sampling at every surface, of at most `max` edges; the path it makes
/// (light first), ending on an emitting surface (on its front or back) or, where the scene
/// has a light at infinity, on the sky when the ray leaves the scene. `None` when it finds
/// none within `max` edges (or a BSDF absorbs it). A path of `k` edges comes with the
/// density of the camera-only split of [`split_densities`] when no interior vertex lies on
/// an emitting shape ([`walks_to_light`]), and never otherwise.
pub fn camera_walk_to_light<R: Random>(
    scene: &Scene,
    max: usize,
    rng: &mut R,
    counters: &mut Counters,
) -> Option<Vec<Vertex>> {
    let mut v = vec![camera_vertex(scene)];
    let mut ray = leave(scene, &mut v, 0, 0, TransportMode::Radiance, rng)?;
    let mut medium = scene.camera_medium;
    for _ in 0..max {
        let found = match media::advance(scene, &mut ray, &mut medium, rng, counters) {
            Stop::Surface(si) => Found::Surface(si),
            Stop::Medium(p, m) => Found::Medium(p, m),
            Stop::Escaped => {
                let from = v.last().map_or(ray.o, |x| x.p);
                v.push(sky_vertex(scene, None, from, ray.d)?);
                v.reverse();
                return Some(v);
            }
            Stop::Lost => return None,
        };
        let mut x = found.vertex(scene, &ray, medium);
        if let Found::Surface(si) = &found
            && scene.area_light(si).is_some()
        {
            v.push(as_light(scene, &x)?);
            v.reverse();
            return Some(v);
        }
        ray = scatter_on(scene, &mut x, &ray, TransportMode::Radiance, rng)?;
        medium = x.medium_towards(scene, ray.d);
        v.push(x);
    }
    None
}

/// The pinhole as a path's last vertex, in the camera's medium.
#[inline]
pub fn camera_vertex(scene: &Scene) -> Vertex {
    Vertex { medium: scene.camera_medium, ..Vertex::camera(scene.camera.position) }
}

/// Whether no edge of path `x` joins two vertices a shadow ray can join ([`connectible`]:
/// the light, the pinhole and rough vertices), so that of the bidirectional strategies only
/// a camera walk that finds the light makes it (a floor's caustic seen in a glass ball; a
/// small light seen in it).
pub fn joined_nowhere(scene: &Scene, x: &[Vertex]) -> bool {
    !x.windows(2).any(|e| connectible(scene, &e[0]) && connectible(scene, &e[1]))
}

/// Whether [`camera_walk_to_light`] can make path `x`: none of its interior vertices lies on
/// an emitting shape (the walk would have stopped there).
pub fn walks_to_light(scene: &Scene, x: &[Vertex]) -> bool {
    let k = x.len() - 1;
    x[1..k].iter().all(|v| scene.shapes.get(v.shape as usize).is_none_or(|s| s.light.is_none()))
}

/// The ray leaving vertex `x` along unit `d`, on the line through `x`: its origin is moved
/// along `d` until it lies off the surface by the usual offset ([`offset_origin`]'s), so
/// that the vertex the ray finds lies exactly in direction `d` from `x` (a perturbation's
/// densities are of the directions between the path's vertices: an origin moved along the
/// normal would bend short edges, near corners, by up to tens of degrees). Within
/// [`GRAZING`] of the tangent plane the origin takes the rest of the offset along the normal.
#[inline]
pub fn ray_from(x: &Vertex, d: Vec3) -> Ray {
    if x.ng == Vec3::ZERO {
        return Ray::new(x.p, d);
    }
    let normal = offset_origin(x.p, x.ng, d) - x.p;
    let mag = normal.length();
    let cos = d.dot(x.ng).abs();
    let along = mag / cos.max(GRAZING);
    let rest = (mag - along * cos).max(0.0);
    Ray::new(x.p + d * along + normal * (rest / mag), d)
}

/// The cosine below which [`ray_from`] leaves the line through its vertex.
pub const GRAZING: f32 = 0.05;

/// Samples the direction a walk leaves the kept vertex `v[i]` along, away from the kept
/// neighbour `v[j]` (`j = i ± 1`): emission from the light (its own directions, as
/// [`crate::light::Light::sample_emission`] draws them), a film position from the
/// pinhole, BSDF sampling in `mode` from a surface (whose `delta` it sets), the phase
/// function from a medium's scattering event. `None` when no direction comes out.
pub fn leave<R: Random>(
    scene: &Scene,
    v: &mut [Vertex],
    i: usize,
    j: usize,
    mode: TransportMode,
    rng: &mut R,
) -> Option<Ray> {
    let u1 = rng.next_1d();
    let u2 = rng.next_2d();
    let x = &v[i];
    match x.kind {
        VertexKind::Camera => {
            let res = Vec2::new(scene.film.width as f32, scene.film.height as f32);
            Some(scene.camera.generate_ray(u2 * res))
        }
        VertexKind::Light(_) if x.infinite => {
            // A point on the disk facing the light, the ray along the light's direction.
            Some(Ray::new(crate::light::disk_point(&scene.bounds, x.ng, u2), -x.ng))
        }
        VertexKind::Light(l) => {
            scene.lights[l as usize].sample_emission_direction(x.ng, u2).map(|(d, _)| ray_from(x, d))
        }
        VertexKind::Surface => {
            let (back, _) = towards(x, &v[j]);
            let bsdf = x.bsdf(scene);
            let s = bsdf.sample(x.frame.to_local(back), x.at(), u1, u2, mode)?;
            let d = x.frame.to_world(s.wi);
            v[i].delta = s.delta;
            Some(ray_from(&v[i], d))
        }
        VertexKind::Medium => {
            let (back, _) = towards(x, &v[j]);
            Some(Ray::new(x.p, scene.media[medium_of(x)].phase.sample(back, u2).0))
        }
        VertexKind::Sky => None,
    }
}

/// Re-traces vertex `i` of `x` along `ray` (a perturbation's), travelling in `medium`: the
/// surface the ray finds, null surfaces passed, scattering as `x_i` does (through a Dirac
/// lobe or not). With `follow`, the ray is turned into the one leaving it through the same
/// Dirac lobe (reflection or transmission) as `x_i`'s, and `medium` into the one it leaves
/// in. No free flight is sampled: the edges' transmittance is the contribution's. `None`
/// when the ray leaves the scene or the surface has no such lobe.
pub fn retrace(
    scene: &Scene,
    ray: &mut Ray,
    medium: &mut Option<u32>,
    x: &[Vertex],
    i: usize,
    follow: bool,
    counters: &mut Counters,
) -> Option<Vertex> {
    let si = surface_along(scene, ray, medium, counters)?;
    let mut v = surface_vertex(scene, &si, x[i].delta);
    v.medium = *medium;
    if follow {
        let d = delta_direction(v.bsdf(scene), si.shading.to_local(-ray.d), si.at(), reflects(x, i))?;
        *ray = si.spawn_ray(si.shading.to_world(d));
        *medium = v.medium_towards(scene, ray.d);
    }
    Some(v)
}

/// The first surface along `ray` that is not a null one, `medium` updated across the null
/// ones (and `ray` left as the last stretch's).
pub fn surface_along(
    scene: &Scene,
    ray: &mut Ray,
    medium: &mut Option<u32>,
    counters: &mut Counters,
) -> Option<crate::scene::shape::SurfaceInteraction> {
    for _ in 0..crate::scene::MAX_NULL_CROSSINGS {
        counters.extension_rays += 1;
        let si = scene.intersect(ray)?;
        if !scene.bsdf(&si).is_null() {
            return Some(si);
        }
        *medium = scene.medium_after(&si, ray.d, *medium);
        *ray = si.spawn_ray(ray.d);
    }
    None
}

/// Whether interior vertex `x_i` reflects (its neighbours on one side of its geometric
/// normal) rather than transmits.
pub fn reflects(x: &[Vertex], i: usize) -> bool {
    let n = x[i].ng;
    (x[i + 1].p - x[i].p).dot(n) * (x[i - 1].p - x[i].p).dot(n) > 0.0
}

/// The path vertex at hit `si`, scattering through a Dirac lobe or not as `delta` says.
pub fn surface_vertex(scene: &Scene, si: &crate::scene::shape::SurfaceInteraction, delta: bool) -> Vertex {
    let b = scene.bsdf_index(si);
    let mut v = Vertex::surface(si, b as u32, Rgb::ONE, !scene.bsdfs[b].is_delta());
    v.delta = delta;
    v
}

/// Turns a surface vertex on an area light's shape into the path's light vertex `x_0`;
/// `None` when its shape emits nothing.
pub fn as_light(scene: &Scene, v: &Vertex) -> Option<Vertex> {
    let l = scene.shapes.get(v.shape as usize)?.light?;
    Some(Vertex { kind: VertexKind::Light(l as u32), bsdf: u32::MAX, delta: false, ..*v })
}

/// Joins two vertices of a path by a shadow ray: `true` when both can take a connection
/// and see each other.
pub fn join(scene: &Scene, a: &Vertex, b: &Vertex, counters: &mut Counters) -> bool {
    if !connectible(scene, a) || !connectible(scene, b) {
        return false;
    }
    counters.connections += 1;
    let seen = visible(scene, a, b, counters);
    if !seen {
        counters.connections_occluded += 1;
    }
    seen
}

/// Regenerates the stretch between `prefix` (kept light-side vertices, possibly none) and
/// `suffix` (kept camera-side vertices, ending at the pinhole): `s` new vertices walked from
/// the light side (a fresh light point first when `prefix` is empty), `t` from the camera
/// side, joined by a shadow ray, or with `prefix` and `s` both empty, the camera walk's last
/// vertex taken as the light it lies on. `None` when the walks or the join fail.
#[allow(clippy::too_many_arguments)]
pub fn regenerate<R: Random>(
    scene: &Scene,
    prefix: &[Vertex],
    suffix: &[Vertex],
    s: usize,
    t: usize,
    rng: &mut R,
    counters: &mut Counters,
) -> Option<Vec<Vertex>> {
    let mut light: Vec<Vertex> = prefix.to_vec();
    let a = prefix.len();
    if s > 0 {
        let ray = if a == 0 {
            let (l, pmf, _) = scene.light_sampler.sample(rng.next_1d())?;
            let u1 = rng.next_1d();
            let (u_pos, u_dir) = (rng.next_2d(), rng.next_2d());
            if pmf <= 0.0 {
                return None;
            }
            if scene.lights[l].at_infinity() {
                // A direction from the light's distribution, a point on the disk facing it.
                let (wi, pdf_dir, _) = scene.lights[l].sample_infinite_direction(u_dir)?;
                if pdf_dir <= 0.0 {
                    return None;
                }
                let p = crate::light::disk_point(&scene.bounds, wi, u_pos);
                light.push(sky_vertex(scene, Some(l), p, wi)?);
                Ray::new(p, -wi)
            } else {
                let es = scene.lights[l].sample_emission(&scene.shapes, u1, u_pos, u_dir)?;
                if es.pdf_dir <= 0.0 {
                    return None;
                }
                let mut y0 = Vertex::light(l, es.p, es.n, es.uv, Rgb::ONE, 0.0);
                if scene.volumetric {
                    y0.medium = crate::integrator::bidir::walk::light_medium(scene, l, &y0, es.d);
                }
                let ray = ray_from(&y0, es.d);
                light.push(y0);
                ray
            }
        } else {
            let j = if a >= 2 { a - 2 } else { a - 1 };
            leave(scene, &mut light, a - 1, j, TransportMode::Importance, rng)?
        };
        let more = s - usize::from(a == 0);
        if more > 0 && !walk(scene, ray, more, TransportMode::Importance, false, rng, &mut light, counters) {
            return None;
        }
    }
    let mut camera: Vec<Vertex> = suffix.iter().rev().copied().collect();
    if t > 0 {
        let c = camera.len();
        let j = if c >= 2 { c - 2 } else { c - 1 };
        let ray = leave(scene, &mut camera, c - 1, j, TransportMode::Radiance, rng)?;
        if !walk(scene, ray, t, TransportMode::Radiance, light.is_empty(), rng, &mut camera, counters) {
            return None;
        }
    }
    if light.is_empty() {
        // The camera walk ends on the light the path starts from.
        let end = camera.last_mut()?;
        if !end.infinite {
            *end = as_light(scene, end)?;
        }
    } else {
        let (n, m) = (light.len(), camera.len());
        if light[0].infinite {
            // On the line from the light walk's next vertex, or from the join's other end.
            let next = if n >= 2 { light[1].p } else { camera[m - 1].p };
            light[0].p = scene.bounds.beyond(next, light[0].ng);
        }
        light[n - 1].delta = false;
        camera[m - 1].delta = false;
        if !join(scene, &light[n - 1], &camera[m - 1], counters) {
            return None;
        }
    }
    light.extend(camera.into_iter().rev());
    Some(light)
}

/// The density of the regenerated stretch of `y` (its vertices `a .. a+n-1`, `n` of them,
/// between kept ends) over every split of the `n + 1` edges it spans into light-side walk,
/// join and camera-side walk, each split chosen with probability `1 / (n + 1)`: what
/// [`regenerate`] with a uniformly chosen `s` produces `y` with.
pub fn stretch_density(scene: &Scene, y: &[Vertex], a: usize, n: usize) -> f64 {
    split_densities(scene, y, a, n).sum::<f64>() / (n + 1) as f64
}

/// The densities of the stretch of `n` vertices after `y[a - 1]` for each split: entry `s`
/// is the density of walking `s` of them from the light side and `n - s` from the camera
/// side, then joining them (0 where the join is not a shadow ray's), for `s` from 0 to `n`.
/// In media, each walked vertex's density takes the free flights that reached it.
pub fn split_densities(scene: &Scene, y: &[Vertex], a: usize, n: usize) -> impl Iterator<Item = f64> {
    // Light-side densities of the new vertices (prefix products), camera-side (suffix).
    // In media, the free flights of edge `e` (between `y[a+e-1]` and `y[a+e]`): a light-side
    // walk reaches `y[a+e]` along it, a camera-side walk `y[a+e-1]`.
    let flights: Vec<media::Edge> =
        if scene.volumetric {
            (0..=n)
                .map(|e| {
                    let ends = (a + e).checked_sub(1).zip(y.get(a + e));
                    ends.map_or(Some(media::Edge::CLEAR), |(i, b)| media::edge(scene, &y[i], b))
                        .unwrap_or(media::Edge { tr: Rgb::ZERO, from_a: 0.0, from_b: 0.0 })
                })
                .collect()
        } else {
            Vec::new()
        };
    let from_light = |i: usize| flights.get(i).map_or(1.0, |e| e.from_a);
    let from_camera = |i: usize| flights.get(i + 1).map_or(1.0, |e| e.from_b);
    let mut light = vec![1.0f64; n + 1];
    for i in 0..n {
        light[i + 1] = light[i] * pdf_from_light(scene, y, a + i) * from_light(i);
    }
    let mut camera = vec![1.0f64; n + 1];
    for i in (0..n).rev() {
        camera[i] = camera[i + 1] * pdf_from_camera(scene, y, a + i) * from_camera(i);
    }
    (0..=n).map(move |s| {
        // The join: between `y[a+s-1]` and `y[a+s]`, or the camera walk reaching the light.
        let joins = if a + s == 0 { true } else { connectible(scene, &y[a + s - 1]) && connectible(scene, &y[a + s]) };
        if joins { light[s] * camera[s] } else { 0.0 }
    })
}
