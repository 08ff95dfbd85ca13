//! Emitters: a closed set dispatched through an enum, and light selection by power.

use crate::math::{Rgb, luminance};
use crate::sampling::Distribution1D;
use crate::scene::shape::{Shape, SurfaceInteraction};
use crate::texture::Texture;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

#[derive(Clone, Debug)]
pub enum Light {
    /// Mitsuba's `area`: one-sided emission from the front of the shape's normal.
    Area { shape: usize, radiance: Texture },
    /// Mitsuba's `point`: isotropic intensity at a position.
    Point { position: Vec3, intensity: Rgb },
}

/// A sample of incident light at a reference point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the reference point to the light.
    pub wi: Vec3,
    /// Point on the light.
    pub p: Vec3,
    /// Its normal (zero for point lights).
    pub n: Vec3,
    /// Incident radiance (or intensity / d² for point lights).
    pub li: Rgb,
    /// Solid-angle density (for delta lights, the density of the delta, 1).
    pub pdf: f32,
    /// The light is a delta distribution in direction (a point light).
    pub delta: bool,
}

impl Light {
    /// Emitted power (luminance), used for light selection.
    pub fn power(&self, shapes: &[Shape]) -> f32 {
        match self {
            Light::Area { shape, radiance } => PI * shapes[*shape].area() * luminance(radiance.mean()),
            Light::Point { intensity, .. } => 4.0 * PI * luminance(*intensity),
        }
    }

    /// Radiance leaving an area light at a surface point towards `w` (unit, away from it).
    #[inline]
    pub fn radiance(&self, ng: Vec3, uv: Vec2, w: Vec3) -> Rgb {
        match self {
            Light::Area { radiance, .. } => {
                if ng.dot(w) > 0.0 {
                    radiance.eval(uv)
                } else {
                    Rgb::ZERO
                }
            }
            Light::Point { .. } => Rgb::ZERO,
        }
    }

    /// Samples incident light at `reference`.
    pub fn sample_li(&self, shapes: &[Shape], reference: Vec3, u1: f32, u: Vec2) -> Option<LightSample> {
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
        }
    }

    /// Solid-angle density of `sample_li` from `reference` producing the surface point `si`.
    pub fn pdf_li(&self, shapes: &[Shape], reference: Vec3, si: &SurfaceInteraction) -> f32 {
        match self {
            Light::Area { shape, .. } => shapes[*shape].pdf_direction(reference, si.p, si.ng),
            Light::Point { .. } => 0.0,
        }
    }

    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. })
    }
}

/// Chooses lights proportionally to their power.
#[derive(Clone, Debug)]
pub struct LightSampler {
    distribution: Option<Distribution1D>,
}

impl LightSampler {
    pub fn new(lights: &[Light], shapes: &[Shape]) -> LightSampler {
        if lights.is_empty() {
            return LightSampler { distribution: None };
        }
        let powers: Vec<f32> = lights.iter().map(|l| l.power(shapes)).collect();
        LightSampler { distribution: Some(Distribution1D::new(&powers)) }
    }

    /// Picks a light: its index, its probability, and `u` rescaled for reuse.
    #[inline]
    pub fn sample(&self, u: f32) -> Option<(usize, f32, f32)> {
        let d = self.distribution.as_ref()?;
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
            |u| light.sample_li(&shapes, reference, u1.next_1d(), u).map(|s| s.wi),
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
            |u| light.sample_li(&shapes, Vec3::ZERO, u1.next_1d(), u).map(|s| s.wi),
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
}
