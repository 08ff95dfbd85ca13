//! MIS weights with merging strategies beside the connections (vertex connection and
//! merging: Georgiev et al. 2012; Hachisuka et al.'s unified path sampling), by the same
//! ratios as the connections' walk.
//!
//! Merging at an interior vertex `x_i` (`1 ≤ i ≤ n - 2`, a rough surface point) samples
//! `x_0..x_i` from the light and `x_i..x_{n-1}` from the camera, and accepts the pair when
//! the light's `x_i` lies within `r` of the camera's: its density is that of the connection
//! strategy `s = i` (light `x_0..x_{i-1}`, camera the rest) times the probability
//! `pL(x_i) π r²` of the light walk's vertex falling in the disk. Used `N` times per camera
//! vertex (one per light path of the iteration), its weight term is `η pL(x_i) p_i` with
//! `η = N π r²` ([`super::StrategyCounts::merging`]); the connections keep theirs.
//!
//! A merge's own path is the light subpath `y_0..y_i` and the camera subpath `z_0..z_{t-1}`
//! with `y_i` near `z_{t-1}`: its densities ([`merge_pdfs`]) are those of the full path
//! `y_0..y_{i-1}, z_{t-1}..z_0`, with `x_i = z_{t-1}` generated from the light side with the
//! light walk's density of `y_i`, and `y_{i-1}` from the camera side along `y_i`'s
//! incoming direction — the quantities that agree with the connections' as `r → 0`.

use super::{FullPath, Heuristic, PathPdfs, StrategyCounts, count_table, remap0};
use crate::integrator::bidir::{Vertex, VertexKind, nee_ratio};
use crate::scene::Scene;

/// One strategy of a path: a connection with `s` light vertices, or a merge at `x_i`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    Connect(usize),
    Merge(usize),
}

/// Whether merging can produce the path at its vertex `i`: an interior rough surface point
/// that the path does not leave through a Dirac lobe.
#[inline]
pub fn mergeable<const N: usize>(p: &PathPdfs<N>, full: &FullPath, i: usize) -> bool {
    if i == 0 || i + 2 > p.n || p.delta[i] {
        return false;
    }
    let v = full.get(i);
    v.kind == VertexKind::Surface && v.is_connectible()
}

/// The weight of `strategy` among the connections (counts `count(s)`) and the merges
/// (weight `eta` each, at the vertices `mergeable(i)`) of a path with densities `p`.
pub fn weight<const N: usize>(
    p: &PathPdfs<N>,
    strategy: Strategy,
    heuristic: Heuristic,
    count: &impl Fn(usize) -> f32,
    eta: f32,
    mergeable: &impl Fn(usize) -> bool,
) -> f32 {
    let n = p.n;
    let at = match strategy {
        Strategy::Connect(s) | Strategy::Merge(s) => s,
    };
    // ratio[i] = p_i / p_at, the connection strategies' densities with the light walk's
    // density of x_0 (next-event estimation's enters through `nee`).
    let mut ratio = [0.0f32; N];
    ratio[at] = 1.0;
    let mut r = 1.0f32;
    for i in (0..at).rev() {
        r *= remap0(p.pe[i]) / remap0(p.pl[i]);
        ratio[i] = r;
    }
    let mut r = 1.0f32;
    for i in at..n.saturating_sub(1) {
        r *= remap0(p.pl[i]) / remap0(p.pe[i]);
        ratio[i + 1] = r;
    }
    let nee = |i: usize| if i == 1 { p.nee_ratio } else { 1.0 };
    let power = |x: f32| match heuristic {
        Heuristic::Balance => x,
        Heuristic::Power => x * x,
    };
    let connect = |i: usize| if p.valid(i) { power(count(i) * nee(i) * ratio[i]) } else { 0.0 };
    let merge = |i: usize| if mergeable(i) { power(eta * p.pl[i] * ratio[i]) } else { 0.0 };
    let own = match strategy {
        Strategy::Connect(s) => power(count(s) * nee(s)),
        Strategy::Merge(i) => power(eta * p.pl[i]),
    };
    if own <= 0.0 {
        return 0.0;
    }
    let total: f32 = (0..n).map(|i| connect(i) + merge(i)).sum();
    let w = own / total;
    if w.is_finite() { w } else { 0.0 }
}

/// The densities of the path a merge of light vertex `y_i` (the last of `light`, `i ≥ 1`)
/// with camera vertex `z_{t-1}` (the last of `camera`, `t ≥ 2`) makes (see the module's
/// documentation).
pub fn merge_pdfs<const N: usize>(scene: &Scene, light: &[Vertex], camera: &[Vertex]) -> PathPdfs<N> {
    let i = light.len() - 1;
    let t = camera.len();
    debug_assert!(i >= 1 && t >= 2);
    let mut p = PathPdfs::copied(&light[..i], camera);
    let (y, z) = (&light[i], &camera[t - 1]);
    let prev = &light[i - 1];
    // x_i from the light side: the light walk's density of `y_i`.
    p.pl[i] = y.pdf_fwd;
    // y_{i-1} from the camera side through z, along y_i's incoming direction, and z's
    // predecessor from the light side through z.
    let dist = if prev.infinite { 1.0 } else { (prev.p - y.p).length() };
    let (fwd, rev) = z.densities(scene, prev, y.wo, dist);
    p.pe[i - 1] = fwd;
    p.pl[i + 1] = rev;
    p.delta[i] = false;
    let x0 = &light[0];
    p.delta_light = matches!(x0.kind, VertexKind::Light(l) if scene.lights[l as usize].is_unreachable());
    p.x0_at_infinity = false;
    p.nee_ratio = nee_ratio(scene, x0, if i >= 2 { light[1].p } else { z.p });
    p
}

/// The MIS weight of merging light vertex `y_i` (the last of `light`) with camera vertex
/// `z_{t-1}` (the last of `camera`), among the strategies of `counts`, whose
/// [`StrategyCounts::merging`] must be set.
pub fn merge_weight<const N: usize>(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    heuristic: Heuristic,
    counts: &impl StrategyCounts,
) -> f32 {
    let Some(eta) = counts.merging() else { return 0.0 };
    let i = light.len() - 1;
    let p = merge_pdfs::<N>(scene, light, camera);
    let full = FullPath { light: &light[..i], camera };
    let table = count_table(&p, &full, counts);
    weight(&p, Strategy::Merge(i), heuristic, &|s| table[s], eta, &|m| mergeable(&p, &full, m))
}
