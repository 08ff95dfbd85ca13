//! How the guided path tracer continues a path at a surface ([`Guided`], the path tracer's
//! [`Continuation`]): one-sample MIS of BSDF sampling and the spatio-directional tree.
//!
//! At a vertex whose BSDF has a non-Dirac lobe and whose spatial leaf has a trained
//! quadtree, the next direction comes from the BSDF with probability `α` (the BSDF
//! fraction) and from the quadtree otherwise; its density is the mixture's,
//! `α p_bsdf + (1 - α) p_tree`, and next-event estimation is weighed against that density.
//! A Dirac lobe the BSDF sample picks keeps its own weight divided by `α` (only the BSDF
//! branch reaches it). A purely Dirac BSDF, or a leaf that has recorded nothing, samples
//! the BSDF as the path tracer does.
//!
//! In a training pass the continuation also keeps the path's non-Dirac vertices and, as
//! radiance reaches the camera, the radiance each of them receives along its sampled
//! direction: the contribution divided by the throughput after the vertex (before the
//! roulette, so that a vertex whose path the roulette ends records nothing and one that
//! survives records its radiance over the survival probability). Contributions count with
//! their MIS weights: the tree learns the light a direction brings to the image, so that
//! emission next-event estimation finds well draws few guided samples. When the path ends,
//! each vertex becomes a record of `mean(L_i) / p(ω_i)` for its quadtree leaf
//! ([`Guided::take_records`]), `p` the mixture's density.

use crate::bsdf::{Bsdf, BsdfSample, TransportMode};
use crate::integrator::guided::sdtree::{DirTree, Record, SdTree, from_square, sphere_pdf, to_square};
use crate::integrator::path::{BsdfSampling, Continuation};
use crate::math::Rgb;
use crate::sampling::{ONE_BELOW, Random};
use crate::scene::shape::SurfaceInteraction;
use glam::Vec3;
use std::cell::Cell;

/// A vertex of a training path: where it is, the direction it sampled (world) and that
/// direction's density, the throughput after it, and the radiance it received so far.
#[derive(Clone, Copy, Debug)]
struct PathVertex {
    /// The spatial leaf of the vertex.
    leaf: u32,
    wi: Vec3,
    pdf: f32,
    beta: Rgb,
    radiance: Rgb,
}

/// The guided continuation over a tree.
pub(crate) struct Guided<'a> {
    pub tree: &'a SdTree,
    /// `α`: the probability of sampling the BSDF at a guided vertex.
    pub bsdf_fraction: f32,
    /// Whether the path's vertices are kept for records (a training pass).
    pub recording: bool,
    vertices: Vec<PathVertex>,
    /// The position last looked up and its spatial leaf: next-event estimation, the
    /// sampling and the record of one vertex share one lookup.
    last: Cell<(Vec3, u32)>,
}

impl<'a> Guided<'a> {
    pub fn new(tree: &'a SdTree, bsdf_fraction: f32, recording: bool) -> Guided<'a> {
        Guided { tree, bsdf_fraction, recording, vertices: Vec::new(), last: Cell::new((Vec3::NAN, 0)) }
    }

    /// The spatial leaf holding `p`.
    #[inline]
    fn leaf(&self, p: Vec3) -> u32 {
        let (q, leaf) = self.last.get();
        if q == p {
            return leaf;
        }
        let leaf = self.tree.leaf_at(p);
        self.last.set((p, leaf));
        leaf
    }

    /// The quadtree that guides the vertex `si` with BSDF `bsdf`, if any.
    #[inline]
    fn guide(&self, si: &SurfaceInteraction, bsdf: &Bsdf) -> Option<&'a DirTree> {
        if bsdf.is_delta() { None } else { self.tree.guide_in(self.leaf(si.p)) }
    }

    /// The mixture's density of the non-Dirac direction `wi` (shading frame) at `si`.
    #[inline]
    fn mixture_pdf(&self, si: &SurfaceInteraction, bsdf: &Bsdf, guide: &DirTree, wo: Vec3, wi: Vec3) -> f32 {
        let p_tree = sphere_pdf(guide.pdf(to_square(si.shading.to_world(wi))));
        self.mixture(si, bsdf, wo, wi, p_tree)
    }

    /// The mixture's density of `wi` given the tree's density `p_tree` of it.
    #[inline]
    fn mixture(&self, si: &SurfaceInteraction, bsdf: &Bsdf, wo: Vec3, wi: Vec3, p_tree: f32) -> f32 {
        let a = self.bsdf_fraction;
        let p_bsdf = bsdf.pdf(wo, wi, si.at(), TransportMode::Radiance);
        a * p_bsdf + (1.0 - a) * p_tree
    }

