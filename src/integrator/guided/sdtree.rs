//! The spatio-directional tree of practical path guiding (Müller, Gross and Novák 2017): a
//! binary tree over space whose leaves each hold two directional quadtrees, one to sample
//! from and one being built from the radiance the paths record.
//!
//! Directions are points of the unit square by the cylindrical map `u = (cos θ + 1) / 2`,
//! `v = φ / 2π`, which preserves area: a density `p` over the square is `p / 4π` over the
//! sphere. A quadtree node holds the sum of the values recorded in its square (an estimate
//! of the radiance integrated over it); sampling descends from the root choosing each child
//! in proportion to its sum and draws uniformly in the leaf, so the density of a point is
//! the product of `4 · sum(child) / sum(node)` down its path ([`DirTree::sample`],
//! [`DirTree::pdf`]). Building a tree stores these fractions in its nodes, so both descents
//! only multiply.
//!
//! The spatial tree covers the cube around the scene's bounding sphere and splits a leaf in
//! the middle of one axis, the axes taken in turn with depth. After each training pass
//! ([`SdTree::finish_pass`]) the trees being built become the ones sampled from; a spatial
//! leaf that took more than `c · √spp` records in a pass of `spp` samples per pixel is split
//! (each half a copy of it, with half its records, until under the threshold); and each
//! quadtree to be built next is the sampled one refined by flux: a node holding more than a
//! fraction `ρ` of its tree's sum is subdivided (a leaf's sum shared evenly among its new
//! children), down to a maximum depth, and a node holding less is a leaf.
//!
//! With a learnt BSDF fraction, each leaf also sums, over the pass's guided vertices in it,
//! an estimate of the second moment `∫ g² / p_α` of their reflected light `g` under the
//! mixture of each candidate fraction `α` (importance-weighted by the density each
//! direction was sampled with), and takes the candidate with the least for the next pass.

use glam::{DVec2, Vec2, Vec3};
use std::f32::consts::PI;

/// A direction's point in the unit square (the cylindrical map).
#[inline]
pub fn to_square(d: Vec3) -> Vec2 {
    let cos_theta = d.z.clamp(-1.0, 1.0);
    let mut phi = d.y.atan2(d.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let below_one = |x: f32| x.clamp(0.0, 1.0f32.next_down());
    Vec2::new(below_one((cos_theta + 1.0) * 0.5), below_one(phi / (2.0 * PI)))
}

/// The direction of a point of the unit square (the inverse of [`to_square`]).
#[inline]
pub fn from_square(p: Vec2) -> Vec3 {
    let cos_theta = 2.0 * p.x - 1.0;
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * p.y).sin_cos();
    Vec3::new(sin_theta * c, sin_theta * s, cos_theta)
}

/// The solid-angle density of a direction whose point has density `square_pdf` in the square.
#[inline]
pub fn sphere_pdf(square_pdf: f64) -> f32 {
    (square_pdf / (4.0 * std::f64::consts::PI)) as f32
}

/// A quadtree node: the sum recorded in its square and its four children (child `ix + 2 iy`
/// covers the half `ix` in `u` and `iy` in `v`), all zero for a leaf (the root is no child);
/// for an inner node of a built tree, the fraction of its sum each child holds (what
/// sampling and the density descend by, without a division per level).
#[derive(Clone, Copy, Debug, Default)]
struct QuadNode {
    sum: f64,
    children: [u32; 4],
    fractions: [f64; 4],
}

impl QuadNode {
    #[inline]
    fn is_leaf(&self) -> bool {
        self.children[0] == 0
    }
}

/// A directional quadtree over the unit square. Children come after their parent in `nodes`.
#[derive(Clone, Debug)]
pub struct DirTree {
    nodes: Vec<QuadNode>,
}

impl Default for DirTree {
    fn default() -> DirTree {
        DirTree { nodes: vec![QuadNode::default()] }
    }
}

/// The child of a node holding the point `p` of its square, and `p` in the child's square.
#[inline]
fn child_at(p: DVec2) -> (usize, DVec2) {
    let ix = (p.x >= 0.5) as usize;
    let iy = (p.y >= 0.5) as usize;
    (ix + 2 * iy, p * 2.0 - DVec2::new(ix as f64, iy as f64))
}

