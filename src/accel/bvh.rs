//! The pure-Rust backend: a compressed wide BVH (CWBVH) from the `obvhs` crate over the
//! same triangles, spheres and hair segments Embree sees, with our own primitive tests
//! (for hair, [`super::curve`]'s round linear segments). Exists so that
//! every result can be cross-checked against Embree, ray by ray.

use super::curve::{LEFT, RIGHT, intersect_round_segment};
use super::{
    BuildOptions, BuildQuality, Cutout, Cutouts, Geometry, Hit, Ray, intersect_sphere, intersect_triangle, keeps_hit,
};
use glam::{Vec3, Vec3A};
use obvhs::{BvhBuildParams, aabb::Aabb, cwbvh::CwBvh, cwbvh::builder::build_cwbvh, ray::RayHit};
use std::sync::Arc;

#[derive(Clone, Copy)]
enum Prim {
    Triangle {
        p: [Vec3; 3],
    },
    Sphere {
        center: Vec3,
        radius: f32,
    },
    /// Segment `seg` of the hair in `curves[curve]`.
    Segment {
        curve: u32,
        seg: u32,
    },
}

/// A hair geometry's own copy of its strands.
struct Curves {
    vertices: Vec<Vec3>,
    segments: Vec<u32>,
    flags: Vec<u8>,
    radius: f32,
}

impl Curves {
    /// The segment's end vertices.
    fn ends(&self, seg: u32) -> (Vec3, Vec3) {
        let k = self.segments[seg as usize] as usize;
        (self.vertices[k], self.vertices[k + 1])
    }

    /// The first hit on segment `seg` (distance and position along it).
    fn intersect(&self, r: &Ray, seg: u32) -> Option<(f32, f32)> {
        let k = self.segments[seg as usize] as usize;
        let f = self.flags[seg as usize];
        let left = (f & LEFT != 0).then(|| self.vertices[k - 1]);
        let right = (f & RIGHT != 0).then(|| self.vertices[k + 2]);
        intersect_round_segment(r, self.vertices[k], self.vertices[k + 1], left, right, self.radius)
    }
}

pub struct ObvhsScene {
    bvh: CwBvh,
    /// Primitives in BVH leaf order, so traversal indexes them directly.
    prims: Vec<Prim>,
    /// (geometry id, primitive id) of each entry of `prims`.
    ids: Vec<(u32, u32)>,
    /// The cut-out of each geometry, if it has one.
    cutouts: Vec<Option<Arc<dyn Cutout>>>,
    /// The hair geometries that `Prim::Segment` refers to.
    curves: Vec<Curves>,
}

