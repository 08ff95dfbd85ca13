//! A trained spatio-directional tree as the [`Guide`] of the bidirectional core's camera
//! walks ([`TreeGuide`]): the cells are the tree's spatial leaves, and a guided vertex
//! samples the one-sample mixture of its BSDF and its leaf's quadtree exactly as the guided
//! path tracer does ([`sample_mixture`]), with its leaf's learnt BSDF fraction or the
//! option's.

use crate::bsdf::{Bsdf, BsdfSample, TransportMode};
use crate::integrator::bidir::Vertex;
use crate::integrator::bidir::guide::Guide;
use crate::integrator::guided::mixture::{mixture, sample_mixture};
use crate::integrator::guided::sdtree::{DirTree, SdTree, sphere_pdf, to_square};
use glam::{Vec2, Vec3};

/// The guide of a trained tree.
pub struct TreeGuide {
    pub tree: SdTree,
    /// `α` where a leaf has not learnt its own BSDF fraction.
    pub bsdf_fraction: f32,
}

impl TreeGuide {
    /// The quadtree and the BSDF fraction that guide the surface vertex `v` with BSDF
    /// `bsdf`: none for a purely Dirac BSDF, a vertex without a cell, a leaf without a
    /// trained quadtree, or a fraction of 1 (the mixture is then the BSDF).
    #[inline]
    fn at(&self, v: &Vertex, bsdf: &Bsdf) -> Option<(&DirTree, f32)> {
        if v.cell == u32::MAX || bsdf.is_delta() {
            return None;
        }
        self.tree.mixture_in(v.cell, self.bsdf_fraction).filter(|&(_, a)| a < 1.0)
    }
}

impl Guide for TreeGuide {
    #[inline]
    fn cell(&self, p: Vec3) -> u32 {
        self.tree.leaf_at(p)
    }

    #[inline]
    fn guides(&self, v: &Vertex, bsdf: &Bsdf) -> bool {
        self.at(v, bsdf).is_some()
    }

    fn sample(&self, v: &Vertex, bsdf: &Bsdf, wo: Vec3, u: f32, u2: Vec2, u3: Vec2) -> Option<BsdfSample> {
        let Some(guide) = self.at(v, bsdf) else {
            return bsdf.sample(wo, v.at(), u, u2, TransportMode::Radiance);
        };
        let mut numbers = [u2, u3].into_iter();
        let next_2d = || numbers.next().expect("a mixture sample takes at most two pairs");
        sample_mixture(guide, bsdf, &v.frame, v.at(), wo, u, next_2d).map(|(bs, _)| bs)
    }

    #[inline]
    fn pdf(&self, v: &Vertex, bsdf: &Bsdf, w: Vec3, bsdf_pdf: f32) -> f32 {
        match self.at(v, bsdf) {
            Some((guide, a)) => mixture(a, bsdf_pdf, sphere_pdf(guide.pdf(to_square(w)))),
            None => bsdf_pdf,
        }
    }
}