/// Which of two parts of weights `a` and `b` the uniform number `u` falls in (0 or 1), and
/// `u` rescaled to be uniform within it.
#[inline]
fn choose(u: f64, a: f64, b: f64) -> (usize, f64) {
    let total = a + b;
    let below_one = |x: f64| x.clamp(0.0, 1.0f64.next_down());
    if u * total < a { (0, below_one(u * total / a)) } else { (1, below_one((u * total - a) / b)) }
}

impl DirTree {
    /// The sum over the whole square (zero for a tree that recorded nothing).
    #[inline]
    pub fn total(&self) -> f64 {
        self.nodes[0].sum
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// A point of the square drawn with [`DirTree::pdf`] from the uniform numbers `u` (the
    /// descent) and `u_leaf` (the position in the leaf), and its density. The tree must be
    /// built ([`DirTree::build`]) with a positive [`DirTree::total`].
    pub fn sample(&self, u: Vec2, u_leaf: Vec2) -> (Vec2, f64) {
        let mut u = u.as_dvec2();
        let (mut origin, mut size) = (DVec2::ZERO, 1.0f64);
        let mut node = &self.nodes[0];
        let mut pdf = 1.0f64;
        while !node.is_leaf() {
            let s = node.fractions;
            let (ix, ux) = choose(u.x, s[0] + s[2], s[1] + s[3]);
            let (iy, uy) = choose(u.y, s[ix], s[ix + 2]);
            u = DVec2::new(ux, uy);
            size *= 0.5;
            origin += DVec2::new(ix as f64, iy as f64) * size;
            pdf *= 4.0 * s[ix + 2 * iy];
            node = &self.nodes[node.children[ix + 2 * iy] as usize];
        }
        let p = origin + u_leaf.as_dvec2() * size;
        (p.as_vec2().clamp(Vec2::ZERO, Vec2::splat(1.0f32.next_down())), pdf)
    }

    /// The density (over the unit square) with which [`DirTree::sample`] draws `p`; zero
    /// for a tree that recorded nothing.
    pub fn pdf(&self, p: Vec2) -> f64 {
        let mut node = &self.nodes[0];
        if node.sum <= 0.0 {
            return 0.0;
        }
        let mut p = p.as_dvec2();
        let mut pdf = 1.0;
        while !node.is_leaf() {
            let (c, inner) = child_at(p);
            pdf *= 4.0 * node.fractions[c];
            if pdf == 0.0 {
                return 0.0;
            }
            node = &self.nodes[node.children[c] as usize];
            p = inner;
        }
        pdf
    }

    /// The leaf whose square holds `p`.
    pub fn leaf_at(&self, p: Vec2) -> u32 {
        let mut p = p.as_dvec2();
        let mut index = 0u32;
        loop {
            let node = &self.nodes[index as usize];
            if node.is_leaf() {
                return index;
            }
            let (c, inner) = child_at(p);
            index = node.children[c];
            p = inner;
        }
    }

    /// Adds `value` to the leaf `leaf` ([`DirTree::leaf_at`]); [`DirTree::build`] then sums
    /// the inner nodes.
    #[inline]
    pub fn add(&mut self, leaf: u32, value: f64) {
        self.nodes[leaf as usize].sum += value;
    }

    /// Sums the leaves' values into the inner nodes, and stores each child's fraction of
    /// its parent's sum.
    pub fn build(&mut self) {
        for i in (0..self.nodes.len()).rev() {
            let node = self.nodes[i];
            if !node.is_leaf() {
                let s = node.children.map(|c| self.nodes[c as usize].sum);
                let sum = (s[0] + s[1]) + (s[2] + s[3]);
                self.nodes[i].sum = sum;
                self.nodes[i].fractions = if sum > 0.0 { s.map(|c| c / sum) } else { [0.0; 4] };
            }
        }
    }

    /// An empty tree whose nodes are this built tree's refined by flux: a node holding more
    /// than `fraction` of the total is subdivided (a leaf's sum shared evenly among its new
    /// children) unless at `max_depth`; the others are leaves. A tree that recorded nothing
    /// keeps its nodes.
    pub fn refined(&self, fraction: f64, max_depth: u32) -> DirTree {
        let total = self.total();
        let mut out = DirTree::default();
        if total <= 0.0 {
            out.nodes = self.nodes.iter().map(|n| QuadNode { sum: 0.0, fractions: [0.0; 4], ..*n }).collect();
            return out;
        }
        // (node of `out`, node of `self` covering the same square, its sum, depth)
        let mut stack = vec![(0usize, Some(0usize), total, 0u32)];
        while let Some((at, old, sum, depth)) = stack.pop() {
            if depth >= max_depth || sum <= fraction * total {
                continue;
            }
            let first = out.nodes.len();
            for c in 0..4 {
                let (old_child, child_sum) = match old.map(|o| self.nodes[o]) {
                    Some(n) if !n.is_leaf() => {
                        let o = n.children[c] as usize;
                        (Some(o), self.nodes[o].sum)
                    }
                    _ => (None, sum / 4.0),
                };
                out.nodes.push(QuadNode::default());
                stack.push((first + c, old_child, child_sum, depth + 1));
            }
            out.nodes[at].children = [0, 1, 2, 3].map(|c| (first + c) as u32);
        }
        out
    }

    /// A quadtree with the given node sums, for tests: `children[i]` lists node `i`'s four
    /// children (children after their parents) or is `None` for a leaf.
    #[cfg(test)]
    pub fn from_nodes(nodes: &[(f64, Option<[u32; 4]>)]) -> DirTree {
        let nodes = nodes
            .iter()
            .map(|&(sum, c)| QuadNode { sum, children: c.unwrap_or([0; 4]), fractions: [0.0; 4] })
            .collect();
        let mut t = DirTree { nodes };
        t.build();
        t
    }
}

/// A node of the spatial tree: a leaf's index in [`SdTree::leaves`], or an inner node
/// split across `axis` at its middle, whose two children are `first` and `first + 1`.
#[derive(Clone, Copy, Debug)]
enum SpatialNode {
    Leaf(u32),
    Inner { axis: u8, first: u32 },
}

/// A spatial leaf: the quadtree sampled from, the one being built, the records it took, and
/// (with a learnt BSDF fraction) the fraction its vertices sample the BSDF with and the
/// pass's estimates of the second moment under each candidate fraction.
#[derive(Clone, Debug, Default)]
pub struct SpatialLeaf {
    pub sampling: DirTree,
    pub building: DirTree,
    pub records: u64,
    pub bsdf_fraction: Option<f32>,
    moments: [f64; FRACTIONS.len()],
    fraction_records: u64,
    depth: u32,
}

/// The BSDF fractions a leaf learns among.
pub const FRACTIONS: [f32; 10] = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0];