    /// Ends the path: its kept vertices as records, added to `out`.
    pub fn take_records(&mut self, out: &mut Vec<Record>) {
        for v in self.vertices.drain(..) {
            let value = (v.radiance.x + v.radiance.y + v.radiance.z) / 3.0 / v.pdf;
            let value = if value.is_finite() && value > 0.0 { value } else { 0.0 };
            out.push(self.tree.record_in(v.leaf, v.wi, value));
        }
    }
}

impl Continuation for Guided<'_> {
    fn sample<R: Random>(
        &mut self,
        si: &SurfaceInteraction,
        bsdf: &Bsdf,
        wo: Vec3,
        sampler: &mut R,
    ) -> Option<BsdfSample> {
        let Some(guide) = self.guide(si, bsdf) else {
            return BsdfSampling.sample(si, bsdf, wo, sampler);
        };
        let a = self.bsdf_fraction;
        let u = sampler.next_1d();
        let (wi, pdf) = if u < a {
            let bs = bsdf.sample(wo, si.at(), (u / a).min(ONE_BELOW), sampler.next_2d(), TransportMode::Radiance)?;
            if bs.delta {
                return Some(BsdfSample { pdf: bs.pdf * a, weight: bs.weight / a, ..bs });
            }
            (bs.wi, self.mixture_pdf(si, bsdf, guide, wo, bs.wi))
        } else {
            let u_tree = sampler.next_2d();
            let u_leaf = sampler.next_2d();
            let (square, p_square) = guide.sample(u_tree, u_leaf);
            let wi = si.shading.to_local(from_square(square));
            (wi, self.mixture(si, bsdf, wo, wi, sphere_pdf(p_square)))
        };
        let f = bsdf.eval(wo, wi, si.at(), TransportMode::Radiance);
        if !(pdf > 0.0 && pdf.is_finite()) || f == Rgb::ZERO {
            return None;
        }
        Some(BsdfSample { wi, f, pdf, weight: f * (wi.z.abs() / pdf), delta: false })
    }

    fn pdf(&self, si: &SurfaceInteraction, bsdf: &Bsdf, wo: Vec3, wi: Vec3) -> f32 {
        match self.guide(si, bsdf) {
            Some(guide) => self.mixture_pdf(si, bsdf, guide, wo, wi),
            None => BsdfSampling.pdf(si, bsdf, wo, wi),
        }
    }

    #[inline]
    fn continued(&mut self, si: &SurfaceInteraction, wi: Vec3, sample: &BsdfSample, beta: Rgb) {
        if self.recording && !sample.delta {
            let leaf = self.leaf(si.p);
            self.vertices.push(PathVertex { leaf, wi, pdf: sample.pdf, beta, radiance: Rgb::ZERO });
        }
    }

    #[inline]
    fn gathered(&mut self, value: Rgb) {
        for v in &mut self.vertices {
            v.radiance += Rgb::select(v.beta.cmpgt(Rgb::ZERO), value / v.beta, Rgb::ZERO);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A path's records by hand: vertex A (density 0.5, throughput 2 after it), a Dirac
    /// vertex (which records nothing), vertex B (density 0.2, throughput 4 after it); then
    /// 8 arrives (next-event estimation after B) and (0, 12, 0) (emission found from B).
    /// A receives a mean of (8 + 4) / 2 = 6 and records 6 / 0.5, B (8 + 4) / 4 = 3 and
    /// records 3 / 0.2; what arrived before A counts for neither.
    #[test]
    fn each_vertex_records_the_radiance_along_its_direction_over_its_density() {
        let tree = SdTree::new(Vec3::ZERO, 1.0);
        let mut g = Guided::new(&tree, 0.5, true);
        let si = SurfaceInteraction {
            p: Vec3::ZERO,
            t: 1.0,
            ng: Vec3::Z,
            shading: crate::math::Frame::from_normal(Vec3::Z),
            uv: glam::Vec2::ZERO,
            base_n: Vec3::Z,
            shape: 0,
            prim: 0,
            wo: Vec3::Z,
        };
        let sample = |pdf: f32, delta: bool| BsdfSample { wi: Vec3::Z, f: Rgb::ONE, pdf, weight: Rgb::ONE, delta };
        g.gathered(Rgb::splat(100.0));
        g.continued(&si, Vec3::Z, &sample(0.5, false), Rgb::splat(2.0));
        g.continued(&si, Vec3::Z, &sample(1.0, true), Rgb::splat(2.0));
        g.continued(&si, -Vec3::Z, &sample(0.2, false), Rgb::splat(4.0));
        g.gathered(Rgb::splat(8.0));
        g.gathered(Rgb::new(0.0, 12.0, 0.0));
        let mut records = Vec::new();
        g.take_records(&mut records);
        let values: Vec<f32> = records.iter().map(|r| r.value).collect();
        assert_eq!(values, vec![6.0 / 0.5, 3.0 / 0.2]);
        assert!(g.vertices.is_empty(), "the next path starts afresh");
    }
}
