//! Emitters: a closed set dispatched through an enum (Mitsuba 3's `area`, `point`, `spot`,
//! `directional`, `constant`, `envmap`, and the sky and the sun of `sunsky`), and light
//! selection by power.
//!
//! Directions: `sample_li` returns the unit direction from the reference point towards the
//! light; infinite lights are evaluated for the direction a ray travels when it leaves the
//! scene (`eval_infinite(d)`).

use crate::math::{Frame, Rgb, luminance};
use crate::sampling::{Distribution1D, Distribution2D, UNIFORM_SPHERE_PDF, square_to_uniform_sphere};
use crate::scene::shape::{Shape, ShapeGeometry, SurfaceInteraction};
use crate::texture::{Bitmap, Texture};
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::Arc;

pub mod cie;
pub mod sun06;
pub mod sunsky;

/// A sphere enclosing the scene (for the power and sampling of lights at infinity).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub center: Vec3,
    pub radius: f32,
}

impl Bounds {
    /// The point on the line from `p` in the unit direction `d` some scene diameters beyond
    /// the scene: where a vertex at infinity in that direction is placed (next-event
    /// estimation's shadow rays end there, and the bidirectional integrators' sky vertices).
    #[inline]
    pub fn beyond(&self, p: Vec3, d: Vec3) -> Vec3 {
        p + d * (2.0 * (self.radius + (p - self.center).length()) + 1.0)
    }
}

/// A lat-long environment map (Mitsuba 3's `envmap`), importance-sampled by luminance.
#[derive(Debug)]
pub struct EnvMap {
    pub bitmap: Arc<Bitmap>,
    /// World → local rotation and its inverse.
    pub to_local: Mat3,
    pub to_world: Mat3,
    pub scale: f32,
    distribution: Distribution2D,
}

impl EnvMap {
    pub fn new(bitmap: Arc<Bitmap>, to_world: Mat3, scale: f32) -> EnvMap {
        let (w, h) = (bitmap.width as usize, bitmap.height as usize);
        let weights: Vec<f32> = (0..h)
            .flat_map(|y| {
                let sin_theta = (PI * (y as f32 + 0.5) / h as f32).sin();
                let bm = &bitmap;
                (0..w).map(move |x| luminance(bm.get(x as u32, y as u32)).max(0.0) * sin_theta)
            })
            .collect();
        let distribution = Distribution2D::new(&weights, w, h);
        EnvMap { bitmap, to_local: to_world.inverse(), to_world, scale, distribution }
    }

    /// Mitsuba 3's parameterisation: `u = atan2(x, -z) / 2π`, `v = acos(y) / π` (local).
    fn uv(&self, d: Vec3) -> Vec2 {
        let v = (self.to_local * d).normalize();
        let mut u = v.x.atan2(-v.z) / (2.0 * PI);
        u -= u.floor();
        Vec2::new(u, v.y.clamp(-1.0, 1.0).acos() / PI)
    }

    fn direction(&self, uv: Vec2) -> Vec3 {
        let (sin_t, cos_t) = (uv.y * PI).sin_cos();
        let (sin_p, cos_p) = (uv.x * 2.0 * PI).sin_cos();
        (self.to_world * Vec3::new(sin_p * sin_t, cos_t, -cos_p * sin_t)).normalize()
    }

    fn eval(&self, d: Vec3) -> Rgb {
        self.radiance_at(self.uv(d))
    }

    fn pdf(&self, d: Vec3) -> f32 {
        self.pdf_at(self.uv(d))
    }

    /// Solid-angle density of [`EnvMap::sample`] at map coordinates `uv`.
    fn pdf_at(&self, uv: Vec2) -> f32 {
        let sin_t = (uv.y * PI).sin();
        if sin_t <= 0.0 { 0.0 } else { self.distribution.pdf(uv) / (2.0 * PI * PI * sin_t) }
    }

    /// Radiance at map coordinates `uv`.
    fn radiance_at(&self, uv: Vec2) -> Rgb {
        self.bitmap.eval(uv) * self.scale
    }

    /// Radiance and solid-angle density for direction `d`, its map coordinates computed once.
    fn eval_pdf(&self, d: Vec3) -> (Rgb, f32) {
        let uv = self.uv(d);
        (self.radiance_at(uv), self.pdf_at(uv))
    }