/// The fewest records of a pass from which a leaf learns its BSDF fraction.
const MIN_FRACTION_RECORDS: u64 = 64;

/// What a vertex of a training path tells its leaf about the BSDF fraction: its estimate
/// `value` of the reflected light along the direction it sampled (`f |cos θ| L`, before
/// dividing by any density), the density it was sampled with, and the BSDF's and the
/// tree's densities of the direction.
#[derive(Clone, Copy, Debug)]
pub struct FractionRecord {
    pub leaf: u32,
    pub value: f32,
    pub pdf: f32,
    pub pdf_bsdf: f32,
    pub pdf_tree: f32,
}

/// The deepest a spatial leaf is split.
const MAX_SPATIAL_DEPTH: u32 = 48;

/// How the trees are refined after a pass.
#[derive(Clone, Copy, Debug)]
pub struct Refinement {
    /// `c`: a spatial leaf is split when its records exceed `c · √spp`.
    pub spatial_threshold: f64,
    /// `ρ`: a quadtree node is subdivided when it holds more than this fraction of the sum.
    pub flux_fraction: f64,
    pub max_depth: u32,
    /// Whether each leaf learns its BSDF fraction.
    pub learn_fraction: bool,
}

/// The spatio-directional tree.
#[derive(Clone, Debug)]
pub struct SdTree {
    /// The cube the tree covers: its corner and side.
    min: Vec3,
    side: f32,
    nodes: Vec<SpatialNode>,
    pub leaves: Vec<SpatialLeaf>,
}

/// One record of a training path: the value `value` for the node `node` of the building
/// quadtree of spatial leaf `leaf`.
#[derive(Clone, Copy, Debug)]
pub struct Record {
    pub leaf: u32,
    pub node: u32,
    pub value: f32,
}

