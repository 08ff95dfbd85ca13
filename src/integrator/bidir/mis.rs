//! MIS weights of bidirectional strategies by the ratio walk (pbrt-v4 style; contract §2), on
//! a copy of the path's densities: the vertices are never modified.
//!
//! A full path `x_0..x_{n-1}` runs from the light end (`x_0 = y_0`) to the camera
//! (`x_{n-1} = z_0`). Strategy `s'` (with `t' = n - s'`) samples `x_0..x_{s'-1}` from the
//! light and the rest from the camera, with density `p_{s'} = Π_{i<s'} pL(x_i) Π_{i≥s'}
//! pE(x_i)`, so `p_{s'+1} / p_{s'} = pL(x_{s'}) / pE(x_{s'})`. Each strategy is used
//! `n(s',t')` times per camera sample (the strategy count, 1 in BDPT); the weight of
//! strategy `s` is `(n_s p_s)^β / Σ_{s'} (n_{s'} p_{s'})^β`, β = 1 (balance) or 2 (power).

use crate::integrator::bidir::guide::Guide;
use crate::integrator::bidir::{Connection, Vertex, VertexKind, nee_ratio};
use crate::scene::Scene;

/// Room for two subpaths of [`crate::integrator::bidir::MAX_VERTICES`].
pub const CAP: usize = 2 * crate::integrator::bidir::MAX_VERTICES;
/// Paths up to this many vertices use a small array.
pub const SHORT: usize = 16;

pub use crate::sampling::Heuristic;

/// The densities of one full path as seen by one strategy, copied out of its vertices and
/// patched where the connection changes them.
/// `N` bounds the path length: short paths use a small array.
#[derive(Clone, Debug)]
pub struct PathPdfs<const N: usize = CAP> {
    pub n: usize,
    /// `pL(x_i)`: area density of `x_i` generated from the light side.
    pub pl: [f32; N],
    /// `pE(x_i)`: area density of `x_i` generated from the camera side.
    pub pe: [f32; N],
    /// `x_i` scatters through a Dirac delta (no connection can end there).
    pub delta: [bool; N],
    /// `x_0` is a light with a delta position or direction (no camera path can hit it).
    pub delta_light: bool,
    /// `x_0` lies at infinity: the pinhole cannot be connected to it (`s = 1, t = 1`).
    pub x0_at_infinity: bool,
    /// Density of next-event estimation producing `x_0` from `x_1`, over `pL(x_0)`.
    pub nee_ratio: f32,
}

impl<const N: usize> PathPdfs<N> {
    /// The densities of the path `light ++ reverse(camera)` as its vertices hold them, before
    /// the patches of the strategy that joins them.
    #[inline(always)]
    pub fn copied(light: &[Vertex], camera: &[Vertex]) -> PathPdfs<N> {
        let n = light.len() + camera.len();
        let mut p = PathPdfs::new(n);
        for (i, v) in light.iter().enumerate() {
            p.pl[i] = v.pdf_fwd;
            p.pe[i] = v.pdf_rev;
            p.delta[i] = v.delta;
        }
        for (j, v) in camera.iter().enumerate() {
            let i = n - 1 - j;
            p.pe[i] = v.pdf_fwd;
            p.pl[i] = v.pdf_rev;
            p.delta[i] = v.delta;
        }
        p
    }

    pub fn new(n: usize) -> PathPdfs<N> {
        assert!(n <= N, "a path of {n} vertices does not fit in {N}");
        PathPdfs {
            n,
            pl: [0.0; N],
            pe: [0.0; N],
            delta: [false; N],
            delta_light: false,
            x0_at_infinity: false,
            nee_ratio: 1.0,
        }
    }

    /// Whether strategy `s` can produce this path: the camera is a pinhole (so `t >= 1`),
    /// a point or directional light cannot be hit, the pinhole cannot be joined to a light at
    /// infinity, and neither end of the connecting edge is specular.
    #[inline]
    pub fn valid(&self, s: usize) -> bool {
        if s >= self.n || (s == 1 && self.n == 2 && self.x0_at_infinity) {
            return false;
        }
        if s == 0 { !self.delta_light } else { !(self.delta[s - 1] | self.delta[s]) }
    }
}

/// Zero densities mark Dirac deltas; they cancel in the ratios (pbrt's `remap0`).
#[inline]
pub(crate) fn remap0(x: f32) -> f32 {
    if x == 0.0 { 1.0 } else { x }
}

/// The weight of strategy `s` of the path, with strategy counts `count(s')`.
pub fn weight_from_pdfs<const N: usize>(
    p: &PathPdfs<N>,
    s: usize,
    heuristic: Heuristic,
    count: &impl Fn(usize) -> f32,
) -> f32 {
    match heuristic {
        Heuristic::Balance => walk::<N, false, false>(p, s, count),
        Heuristic::Power => walk::<N, true, false>(p, s, count),
    }
}

