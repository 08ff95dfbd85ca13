//! What the ray-query backends share: rays and hits, the geometry they are built over,
//! cutouts (alpha masks) that reject hits, the build options and the build errors.

use glam::Vec3;
use std::sync::Arc;

/// A ray segment `o + t d` for `t` in `[tmin, tmax]`. `d` need not be normalised.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub o: Vec3,
    pub d: Vec3,
    pub tmin: f32,
    pub tmax: f32,
}

impl Ray {
    pub fn new(o: Vec3, d: Vec3) -> Ray {
        Ray { o, d, tmin: 0.0, tmax: f32::INFINITY }
    }

    pub fn segment(o: Vec3, d: Vec3, tmax: f32) -> Ray {
        Ray { o, d, tmin: 0.0, tmax }
    }

    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }
}

/// A closest hit: which primitive of which geometry, where along the ray, and the
/// barycentric coordinates `(u, v)` with `p = (1-u-v) p0 + u p1 + v p2` for triangles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub geom: u32,
    pub prim: u32,
    pub u: f32,
    pub v: f32,
}

/// What the accelerator is built from: one entry per scene shape, in shape order, so the
/// geometry id of a hit is the shape index.
#[derive(Clone, Copy, Debug)]
pub enum Geometry<'a> {
    Triangles {
        positions: &'a [Vec3],
        indices: &'a [[u32; 3]],
    },
    Sphere {
        center: Vec3,
        radius: f32,
    },
    /// Strands of straight segments of one radius (a `hair` shape), traced as Embree's
    /// round linear curves ([`crate::accel::curve`]): segment `i` runs from vertex
    /// `segments[i]` to the next one, and `flags[i]` says which neighbours it has
    /// ([`crate::accel::curve::LEFT`], [`crate::accel::curve::RIGHT`]). The primitive id of
    /// a hit is the segment; its `u` is the position along the segment (0 to 1), `v` is 0.
    Curves {
        vertices: &'a [Vec3],
        segments: &'a [u32],
        flags: &'a [u8],
        radius: f32,
    },
}

/// A cut-out (Mitsuba's `mask` BSDF) on a triangle mesh: the opacity `α` in `[0, 1]` at a
/// hit. Both backends skip a hit where [`keeps_hit`] says so, for every kind of query, so a
/// transparent part of a surface is never hit nor blocks a shadow ray.
pub trait Cutout: Send + Sync {
    /// The opacity at the hit of triangle `prim` with barycentric coordinates `(u, v)` (as
    /// in [`Hit`]).
    fn opacity(&self, prim: u32, u: f32, v: f32) -> f32;
}

/// The cut-outs of a scene: `(geometry id, cut-out)` pairs for the triangle meshes that have
/// one.
pub type Cutouts = [(u32, Arc<dyn Cutout>)];

/// Whether a hit on a geometry with a cut-out counts: always where the opacity `α` is 1,
/// never where it is 0, and in between with probability `α`, decided by a hash of the ray
/// (origin and direction, bit for bit) and the hit primitive (pbrt-v4's stochastic alpha).
/// The same query gets the same answer in both backends and on every thread, and a hit
/// that is kept is fully opaque: every ray, traced or a shadow ray, passes a surface of
/// opacity `α` with probability `1 - α`, so every estimator keeps its expectation.
#[inline]
pub fn keeps_hit(cutout: &dyn Cutout, ray: &Ray, geom: u32, prim: u32, u: f32, v: f32) -> bool {
    let alpha = cutout.opacity(prim, u, v);
    if alpha >= 1.0 {
        return true;
    }
    if alpha.is_nan() || alpha <= 0.0 {
        return false;
    }
    hit_hash01(ray, geom, prim) < alpha
}

/// A number in `[0, 1)` from the ray's origin and direction bits and the hit's ids.
#[inline]
pub fn hit_hash01(ray: &Ray, geom: u32, prim: u32) -> f32 {
    #[inline]
    fn mix(h: u64) -> u64 {
        // SplitMix64's finaliser.
        let mut z = h.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    let words = [
        ((ray.o.x.to_bits() as u64) << 32) | ray.o.y.to_bits() as u64,
        ((ray.o.z.to_bits() as u64) << 32) | ray.d.x.to_bits() as u64,
        ((ray.d.y.to_bits() as u64) << 32) | ray.d.z.to_bits() as u64,
        ((geom as u64) << 32) | prim as u64,
    ];
    let h = words.iter().fold(0x5851_f42d_4c95_7f2d_u64, |h, &w| mix(h ^ w));
    (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// Build quality of the acceleration structure (Embree's `RTCBuildQuality`; for obvhs the
/// build presets `fast`, `medium`, `slow`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum BuildQuality {
    Low,
    #[default]
    Medium,
    High,
}

/// How Embree arranges its BVH over the scene's shapes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum BvhLayout {
    /// One BVH over all triangles of all shapes, built at the scene's build quality.
    Flat,
    /// One BVH per shape (built at the build quality) under a BVH over the shapes: Embree's
    /// two-level structure (`RTC_BUILD_QUALITY_LOW` for the scene). Faster to trace in scenes
    /// made of a few separate shapes (BENCHMARKS.md, "Embree's BVH layout").
    #[default]
    TwoLevel,
}

/// Options for building an accelerator.
#[derive(Clone, Debug, Default)]
pub struct BuildOptions {
    /// Build quality of the BVH (with the two-level layout: of each shape's BVH).
    pub quality: BuildQuality,
    /// Embree's BVH layout; the obvhs backend always builds one BVH over all primitives.
    pub layout: BvhLayout,
    /// Embree's `RTC_SCENE_FLAG_ROBUST`: avoids optimisations that reduce arithmetic accuracy.
    pub robust: bool,
    /// Embree's `RTC_SCENE_FLAG_COMPACT`: a more memory-frugal layout.
    pub compact: bool,
    /// Embree device configuration (`key=value` pairs separated by commas, such as
    /// `max_isa=avx2` or `threads=1`), appended to the `PCBPT_EMBREE_CONFIG` environment
    /// variable's; see [`embree::device_config`]. obvhs ignores it.
    pub embree_config: Option<String>,
}

/// An error while building an accelerator.
#[derive(Debug, thiserror::Error)]
pub enum AccelError {
    #[error("Embree: {0}")]
    Embree(String),
    #[error("the obvhs backend is not compiled in; rebuild with `--features obvhs`")]
    ObvhsDisabled,
    #[error("{0}")]
    Unsupported(&'static str),
    #[error("geometry {index}: {message}")]
    BadGeometry { index: usize, message: String },
}