impl SdTree {
    /// One leaf over the cube around the sphere `center`, `radius`, its quadtrees empty.
    pub fn new(center: Vec3, radius: f32) -> SdTree {
        let radius = radius.max(1e-6);
        SdTree {
            min: center - Vec3::splat(radius),
            side: 2.0 * radius,
            nodes: vec![SpatialNode::Leaf(0)],
            leaves: vec![SpatialLeaf::default()],
        }
    }

    /// The leaf whose box holds `p` (a point outside the cube: the nearest box).
    pub fn leaf_at(&self, p: Vec3) -> u32 {
        let mut q = ((p - self.min) / self.side).clamp(Vec3::ZERO, Vec3::ONE);
        let mut node = self.nodes[0];
        loop {
            match node {
                SpatialNode::Leaf(l) => return l,
                SpatialNode::Inner { axis, first } => {
                    let a = axis as usize;
                    let upper = q[a] >= 0.5;
                    q[a] = q[a] * 2.0 - upper as u32 as f32;
                    node = self.nodes[(first + upper as u32) as usize];
                }
            }
        }
    }

    /// The quadtree to sample from at `p`, where it has recorded anything.
    #[inline]
    pub fn guide_at(&self, p: Vec3) -> Option<&DirTree> {
        self.guide_in(self.leaf_at(p))
    }

    /// The quadtree to sample from in the leaf `leaf`, where it has recorded anything.
    #[inline]
    pub fn guide_in(&self, leaf: u32) -> Option<&DirTree> {
        let t = &self.leaves[leaf as usize].sampling;
        (t.total() > 0.0).then_some(t)
    }

    /// The BSDF fraction of the leaf `leaf`: the one it learnt, else `otherwise`.
    #[inline]
    pub fn bsdf_fraction_in(&self, leaf: u32, otherwise: f32) -> f32 {
        self.leaves[leaf as usize].bsdf_fraction.unwrap_or(otherwise)
    }

    /// The mixture the leaf `leaf` samples from: its trained quadtree, if it has one, and its
    /// BSDF fraction ([`SdTree::bsdf_fraction_in`]).
    #[inline]
    pub fn mixture_in(&self, leaf: u32, otherwise: f32) -> Option<(&DirTree, f32)> {
        Some((self.guide_in(leaf)?, self.bsdf_fraction_in(leaf, otherwise)))
    }

    /// The BSDF fractions the leaves learnt, least first.
    pub fn learnt_fractions(&self) -> Vec<f32> {
        let mut learnt: Vec<f32> = self.leaves.iter().filter_map(|l| l.bsdf_fraction).collect();
        learnt.sort_by(f32::total_cmp);
        learnt
    }

    /// The record of `value` at `p` for the direction `d` (world).
    #[inline]
    pub fn record_for(&self, p: Vec3, d: Vec3, value: f32) -> Record {
        self.record_in(self.leaf_at(p), d, value)
    }

    /// The record of `value` in the spatial leaf `leaf` for the direction `d` (world).
    #[inline]
    pub fn record_in(&self, leaf: u32, d: Vec3, value: f32) -> Record {
        let node = self.leaves[leaf as usize].building.leaf_at(to_square(d));
        Record { leaf, node, value }
    }

    /// Adds records to the building trees, in order.
    pub fn add(&mut self, records: &[Record]) {
        for r in records {
            let leaf = &mut self.leaves[r.leaf as usize];
            leaf.building.add(r.node, r.value as f64);
            leaf.records += 1;
        }
    }

    /// Adds the estimates of the second moment under each candidate BSDF fraction, in order:
    /// a record sampled with density `p` adds `value² / (p · p_α)`, `p_α` the mixture's
    /// density with fraction `α`, an estimate of `∫ value² / p_α`.
    pub fn add_fraction_records(&mut self, records: &[FractionRecord]) {
        for r in records {
            let leaf = &mut self.leaves[r.leaf as usize];
            leaf.fraction_records += 1;
            let v = r.value as f64;
            if !(v > 0.0 && v.is_finite() && r.pdf > 0.0) {
                continue;
            }
            for (m, &a) in leaf.moments.iter_mut().zip(&FRACTIONS) {
                let p_a = a as f64 * r.pdf_bsdf as f64 + (1.0 - a as f64) * r.pdf_tree as f64;
                *m += if p_a > 0.0 { v * v / (r.pdf as f64 * p_a) } else { f64::INFINITY };
            }
        }
    }