/// The ratio walk of [`weight_from_pdfs`], one copy per heuristic (`POWER`: β = 2).
/// `PLAIN`: unit counts and a unit NEE ratio, so that each term is the ratio alone (the
/// general terms multiply it by exact ones).
#[inline(always)]
fn walk<const N: usize, const POWER: bool, const PLAIN: bool>(
    p: &PathPdfs<N>,
    s: usize,
    count: &impl Fn(usize) -> f32,
) -> f32 {
    let n_s = count(s);
    if n_s <= 0.0 {
        return 0.0;
    }
    // p_1 uses next-event estimation's density for x_0; the others the light subpath's.
    let nee = |i: usize| if i == 1 { p.nee_ratio } else { 1.0 };
    let inv_norm = 1.0 / (nee(s) * n_s);
    let term = |i: usize, r: f32| -> f32 {
        if !p.valid(i) {
            return 0.0;
        }
        if PLAIN {
            return if POWER { r * r } else { r };
        }
        let c = count(i);
        if c > 0.0 {
            let x = r * nee(i) * c * inv_norm;
            if POWER { x * x } else { x }
        } else {
            0.0
        }
    };
    let mut sum = 1.0f32;
    // Towards the light: p_i / p_s.
    let mut r = 1.0f32;
    for i in (0..s).rev() {
        r *= remap0(p.pe[i]) / remap0(p.pl[i]);
        sum += term(i, r);
    }
    // Towards the camera: p_{i+1} / p_s.
    let mut r = 1.0f32;
    for i in s..p.n.saturating_sub(1) {
        r *= remap0(p.pl[i]) / remap0(p.pe[i]);
        sum += term(i + 1, r);
    }
    let w = 1.0 / sum;
    if w.is_finite() { w } else { 0.0 }
}

/// [`weight_from_pdfs`] with every strategy count 1 (BDPT's): where next-event estimation
/// also samples `x_0` with the light subpath's density (no sphere light), every ratio term
/// is the plain ratio, and the walk needs no count or density-ratio factors. The same
/// value, bit for bit, as the general walk with unit counts.
pub fn weight_unit_counts<const N: usize>(p: &PathPdfs<N>, s: usize, heuristic: Heuristic) -> f32 {
    if p.nee_ratio != 1.0 {
        return weight_from_pdfs(p, s, heuristic, &|_| 1.0);
    }
    match heuristic {
        Heuristic::Balance => walk::<N, false, true>(p, s, &|_| 1.0),
        Heuristic::Power => walk::<N, true, true>(p, s, &|_| 1.0),
    }
}

/// A full path given by its two subpath prefixes: `light = y_0..y_{s-1}`,
/// `camera = z_0..z_{t-1}`.
#[derive(Clone, Copy)]
pub struct FullPath<'a> {
    pub light: &'a [Vertex],
    pub camera: &'a [Vertex],
}

impl FullPath<'_> {
    pub fn len(&self) -> usize {
        self.light.len() + self.camera.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Vertex `x_i`, counted from the light end.
    #[inline]
    pub fn get(&self, i: usize) -> &Vertex {
        if i < self.light.len() { &self.light[i] } else { &self.camera[self.len() - 1 - i] }
    }
}

/// How many times per camera sample each strategy is used (`n(s,t)`).
pub trait StrategyCounts {
    fn count(&self, path: &FullPath, s: usize, t: usize) -> f32;

    /// Whether every count is one (BDPT): the weights need not look them up.
    fn all_ones(&self) -> bool {
        false
    }

    /// Whether the counts are costly functions of the path, better evaluated together by
    /// [`StrategyCounts::fill`] once per weight.
    fn path_dependent(&self) -> bool {
        false
    }

    /// Whether the counts carry factors that are functions of the path's densities
    /// ([`StrategyCounts::density_factors`]: a correction for correlated samples, such as
    /// PCBPT's `--pc-mis correlated`).
    fn density_dependent(&self) -> bool {
        false
    }

    /// The factors of the counts of the strategies `0..n` of a path of `n` vertices whose
    /// densities are `pl(i)`, `pe(i)`, into `out[..n]` (left as they are by default). They
    /// must be the same whichever strategy sampled the path, so that the weights still sum
    /// to one.
    fn density_factors(&self, _n: usize, _pl: impl Fn(usize) -> f32, _pe: impl Fn(usize) -> f32, _out: &mut [f32]) {}

    /// Merging strategies beside the connections ([`merging`]): `η = N π r²`, the weight of
    /// a merge at a vertex relative to its density; `None` (the default) when there are none.
    fn merging(&self) -> Option<f32> {
        None
    }

