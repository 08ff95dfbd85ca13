//! Scenes: loading Mitsuba XML into an editable description ([`xml`]), instantiating it
//! into the render-ready, immutable [`Scene`] ([`load`]), and the queries integrators make.

pub mod hair;
pub mod load;
pub mod mesh;
pub mod ply;
pub mod progress;
pub mod serialized;
pub mod shape;
pub mod vol;
pub mod xml;

use crate::accel::{Accel, Backend, BuildOptions, Hit, Ray};
use crate::bsdf::Bsdf;
use crate::camera::Camera;
use crate::film::Filter;
use crate::light::{Bounds, Light, LightSampler};
use crate::math::Rgb;
use crate::medium::Medium;
use glam::Vec3;
use shape::{Shape, SurfaceInteraction};
use std::path::PathBuf;

/// Image size and reconstruction filter (`hdrfilm`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilmSpec {
    pub width: u32,
    pub height: u32,
    pub filter: Filter,
    /// The 8-bit output of a low-dynamic-range film (`ldrfilm`): its tonemapping, and the
    /// format its default output takes (`png`); `None` for `hdrfilm`.
    pub ldr: Option<crate::image_io::tonemap::Ldr>,
}

/// The integrator the scene asks for, with the parameters all integrators share.
#[derive(Clone, Debug, PartialEq)]
pub struct IntegratorSpec {
    /// Plugin name in the scene file (`path`, …).
    pub plugin: String,
    /// Longest path, in segments from the camera; -1 = unlimited (Mitsuba's meaning).
    pub max_depth: i32,
    /// Depth from which Russian roulette may end paths.
    pub rr_depth: u32,
    /// Emitters seen directly by the camera are not shown.
    pub hide_emitters: bool,
    /// Mitsuba 0.5/0.6's `strictNormals` of the `path` integrator: a path ends where the
    /// geometric and the shading normal put the incident direction on different sides, and a
    /// light sample or a BSDF sample counts only where they agree on the outgoing one.
    pub strict_normals: bool,
}

/// Sample count, seed and kind of the scene's sampler.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SamplerSpec {
    pub spp: u32,
    pub seed: u64,
    pub kind: crate::sampling::SamplerKind,
}

/// Counts and warnings gathered while loading.
#[derive(Clone, Debug, Default)]
pub struct LoadStats {
    pub triangles: usize,
    pub vertices: usize,
    pub spheres: usize,
    /// Segments of the `hair` shapes.
    pub hair_segments: usize,
    /// Bytes of the shapes' vertex and triangle arrays (positions, normals, uvs, indices,
    /// emitters' sampling tables), not counting the accelerator's own copies and BVH.
    pub mesh_bytes: usize,
    /// Seconds spent reading the scene file and its meshes (everything before the BVH).
    pub read_seconds: f64,
    /// Seconds spent building the accelerator.
    pub bvh_seconds: f64,
    pub degenerate_triangles: usize,
    pub warnings: Vec<String>,
    /// Every file the scene was read from: the scene file, its includes, meshes and
    /// textures (what identifies a render's input, with the parameter overrides).
    pub files: Vec<std::path::PathBuf>,
}

/// Options for loading a scene.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// `-D name=value` parameter overrides.
    pub overrides: Vec<(String, String)>,
    pub backend: Backend,
    pub build: BuildOptions,
    /// Draw per-file and BVH-build progress on stderr when it is a terminal.
    pub progress: bool,
    /// Who picks the integrator instead of the scene file, for messages (`--integrator
    /// bdpt`). Then the file's `<integrator>` only gives what applies to any integrator
    /// (`max_depth`, `rr_depth`, `hide_emitters`): an unknown type or properties only
    /// another integrator reads are one warning instead of an error.
    pub integrator_override: Option<String>,
    /// The film size `(width, height)` instead of the scene's (`--resolution`).
    pub resolution: Option<(u32, u32)>,
    /// Threads that read the scene's files and build its tables (`--threads`; 0 = all cores).
    pub threads: usize,
}

/// Parses a film size `WxH` (`320x180`; `×` and `X` work too): both at least 1 and at most
/// 65536.
pub fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("\"{s}\" is not a resolution WxH (e.g. 320x180)");
    let (w, h) = s.trim().split_once(['x', 'X', '×']).ok_or_else(bad)?;
    let w: u32 = w.trim().parse().map_err(|_| bad())?;
    let h: u32 = h.trim().parse().map_err(|_| bad())?;
    if !(1..=65536).contains(&w) || !(1..=65536).contains(&h) {
        return Err(format!("\"{s}\": width and height must be between 1 and 65536"));
    }
    Ok((w, h))
}

/// The most null surfaces a ray crosses before it counts as blocked (a guard against
/// rays caught between coincident boundaries).
pub const MAX_NULL_CROSSINGS: usize = 256;

