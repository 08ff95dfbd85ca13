//! Ray queries (contract §7): one small interface, two backends.
//!
//! [`Accel`] answers closest-hit and occlusion queries, for single rays and batches, over
//! the scene's primitives: triangle meshes, exact spheres and hair ([`curve`]: strands of
//! round linear segments). The default backend is the
//! system Embree ([`embree`], over the raw bindings of our own bindgen layer, [`crate::ffi::embree`]);
//! with the `obvhs` feature the pure-Rust CWBVH of the `obvhs` crate ([`bvh`]) is
//! available too, and both report the same hits (up to floating-point ties at shared edges).

#[cfg(feature = "obvhs")]
pub mod bvh;
pub mod curve;
#[allow(unsafe_code)]
pub mod embree;
pub mod query;
#[cfg(feature = "ray-record")]
pub mod record;
pub use query::{
    AccelError, BuildOptions, BuildQuality, BvhLayout, Cutout, Cutouts, Geometry, Hit, Ray, hit_hash01, keeps_hit,
};

use glam::Vec3;
use std::fmt;

/// The ray-tracing backend to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Backend {
    #[default]
    Embree,
    Obvhs,
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Backend::Embree => "embree",
            Backend::Obvhs => "obvhs",
        })
    }
}

/// A built acceleration structure over the scene's shapes.
pub enum Accel {
    Embree(embree::EmbreeScene),
    #[cfg(feature = "obvhs")]
    Obvhs(bvh::ObvhsScene),
}

impl Accel {
    pub fn build(backend: Backend, geometry: &[Geometry<'_>], options: BuildOptions) -> Result<Accel, AccelError> {
        Accel::build_with_cutouts(backend, geometry, &[], options)
    }

    /// As [`Accel::build`], with cut-outs on some geometries (each id at most once): their
    /// hits are kept or skipped by [`keeps_hit`] in every query.
    pub fn build_with_cutouts(
        backend: Backend,
        geometry: &[Geometry<'_>],
        cutouts: &Cutouts,
        options: BuildOptions,
    ) -> Result<Accel, AccelError> {
        validate(geometry)?;
        let mut seen = vec![false; geometry.len()];
        for (g, _) in cutouts {
            let index = *g as usize;
            match (seen.get_mut(index), geometry.get(index)) {
                (Some(s), Some(Geometry::Triangles { .. })) if !*s => *s = true,
                _ => {
                    return Err(AccelError::BadGeometry {
                        index,
                        message: "a cut-out needs a triangle mesh that exists and has no other cut-out".into(),
                    });
                }
            }
        }
        match backend {
            Backend::Embree => Ok(Accel::Embree(embree::EmbreeScene::build(geometry, cutouts, &options)?)),
            #[cfg(feature = "obvhs")]
            Backend::Obvhs => Ok(Accel::Obvhs(bvh::ObvhsScene::build(geometry, cutouts, options))),
            #[cfg(not(feature = "obvhs"))]
            Backend::Obvhs => Err(AccelError::ObvhsDisabled),
        }
    }

    pub fn backend(&self) -> Backend {
        match self {
            Accel::Embree(_) => Backend::Embree,
            #[cfg(feature = "obvhs")]
            Accel::Obvhs(_) => Backend::Obvhs,
        }
    }

    /// The closest hit along the ray, if any.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        #[cfg(feature = "ray-record")]
        record::push(record::Query::Intersect(*ray));
        match self {
            Accel::Embree(s) => s.intersect(ray),
            #[cfg(feature = "obvhs")]
            Accel::Obvhs(s) => s.intersect(ray),
        }
    }

    /// `true` when anything blocks the ray within `[tmin, tmax]`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        #[cfg(feature = "ray-record")]
        record::push(record::Query::Occluded(*ray));
        match self {
            Accel::Embree(s) => s.occluded(ray),
            #[cfg(feature = "obvhs")]
            Accel::Obvhs(s) => s.occluded(ray),
        }
    }

    /// Closest hits for a batch of rays; `coherent` tells the backend the rays are similar
    /// (camera rays), which Embree's stream traversal can exploit.
    pub fn intersect_batch(&self, rays: &[Ray], coherent: bool, out: &mut Vec<Option<Hit>>) {
        #[cfg(feature = "ray-record")]
        rays.iter().for_each(|r| record::push(record::Query::Intersect(*r)));
        out.clear();
        match self {
            Accel::Embree(s) => s.intersect_batch(rays, coherent, out),
            #[cfg(feature = "obvhs")]
            Accel::Obvhs(s) => out.extend(rays.iter().map(|r| s.intersect(r))),
        }
    }

