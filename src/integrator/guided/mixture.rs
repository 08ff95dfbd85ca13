//! How the guided path tracer continues a path at a surface ([`Guided`], the path tracer's
//! [`Continuation`]): one-sample MIS of BSDF sampling and the spatio-directional tree.
//!
//! At a vertex whose BSDF has a non-Dirac lobe and whose spatial leaf has a trained
//! quadtree, the next direction comes from the BSDF with probability `α` (the BSDF
//! fraction: the leaf's own where it learnt one, else the option's) and from the quadtree
//! otherwise; its density is the mixture's,
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
//! ([`Guided::take_records`]), `p` the mixture's density; a vertex a tree guided also
//! becomes a record, for its spatial leaf, of `f |cos θ| L_i` with the density it was
//! sampled with and the BSDF's and the tree's densities of its direction, from which the
//! leaf learns its fraction ([`SdTree::add_fraction_records`]).

use crate::bsdf::{At, Bsdf, BsdfSample, TransportMode};
use crate::integrator::guided::sdtree::{DirTree, FractionRecord, Record, SdTree, from_square, sphere_pdf, to_square};
use crate::integrator::path::{BsdfSampling, Continuation};
use crate::math::{Frame, Rgb};
use crate::sampling::{ONE_BELOW, Random};
use crate::scene::shape::SurfaceInteraction;
use glam::{Vec2, Vec3};
use std::cell::Cell;

/// A vertex of a training path: where it is, the direction it sampled (world) and that
/// direction's density, the throughput after it, and the radiance it received so far; its
/// BSDF value times the cosine, and the BSDF's and the tree's densities of the direction
/// where a tree guided it.
#[derive(Clone, Copy, Debug)]
struct PathVertex {
    /// The spatial leaf of the vertex.
    leaf: u32,
    wi: Vec3,
    pdf: f32,
    beta: Rgb,
    radiance: Rgb,
    f_cos: Rgb,
    densities: Option<(f32, f32)>,
}

/// The guided continuation over a tree.
pub(crate) struct Guided<'a> {
    pub tree: &'a SdTree,
    /// `α`: the probability of sampling the BSDF at a guided vertex whose leaf has not
    /// learnt its own.
    pub bsdf_fraction: f32,
    /// Whether the path's vertices are kept for records (a training pass).
    pub recording: bool,
    vertices: Vec<PathVertex>,
    /// The position last looked up and its spatial leaf: next-event estimation, the
    /// sampling and the record of one vertex share one lookup.
    last: Cell<(Vec3, u32)>,
    /// The BSDF's and the tree's densities of the last guided sample's direction.
    sampled: Option<(f32, f32)>,
}