    /// A direction towards the map, its solid-angle density and the radiance arriving along
    /// it (looked up at the sampled map coordinates, not at the direction's, which are the
    /// same up to rounding and cost a trigonometric round trip).
    fn sample(&self, u: Vec2) -> Option<(Vec3, f32, Rgb)> {
        let (uv, pdf_uv) = self.distribution.sample(u);
        let sin_t = (uv.y * PI).sin();
        if sin_t <= 0.0 || pdf_uv <= 0.0 {
            return None;
        }
        Some((self.direction(uv), pdf_uv / (2.0 * PI * PI * sin_t), self.radiance_at(uv)))
    }
}

#[derive(Clone, Debug)]
pub enum Light {
    /// One-sided emission from the front of the shape's normal.
    Area { shape: usize, radiance: Texture },
    /// Isotropic intensity at a position.
    Point { position: Vec3, intensity: Rgb },
    /// A point light emitting into a cone around `frame.n`, with Mitsuba's linear falloff
    /// (in angle) between `beam_width` and `cutoff_angle`.
    Spot { position: Vec3, frame: Frame, intensity: Rgb, cutoff: f32, beam_width: f32 },
    /// Parallel light travelling along `direction`, `irradiance` on a perpendicular surface.
    Directional { direction: Vec3, irradiance: Rgb },
    /// Uniform radiance from every direction at infinity.
    Constant { radiance: Rgb },
    /// Radiance at infinity from a lat-long image.
    Envmap(Arc<EnvMap>),
    /// The Hosek–Wilkie sky of `sunsky` (or `sky`).
    Sky(Arc<sunsky::Sky>),
    /// The sun of `sunsky` (or `sun`): a small bright disk at infinity.
    Sun(Arc<sunsky::Sun>),
}

/// A sample of incident light at a reference point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the reference point to the light.
    pub wi: Vec3,
    /// Point on the light (for lights at infinity, a point beyond the scene).
    pub p: Vec3,
    /// Its normal (zero for point-like and infinite lights).
    pub n: Vec3,
    /// Incident radiance (or intensity / d² for point lights, irradiance for directional).
    pub li: Rgb,
    /// Solid-angle density (for delta lights, the density of the delta, 1).
    pub pdf: f32,
    /// The light is a delta distribution in direction.
    pub delta: bool,
}

impl Light {
    /// Emitted power (luminance), used for light selection.
    pub fn power(&self, shapes: &[Shape], bounds: &Bounds) -> f32 {
        let disk = PI * bounds.radius * bounds.radius;
        match self {
            Light::Area { shape, radiance } => PI * shapes[*shape].area() * luminance(radiance.mean()),
            Light::Point { intensity, .. } => 4.0 * PI * luminance(*intensity),
            Light::Spot { intensity, cutoff, beam_width, .. } => {
                2.0 * PI * (1.0 - 0.5 * (cutoff.cos() + beam_width.cos())) * luminance(*intensity)
            }
            Light::Directional { irradiance, .. } => disk * luminance(*irradiance),
            Light::Constant { radiance } => 4.0 * PI * disk * luminance(*radiance),
            Light::Envmap(e) => 4.0 * PI * disk * luminance(e.bitmap.mean()) * e.scale,
            Light::Sky(s) => disk * s.luminance_integral(),
            Light::Sun(s) => disk * luminance(s.irradiance()),
        }
    }

    /// Radiance leaving an area light at a surface point towards `w` (unit, away from it).
    #[inline]
    pub fn radiance(&self, ng: Vec3, uv: Vec2, w: Vec3) -> Rgb {
        match self {
            Light::Area { radiance, .. } if ng.dot(w) > 0.0 => radiance.eval(uv),
            _ => Rgb::ZERO,
        }
    }

    /// Radiance arriving along a ray that leaves the scene in direction `d` (unit).
    #[inline]
    pub fn eval_infinite(&self, d: Vec3) -> Rgb {
        match self {
            Light::Constant { radiance } => *radiance,
            Light::Envmap(e) => e.eval(d),
            Light::Sky(s) => s.eval(d),
            Light::Sun(s) => s.eval(d),
            _ => Rgb::ZERO,
        }
    }

    /// [`Light::eval_infinite`] and [`Light::pdf_infinite`] together, sharing the work of
    /// both (an environment map's coordinates of `d`).
    #[inline]
    pub fn eval_pdf_infinite(&self, d: Vec3) -> (Rgb, f32) {
        match self {
            Light::Envmap(e) => e.eval_pdf(d),
            _ => (self.eval_infinite(d), self.pdf_infinite(d)),
        }
    }