impl ObvhsScene {
    pub fn build(geometry: &[Geometry<'_>], cutouts: &Cutouts, options: BuildOptions) -> ObvhsScene {
        let mut prims = Vec::new();
        let mut ids = Vec::new();
        let mut curves = Vec::new();
        for (g, geom) in geometry.iter().enumerate() {
            match geom {
                Geometry::Triangles { positions, indices } => {
                    for (i, t) in indices.iter().enumerate() {
                        prims.push(Prim::Triangle { p: t.map(|k| positions[k as usize]) });
                        ids.push((g as u32, i as u32));
                    }
                }
                Geometry::Sphere { center, radius } => {
                    prims.push(Prim::Sphere { center: *center, radius: *radius });
                    ids.push((g as u32, 0));
                }
                Geometry::Curves { vertices, segments, flags, radius } => {
                    for i in 0..segments.len() {
                        prims.push(Prim::Segment { curve: curves.len() as u32, seg: i as u32 });
                        ids.push((g as u32, i as u32));
                    }
                    curves.push(Curves {
                        vertices: vertices.to_vec(),
                        segments: segments.to_vec(),
                        flags: flags.to_vec(),
                        radius: *radius,
                    });
                }
            }
        }
        let aabbs: Vec<Aabb> = prims
            .iter()
            .map(|p| match p {
                Prim::Triangle { p } => Aabb::from_points(&p.map(Vec3A::from)),
                Prim::Sphere { center, radius } => {
                    Aabb::new(Vec3A::from(*center - Vec3::splat(*radius)), Vec3A::from(*center + Vec3::splat(*radius)))
                }
                Prim::Segment { curve, seg } => {
                    let c = &curves[*curve as usize];
                    let (a, b) = c.ends(*seg);
                    let r = Vec3::splat(c.radius);
                    Aabb::new(Vec3A::from(a.min(b) - r), Vec3A::from(a.max(b) + r))
                }
            })
            .collect();
        let params = match options.quality {
            BuildQuality::Low => BvhBuildParams::fast_build(),
            BuildQuality::Medium => BvhBuildParams::medium_build(),
            BuildQuality::High => BvhBuildParams::slow_build(),
        };
        let mut build_time = std::time::Duration::ZERO;
        let bvh = if aabbs.is_empty() { CwBvh::default() } else { build_cwbvh(&aabbs, params, &mut build_time) };
        let ordered = bvh.primitive_indices.iter().map(|&i| prims[i as usize]).collect();
        let ordered_ids = bvh.primitive_indices.iter().map(|&i| ids[i as usize]).collect();
        let mut by_geometry: Vec<Option<Arc<dyn Cutout>>> = vec![None; geometry.len()];
        for (g, c) in cutouts {
            by_geometry[*g as usize] = Some(c.clone());
        }
        ObvhsScene { bvh, prims: ordered, ids: ordered_ids, cutouts: by_geometry, curves }
    }

    /// Whether a hit with barycentrics `(u, v)` on leaf triangle `id` counts (its
    /// geometry's cut-out, if any, keeps it).
    #[inline]
    fn keeps(&self, r: &Ray, id: usize, u: f32, v: f32) -> bool {
        let (geom, prim) = self.ids[id];
        match &self.cutouts[geom as usize] {
            None => true,
            Some(c) => keeps_hit(c.as_ref(), r, geom, prim, u, v),
        }
    }

    fn bvh_ray(r: &Ray) -> obvhs::ray::Ray {
        // obvhs takes a component of -0 as positive for the ray's octant but inverts it to a
        // large negative number, and then misses every box: adding +0 turns -0 into +0.
        let d = Vec3A::from(r.d) + Vec3A::ZERO;
        obvhs::ray::Ray::new(Vec3A::from(r.o), d, r.tmin, r.tmax)
    }

    pub fn intersect(&self, r: &Ray) -> Option<Hit> {
        if self.prims.is_empty() {
            return None;
        }
        let mut best: Option<(f32, u32, f32, f32)> = None;
        let mut hit = RayHit::none();
        let mut ray = *r;
        self.bvh.ray_traverse(Self::bvh_ray(r), &mut hit, |_, id| match self.prims[id] {
            Prim::Triangle { p } => match intersect_triangle(&ray, p[0], p[1], p[2]) {
                Some((t, u, v)) if self.keeps(r, id, u, v) => {
                    best = Some((t, id as u32, u, v));
                    ray.tmax = t;
                    t
                }
                _ => f32::INFINITY,
            },
            Prim::Sphere { center, radius } => match intersect_sphere(&ray, center, radius) {
                Some(t) => {
                    best = Some((t, id as u32, 0.0, 0.0));
                    ray.tmax = t;
                    t
                }
                None => f32::INFINITY,
            },
            Prim::Segment { curve, seg } => match self.curves[curve as usize].intersect(&ray, seg) {
                Some((t, u)) => {
                    best = Some((t, id as u32, u, 0.0));
                    ray.tmax = t;
                    t
                }
                None => f32::INFINITY,
            },
        });
        best.map(|(t, id, u, v)| {
            let (geom, prim) = self.ids[id as usize];
            Hit { t, geom, prim, u, v }
        })
    }

    pub fn occluded(&self, r: &Ray) -> bool {
        if self.prims.is_empty() {
            return false;
        }
        !self.bvh.ray_traverse_miss(Self::bvh_ray(r), |_, id| {
            let t = match self.prims[id] {
                Prim::Triangle { p } => {
                    intersect_triangle(r, p[0], p[1], p[2]).filter(|&(_, u, v)| self.keeps(r, id, u, v)).map(|h| h.0)
                }
                Prim::Sphere { center, radius } => intersect_sphere(r, center, radius),
                Prim::Segment { curve, seg } => self.curves[curve as usize].intersect(r, seg).map(|h| h.0),
            };
            t.unwrap_or(f32::INFINITY)
        })
    }
}