impl<'a> Guided<'a> {
    pub fn new(tree: &'a SdTree, bsdf_fraction: f32, recording: bool) -> Guided<'a> {
        Guided { tree, bsdf_fraction, recording, vertices: Vec::new(), last: Cell::new((Vec3::NAN, 0)), sampled: None }
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

    /// The quadtree that guides the vertex `si` with BSDF `bsdf`, if any, and the BSDF
    /// fraction there.
    #[inline]
    fn guide(&self, si: &SurfaceInteraction, bsdf: &Bsdf) -> Option<(&'a DirTree, f32)> {
        if bsdf.is_delta() {
            return None;
        }
        self.tree.mixture_in(self.leaf(si.p), self.bsdf_fraction)
    }

    /// The mixture's density of the non-Dirac direction `wi` (shading frame) at `si`, with
    /// BSDF fraction `a`.
    #[inline]
    fn mixture_pdf(
        &self,
        si: &SurfaceInteraction,
        bsdf: &Bsdf,
        (guide, a): (&DirTree, f32),
        wo: Vec3,
        wi: Vec3,
    ) -> f32 {
        let p_tree = sphere_pdf(guide.pdf(to_square(si.shading.to_world(wi))));
        mixture(a, bsdf.pdf(wo, wi, si.at(), TransportMode::Radiance), p_tree)
    }

    /// Ends the path: its kept vertices as records, added to `out`, and what the guided ones
    /// tell their leaves about the BSDF fraction, added to `fractions`.
    pub fn take_records(&mut self, out: &mut Vec<Record>, fractions: &mut Vec<FractionRecord>) {
        for v in self.vertices.drain(..) {
            let value = (v.radiance.x + v.radiance.y + v.radiance.z) / 3.0 / v.pdf;
            let value = if value.is_finite() && value > 0.0 { value } else { 0.0 };
            out.push(self.tree.record_in(v.leaf, v.wi, value));
            if let Some((pdf_bsdf, pdf_tree)) = v.densities {
                let g = v.radiance * v.f_cos;
                let value = (g.x + g.y + g.z) / 3.0;
                let value = if value.is_finite() && value > 0.0 { value } else { 0.0 };
                fractions.push(FractionRecord { leaf: v.leaf, value, pdf: v.pdf, pdf_bsdf, pdf_tree });
            }
        }
    }
}

/// The density of the one-sample mixture that samples the BSDF (density `p_bsdf`) with
/// probability `a` and the tree (density `p_tree`) otherwise.
#[inline]
pub(crate) fn mixture(a: f32, p_bsdf: f32, p_tree: f32) -> f32 {
    a * p_bsdf + (1.0 - a) * p_tree
}

/// A sample of the one-sample mixture of `bsdf` (probability `a`) and the quadtree `guide`
/// at a vertex with shading frame `frame`, for light leaving towards `wo` (shading frame):
/// `u` chooses, `next_2d` gives the BSDF's or the tree's numbers. Returns the sample (its
/// density and weight the mixture's) and, unless it came from a Dirac lobe (whose weight
/// is divided by `a`, only the BSDF branch reaching it), the BSDF's and the tree's
/// densities of its direction.
#[inline]
#[allow(clippy::too_many_arguments)]
pub(crate) fn sample_mixture(
    (guide, a): (&DirTree, f32),
    bsdf: &Bsdf,
    frame: &Frame,
    at: At,
    wo: Vec3,
    u: f32,
    mut next_2d: impl FnMut() -> Vec2,
) -> Option<(BsdfSample, Option<(f32, f32)>)> {
    let (wi, p_tree) = if u < a {
        let bs = bsdf.sample(wo, at, (u / a).min(ONE_BELOW), next_2d(), TransportMode::Radiance)?;
        if bs.delta {
            return Some((BsdfSample { pdf: bs.pdf * a, weight: bs.weight / a, ..bs }, None));
        }
        (bs.wi, sphere_pdf(guide.pdf(to_square(frame.to_world(bs.wi)))))
    } else {
        let u_tree = next_2d();
        let u_leaf = next_2d();
        let (square, p_square) = guide.sample(u_tree, u_leaf);
        (frame.to_local(from_square(square)), sphere_pdf(p_square))
    };
    let p_bsdf = bsdf.pdf(wo, wi, at, TransportMode::Radiance);
    let pdf = mixture(a, p_bsdf, p_tree);
    let f = bsdf.eval(wo, wi, at, TransportMode::Radiance);
    if !(pdf > 0.0 && pdf.is_finite()) || f == Rgb::ZERO {
        return None;
    }
    Some((BsdfSample { wi, f, pdf, weight: f * (wi.z.abs() / pdf), delta: false }, Some((p_bsdf, p_tree))))
}

impl Continuation for Guided<'_> {
    fn sample<R: Random>(
        &mut self,
        si: &SurfaceInteraction,
        bsdf: &Bsdf,
        wo: Vec3,
        sampler: &mut R,
    ) -> Option<BsdfSample> {
        self.sampled = None;
        // Without a tree, the BSDF alone; with the fraction 1 too, as the mixture would sample
        // it with the same numbers, unless a training pass records the tree's density.
        let Some((guide, a)) = self.guide(si, bsdf).filter(|&(_, a)| a < 1.0 || self.recording) else {
            return BsdfSampling.sample(si, bsdf, wo, sampler);
        };
        let u = sampler.next_1d();
        let (bs, densities) = sample_mixture((guide, a), bsdf, &si.shading, si.at(), wo, u, || sampler.next_2d())?;
        self.sampled = densities;
        Some(bs)
    }

    fn pdf(&self, si: &SurfaceInteraction, bsdf: &Bsdf, wo: Vec3, wi: Vec3) -> f32 {
        match self.guide(si, bsdf) {
            Some(guide) if guide.1 < 1.0 => self.mixture_pdf(si, bsdf, guide, wo, wi),
            _ => BsdfSampling.pdf(si, bsdf, wo, wi),
        }
    }

    #[inline]
    fn continued(&mut self, si: &SurfaceInteraction, wi: Vec3, sample: &BsdfSample, beta: Rgb) {
        if self.recording && !sample.delta {
            let leaf = self.leaf(si.p);
            self.vertices.push(PathVertex {
                leaf,
                wi,
                pdf: sample.pdf,
                beta,
                radiance: Rgb::ZERO,
                f_cos: sample.f * sample.wi.z.abs(),
                densities: self.sampled.take(),
            });
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
        let (mut records, mut fractions) = (Vec::new(), Vec::new());
        g.take_records(&mut records, &mut fractions);
        assert!(fractions.is_empty(), "no vertex was guided by a tree");
        let values: Vec<f32> = records.iter().map(|r| r.value).collect();
        assert_eq!(values, vec![6.0 / 0.5, 3.0 / 0.2]);
        assert!(g.vertices.is_empty(), "the next path starts afresh");
    }
}