    /// Solid-angle density of `sample_li` choosing direction `d` for a light at infinity.
    #[inline]
    pub fn pdf_infinite(&self, d: Vec3) -> f32 {
        match self {
            Light::Constant { .. } => UNIFORM_SPHERE_PDF,
            Light::Envmap(e) => e.pdf(d),
            Light::Sky(s) => s.pdf(d),
            Light::Sun(s) => s.pdf(d),
            _ => 0.0,
        }
    }

    /// Lights at infinity that rays leaving the scene can hit.
    pub fn is_infinite(&self) -> bool {
        matches!(self, Light::Constant { .. } | Light::Envmap(_) | Light::Sky(_) | Light::Sun(_))
    }

    /// Samples incident light at `reference`.
    pub fn sample_li(
        &self,
        shapes: &[Shape],
        bounds: &Bounds,
        reference: Vec3,
        u1: f32,
        u: Vec2,
    ) -> Option<LightSample> {
        let far = |wi: Vec3| bounds.beyond(reference, wi);
        match self {
            Light::Area { shape, .. } => {
                let (ps, pdf) = shapes[*shape].sample_direction(reference, u1, u)?;
                let d = ps.p - reference;
                let dist = d.length();
                if dist.is_nan() || dist <= 0.0 || !(pdf.is_finite() && pdf > 0.0) {
                    return None;
                }
                let wi = d / dist;
                let li = self.radiance(ps.n, ps.uv, -wi);
                if li == Rgb::ZERO {
                    return None;
                }
                Some(LightSample { wi, p: ps.p, n: ps.n, li, pdf, delta: false })
            }
            Light::Point { position, intensity } => {
                let d = *position - reference;
                let dist2 = d.length_squared();
                if dist2 <= 0.0 {
                    return None;
                }
                Some(LightSample {
                    wi: d / dist2.sqrt(),
                    p: *position,
                    n: Vec3::ZERO,
                    li: *intensity / dist2,
                    pdf: 1.0,
                    delta: true,
                })
            }
            Light::Spot { position, frame, intensity, cutoff, beam_width } => {
                let d = *position - reference;
                let dist2 = d.length_squared();
                if dist2 <= 0.0 {
                    return None;
                }
                let wi = d / dist2.sqrt();
                let falloff = spot_falloff(frame.n.dot(-wi), *cutoff, *beam_width);
                if falloff <= 0.0 {
                    return None;
                }
                Some(LightSample {
                    wi,
                    p: *position,
                    n: Vec3::ZERO,
                    li: *intensity * (falloff / dist2),
                    pdf: 1.0,
                    delta: true,
                })
            }
            Light::Directional { direction, irradiance } => {
                let wi = -*direction;
                Some(LightSample { wi, p: far(wi), n: Vec3::ZERO, li: *irradiance, pdf: 1.0, delta: true })
            }
            Light::Constant { radiance } => {
                let wi = square_to_uniform_sphere(u);
                Some(LightSample {
                    wi,
                    p: far(wi),
                    n: Vec3::ZERO,
                    li: *radiance,
                    pdf: UNIFORM_SPHERE_PDF,
                    delta: false,
                })
            }
            Light::Envmap(_) | Light::Sky(_) | Light::Sun(_) => {
                let (wi, pdf, li) = self.sample_infinite_direction(u)?;
                Some(LightSample { wi, p: far(wi), n: Vec3::ZERO, li, pdf, delta: false })
            }
        }
    }

    /// Solid-angle density of `sample_li` from `reference` producing the surface point `si`
    /// of an area light.
    pub fn pdf_li(&self, shapes: &[Shape], reference: Vec3, si: &SurfaceInteraction) -> f32 {
        match self {
            Light::Area { shape, .. } => shapes[*shape].pdf_direction(reference, si.p, si.ng),
            _ => 0.0,
        }
    }

    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Spot { .. } | Light::Directional { .. })
    }
}