/// A render-ready scene.
pub struct Scene {
    pub path: PathBuf,
    pub shapes: Vec<Shape>,
    pub bsdfs: Vec<Bsdf>,
    pub lights: Vec<Light>,
    pub light_sampler: LightSampler,
    /// Indices of the lights at infinity (`constant`, `envmap`).
    pub infinite_lights: Vec<usize>,
    /// A sphere around all shapes (and the camera).
    pub bounds: Bounds,
    pub camera: Camera,
    pub film: FilmSpec,
    pub integrator: IntegratorSpec,
    pub sampler: SamplerSpec,
    pub accel: Accel,
    pub stats: LoadStats,
    /// The participating media that shapes bound (`Shape::media`) and the camera sits in.
    pub media: Vec<Medium>,
    /// The medium around the camera (`None`: vacuum).
    pub camera_medium: Option<u32>,
    /// Whether light meets media or null surfaces on its way (what an integrator without
    /// media refuses).
    pub volumetric: bool,
}

impl Scene {
    /// The closest surface along the ray.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceInteraction> {
        let hit = self.accel.intersect(ray)?;
        Some(self.interaction(ray, &hit))
    }

    /// The surface point of a hit along `ray` (as [`Scene::intersect`] gives it, for a hit
    /// found by a batch query).
    #[inline]
    pub fn interaction(&self, ray: &Ray, hit: &Hit) -> SurfaceInteraction {
        let shape = &self.shapes[hit.geom as usize];
        let mut si = shape.interaction(ray, hit);
        if let Some(p) = &self.bsdfs[shape.bsdf].perturbation {
            shape.perturb(&mut si, p);
        }
        si
    }

    /// `true` when something blocks the ray segment.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.accel.occluded(ray)
    }

    /// The BSDF of a surface point.
    #[inline]
    pub fn bsdf(&self, si: &SurfaceInteraction) -> &Bsdf {
        &self.bsdfs[self.bsdf_index(si)]
    }

    /// Where the BSDF of a surface point is in `bsdfs`.
    #[inline]
    pub fn bsdf_index(&self, si: &SurfaceInteraction) -> usize {
        self.shapes[si.shape as usize].bsdf
    }

    /// The medium a ray leaving the surface point `si` in direction `d` travels in, when the
    /// ray that reached it travelled in `current`.
    #[inline]
    pub fn medium_after(&self, si: &SurfaceInteraction, d: Vec3, current: Option<u32>) -> Option<u32> {
        self.shapes[si.shape as usize].media.map_or(current, |m| m.towards(si.ng, d))
    }

    /// The fraction of light that travels along the segment `ray` (from `ray.o` to
    /// `ray.at(ray.tmax)`) starting in `medium`: zero when a surface blocks it; null
    /// surfaces (medium boundaries) are crossed, each medium's transmittance applied on its
    /// stretch. Without media, a plain occlusion query.
    pub fn transmittance(&self, ray: &Ray, medium: Option<u32>) -> Rgb {
        self.transmittance_to(ray, medium, false)
    }

    /// [`Scene::transmittance`] towards a light at infinity (`infinite`), whose point
    /// `ray.at(ray.tmax)` stands for a direction: past the last surface a medium that
    /// nothing bounds goes on for ever, so light from infinity crosses all of it.
    pub fn transmittance_to(&self, ray: &Ray, mut medium: Option<u32>, infinite: bool) -> Rgb {
        if !self.volumetric {
            return if self.occluded(ray) { Rgb::ZERO } else { Rgb::ONE };
        }
        let end = ray.at(ray.tmax);
        let mut ray = *ray;
        let mut tr = Rgb::ONE;
        for _ in 0..MAX_NULL_CROSSINGS {
            let hit = self.intersect(&ray);
            if let Some(m) = medium {
                let len = ray.d.length();
                let d = match &hit {
                    Some(si) => si.t * len,
                    None if infinite => f32::INFINITY,
                    None => ray.tmax * len,
                };
                tr *= self.media[m as usize].transmittance(ray.o, ray.d / len, d);
            }
            let Some(si) = hit else {
                return tr;
            };
            if !self.bsdf(&si).is_null() || tr == Rgb::ZERO {
                return Rgb::ZERO;
            }
            medium = self.medium_after(&si, ray.d, medium);
            ray = si.spawn_ray_to(end);
        }
        Rgb::ZERO
    }

    /// The medium at the point `p`, for a point no walk reached (a light's position): the
    /// side facing `p` of the first surface bounding media that a ray from `p` meets (other
    /// surfaces are passed through); the camera's medium where no such surface is met.
    pub fn medium_at(&self, p: Vec3) -> Option<u32> {
        if self.media.is_empty() {
            return None;
        }
        // An arbitrary direction, unlikely to graze axis-aligned walls.
        let d = Vec3::new(0.2752, 0.9312, 0.2389).normalize();
        let mut ray = Ray::new(p, d);
        for _ in 0..MAX_NULL_CROSSINGS {
            let Some(si) = self.intersect(&ray) else { break };
            if let Some(m) = self.shapes[si.shape as usize].media {
                // Leaving along the normal means `p` is inside.
                return if si.ng.dot(d) > 0.0 { m.interior } else { m.exterior };
            }
            ray = si.spawn_ray(d);
        }
        self.camera_medium
    }

    /// The area light of a surface point, if its shape emits.
    #[inline]
    pub fn area_light(&self, si: &SurfaceInteraction) -> Option<(usize, &Light)> {
        self.shapes[si.shape as usize].light.map(|l| (l, &self.lights[l]))
    }
}
