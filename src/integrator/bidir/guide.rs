//! Guided camera walks: a [`Guide`] that camera subpaths sample their directions from at
//! surface vertices instead of the BSDF alone (PCBPT's `--pc-guiding` gives one over a
//! trained spatio-directional tree).
//!
//! The guide replaces the density of every camera-side step, wherever the core writes one:
//! a camera walk's forward densities, a light walk's reverse ones (the density of the camera
//! side reaching a light vertex's predecessor), and the camera-side densities of the ends of
//! connections, next-event estimation and light tracing. The light side keeps its BSDF
//! densities. So every strategy of a path sees the densities that generated it, and the MIS
//! weights of the ratio walk stay exact.
//!
//! A guide's decisions are functions of the vertex alone (its cell and BSDF), never of what
//! it sampled, so a density can be evaluated at any vertex of either walk.

use crate::bsdf::{Bsdf, BsdfSample};
use crate::integrator::bidir::Vertex;
use glam::{Vec2, Vec3};

/// Where camera walks take their directions from at surface vertices.
pub trait Guide: Send + Sync {
    /// The cell of the guide holding the point `p` (kept in [`Vertex::cell`] by the walks).
    fn cell(&self, p: Vec3) -> u32;

    /// Whether the guide samples at the surface vertex `v` with BSDF `bsdf` (else the BSDF
    /// alone does, and the densities there are the BSDF's).
    fn guides(&self, v: &Vertex, bsdf: &Bsdf) -> bool;

    /// A direction leaving the guided surface vertex `v` (`wo`, towards the camera side, in
    /// its shading frame) from `u` (the choice), `u2` and `u3`: the sample as the BSDF's
    /// would be, its density and weight the guide's.
    fn sample(&self, v: &Vertex, bsdf: &Bsdf, wo: Vec3, u: f32, u2: Vec2, u3: Vec2) -> Option<BsdfSample>;

    /// The solid-angle density with which the camera side, at surface vertex `v`, samples
    /// the unit world direction `w`, given that the BSDF alone samples it with `bsdf_pdf`.
    fn pdf(&self, v: &Vertex, bsdf: &Bsdf, w: Vec3, bsdf_pdf: f32) -> f32;
}