/// An emitted ray: a point on a light and a direction leaving it (light tracing).
#[derive(Clone, Copy, Debug)]
pub struct EmissionSample {
    pub p: Vec3,
    /// Surface normal at `p` (zero for point lights).
    pub n: Vec3,
    pub uv: Vec2,
    /// Unit direction the light travels.
    pub d: Vec3,
    /// Area density of `p` (1 for a delta position).
    pub pdf_pos: f32,
    /// Solid-angle density of `d` given `p`.
    pub pdf_dir: f32,
}

impl Light {
    /// `true` when the light's position is a delta distribution (rays cannot hit it).
    pub fn is_delta_position(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Spot { .. })
    }

    /// `true` when no ray can hit the light: a delta position or a delta direction.
    pub fn is_unreachable(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Spot { .. } | Light::Directional { .. })
    }

    /// `true` for lights at infinity: `directional`, `constant`, `envmap`, sky and sun.
    pub fn at_infinity(&self) -> bool {
        matches!(
            self,
            Light::Directional { .. } | Light::Constant { .. } | Light::Envmap(_) | Light::Sky(_) | Light::Sun(_)
        )
    }

    /// Samples light arriving from infinity, for a light subpath: the unit direction `wi`
    /// *towards* the light (the light travels along `-wi`) and its solid-angle density (1 for a
    /// directional light's delta), and the radiance (irradiance for directional lights)
    /// carried along it. The ray then starts on the disk of radius `bounds.radius` facing
    /// `-wi` ([`disk_point`]).
    pub fn sample_infinite_direction(&self, u: Vec2) -> Option<(Vec3, f32, Rgb)> {
        match self {
            Light::Directional { direction, irradiance } => Some((-*direction, 1.0, *irradiance)),
            Light::Constant { radiance } => Some((square_to_uniform_sphere(u), UNIFORM_SPHERE_PDF, *radiance)),
            Light::Envmap(e) => {
                let (wi, pdf, li) = e.sample(u)?;
                (li != Rgb::ZERO && pdf > 0.0).then_some((wi, pdf, li))
            }
            Light::Sky(s) => {
                let (wi, pdf) = s.sample(u)?;
                let li = s.eval(wi);
                (li != Rgb::ZERO && pdf > 0.0).then_some((wi, pdf, li))
            }
            Light::Sun(s) => {
                let (wi, pdf) = s.sample(u);
                let li = s.eval(wi);
                (li != Rgb::ZERO && pdf > 0.0).then_some((wi, pdf, li))
            }
            _ => None,
        }
    }

    /// Samples a point on the light (area lights uniformly by area) and a direction of
    /// emission ([`Light::sample_emission_direction`]).
    pub fn sample_emission(&self, shapes: &[Shape], u1: f32, u_pos: Vec2, u_dir: Vec2) -> Option<EmissionSample> {
        match self {
            Light::Area { shape, .. } => {
                let s = &shapes[*shape];
                let ps = s.sample_area(u1, u_pos);
                if ps.n == Vec3::ZERO {
                    return None;
                }
                let (d, pdf_dir) = self.sample_emission_direction(ps.n, u_dir)?;
                Some(EmissionSample { p: ps.p, n: ps.n, uv: ps.uv, d, pdf_pos: 1.0 / s.area(), pdf_dir })
            }
            Light::Point { position, .. } | Light::Spot { position, .. } => {
                let (d, pdf_dir) = self.sample_emission_direction(Vec3::ZERO, u_dir)?;
                Some(EmissionSample { p: *position, n: Vec3::ZERO, uv: Vec2::ZERO, d, pdf_pos: 1.0, pdf_dir })
            }
            _ => None,
        }
    }

    /// A direction of emission from a point of the light with normal `n` and its
    /// solid-angle density ([`Light::pdf_emission_direction`]'s): cosine-weighted about an
    /// area light's normal, uniform for a point light, uniform within a spot light's cutoff
    /// cone. What [`Light::sample_emission`] draws, and a walk leaving a kept light point
    /// needs. `None` for lights at infinity and below an area light's surface.
    pub fn sample_emission_direction(&self, n: Vec3, u: Vec2) -> Option<(Vec3, f32)> {
        match self {
            Light::Area { .. } => {
                let local = crate::sampling::square_to_cosine_hemisphere(u);
                if local.z <= 0.0 {
                    return None;
                }
                Some((Frame::from_normal(n).to_world(local), local.z * std::f32::consts::FRAC_1_PI))
            }
            Light::Point { .. } => Some((square_to_uniform_sphere(u), UNIFORM_SPHERE_PDF)),
            Light::Spot { frame, cutoff, .. } => {
                let cos_max = cutoff.cos();
                let d = frame.to_world(crate::sampling::square_to_uniform_cone(u, cos_max));
                Some((d, crate::sampling::square_to_uniform_cone_pdf(cos_max)))
            }
            _ => None,
        }
    }

    /// Solid-angle density of [`Light::sample_emission`] choosing direction `d` (unit) at a
    /// point with normal `n`.
    pub fn pdf_emission_direction(&self, n: Vec3, d: Vec3) -> f32 {
        match self {
            Light::Area { .. } => n.dot(d).max(0.0) * std::f32::consts::FRAC_1_PI,
            Light::Point { .. } => UNIFORM_SPHERE_PDF,
            Light::Spot { frame, cutoff, .. } => {
                let cos_max = cutoff.cos();
                if frame.n.dot(d) > cos_max { crate::sampling::square_to_uniform_cone_pdf(cos_max) } else { 0.0 }
            }
            _ => 0.0,
        }
    }

    /// Emitted radiance (area lights) or intensity (point and spot lights) leaving a point
    /// of the light with normal `n` and texture coordinates `uv` in direction `d` (unit).
    #[inline]
    pub fn emitted(&self, n: Vec3, uv: Vec2, d: Vec3) -> Rgb {
        match self {
            Light::Area { .. } => self.radiance(n, uv, d),
            Light::Point { intensity, .. } => *intensity,
            Light::Spot { frame, intensity, cutoff, beam_width, .. } => {
                *intensity * spot_falloff(frame.n.dot(d), *cutoff, *beam_width)
            }
            _ => Rgb::ZERO,
        }
    }
}