    /// After a training pass of `spp` samples per pixel: the built trees become the ones
    /// sampled from, each leaf that took enough records takes the candidate BSDF fraction
    /// with the least second moment (when learning), crowded spatial leaves are split, and
    /// the next trees to build are refined by flux and empty.
    pub fn finish_pass(&mut self, spp: u32, r: &Refinement) {
        for leaf in &mut self.leaves {
            leaf.building.build();
            leaf.sampling = leaf.building.clone();
            if r.learn_fraction && leaf.fraction_records >= MIN_FRACTION_RECORDS {
                let best = (0..FRACTIONS.len()).min_by(|&i, &j| leaf.moments[i].total_cmp(&leaf.moments[j]));
                if let Some(i) = best.filter(|&i| leaf.moments[i].is_finite()) {
                    leaf.bsdf_fraction = Some(FRACTIONS[i]);
                }
            }
            leaf.moments = [0.0; FRACTIONS.len()];
            leaf.fraction_records = 0;
        }
        self.split_leaves(r.spatial_threshold * (spp as f64).sqrt());
        for leaf in &mut self.leaves {
            leaf.building = leaf.sampling.refined(r.flux_fraction, r.max_depth);
            leaf.records = 0;
        }
    }

    /// Splits every leaf with more than `threshold` records, its halves each a copy of it
    /// with half its records, until none has more.
    fn split_leaves(&mut self, threshold: f64) {
        let mut i = 0;
        while i < self.nodes.len() {
            if let SpatialNode::Leaf(l) = self.nodes[i] {
                let leaf = &mut self.leaves[l as usize];
                if leaf.records as f64 > threshold && leaf.depth < MAX_SPATIAL_DEPTH {
                    leaf.records /= 2;
                    leaf.depth += 1;
                    let twin = leaf.clone();
                    let axis = ((leaf.depth - 1) % 3) as u8;
                    let first = self.nodes.len() as u32;
                    self.leaves.push(twin);
                    self.nodes.push(SpatialNode::Leaf(l));
                    self.nodes.push(SpatialNode::Leaf(self.leaves.len() as u32 - 1));
                    self.nodes[i] = SpatialNode::Inner { axis, first };
                }
            }
            i += 1;
        }
    }

