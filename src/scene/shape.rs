//! Render-ready shapes: triangle meshes, exact spheres and hair, their surface interactions
//! and the area sampling that area lights use.

use super::hair::Hair;
use super::mesh::TriangleMesh;
use crate::accel::{Cutout, Geometry, Hit, Ray};
use crate::bsdf::At;
use crate::bsdf::perturb::{Perturbation, tangent_frame};
use crate::math::Frame;
use crate::sampling::{
    Distribution1D, square_to_uniform_cone, square_to_uniform_cone_pdf, square_to_uniform_sphere,
    square_to_uniform_triangle,
};
use crate::texture::Opacity;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::Arc;

#[derive(Clone, Debug)]
pub enum ShapeGeometry {
    Mesh(TriangleMesh),
    Sphere {
        center: Vec3,
        radius: f32,
    },
    /// Mitsuba 0.6's `hair`: strands of round segments ([`super::hair`]).
    Hair(Hair),
}

/// A shape of the scene with its material and (optional) area emitter.
#[derive(Clone, Debug)]
pub struct Shape {
    pub geometry: ShapeGeometry,
    /// Index into `Scene::bsdfs`.
    pub bsdf: usize,
    /// Index into `Scene::lights` when the shape emits.
    pub light: Option<usize>,
    /// Normals point inwards (Mitsuba's `flip_normals`).
    pub flip_normals: bool,
    /// The shape's `id` in the scene file, or its plugin name.
    pub name: String,
    /// The media on its two sides, where the shape bounds a medium (elsewhere a ray keeps
    /// the medium it travels in).
    pub media: Option<crate::medium::MediumInterface>,
    area: f32,
    /// Triangle (or hair segment) selection by area (meshes that emit; hair).
    area_distribution: Option<Distribution1D>,
    /// Unit normals of a sampled mesh's triangles (before `flip_normals`), filled with the
    /// area distribution: sampling a point then needs no cross product.
    sample_normals: Vec<Vec3>,
}

/// A point on a surface hit by a ray.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceInteraction {
    pub p: Vec3,
    pub t: f32,
    /// Geometric normal (after `flip_normals`).
    pub ng: Vec3,
    /// Shading frame (its `n` is the interpolated normal, after `flip_normals`).
    pub shading: Frame,
    pub uv: Vec2,
    /// The unperturbed shading normal in `shading` where a `bumpmap` or `normalmap` has
    /// perturbed it, `Vec3::Z` elsewhere (what the BSDF's side test and shadowing need).
    pub base_n: Vec3,
    pub shape: u32,
    pub prim: u32,
    /// Unit direction back along the incoming ray.
    pub wo: Vec3,
}

impl SurfaceInteraction {
    /// Where the BSDF is evaluated: texture coordinates and the unperturbed normal.
    #[inline]
    pub fn at(&self) -> At {
        At { uv: self.uv, base_n: self.base_n }
    }

    /// A ray leaving the surface in direction `d`, offset to avoid self-intersection.
    #[inline]
    pub fn spawn_ray(&self, d: Vec3) -> Ray {
        Ray::new(crate::math::offset_origin(self.p, self.ng, d), d)
    }

    /// A shadow ray towards `target` (stopping just short of it).
    #[inline]
    pub fn spawn_ray_to(&self, target: Vec3) -> Ray {
        let o = crate::math::offset_origin(self.p, self.ng, target - self.p);
        Ray::segment(o, target - o, 1.0 - crate::math::SHADOW_EPSILON)
    }
}

/// A point sampled on a shape.
#[derive(Clone, Copy, Debug)]
pub struct PositionSample {
    pub p: Vec3,
    pub n: Vec3,
    pub uv: Vec2,
}

impl Shape {
    pub fn new(geometry: ShapeGeometry, bsdf: usize, flip_normals: bool, name: String) -> Shape {
        let area = match &geometry {
            ShapeGeometry::Mesh(m) => (0..m.indices.len()).map(|i| m.triangle_area(i) as f64).sum::<f64>() as f32,
            ShapeGeometry::Sphere { radius, .. } => 4.0 * PI * radius * radius,
            ShapeGeometry::Hair(h) => h.area(),
        };
        Shape {
            geometry,
            bsdf,
            light: None,
            flip_normals,
            name,
            media: None,
            area,
            area_distribution: None,
            sample_normals: Vec::new(),
        }
    }