/// A point of the disk of radius `bounds.radius` that faces direction `wi` across the
/// bounding sphere (centred at `center + radius · wi`, perpendicular to `wi`), uniform in
/// area: where a light path from infinity arriving along `-wi` starts. Its density is
/// `1 / (π radius²)`.
pub fn disk_point(bounds: &Bounds, wi: Vec3, u: Vec2) -> Vec3 {
    let d = crate::sampling::square_to_uniform_disk_concentric(u) * bounds.radius;
    let f = Frame::from_normal(wi);
    bounds.center + wi * bounds.radius + f.s * d.x + f.t * d.y
}

/// Mitsuba 3's spot falloff: 1 inside the beam, linear in angle to 0 at the cutoff.
#[inline]
pub fn spot_falloff(cos_theta: f32, cutoff: f32, beam_width: f32) -> f32 {
    if cos_theta <= cutoff.cos() {
        return 0.0;
    }
    if cos_theta >= beam_width.cos() {
        return 1.0;
    }
    ((cutoff - cos_theta.clamp(-1.0, 1.0).acos()) / (cutoff - beam_width)).clamp(0.0, 1.0)
}

/// Chooses lights proportionally to their power.
#[derive(Clone, Debug)]
pub struct LightSampler {
    distribution: Option<Distribution1D>,
    sphere_lights: bool,
    unreachable_lights: bool,
}

impl LightSampler {
    pub fn new(lights: &[Light], shapes: &[Shape], bounds: &Bounds) -> LightSampler {
        let sphere_lights = lights.iter().any(|l| {
            matches!(l, Light::Area { shape, .. } if matches!(shapes[*shape].geometry, ShapeGeometry::Sphere { .. }))
        });
        let unreachable_lights = lights.iter().any(Light::is_unreachable);
        let distribution = (!lights.is_empty()).then(|| {
            let powers: Vec<f32> = lights.iter().map(|l| l.power(shapes, bounds)).collect();
            Distribution1D::new(&powers)
        });
        LightSampler { distribution, sphere_lights, unreachable_lights }
    }

    /// Whether some area light is a sphere (whose points next-event estimation samples by
    /// the cone they subtend, not by area).
    #[inline]
    pub fn any_sphere_light(&self) -> bool {
        self.sphere_lights
    }

    /// Whether some light cannot be reached by a ray: a delta position (point and spot
    /// lights) or a delta direction (directional lights).
    #[inline]
    pub fn any_unreachable(&self) -> bool {
        self.unreachable_lights
    }