    /// Occlusion for a batch of rays.
    pub fn occluded_batch(&self, rays: &[Ray], coherent: bool, out: &mut Vec<bool>) {
        #[cfg(feature = "ray-record")]
        rays.iter().for_each(|r| record::push(record::Query::Occluded(*r)));
        out.clear();
        match self {
            Accel::Embree(s) => s.occluded_batch(rays, coherent, out),
            #[cfg(feature = "obvhs")]
            Accel::Obvhs(s) => out.extend(rays.iter().map(|r| s.occluded(r))),
        }
    }
}

fn validate(geometry: &[Geometry<'_>]) -> Result<(), AccelError> {
    for (index, g) in geometry.iter().enumerate() {
        let bad = |message: String| Err(AccelError::BadGeometry { index, message });
        match g {
            Geometry::Triangles { positions, indices } => {
                if let Some(p) = positions.iter().find(|p| !p.is_finite()) {
                    return bad(format!("non-finite vertex {p}"));
                }
                let n = positions.len() as u32;
                if let Some(t) = indices.iter().find(|t| t.iter().any(|&i| i >= n)) {
                    return bad(format!("triangle {t:?} indexes past the {n} vertices"));
                }
            }
            Geometry::Sphere { center, radius } => {
                if !(center.is_finite() && radius.is_finite() && *radius > 0.0) {
                    return bad(format!("sphere at {center} with radius {radius}"));
                }
            }
            Geometry::Curves { vertices, segments, flags, radius } => {
                if !(radius.is_finite() && *radius > 0.0) {
                    return bad(format!("curves of radius {radius}"));
                }
                if let Some(p) = vertices.iter().find(|p| !p.is_finite()) {
                    return bad(format!("non-finite vertex {p}"));
                }
                if flags.len() != segments.len() {
                    return bad(format!("{} curve flags for {} segments", flags.len(), segments.len()));
                }
                let n = vertices.len();
                let fits = |&(&k, &f): &(&u32, &u8)| {
                    let k = k as usize;
                    k + 1 < n
                        && (f & curve::LEFT == 0 || k >= 1)
                        && (f & curve::RIGHT == 0 || k + 2 < n)
                        && f & !(curve::LEFT | curve::RIGHT) == 0
                };
                if let Some((k, f)) = segments.iter().zip(flags.iter()).find(|s| !fits(s)) {
                    return bad(format!("segment from vertex {k} (flags {f}) does not fit the {n} vertices"));
                }
            }
        }
    }
    Ok(())
}

/// Watertight-enough ray–triangle test (Möller–Trumbore) shared by the pure-Rust backend
/// and the tests: returns `(t, u, v)` with Embree's barycentric convention.
#[inline]
pub fn intersect_triangle(ray: &Ray, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<(f32, f32, f32)> {
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let pvec = ray.d.cross(e2);
    let det = e1.dot(pvec);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let tvec = ray.o - p0;
    let u = tvec.dot(pvec) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qvec = tvec.cross(e1);
    let v = ray.d.dot(qvec) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(qvec) * inv;
    (t > ray.tmin && t <= ray.tmax).then_some((t, u, v))
}

/// Ray–sphere intersection: the nearest root inside `(tmin, tmax]`.
#[inline]
pub fn intersect_sphere(ray: &Ray, center: Vec3, radius: f32) -> Option<f32> {
    // Solved in f64: the f32 discriminant loses the hit for grazing rays from afar.
    let o = (ray.o - center).as_dvec3();
    let d = ray.d.as_dvec3();
    let a = d.length_squared();
    let b = o.dot(d);
    let c = o.length_squared() - (radius as f64) * (radius as f64);
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    let q = if b < 0.0 { -b + sq } else { -b - sq };
    let (mut t0, mut t1) = (q / a, c / q);
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    let (tmin, tmax) = (ray.tmin as f64, ray.tmax as f64);
    [t0, t1].into_iter().find(|&t| t > tmin && t <= tmax).map(|t| t as f32)
}