    /// Prepares area sampling (called for emitting shapes).
    pub fn prepare_sampling(&mut self) {
        match &self.geometry {
            ShapeGeometry::Mesh(m) => {
                let areas: Vec<f32> = (0..m.indices.len()).map(|i| m.triangle_area(i)).collect();
                self.area_distribution = Some(Distribution1D::new(&areas));
                self.sample_normals = (0..m.indices.len()).map(|i| m.triangle_normal(i)).collect();
            }
            ShapeGeometry::Hair(h) => {
                let lengths: Vec<f32> = (0..h.segments.len())
                    .map(|i| {
                        let (a, b) = h.segment(i);
                        (b - a).length()
                    })
                    .collect();
                self.area_distribution = Some(Distribution1D::new(&lengths));
            }
            ShapeGeometry::Sphere { .. } => {}
        }
    }

    pub fn area(&self) -> f32 {
        self.area
    }

    /// Bytes held by the shape's per-vertex and per-triangle arrays (the mesh and, for an
    /// emitting mesh, its sampling tables); for hair its vertices and segments; zero for a sphere.
    pub fn memory_bytes(&self) -> usize {
        if let ShapeGeometry::Hair(h) = &self.geometry {
            return h.memory_bytes();
        }
        let ShapeGeometry::Mesh(m) = &self.geometry else { return 0 };
        let vec3 = std::mem::size_of::<Vec3>();
        m.positions.capacity() * vec3
            + m.normals.as_ref().map_or(0, |n| n.capacity() * vec3)
            + m.uvs.as_ref().map_or(0, |t| t.capacity() * std::mem::size_of::<Vec2>())
            + m.indices.capacity() * std::mem::size_of::<[u32; 3]>()
            + self.sample_normals.capacity() * vec3
            + self.area_distribution.as_ref().map_or(0, |d| 2 * d.len() * std::mem::size_of::<f32>())
    }