    /// Picks a light: its index, its probability, and `u` rescaled for reuse.
    #[inline]
    pub fn sample(&self, u: f32) -> Option<(usize, f32, f32)> {
        let d = self.distribution.as_ref()?;
        if d.len() == 1 {
            return Some((0, 1.0, u));
        }
        let (i, rest) = d.sample(u);
        Some((i, d.pmf(i), rest))
    }

    #[inline]
    pub fn pmf(&self, light: usize) -> f32 {
        self.distribution.as_ref().map_or(0.0, |d| d.pmf(light))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::{Hit, Ray};
    use crate::sampling::chi2::{Chi2Test, SphereDomain};
    use crate::scene::mesh;
    use crate::scene::shape::ShapeGeometry;

    const BOUNDS: Bounds = Bounds { center: Vec3::ZERO, radius: 10.0 };

    /// χ² test of `sample_li` directions from `reference` against `pdf_li`, finding the
    /// point a direction sees with the shape's own ray test.
    fn check(shape: Shape, reference: Vec3) -> crate::sampling::chi2::Chi2Result {
        let light = Light::Area { shape: 0, radiance: Texture::Constant(Vec3::ONE) };
        let shapes = vec![shape];
        let accel = crate::accel::Accel::build(
            crate::accel::Backend::Embree,
            &[shapes[0].accel_geometry()],
            Default::default(),
        )
        .unwrap();
        let mut u1 = crate::sampling::Sampler::new(&[17]);
        let t = Chi2Test::new(SphereDomain::default());
        t.run(
            |u| light.sample_li(&shapes, &BOUNDS, reference, u1.next_1d(), u).map(|s| s.wi),
            |w| {
                let ray = Ray::new(reference, w);
                match accel.intersect(&ray) {
                    Some(h) => {
                        let si = shapes[0].interaction(&ray, &Hit { ..h });
                        if light.radiance(si.ng, si.uv, -w) == Vec3::ZERO {
                            0.0
                        } else {
                            light.pdf_li(&shapes, reference, &si)
                        }
                    }
                    None => 0.0,
                }
            },
        )
    }

    fn mesh_shape(mut m: mesh::TriangleMesh, t: glam::Mat4) -> Shape {
        m.transform(&crate::math::Transform::new(t));
        let mut s = Shape::new(ShapeGeometry::Mesh(m), 0, false, "test".into());
        s.prepare_sampling();
        s
    }

    #[test]
    fn rectangle_light_sampling_chi2() {
        let s = mesh_shape(
            mesh::rectangle(),
            glam::Mat4::from_translation(Vec3::new(0.2, 0.0, 1.0))
                * glam::Mat4::from_rotation_x(PI)
                * glam::Mat4::from_scale(Vec3::new(1.5, 0.7, 1.0)),
        );
        check(s, Vec3::ZERO).assert_pass();
    }

    #[test]
    fn triangle_mesh_light_sampling_chi2() {
        // A cube has triangles facing every way: only those facing the point emit towards it.
        let s = mesh_shape(
            mesh::cube(),
            glam::Mat4::from_translation(Vec3::new(0.5, -2.0, 1.0)) * glam::Mat4::from_scale(Vec3::new(0.5, 1.0, 0.3)),
        );
        check(s, Vec3::ZERO).assert_pass();
    }

    #[test]
    fn sphere_light_sampling_chi2() {
        let mut s = Shape::new(
            ShapeGeometry::Sphere { center: Vec3::new(0.0, 1.0, 2.0), radius: 0.8 },
            0,
            false,
            "sphere".into(),
        );
        s.prepare_sampling();
        check(s.clone(), Vec3::ZERO).assert_pass();
        // From inside the sphere, area sampling; an outward-facing sphere emits nothing inwards.
        let mut inward = s;
        inward.flip_normals = true;
        check(inward, Vec3::new(0.0, 1.1, 2.0)).assert_pass();
    }

    fn gradient_envmap() -> EnvMap {
        // A sky brighter towards local +y and towards +x, with a hot spot.
        let (w, h) = (32, 16);
        let mut texels = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let hot = if (10..12).contains(&x) && (4..6).contains(&y) { 20.0 } else { 0.0 };
                texels.push(Vec3::new(1.0 + hot + x as f32 / 8.0, 2.0 - y as f32 / 8.0 + hot, 0.5 + hot));
            }
        }
        let bm =
            Arc::new(Bitmap::new(w, h, texels, crate::texture::FilterType::Bilinear, crate::texture::WrapMode::Repeat));
        EnvMap::new(bm, Mat3::from_rotation_x(0.4), 1.0)
    }

    #[test]
    fn envmap_sampling_chi2_and_round_trip() {
        let light = Light::Envmap(Arc::new(gradient_envmap()));
        let mut u1 = crate::sampling::Sampler::new(&[21]);
        let t = Chi2Test::new(SphereDomain::default());
        t.run(|u| light.sample_li(&[], &BOUNDS, Vec3::ZERO, u1.next_1d(), u).map(|s| s.wi), |w| light.pdf_infinite(w))
            .assert_pass();
        let Light::Envmap(e) = &light else { unreachable!() };
        for uv in [Vec2::new(0.1, 0.3), Vec2::new(0.7, 0.8), Vec2::new(0.95, 0.05)] {
            let back = e.uv(e.direction(uv));
            assert!((back - uv).abs().max_element() < 1e-4, "{uv} -> {back}");
        }
        // Negative control: a uniform-sphere pdf is rejected.
        let r =
            t.run(|u| light.sample_li(&[], &BOUNDS, Vec3::ZERO, u1.next_1d(), u).map(|s| s.wi), |_| UNIFORM_SPHERE_PDF);
        assert!(!r.passed());
    }

    #[test]
    fn constant_environment_sampling_chi2() {
        let light = Light::Constant { radiance: Vec3::ONE };
        let mut u1 = crate::sampling::Sampler::new(&[22]);
        let t = Chi2Test::new(SphereDomain::default());
        t.run(|u| light.sample_li(&[], &BOUNDS, Vec3::ZERO, u1.next_1d(), u).map(|s| s.wi), |w| light.pdf_infinite(w))
            .assert_pass();
    }

    #[test]
    fn spot_falloff_is_mitsubas() {
        let (cutoff, beam) = (20f32.to_radians(), 15f32.to_radians());
        assert_eq!(spot_falloff(1.0, cutoff, beam), 1.0);
        assert_eq!(spot_falloff(21f32.to_radians().cos(), cutoff, beam), 0.0);
        assert!((spot_falloff(17.5f32.to_radians().cos(), cutoff, beam) - 0.5).abs() < 1e-3);
    }

    #[test]
    fn light_sampling_chi2_rejects_wrong_pdf() {
        // Negative control: claim the area density without the cosine term.
        let s = mesh_shape(
            mesh::rectangle(),
            glam::Mat4::from_translation(Vec3::new(0.0, 0.0, 1.0)) * glam::Mat4::from_rotation_x(PI),
        );
        let light = Light::Area { shape: 0, radiance: Texture::Constant(Vec3::ONE) };
        let shapes = vec![s];
        let mut u1 = crate::sampling::Sampler::new(&[3]);
        let t = Chi2Test::new(SphereDomain::default());
        let r = t.run(
            |u| light.sample_li(&shapes, &BOUNDS, Vec3::ZERO, u1.next_1d(), u).map(|s| s.wi),
            |w| {
                if w.z <= 0.0 {
                    return 0.0;
                }
                let p = w / w.z;
                if p.x.abs() > 1.0 || p.y.abs() > 1.0 {
                    return 0.0;
                }
                p.length_squared() / shapes[0].area()
            },
        );
        assert!(!r.passed(), "{r}");
    }

    #[test]
    fn emission_directions_follow_their_densities_chi2() {
        // The directions a walk leaves a kept light point along (MEMLT's), against the
        // densities of `sample_emission`: cosine about an area light's normal, uniform for a
        // point light, uniform in a spot light's cone.
        let n = Vec3::new(0.3, -0.5, 0.8).normalize();
        let area = Light::Area { shape: 0, radiance: Texture::Constant(Vec3::ONE) };
        let point = Light::Point { position: Vec3::ZERO, intensity: Vec3::ONE };
        let frame = Frame::from_normal(Vec3::new(-0.2, 0.1, -1.0).normalize());
        let spot = Light::Spot { position: Vec3::ZERO, frame, intensity: Vec3::ONE, cutoff: 0.5, beam_width: 0.3 };
        for light in [&area, &point, &spot] {
            let t = Chi2Test::new(SphereDomain::default());
            t.run(|u| light.sample_emission_direction(n, u).map(|s| s.0), |w| light.pdf_emission_direction(n, w))
                .assert_pass();
        }
        // Negative control: the cone's density claimed with a cutoff 5% wider.
        let wider = Light::Spot { position: Vec3::ZERO, frame, intensity: Vec3::ONE, cutoff: 0.525, beam_width: 0.3 };
        let t = Chi2Test::new(SphereDomain::default());
        let r = t.run(|u| spot.sample_emission_direction(n, u).map(|s| s.0), |w| wider.pdf_emission_direction(n, w));
        assert!(!r.passed(), "{r}");
        // Lights at infinity have no emission point to leave from.
        assert_eq!(Light::Constant { radiance: Vec3::ONE }.sample_emission_direction(n, Vec2::splat(0.5)), None);
    }

    /// Counts of disk points (from `point(u)`) in 8 rings of equal area × 16 sectors of
    /// the disk facing `wi`, against the uniform density's equal counts.
    fn disk_cells(wi: Vec3, point: impl Fn(Vec2) -> Vec3) -> crate::sampling::chi2::Chi2Result {
        let bounds = Bounds { center: Vec3::new(0.3, -0.2, 0.5), radius: 2.5 };
        let f = Frame::from_normal(wi);
        let (rings, sectors, n) = (8usize, 16usize, 200_000usize);
        let mut counts = vec![0u64; rings * sectors];
        let mut rng = crate::sampling::Sampler::new(&[17]);
        for _ in 0..n {
            let q = point(rng.next_2d()) - (bounds.center + wi * bounds.radius);
            assert!(q.dot(wi).abs() < 1e-4, "the point leaves the disk's plane");
            let (x, y) = (q.dot(f.s) / bounds.radius, q.dot(f.t) / bounds.radius);
            let r2 = x * x + y * y;
            assert!(r2 <= 1.0 + 1e-4, "outside the disk: r² = {r2}");
            let ring = ((r2 * rings as f32) as usize).min(rings - 1);
            let phi = y.atan2(x).rem_euclid(2.0 * PI);
            let sector = ((phi / (2.0 * PI) * sectors as f32) as usize).min(sectors - 1);
            counts[ring * sectors + sector] += 1;
        }
        let expected = vec![n as f64 / (rings * sectors) as f64; rings * sectors];
        crate::sampling::chi2::discrete_chi2(&counts, &expected)
    }

    #[test]
    fn disk_points_of_lights_at_infinity_are_uniform_chi2() {
        let bounds = Bounds { center: Vec3::new(0.3, -0.2, 0.5), radius: 2.5 };
        for wi in [Vec3::Z, Vec3::new(0.3, -0.8, 0.2).normalize(), -Vec3::X] {
            disk_cells(wi, |u| disk_point(&bounds, wi, u)).assert_pass();
        }
        // Negative control: points uniform in radius, not in area.
        let wi = Vec3::new(0.3, -0.8, 0.2).normalize();
        let r = disk_cells(wi, |u| {
            let f = Frame::from_normal(wi);
            let (r, phi) = (u.x * bounds.radius, 2.0 * PI * u.y);
            bounds.center + wi * bounds.radius + f.s * (r * phi.cos()) + f.t * (r * phi.sin())
        });
        assert!(!r.passed(), "{r}");
    }

    #[test]
    fn directions_of_lights_at_infinity_follow_their_densities_chi2() {
        // Light subpaths draw their direction as next-event estimation does.
        let env = Light::Envmap(Arc::new(gradient_envmap()));
        let constant = Light::Constant { radiance: Vec3::ONE };
        for light in [&env, &constant] {
            let t = Chi2Test::new(SphereDomain::default());
            t.run(|u| light.sample_infinite_direction(u).map(|(wi, _, _)| wi), |w| light.pdf_infinite(w)).assert_pass();
        }
        // Negative control: the constant light's density claimed for the envmap's draws.
        let t = Chi2Test::new(SphereDomain::default());
        let r = t.run(|u| env.sample_infinite_direction(u).map(|(wi, _, _)| wi), |_| UNIFORM_SPHERE_PDF);
        assert!(!r.passed(), "{r}");
        // A directional light's direction is a delta: always the same.
        let d = Light::Directional { direction: Vec3::new(0.0, -1.0, 0.0), irradiance: Vec3::ONE };
        assert_eq!(d.sample_infinite_direction(Vec2::new(0.3, 0.9)).map(|s| s.0), Some(Vec3::Y));
    }
}