    /// The quadtree nodes sampled from, over all leaves.
    pub fn sampling_nodes(&self) -> usize {
        self.leaves.iter().map(|l| l.sampling.node_count()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;
    use crate::sampling::chi2::{Chi2Test, SphereDomain};

    /// Radiance with a narrow bright lobe, a broad weaker one, and a floor.
    fn radiance(d: Vec3) -> f64 {
        let peak = Vec3::new(0.3, -0.5, 0.8).normalize();
        let other = Vec3::new(-0.6, 0.2, -0.3).normalize();
        (40.0 * d.dot(peak).max(0.0).powi(30) + 2.0 * d.dot(other).max(0.0).powi(4) + 0.01) as f64
    }

    /// A quadtree trained as between training passes: uniform directions record
    /// [`radiance`], the tree is built and refined by flux, four times.
    fn trained() -> DirTree {
        let mut tree = DirTree::default();
        let mut rng = Sampler::new(&[7]);
        for pass in 0..4 {
            for _ in 0..20_000 {
                let d = from_square(rng.next_2d());
                tree.add(tree.leaf_at(to_square(d)), radiance(d));
            }
            tree.build();
            if pass == 3 {
                return tree;
            }
            tree = tree.refined(0.01, 20);
        }
        unreachable!()
    }

    /// Σ pdf · area over the leaves, each leaf's density taken at its centre.
    fn leaf_integral(tree: &DirTree) -> f64 {
        let mut total = 0.0;
        let mut stack = vec![(0usize, DVec2::ZERO, 1.0f64)];
        while let Some((i, origin, size)) = stack.pop() {
            let n = tree.nodes[i];
            if n.is_leaf() {
                total += tree.pdf((origin + DVec2::splat(size / 2.0)).as_vec2()) * size * size;
                continue;
            }
            for c in 0..4 {
                let o = origin + DVec2::new((c % 2) as f64, (c / 2) as f64) * size / 2.0;
                stack.push((n.children[c] as usize, o, size / 2.0));
            }
        }
        total
    }

    #[test]
    fn the_map_preserves_area_and_inverts() {
        let mut rng = Sampler::new(&[3]);
        for _ in 0..1000 {
            let p = rng.next_2d();
            let d = from_square(p);
            assert!((d.length() - 1.0).abs() < 1e-5);
            assert!(to_square(d).distance(p) < 1e-4, "{p} → {d} → {}", to_square(d));
        }
        // A band of the square of area a covers a solid angle 4π a.
        assert!((sphere_pdf(1.0) - 1.0 / (4.0 * PI)).abs() < 1e-9);
    }

    #[test]
    fn a_trained_quadtree_is_deep_and_its_pdf_integrates_to_one() {
        let tree = trained();
        assert!(tree.node_count() > 200, "only {} nodes", tree.node_count());
        let integral = leaf_integral(&tree);
        assert!((integral - 1.0).abs() < 1e-9, "∫ pdf over the square = {integral}");
        // The sums are an estimate of the radiance: the peak's leaf is far denser than the floor's.
        let peak = tree.pdf(to_square(Vec3::new(0.3, -0.5, 0.8).normalize()));
        let floor = tree.pdf(to_square(Vec3::new(0.0, 0.9, -0.2).normalize()));
        assert!(peak > 20.0 * floor, "peak {peak}, floor {floor}");
    }

    #[test]
    fn quadtree_sampling_follows_its_pdf() {
        let tree = trained();
        let mut leaf_rng = Sampler::new(&[11]);
        let r = Chi2Test::new(SphereDomain::default())
            .run(|u| from_square(tree.sample(u, leaf_rng.next_2d()).0), |d| sphere_pdf(tree.pdf(to_square(d))));
        r.assert_pass();
        assert!((r.pdf_integral - 1.0).abs() < 2e-3, "∫ pdf over the sphere = {}", r.pdf_integral);
    }

    /// The negative control: the same samples against the pdf mirrored in φ (a density that
    /// integrates to one but is not the one sampled) must fail.
    #[test]
    fn quadtree_chi2_rejects_a_mirrored_pdf() {
        let tree = trained();
        let mut leaf_rng = Sampler::new(&[11]);
        let r = Chi2Test::new(SphereDomain::default()).run(
            |u| from_square(tree.sample(u, leaf_rng.next_2d()).0),
            |d| {
                let p = to_square(d);
                sphere_pdf(tree.pdf(Vec2::new(p.x, 1.0f32.next_down() - p.y)))
            },
        );
        assert!(!r.passed(), "the mirrored pdf passed: {r}");
    }

    #[test]
    fn refinement_subdivides_by_flux_and_keeps_an_empty_tree() {
        // One quarter holds nearly all the sum: it is split down to where a node holds at
        // most 1%, the other quarters (0.5% each) stay leaves.
        let tree = DirTree::from_nodes(&[
            (0.0, Some([1, 2, 3, 4])),
            (0.97, None),
            (0.005, None),
            (0.005, None),
            (0.005, None),
        ]);
        let r = tree.refined(0.01, 20);
        // 0.97 → 4 × 0.2425 → 16 × 0.0606 → 64 × 0.0152 → 256 × 0.0038: 1 + 4 + 4 + 16 + 64 + 256.
        assert_eq!(r.node_count(), 1 + 4 + 4 + 16 + 64 + 256);
        assert_eq!(r.total(), 0.0, "the refined tree starts empty");
        assert_eq!(tree.refined(0.01, 2).node_count(), 1 + 4 + 4, "the depth is capped");
        let empty = DirTree::default();
        assert_eq!(empty.refined(0.01, 20).node_count(), 1);
    }

    /// A leaf learns the candidate fraction whose mixture best matches its vertices'
    /// integrand: the BSDF's fraction 1 where the BSDF's density is proportional to the
    /// light reflected and the tree's is not, the least fraction where the tree's is; and
    /// nothing without learning or with too few records.
    #[test]
    fn leaves_learn_the_bsdf_fraction_whose_mixture_fits_best() {
        let mut rng = Sampler::new(&[5]);
        // Directions sampled uniformly (density 1 on a domain of measure 1); the integrand
        // is 3x² in x ∈ [0, 1); one density follows it, the other is constant.
        let records = |leaf: u32, bsdf_fits: bool, rng: &mut Sampler| -> Vec<FractionRecord> {
            (0..1000)
                .map(|_| {
                    let x = rng.next_1d();
                    let (fit, flat) = (3.0 * x * x, 1.0);
                    let (pdf_bsdf, pdf_tree) = if bsdf_fits { (fit, flat) } else { (flat, fit) };
                    FractionRecord { leaf, value: 3.0 * x * x, pdf: 1.0, pdf_bsdf, pdf_tree }
                })
                .collect()
        };
        let mut t = SdTree::new(Vec3::ZERO, 1.0);
        t.add(&[t.record_for(Vec3::splat(-0.5), Vec3::Z, 1.0), t.record_for(Vec3::splat(0.5), Vec3::Z, 1.0)]);
        let r = Refinement { spatial_threshold: 1.0, flux_fraction: 0.01, max_depth: 20, learn_fraction: true };
        t.finish_pass(1, &r);
        let (a, b) = (t.leaf_at(Vec3::splat(-0.5)), t.leaf_at(Vec3::splat(0.5)));
        assert_ne!(a, b);
        t.add_fraction_records(&records(a, true, &mut rng));
        t.add_fraction_records(&records(b, false, &mut rng));
        let fixed = Refinement { learn_fraction: false, ..r };
        let mut unlearnt = t.clone();
        unlearnt.finish_pass(1, &fixed);
        assert!(unlearnt.leaves.iter().all(|l| l.bsdf_fraction.is_none()), "learnt without learning");
        t.finish_pass(1, &r);
        assert_eq!(t.leaves[t.leaf_at(Vec3::splat(-0.5)) as usize].bsdf_fraction, Some(1.0));
        assert_eq!(t.leaves[t.leaf_at(Vec3::splat(0.5)) as usize].bsdf_fraction, Some(FRACTIONS[0]));
        // Too few records: the leaf keeps what it had.
        let c = t.leaf_at(Vec3::splat(0.5));
        t.add_fraction_records(&records(c, true, &mut rng)[..(MIN_FRACTION_RECORDS - 1) as usize]);
        t.finish_pass(1, &r);
        assert_eq!(t.leaves[t.leaf_at(Vec3::splat(0.5)) as usize].bsdf_fraction, Some(FRACTIONS[0]));
    }

    #[test]
    fn crowded_spatial_leaves_split_along_alternating_axes() {
        let mut t = SdTree::new(Vec3::ZERO, 1.0);
        let d = Vec3::Z;
        // 1010 records in one corner; the halves of a split leaf share its records evenly,
        // wherever they fell.
        let records = vec![t.record_for(Vec3::splat(-0.9), d, 1.0); 1010];
        t.add(&records);
        let r = Refinement { spatial_threshold: 100.0, flux_fraction: 0.01, max_depth: 20, learn_fraction: false };
        t.finish_pass(1, &r);
        // 1010 > 100 → two halves of 505 → … until ≤ 100: four levels (63 each).
        let corner = t.leaf_at(Vec3::splat(-0.9));
        assert_eq!(t.leaves[corner as usize].depth, 4);
        assert_ne!(t.leaf_at(Vec3::splat(0.9)), corner);
        assert_ne!(t.leaf_at(Vec3::new(0.9, -0.9, -0.9)), corner, "x is split first");
        assert_ne!(t.leaf_at(Vec3::new(-0.9, 0.9, -0.9)), corner, "then y");
        assert_ne!(t.leaf_at(Vec3::new(-0.9, -0.9, 0.9)), corner, "then z");
        assert_ne!(t.leaf_at(Vec3::new(-0.4, -0.9, -0.9)), corner, "then x again");
        // Each leaf samples what the split leaf recorded, and builds afresh.
        for leaf in &t.leaves {
            assert_eq!(leaf.sampling.total(), 1010.0);
            assert_eq!(leaf.records, 0);
            assert_eq!(leaf.building.total(), 0.0);
        }
        assert!(t.guide_at(Vec3::ZERO).is_some());
    }
}