    pub fn accel_geometry(&self) -> Geometry<'_> {
        match &self.geometry {
            ShapeGeometry::Mesh(m) => Geometry::Triangles { positions: &m.positions, indices: &m.indices },
            ShapeGeometry::Sphere { center, radius } => Geometry::Sphere { center: *center, radius: *radius },
            ShapeGeometry::Hair(h) => h.accel_geometry(),
        }
    }

    /// The cut-out a `mask` of this opacity makes of the shape (a mesh; `None` for a
    /// sphere or hair, or where the opacity is 1 everywhere).
    pub fn cutout(&self, opacity: &Arc<Opacity>) -> Option<Arc<dyn Cutout>> {
        let ShapeGeometry::Mesh(m) = &self.geometry else { return None };
        if matches!(**opacity, Opacity::Constant(a) if a >= 1.0) {
            return None;
        }
        Some(Arc::new(MeshCutout { indices: m.indices.clone(), uvs: m.uvs.clone(), opacity: opacity.clone() }))
    }

    /// The surface interaction of a hit on this shape.
    pub fn interaction(&self, ray: &Ray, hit: &Hit) -> SurfaceInteraction {
        let sign = if self.flip_normals { -1.0 } else { 1.0 };
        let wo = -ray.d.normalize();
        match &self.geometry {
            ShapeGeometry::Mesh(m) => {
                let tri = m.indices[hit.prim as usize];
                let [p0, p1, p2] = tri.map(|k| m.positions[k as usize]);
                let (b1, b2) = (hit.u, hit.v);
                let b0 = 1.0 - b1 - b2;
                let p = p0 * b0 + p1 * b1 + p2 * b2;
                let ng = (p1 - p0).cross(p2 - p0).normalize_or_zero() * sign;
                let ns = match &m.normals {
                    Some(n) => {
                        let [n0, n1, n2] = tri.map(|k| n[k as usize]);
                        let n = (n0 * b0 + n1 * b1 + n2 * b2).normalize_or_zero() * sign;
                        if n == Vec3::ZERO { ng } else { n }
                    }
                    None => ng,
                };
                let uv = match &m.uvs {
                    Some(t) => {
                        let [t0, t1, t2] = tri.map(|k| t[k as usize]);
                        t0 * b0 + t1 * b1 + t2 * b2
                    }
                    None => Vec2::new(b1, b2),
                };
                SurfaceInteraction {
                    p,
                    t: hit.t,
                    ng,
                    shading: Frame::from_normal(ns),
                    uv,
                    base_n: Vec3::Z,
                    shape: hit.geom,
                    prim: hit.prim,
                    wo,
                }
            }
            ShapeGeometry::Sphere { center, radius } => {
                let local = (ray.at(hit.t) - *center).normalize_or_zero();
                let p = *center + local * *radius;
                let n = local * sign;
                let uv = sphere_uv(local);
                SurfaceInteraction {
                    p,
                    t: hit.t,
                    ng: n,
                    shading: Frame::from_normal(n),
                    uv,
                    base_n: Vec3::Z,
                    shape: hit.geom,
                    prim: hit.prim,
                    wo,
                }
            }
            ShapeGeometry::Hair(h) => {
                let (p, n, frame, uv) = h.surface_point(hit.prim as usize, ray.at(hit.t));
                let shading = if self.flip_normals { Frame { s: frame.s, t: -frame.t, n: -n } } else { frame };
                SurfaceInteraction {
                    p,
                    t: hit.t,
                    ng: n * sign,
                    shading,
                    uv,
                    base_n: Vec3::Z,
                    shape: hit.geom,
                    prim: hit.prim,
                    wo,
                }
            }
        }
    }

    /// The partial derivatives `(dp/du, dp/dv)` of the surface at an interaction on it, as
    /// Mitsuba 3 defines them: on a mesh with texture coordinates from the triangle's
    /// positions and uvs (any tangent basis of the face normal when the uvs are
    /// degenerate), on a mesh without them the edges `p1 - p0`, `p2 - p0` (the barycentric
    /// parameterisation its `uv` then is); on a sphere those of its `(φ / 2π, θ / π)`; on
    /// hair those of the segment's cylinder ([`Hair::tangents`]).
    pub fn tangents(&self, si: &SurfaceInteraction) -> (Vec3, Vec3) {
        match &self.geometry {
            ShapeGeometry::Mesh(m) => {
                let tri = m.indices[si.prim as usize];
                let [p0, p1, p2] = tri.map(|k| m.positions[k as usize]);
                let (dp0, dp1) = (p1 - p0, p2 - p0);
                let Some(t) = &m.uvs else { return (dp0, dp1) };
                let [t0, t1, t2] = tri.map(|k| t[k as usize]);
                let (duv0, duv1) = (t1 - t0, t2 - t0);
                let det = duv0.x * duv1.y - duv0.y * duv1.x;
                if det == 0.0 {
                    let f = Frame::from_normal(dp0.cross(dp1).normalize_or_zero());
                    return (f.s, f.t);
                }
                let inv = 1.0 / det;
                ((dp0 * duv1.y - dp1 * duv0.y) * inv, (dp1 * duv0.x - dp0 * duv1.x) * inv)
            }
            ShapeGeometry::Sphere { center, radius } => {
                let local = (si.p - *center) / *radius;
                let dp_du = Vec3::new(-local.y, local.x, 0.0) * (2.0 * PI * radius);
                let rd = (local.x * local.x + local.y * local.y).sqrt();
                let dp_dv =
                    if rd == 0.0 { Vec3::X } else { Vec3::new(local.z * local.x / rd, local.z * local.y / rd, -rd) };
                (dp_du, dp_dv * (PI * radius))
            }
            ShapeGeometry::Hair(h) => {
                let n = if self.flip_normals { -si.ng } else { si.ng };
                h.tangents(si.prim as usize, n)
            }
        }
    }

    /// The partial derivatives `(∂n/∂u, ∂n/∂v)` of the unit shading normal at an interaction,
    /// in the parameterisation of [`Shape::tangents`] (what Manifold Exploration's
    /// constraint Jacobians need beside `dp/du`, `dp/dv`; contract `memlt.md`, "What the rest
    /// of a renderer must supply"). On a mesh with vertex normals the normal is the
    /// normalised barycentric interpolation `N / |N|`, whose derivative is
    /// `(∂N - n (n · ∂N)) / |N|`; on a mesh without them (and where the interpolation
    /// vanishes) it is the constant face normal, zero derivatives; on a sphere `n = (p - c) / r`;
    /// on hair the cylinder's normal, which turns around the axis only (`∂n/∂v = dp/dv / r`).
    /// Both after `flip_normals`. A `bumpmap` or `normalmap` is not differentiated: these
    /// are the derivatives of the unperturbed normal.
    pub fn normal_derivatives(&self, si: &SurfaceInteraction) -> (Vec3, Vec3) {
        let sign = if self.flip_normals { -1.0 } else { 1.0 };
        match &self.geometry {
            ShapeGeometry::Mesh(m) => {
                let Some(normals) = &m.normals else { return (Vec3::ZERO, Vec3::ZERO) };
                let tri = m.indices[si.prim as usize];
                let [p0, p1, p2] = tri.map(|k| m.positions[k as usize]);
                let [n0, n1, n2] = tri.map(|k| normals[k as usize]);
                let (e1, e2) = (p1 - p0, p2 - p0);
                // Barycentrics of the point, and their derivatives along u and v: both by
                // the normal equations of `e1 b1 + e2 b2 = x` in the triangle's plane.
                let (g11, g12, g22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
                let det = g11 * g22 - g12 * g12;
                if det == 0.0 || !det.is_finite() {
                    return (Vec3::ZERO, Vec3::ZERO);
                }
                let bary = |x: Vec3| {
                    let (r1, r2) = (e1.dot(x), e2.dot(x));
                    ((g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det)
                };
                let (b1, b2) = bary(si.p - p0);
                let big_n = n0 * (1.0 - b1 - b2) + n1 * b1 + n2 * b2;
                let len = big_n.length();
                if len == 0.0 || !len.is_finite() {
                    return (Vec3::ZERO, Vec3::ZERO);
                }
                let n = big_n / len;
                let (dp_du, dp_dv) = self.tangents(si);
                let d = |dp: Vec3| {
                    let (d1, d2) = bary(dp);
                    let dn = (n1 - n0) * d1 + (n2 - n0) * d2;
                    (dn - n * n.dot(dn)) / len * sign
                };
                (d(dp_du), d(dp_dv))
            }
            ShapeGeometry::Sphere { radius, .. } => {
                let (dp_du, dp_dv) = self.tangents(si);
                (dp_du * (sign / radius), dp_dv * (sign / radius))
            }
            ShapeGeometry::Hair(h) => {
                let (_, dp_dv) = self.tangents(si);
                (Vec3::ZERO, dp_dv * (sign / h.radius))
            }
        }
    }

    /// Perturbs the shading frame of an interaction on this shape (its BSDF's `bumpmap` or
    /// `normalmap`), around Mitsuba 3's frame of the unperturbed normal and `dp/du`.
    pub fn perturb(&self, si: &mut SurfaceInteraction, p: &Perturbation) {
        let (dp_du, dp_dv) = self.tangents(si);
        let base = tangent_frame(si.shading.n, dp_du);
        if let Some((frame, base_n)) = p.apply(&base, dp_du, dp_dv, si.ng, si.uv) {
            si.shading = frame;
            si.base_n = base_n;
        }
    }

    /// Samples a point uniformly by area; the density is `1 / area()`.
    pub fn sample_area(&self, u1: f32, u: Vec2) -> PositionSample {
        let sign = if self.flip_normals { -1.0 } else { 1.0 };
        match &self.geometry {
            ShapeGeometry::Mesh(m) => {
                let (i, _) = self
                    .area_distribution
                    .as_ref()
                    .map(|d| d.sample(u1))
                    .unwrap_or_else(|| ((u1 * m.indices.len() as f32) as usize % m.indices.len().max(1), 0.0));
                let tri = m.indices[i];
                let [p0, p1, p2] = tri.map(|k| m.positions[k as usize]);
                let b = square_to_uniform_triangle(u);
                let p = p0 * (1.0 - b.x - b.y) + p1 * b.x + p2 * b.y;
                let n = match self.sample_normals.get(i) {
                    Some(n) => *n,
                    None => m.triangle_normal(i),
                } * sign;
                let uv = match &m.uvs {
                    Some(t) => {
                        let [t0, t1, t2] = tri.map(|k| t[k as usize]);
                        t0 * (1.0 - b.x - b.y) + t1 * b.x + t2 * b.y
                    }
                    None => b,
                };
                PositionSample { p, n, uv }
            }
            ShapeGeometry::Sphere { center, radius } => {
                let d = square_to_uniform_sphere(u);
                PositionSample { p: *center + d * *radius, n: d * sign, uv: sphere_uv(d) }
            }
            ShapeGeometry::Hair(h) => {
                // A segment by length, then a point uniformly on its cylinder.
                let i = match &self.area_distribution {
                    Some(d) => d.sample(u1).0,
                    None => ((u1 * h.segments.len() as f32) as usize).min(h.segments.len() - 1),
                };
                let (a, b) = h.segment(i);
                let around = Frame::from_normal((b - a).normalize());
                let phi = 2.0 * PI * u.y;
                let on_axis = a + (b - a) * u.x;
                let (p, n, _, uv) = h.surface_point(i, on_axis + around.to_world(Vec3::new(phi.cos(), phi.sin(), 0.0)));
                PositionSample { p, n: n * sign, uv }
            }
        }
    }

    /// Samples a point on the shape as seen from `reference`, returning it with the
    /// solid-angle density at `reference`. Spheres sample the cone they subtend (when
    /// `reference` is outside); other shapes sample by area.
    pub fn sample_direction(&self, reference: Vec3, u1: f32, u: Vec2) -> Option<(PositionSample, f32)> {
        if let ShapeGeometry::Sphere { center, radius } = &self.geometry {
            let dc = *center - reference;
            let dist2 = dc.length_squared();
            if dist2 > radius * radius * (1.0 + 1e-4) {
                let dist = dist2.sqrt();
                let sin_max2 = radius * radius / dist2;
                let cos_max = (1.0 - sin_max2).max(0.0).sqrt();
                let frame = Frame::from_normal(dc / dist);
                let w = frame.to_world(square_to_uniform_cone(u, cos_max));
                // Nearest intersection of the ray reference + t w with the sphere.
                let b = w.dot(dc);
                let disc = (radius * radius - (dist2 - b * b)).max(0.0);
                let t = b - disc.sqrt();
                let local = (reference + w * t - *center).normalize_or_zero();
                let sign = if self.flip_normals { -1.0 } else { 1.0 };
                let ps = PositionSample { p: *center + local * *radius, n: local * sign, uv: sphere_uv(local) };
                return Some((ps, square_to_uniform_cone_pdf(cos_max)));
            }
        }
        let ps = self.sample_area(u1, u);
        let d = ps.p - reference;
        let dist2 = d.length_squared();
        let cos = ps.n.dot(-d).abs() / dist2.sqrt();
        if cos <= 0.0 || dist2 <= 0.0 {
            return None;
        }
        Some((ps, dist2 / (cos * self.area)))
    }

    /// The solid-angle density with which [`Shape::sample_direction`] from `reference`
    /// yields the point `p` with normal `n`.
    pub fn pdf_direction(&self, reference: Vec3, p: Vec3, n: Vec3) -> f32 {
        if let ShapeGeometry::Sphere { center, radius } = &self.geometry {
            let dist2 = (*center - reference).length_squared();
            if dist2 > radius * radius * (1.0 + 1e-4) {
                let cos_max = (1.0 - radius * radius / dist2).max(0.0).sqrt();
                return square_to_uniform_cone_pdf(cos_max);
            }
        }
        let d = p - reference;
        let dist2 = d.length_squared();
        let cos = n.dot(d).abs() / dist2.sqrt();
        if cos <= 0.0 { 0.0 } else { dist2 / (cos * self.area) }
    }
}

/// A mesh's cut-out: the opacity at the texture coordinates of a hit, interpolated as
/// [`Shape::interaction`] interpolates them (its own copy of the indices and uvs, which the
/// accelerator keeps as long as it lives).
struct MeshCutout {
    indices: Vec<[u32; 3]>,
    uvs: Option<Vec<Vec2>>,
    opacity: Arc<Opacity>,
}

impl Cutout for MeshCutout {
    fn opacity(&self, prim: u32, u: f32, v: f32) -> f32 {
        let uv = match (&self.uvs, self.indices.get(prim as usize)) {
            (Some(t), Some(tri)) => {
                let [t0, t1, t2] = tri.map(|k| t[k as usize]);
                t0 * (1.0 - u - v) + t1 * u + t2 * v
            }
            _ => Vec2::new(u, v),
        };
        self.opacity.eval(uv)
    }
}

/// Mitsuba's sphere parameterisation: `u = φ / 2π`, `v = θ / π`.
fn sphere_uv(local: Vec3) -> Vec2 {
    let mut phi = local.y.atan2(local.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    Vec2::new(phi / (2.0 * PI), local.z.clamp(-1.0, 1.0).acos() / PI)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hit at barycentrics `(b1, b2)` of triangle 0.
    fn mesh_hit(shape: &Shape, b1: f32, b2: f32) -> SurfaceInteraction {
        let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z);
        shape.interaction(&ray, &Hit { t: 1.0, geom: 0, prim: 0, u: b1, v: b2 })
    }

    /// The barycentrics of a point of triangle 0's plane, by Cramer's rule on cross products
    /// (not the normal equations `normal_derivatives` uses).
    fn barycentrics(m: &TriangleMesh, p: Vec3) -> (f32, f32) {
        let [p0, p1, p2] = m.triangle(0);
        let (e1, e2, x) = (p1 - p0, p2 - p0, p - p0);
        let n = e1.cross(e2);
        (x.cross(e2).dot(n) / n.length_squared(), e1.cross(x).dot(n) / n.length_squared())
    }

    /// Central differences of the shading normal along `dp/du` and `dp/dv`, stepping `h`
    /// in the parameters, against `normal_derivatives`; returns the largest difference
    /// relative to the derivatives' size, and that size.
    fn compare(shape: &Shape, si: &SurfaceInteraction, at: impl Fn(Vec3) -> SurfaceInteraction, h: f32) -> (f32, f32) {
        let (dp_du, dp_dv) = shape.tangents(si);
        let (dn_du, dn_dv) = shape.normal_derivatives(si);
        let scale = dn_du.length().max(dn_dv.length());
        let mut worst = 0.0f32;
        for (dp, dn) in [(dp_du, dn_du), (dp_dv, dn_dv)] {
            let fd = (at(si.p + dp * h).shading.n - at(si.p - dp * h).shading.n) / (2.0 * h);
            worst = worst.max((fd - dn).length() / scale.max(1e-6));
            // The derivative of a unit vector is orthogonal to it.
            assert!(dn.dot(si.shading.n).abs() <= 1e-4 * scale.max(1.0), "{dn} not tangent to {}", si.shading.n);
        }
        (worst, scale)
    }

    fn curved_triangle(uvs: Option<Vec<Vec2>>) -> TriangleMesh {
        TriangleMesh {
            positions: vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(2.0, 0.3, 0.1), Vec3::new(0.4, 1.5, -0.2)],
            normals: Some(vec![
                Vec3::new(-0.3, -0.2, 1.0).normalize(),
                Vec3::new(0.5, 0.1, 1.0).normalize(),
                Vec3::new(0.0, 0.6, 1.0).normalize(),
            ]),
            uvs,
            indices: vec![[0, 1, 2]],
        }
    }

    #[test]
    fn mesh_normal_derivatives_match_finite_differences() {
        let skewed = Some(vec![Vec2::new(0.1, 0.2), Vec2::new(0.9, 0.35), Vec2::new(0.3, 1.1)]);
        let degenerate = Some(vec![Vec2::splat(0.5); 3]);
        for (name, uvs) in [("uvs", skewed), ("no uvs", None), ("degenerate uvs", degenerate)] {
            for flip in [false, true] {
                let shape = Shape::new(ShapeGeometry::Mesh(curved_triangle(uvs.clone())), 0, flip, name.into());
                let ShapeGeometry::Mesh(m) = &shape.geometry else { unreachable!() };
                for (b1, b2) in [(0.2, 0.3), (0.6, 0.1), (0.1, 0.7)] {
                    let si = mesh_hit(&shape, b1, b2);
                    let at = |p: Vec3| {
                        let (c1, c2) = barycentrics(m, p);
                        mesh_hit(&shape, c1, c2)
                    };
                    let (err, scale) = compare(&shape, &si, at, 1e-3);
                    assert!(err < 1e-2, "{name}, flip {flip}, ({b1}, {b2}): relative error {err}");
                    // The normals bend: a zero derivative would fail the comparison.
                    assert!(scale > 0.05, "{name}: the test triangle's normals must vary ({scale})");
                }
            }
        }
    }

    #[test]
    fn sphere_normal_derivatives_match_finite_differences() {
        let (center, radius) = (Vec3::new(0.5, -1.0, 2.0), 1.7);
        for flip in [false, true] {
            let shape = Shape::new(ShapeGeometry::Sphere { center, radius }, 0, flip, "sphere".into());
            // A ray from outside towards the surface point in direction `dir` from the centre.
            let hit_towards = |p: Vec3| {
                let dir = (p - center).normalize();
                let ray = Ray::new(center + dir * (3.0 * radius), -dir);
                shape.interaction(&ray, &Hit { t: 2.0 * radius, geom: 0, prim: 0, u: 0.0, v: 0.0 })
            };
            for dir in [Vec3::new(0.3, 0.4, 0.5), Vec3::new(-0.7, 0.2, -0.3), Vec3::new(0.1, -0.9, 0.2)] {
                let si = hit_towards(center + dir.normalize() * radius);
                let (err, scale) = compare(&shape, &si, hit_towards, 1e-3);
                assert!(err < 1e-2, "flip {flip}, {dir}: relative error {err}");
                assert!(scale > 0.5, "{scale}");
            }
        }
    }

    #[test]
    fn hair_is_sampled_uniformly_on_its_cylinders() {
        use crate::scene::hair::{Hair, HairParams, Strands};
        // Segments of lengths 1 and 3: a quarter of the samples on the first.
        let strands = Strands { vertices: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 3.0, 0.0)], starts: vec![0] };
        let params = HairParams { radius: 0.1, angle_threshold: 0.0, reduction: 0.0 };
        let hair = Hair::build(&strands, &crate::math::Transform::default(), params).unwrap();
        let mut shape = Shape::new(ShapeGeometry::Hair(hair), 0, false, "hair".into());
        shape.prepare_sampling();
        assert!((shape.area() - 2.0 * PI * 0.1 * 4.0).abs() < 1e-5);
        let mut sampler = crate::sampling::Sampler::new(&[9]);
        let n = 20_000;
        let mut on_first = 0;
        for _ in 0..n {
            let ps = shape.sample_area(sampler.next_1d(), sampler.next_2d());
            // The first segment's normals are perpendicular to x, the second's to y.
            let first = ps.n.x.abs() < 1e-5;
            let (axis, dist) = if first {
                (Vec3::X, Vec2::new(ps.p.y, ps.p.z).length())
            } else {
                (Vec3::Y, Vec2::new(ps.p.x - 1.0, ps.p.z).length())
            };
            on_first += usize::from(first);
            assert!((dist - 0.1).abs() < 1e-5 && ps.n.dot(axis).abs() < 1e-5, "{ps:?}");
            assert!((ps.n.length() - 1.0).abs() < 1e-5 && (0.0..=1.0).contains(&ps.uv.x));
        }
        let share = on_first as f32 / n as f32;
        assert!((share - 0.25).abs() < 0.015, "{share}");
    }

    #[test]
    fn flat_meshes_have_constant_normals() {
        let mut m = curved_triangle(None);
        m.normals = None;
        let shape = Shape::new(ShapeGeometry::Mesh(m), 0, false, "flat".into());
        assert_eq!(shape.normal_derivatives(&mesh_hit(&shape, 0.3, 0.3)), (Vec3::ZERO, Vec3::ZERO));
    }
}