    /// The counts of the strategies `s'` of the path for which `needed(s')`, into `out[s']`.
    fn fill(&self, path: &FullPath, needed: &dyn Fn(usize) -> bool, out: &mut [f32]) {
        let n = path.len();
        for (s, o) in out.iter_mut().enumerate().take(n) {
            if needed(s) {
                *o = self.count(path, s, n - s);
            }
        }
    }
}

/// The counts of BDPT and light tracing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Counts {
    /// BDPT: every strategy once.
    Bdpt,
    /// Light tracing alone: only `t = 1` (and the camera ray to the sky).
    LightTrace,
}

impl StrategyCounts for Counts {
    fn all_ones(&self) -> bool {
        *self == Counts::Bdpt
    }

    #[inline]
    fn count(&self, path: &FullPath, s: usize, t: usize) -> f32 {
        match *self {
            Counts::Bdpt => 1.0,
            // Light tracing cannot reach the pinhole from infinity: the sky seen directly is
            // the camera ray's (`s = 0, t = 2`).
            Counts::LightTrace => {
                if t == 1 || s == 0 && t == 2 && path.get(0).infinite {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }
}

/// Copies the densities of the path `light ++ reverse(camera)` and patches those the
/// connection of `y_{s-1}` and `z_{t-1}` changes: the reverse densities of the two
/// connecting vertices and of their predecessors. For `s = 1` and `t = 1` the slices hold
/// the sampled light point and the camera. `conn` is the connection's evaluation (absent
/// for `s = 0`, where the camera subpath ends on an emitter).
#[inline(always)]
pub fn path_pdfs<const N: usize>(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    conn: Option<&Connection>,
) -> PathPdfs<N> {
    let (s, t) = (light.len(), camera.len());
    let n = s + t;
    debug_assert!(t >= 1 && n <= CAP);
    let mut p = PathPdfs::copied(light, camera);
    let pt = &camera[t - 1];
    match conn {
        Some(c) => {
            let qs = &light[s - 1];
            // pt and qs as reached across the connection.
            p.pl[s] = c.light_end.pdf_fwd * pt.cos_area(c.w) * c.inv_dist2;
            p.pe[s - 1] = c.camera_end.pdf_fwd * qs.cos_area(c.w) * c.inv_dist2;
            // Their predecessors, generated from them given the other end.
            if t >= 2 {
                p.pl[s + 1] = c.camera_end.pdf_rev * pt.to_prev;
            }
            if s >= 2 {
                p.pe[s - 2] = c.light_end.pdf_rev * qs.to_prev;
            }
            p.delta[s - 1] = false;
        }
        None => {
            debug_assert_eq!(s, 0);
            p.pl[0] = pt.pdf_light_origin(scene);
            if t >= 2 {
                p.pl[1] = pt.pdf_light(scene, &camera[t - 2]);
            }
        }
    }
    p.delta[s] = false;
    let x0 = if s > 0 { &light[0] } else { pt };
    p.delta_light = scene.light_sampler.any_unreachable()
        && match x0.kind {
            VertexKind::Light(l) => scene.lights[l as usize].is_unreachable(),
            _ => false,
        };
    p.x0_at_infinity = n == 2 && x0.at_infinity();
    let x1 = FullPath { light, camera }.get(1).p;
    p.nee_ratio = nee_ratio(scene, x0, x1);
    p
}

/// The MIS weight of the strategy that joins `light` (`y_0..y_{s-1}`) and `camera`
/// (`z_0..z_{t-1}`), with the connection already evaluated (`None` for `s = 0`).
pub fn mis_weight_with(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    conn: Option<&Connection>,
    heuristic: Heuristic,
    counts: &impl StrategyCounts,
) -> f32 {
    // Most paths are short: a small array is cheaper to set up.
    if light.len() + camera.len() <= SHORT {
        weight_in::<SHORT>(scene, light, camera, conn, heuristic, counts)
    } else {
        weight_in::<CAP>(scene, light, camera, conn, heuristic, counts)
    }
}

/// [`mis_weight_with`] with the path's densities in arrays of `N`.
#[inline(always)]
fn weight_in<const N: usize>(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    conn: Option<&Connection>,
    heuristic: Heuristic,
    counts: &impl StrategyCounts,
) -> f32 {
    let full = FullPath { light, camera };
    let (n, s) = (full.len(), light.len());
    let p = path_pdfs::<N>(scene, light, camera, conn);
    if let Some(eta) = counts.merging() {
        let table = count_table(&p, &full, counts);
        let mergeable = |m| merging::mergeable(&p, &full, m);
        merging::weight(&p, merging::Strategy::Connect(s), heuristic, &|i| table[i], eta, &mergeable)
    } else if counts.path_dependent() || counts.density_dependent() {
        // Costly or corrected counts: all those the walk needs, evaluated together first.
        let table = count_table(&p, &full, counts);
        weight_from_pdfs(&p, s, heuristic, &|i| table[i])
    } else if counts.all_ones() {
        weight_unit_counts(&p, s, heuristic)
    } else {
        weight_from_pdfs(&p, s, heuristic, &|sp| counts.count(&full, sp, n - sp))
    }
}

/// The counts of every strategy of the path that the walk needs (the sampled one and the
/// valid ones), with their density-dependent factors applied.
pub(crate) fn count_table<const N: usize>(p: &PathPdfs<N>, full: &FullPath, counts: &impl StrategyCounts) -> [f32; N] {
    let (n, s) = (full.len(), full.light.len());
    let mut table = [0.0f32; N];
    counts.fill(full, &|i| i == s || p.valid(i), &mut table);
    if counts.density_dependent() {
        let mut c = [1.0f32; N];
        counts.density_factors(n, |i| p.pl[i], |i| p.pe[i], &mut c);
        table[..n].iter_mut().zip(&c[..n]).for_each(|(t, c)| *t *= c);
    }
    table
}

/// The MIS weight of the strategy that joins `light` and `camera`, evaluating the
/// connection itself.
pub fn mis_weight(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    heuristic: Heuristic,
    counts: &impl StrategyCounts,
) -> f32 {
    let conn = match light.last() {
        Some(qs) => match Connection::new(scene, qs, &camera[camera.len() - 1]) {
            Some(c) => Some(c),
            None => return 0.0,
        },
        None => None,
    };
    mis_weight_with(scene, light, camera, conn.as_ref(), heuristic, counts)
}

/// The weights of every strategy of a full path computed from scratch: each strategy's
/// density is the product of the generation densities of all vertices (no ratios, no
/// patching). The reference the ratio walk is tested against; `path` runs from the light
/// end to the camera, without Dirac deltas.
pub fn brute_force_weights(
    scene: &Scene,
    path: &[Vertex],
    heuristic: Heuristic,
    counts: &impl StrategyCounts,
) -> Vec<f64> {
    brute_force_weights_with(scene, path, heuristic, counts, None)
}

/// [`brute_force_weights`] of a path whose camera walks follow `guide` (the camera side's
/// densities at surface vertices are the guide's, [`Vertex::pdf_with`]).
pub fn brute_force_weights_with(
    scene: &Scene,
    path: &[Vertex],
    heuristic: Heuristic,
    counts: &impl StrategyCounts,
    guide: Option<&dyn Guide>,
) -> Vec<f64> {
    let n = path.len();
    let pl: Vec<f64> = (0..n)
        .map(|i| match i {
            0 => path[0].pdf_light_origin(scene) as f64,
            1 => path[0].pdf_light(scene, &path[1]) as f64,
            _ => path[i - 1].pdf(scene, Some(&path[i - 2]), &path[i]) as f64,
        })
        .collect();
    let pe: Vec<f64> = (0..n)
        .map(|i| {
            if i == n - 1 {
                1.0
            } else if i == n - 2 {
                path[n - 1].pdf(scene, None, &path[i]) as f64
            } else {
                path[i + 1].pdf_with(scene, Some(&path[i + 2]), &path[i], guide) as f64
            }
        })
        .collect();
    let mut corr = vec![1.0f32; n];
    counts.density_factors(n, |i| pl[i] as f32, |i| pe[i] as f32, &mut corr);
    let nee = nee_ratio(scene, &path[0], path[1].p) as f64;
    let delta_light = matches!(path[0].kind, VertexKind::Light(l) if scene.lights[l as usize].is_unreachable());
    let at_infinity = path[0].at_infinity();
    let dens: Vec<f64> = (0..n)
        .map(|s| {
            if s == 0 && delta_light || s == 1 && n == 2 && at_infinity {
                return 0.0;
            }
            // Strategy s: the light subpath is path[0..s], the camera subpath the rest.
            let light: Vec<Vertex> = path[..s].to_vec();
            let camera: Vec<Vertex> = path[s..].iter().rev().copied().collect();
            let c = counts.count(&FullPath { light: &light, camera: &camera }, s, n - s) as f64 * corr[s] as f64;
            let mut p = c * if s == 1 { nee } else { 1.0 };
            for (i, (l, e)) in pl.iter().zip(&pe).enumerate() {
                p *= if i < s { *l } else { *e };
            }
            match heuristic {
                Heuristic::Balance => p,
                Heuristic::Power => p * p,
            }
        })
        .collect();
    let total: f64 = dens.iter().sum();
    dens.iter().map(|d| d / total).collect()
}

pub mod merging;
#[cfg(test)]
mod tests;
