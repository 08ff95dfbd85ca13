//! PCBPT's cache (Popov et al. 2015, contract §3, steps 2–4): the record pixels' camera
//! vertices, every record's CMF over the light pool, and the lookup that blends the CMFs of
//! a camera vertex's nearest records and draws pool vertices from the blend.

use crate::bsdf::TransportMode;
use crate::film::tiles;
use crate::integrator::bidir::Vertex;
use crate::integrator::bidir::mis::FullPath;
use crate::integrator::bidir::pool::LightPool;
use crate::integrator::bidir::walk::{WalkLimits, camera_subpath, visible};
use crate::integrator::pcbpt::{DistanceTerm, PcOptions, PcSampling};
use crate::integrator::stats::Counters;
use crate::math::{Rgb, luminance};
use crate::sampling::Sampler;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use kiddo::{KdTree, SquaredEuclidean};
use rayon::prelude::*;

/// Key word that separates the record pixels' random streams from the others.
const CACHE_STREAM: u64 = 0x6361_6368;
/// Most records one lookup blends.
pub const MAX_NEIGHBOURS: usize = 16;

/// Caches of at most this many records find neighbours by a linear scan.
const LINEAR_SCAN: usize = 128;
const _: () = assert!(LINEAR_SCAN <= 256, "candidate lists store record indices in bytes");

/// CMF entries per block of the two-level search: the blended CMF is first searched over
/// the block ends (a compact copy of every record's CMF at them), then inside one block.
const BLOCK: usize = 64;
/// The target's geometry term is clamped at distances below this fraction of the scene's
/// bounding radius (the `1/d²` singularity).
const CLAMP_FRACTION: f32 = 0.01;

/// A cache record: a camera vertex and its normal turned towards its incoming direction.
#[derive(Clone, Copy, Debug)]
pub struct Record {
    pub vertex: Vertex,
    pub n: Vec3,
}

/// `n` turned to the side of `w`.
#[inline]
fn facing(n: Vec3, w: Vec3) -> Vec3 {
    if n.dot(w) < 0.0 { -n } else { n }
}

impl Record {
    pub fn new(v: &Vertex) -> Record {
        Record { vertex: *v, n: facing(v.frame.n, v.wo) }
    }
}

/// Traces the record pixels of one iteration: one jittered pixel per `stride × stride` tile,
/// its connectible camera vertices `z_1..z_D` in tile order.
pub fn trace_records(
    scene: &Scene,
    limits: &WalkLimits,
    opts: &PcOptions,
    seed: u64,
    iteration: u64,
) -> (Vec<Record>, Counters) {
    let limits =
        WalkLimits { camera_vertices: limits.camera_vertices.min(opts.cache_depth as usize + 1), ..limits.clone() };
    let tile_list = tiles(scene.film.width, scene.film.height, opts.stride);
    let parts: Vec<(Vec<Record>, Counters)> = tile_list
        .par_chunks(64)
        .enumerate()
        .map(|(c, chunk)| {
            let mut records = Vec::new();
            let mut counters = Counters::default();
            let mut path = Vec::new();
            for (i, tile) in chunk.iter().enumerate() {
                let mut rng = Sampler::new(&[seed, CACHE_STREAM, iteration, (c * 64 + i) as u64]);
                let u = rng.next_2d();
                let pos =
                    Vec2::new(tile.x0 as f32 + u.x * tile.width as f32, tile.y0 as f32 + u.y * tile.height as f32);
                camera_subpath(scene, pos, &limits, &mut rng, &mut path, &mut counters);
                records.extend(path.iter().skip(1).filter(|v| v.scatters() && v.is_connectible()).map(Record::new));
            }
            (records, counters)
        })
        .collect();
    let mut records = Vec::new();
    let mut counters = Counters::default();
    for (r, c) in parts {
        records.extend(r);
        counters += c;
    }
    (records, counters)
}

/// How a lookup blends records.
#[derive(Clone, Copy, Debug)]
pub struct Blend {
    pub neighbours: usize,
    pub uniform: f32,
    pub distance_term: DistanceTerm,
}

/// The records a camera vertex blends and their weights.
#[derive(Clone, Copy, Debug)]
pub struct Neighbours {
    pub index: [u32; MAX_NEIGHBOURS],
    pub weight: [f64; MAX_NEIGHBOURS],
    pub len: usize,
    /// `Σ w_i + uniform`.
    pub norm: f64,
}

/// The records nearest to a point and their squared distances.
#[derive(Clone, Copy, Debug)]
pub struct Nearest {
    pub index: [u32; MAX_NEIGHBOURS],
    pub dist2: [f32; MAX_NEIGHBOURS],
    pub len: usize,
}

/// The PCBPT cache of one iteration: records, their kd-tree and their CMFs over the pool.
pub struct Cache {
    /// Unique per cache built (keys the lookup memo).
    id: u64,
    pub records: Vec<Record>,
    tree: Option<KdTree<f32, 3>>,
    /// Record positions, for the linear scan of small caches.
    sites: Vec<Site>,
    /// Candidate lists of small caches: the linear scan runs over one cell's candidates.
    grid: Option<CandidateGrid>,
    /// `records × v` normalised CMFs, record after record.
    cmf: Vec<f32>,
    /// `records × blocks`: each record's CMF at the last index of every [`BLOCK`].
    block_ends: Vec<f32>,
    /// `Q_c` of each record (0: the record falls back to uniform).
    pub totals: Vec<f64>,
    /// Pool vertices `V`.
    pub v: usize,
    /// `1 / V`.
    inv_v: f64,
    pub blend: Blend,
    clamp2: f32,
}

/// The smallest `i < n` with `f(i) > target` for a non-decreasing `f` with `f(n - 1) > target`,
/// by a binary search whose steps are branch-free selects.
#[inline(always)]
fn first_above(n: usize, target: f64, f: impl Fn(usize) -> f64) -> usize {
    let (mut base, mut len) = (0usize, n);
    while len > 1 {
        let half = len / 2;
        let mid = base + half;
        base = if f(mid - 1) <= target { mid } else { base };
        len -= half;
    }
    base
}

/// The largest `f32` at or below `u`: for any `f32` `x`, `x <= u` exactly when
/// `x <= f32_at_or_below(u)`, so CMF entries compare with `u` in single precision.
#[inline]
fn f32_at_or_below(u: f64) -> f32 {
    let x = u as f32;
    if x as f64 <= u { x } else { x.next_down() }
}

/// How many entries of `xs` are at or below `u`; for non-decreasing `xs`, the index of the
/// first entry above it. Branch-free, so the compiler vectorises it: the entries are
/// compared all at once instead of by a chain of dependent probes.
#[inline(always)]
fn count_at_or_below(xs: &[f32], u: f32) -> usize {
    xs.iter().map(|&x| (x <= u) as u32).sum::<u32>() as usize
}

/// The last CMF index of block `j` over `v` entries.
#[inline]
fn block_end(j: usize, v: usize) -> usize {
    ((j + 1) * BLOCK).min(v) - 1
}

/// A fresh cache identity.
fn next_id() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// The target `q_c(v)` without visibility: `α_L` times both ends' BSDF and cosine terms over
/// the clamped squared distance. `alpha` and `wo` stand for the light vertex's throughput
/// and direction to its predecessor.
#[inline]
fn target(scene: &Scene, y: &Vertex, alpha: Rgb, wo: Vec3, rec: &Record, clamp2: f32) -> f32 {
    let d = rec.vertex.p - y.p;
    let dist2 = d.length_squared();
    if dist2 == 0.0 || !dist2.is_finite() {
        return 0.0;
    }
    let w = d / dist2.sqrt();
    let fl = y.scatter(scene, wo, w, TransportMode::Importance);
    if fl == Rgb::ZERO {
        return 0.0;
    }
    let fe = rec.vertex.scatter(scene, rec.vertex.wo, -w, TransportMode::Radiance);
    luminance(alpha * fl * fe).max(0.0) / dist2.max(clamp2)
}

impl Cache {
    /// An empty cache over a pool of `v` vertices: every lookup is uniform.
    pub fn uniform(v: usize, blend: Blend) -> Cache {
        Cache {
            id: next_id(),
            records: Vec::new(),
            tree: None,
            sites: Vec::new(),
            grid: None,
            cmf: Vec::new(),
            block_ends: Vec::new(),
            inv_v: 1.0 / v.max(1) as f64,
            totals: Vec::new(),
            v,
            blend,
            clamp2: 0.0,
        }
    }

    /// Bytes the CMFs of `records` records over `v` vertices take.
    pub fn bytes(records: usize, v: usize) -> f64 {
        records as f64 * ((v + v.div_ceil(BLOCK)) as f64 * 4.0 + 8.0 + std::mem::size_of::<Record>() as f64)
    }

    /// Evaluates every record's PMF over the pool (in parallel over records, shadow rays
    /// included when `visibility` is set) and builds the kd-tree.
    pub fn build(
        scene: &Scene,
        pool: &LightPool,
        records: Vec<Record>,
        blend: Blend,
        visibility: bool,
    ) -> (Cache, Counters) {
        let v = pool.connectible.len();
        let clamp2 = (CLAMP_FRACTION * scene.bounds.radius).powi(2);
        let mut cmf = vec![0.0f32; records.len() * v];
        let results: Vec<(f64, Counters)> = if v == 0 {
            vec![(0.0, Counters::default()); records.len()]
        } else {
            cmf.par_chunks_mut(v)
                .zip(records.par_iter())
                .map(|(row, rec)| {
                    let mut counters = Counters::default();
                    let mut total = 0.0f64;
                    for (k, &g) in pool.connectible.iter().enumerate() {
                        let y = &pool.vertices[g as usize];
                        let mut q = target(scene, y, y.beta, y.wo, rec, clamp2);
                        if q > 0.0 && visibility && !visible(scene, y, &rec.vertex, &mut counters) {
                            q = 0.0;
                        }
                        row[k] = q;
                        total += q as f64;
                    }
                    if total > 0.0 {
                        let inv = 1.0 / total;
                        let mut acc = 0.0f64;
                        for c in row.iter_mut() {
                            acc += *c as f64;
                            *c = (acc * inv) as f32;
                        }
                        row[v - 1] = 1.0;
                    } else {
                        for (k, c) in row.iter_mut().enumerate() {
                            *c = ((k + 1) as f64 / v as f64) as f32;
                        }
                    }
                    (total, counters)
                })
                .collect()
        };
        let mut counters = Counters::default();
        let mut totals = Vec::with_capacity(results.len());
        for (t, c) in results {
            totals.push(t);
            counters += c;
        }
        let points: Vec<[f32; 3]> = records.iter().map(|r| r.vertex.p.to_array()).collect();
        let tree = (!points.is_empty()).then(|| KdTree::from(&points));
        let block_ends = if v == 0 {
            Vec::new()
        } else {
            cmf.chunks_exact(v).flat_map(|row| (0..v.div_ceil(BLOCK)).map(|j| row[block_end(j, v)])).collect()
        };
        let inv_v = 1.0 / v.max(1) as f64;
        let sites: Vec<Site> = points.iter().enumerate().map(|(i, &p)| Site { p, id: i as u32 }).collect();
        let k = blend.neighbours.clamp(1, MAX_NEIGHBOURS);
        let grid = (records.len() <= LINEAR_SCAN && records.len() > k).then(|| CandidateGrid::new(&sites, k));
        let cache =
            Cache { id: next_id(), records, tree, sites, cmf, block_ends, totals, v, inv_v, blend, clamp2, grid };
        (cache, counters)
    }

    /// Bytes the cache holds.
    pub fn memory(&self) -> f64 {
        Cache::bytes(self.records.len(), self.v)
    }

    /// The stored CMF of record `c`.
    pub fn row(&self, c: usize) -> &[f32] {
        &self.cmf[c * self.v..(c + 1) * self.v]
    }

    /// The records blended for a vertex at `p` with normal `n` (turned towards `wo`) and
    /// incoming direction `wo`, with their weights (supplemental Eq. 1).
    pub fn lookup(&self, p: Vec3, n: Vec3, wo: Vec3) -> Neighbours {
        self.weigh(&self.nearest(p), n, wo)
    }

    /// [`Cache::lookup`] without the memo, for points looked up once (camera vertices
    /// choosing their connections).
    pub fn lookup_once(&self, p: Vec3, n: Vec3, wo: Vec3) -> Neighbours {
        self.weigh(&self.nearest_uncached(p), n, wo)
    }

    /// The nearest records of `p` and their squared distances, through a per-thread
    /// direct-mapped memo: pool vertices are looked up from every pixel that connects to them,
    /// camera vertices by every weight of their sample.
    pub fn nearest(&self, p: Vec3) -> Nearest {
        const SLOTS: usize = 1 << 13;
        type Slot = Option<((u64, [u32; 3]), Nearest)>;
        thread_local! {
            static MEMO: std::cell::RefCell<Vec<Slot>> = const { std::cell::RefCell::new(Vec::new()) };
        }
        let bits = p.to_array().map(f32::to_bits);
        let key = (self.id, bits);
        let h = (bits[0] as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (bits[1] as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
            ^ (bits[2] as u64).wrapping_mul(0x1656_67B1_9E37_79F9)
            ^ self.id.wrapping_mul(0x27D4_EB2F_1656_67C5);
        let slot = (h >> 51) as usize & (SLOTS - 1);
        MEMO.with(|m| {
            let mut m = m.borrow_mut();
            if m.is_empty() {
                m.resize(SLOTS, None);
            }
            if let Some((k, near)) = &m[slot]
                && *k == key
            {
                return *near;
            }
            let near = self.nearest_uncached(p);
            m[slot] = Some((key, near));
            near
        })
    }

    /// The nearest records of `p`: from the kd-tree, or for a cache of at most
    /// [`LINEAR_SCAN`] records by a scan of their positions (faster than a tree walk there).
    pub fn nearest_uncached(&self, p: Vec3) -> Nearest {
        if self.records.len() <= LINEAR_SCAN {
            return self.nearest_by_scan(p);
        }
        let mut near = Nearest { index: [0; MAX_NEIGHBOURS], dist2: [0.0; MAX_NEIGHBOURS], len: 0 };
        let Some(tree) = &self.tree else { return near };
        let found = tree.nearest_n::<SquaredEuclidean>(&p.to_array(), self.blend.neighbours.clamp(1, MAX_NEIGHBOURS));
        for f in found.iter().take(MAX_NEIGHBOURS) {
            near.index[near.len] = f.item as u32;
            near.dist2[near.len] = f.distance;
            near.len += 1;
        }
        near
    }

    /// The nearest records of `p` by a linear scan: over the candidates of `p`'s cell of the
    /// [`CandidateGrid`] where there is one, else over every record.
    fn nearest_by_scan(&self, p: Vec3) -> Nearest {
        let k = self.blend.neighbours.clamp(1, MAX_NEIGHBOURS);
        if let Some(grid) = &self.grid
            && let Some(cell) = grid.cell(p)
        {
            let range = grid.start[cell] as usize..grid.start[cell + 1] as usize;
            return scan_nearest(grid.ids[range].iter().map(|&i| &self.sites[i as usize]), p, k);
        }
        scan_nearest(self.sites.iter(), p, k)
    }

    /// The weights of the nearest records for a vertex with normal `n` (turned towards
    /// `wo`) and incoming direction `wo` (supplemental Eq. 1).
    pub fn weigh(&self, near: &Nearest, n: Vec3, wo: Vec3) -> Neighbours {
        let mut nb = Neighbours {
            index: [0; MAX_NEIGHBOURS],
            weight: [0.0; MAX_NEIGHBOURS],
            len: 0,
            norm: self.blend.uniform as f64,
        };
        let dmax = near.dist2[..near.len].iter().fold(0.0f32, |a, &b| a.max(b)).sqrt();
        for k in 0..near.len {
            let c = near.index[k] as usize;
            let rec = &self.records[c];
            let dist = if dmax > 0.0 {
                let ratio = near.dist2[k].sqrt() / dmax;
                match self.blend.distance_term {
                    DistanceTerm::Printed => ratio,
                    DistanceTerm::Falloff => 1.0 - ratio,
                }
            } else {
                1.0
            };
            let w = n.dot(rec.n).max(0.0) * wo.dot(rec.vertex.wo).max(0.0) * dist;
            if w > 0.0 {
                nb.index[nb.len] = c as u32;
                nb.weight[nb.len] = w as f64;
                nb.norm += w as f64;
                nb.len += 1;
            }
        }
        nb
    }

    /// The lookup of a camera vertex choosing its connections.
    #[inline]
    pub fn lookup_vertex(&self, z: &Vertex) -> Neighbours {
        self.lookup_once(z.p, facing(z.frame.n, z.wo), z.wo)
    }

    /// The blended CMF at index `i` (Eq. 2) times `nb.norm`, from the records' CMF values
    /// `row(c)` there: the search compares it with `u · norm` and divides nothing.
    #[inline(always)]
    fn mass_at(&self, nb: &Neighbours, i: usize, row: impl Fn(usize) -> f32) -> f64 {
        if i + 1 >= self.v {
            return nb.norm;
        }
        let mut sum = self.blend.uniform as f64 * (i + 1) as f64 * self.inv_v;
        for k in 0..nb.len {
            sum += nb.weight[k] * row(nb.index[k] as usize) as f64;
        }
        sum
    }

    #[inline(always)]
    fn entry_mass(&self, nb: &Neighbours, i: usize) -> f64 {
        self.mass_at(nb, i, |c| self.cmf[c * self.v + i])
    }

    /// The blended CMF at index `i` (Eq. 2), evaluated from the blended records only.
    #[inline]
    pub fn cmf_at(&self, nb: &Neighbours, i: usize) -> f64 {
        self.entry_mass(nb, i) / nb.norm
    }

    /// The blended PMF of index `i`: the mass between two CMF entries.
    #[inline]
    pub fn pmf(&self, nb: &Neighbours, i: usize) -> f64 {
        let below = if i == 0 { 0.0 } else { self.entry_mass(nb, i - 1) };
        (self.entry_mass(nb, i) - below) / nb.norm
    }

    /// Inverts the blended CMF for `u ∈ [0, 1)` by binary search (`O(neighbours log V)`):
    /// the smallest index whose CMF exceeds `u`, and its probability. The search runs over
    /// the block ends first (all blocks before the answer's end at or below `u`), then
    /// inside the answer's block, so most CMF reads hit the compact block-end copy.
    pub fn sample(&self, nb: &Neighbours, u: f64) -> (usize, f64) {
        debug_assert!(self.v > 0);
        let target = u * nb.norm;
        let blocks = self.v.div_ceil(BLOCK);
        let block = first_above(blocks, target, |j| {
            self.mass_at(nb, block_end(j, self.v), |c| self.block_ends[c * blocks + j])
        });
        let start = block * BLOCK;
        let i = start + first_above(block_end(block, self.v) + 1 - start, target, |k| self.entry_mass(nb, start + k));
        (i, self.pmf(nb, i))
    }

    /// Draws from the same blended PMF as [`Cache::sample`] by sampling the mixture it is:
    /// `u` picks record `i` with probability `w_i / Σ` or the uniform distribution with
    /// `uniform / Σ`, and, rescaled into the picked interval, inverts that record's CMF alone
    /// (block ends first, then one block). The probability returned is the blended PMF of
    /// the drawn index, as [`Cache::sample`] returns it; stratified `u`s stay stratified.
    pub fn sample_mixture(&self, nb: &Neighbours, u: f64) -> (usize, f64) {
        let i = self.mixture_index(nb, u);
        (i, self.pmf(nb, i))
    }

    /// [`Cache::sample_mixture`] of every `us[k]` into `out[k]`, in two passes: all the
    /// inversions, then all the PMFs. The draws are independent, so each pass's reads of
    /// CMF rows far apart overlap instead of waiting one after another.
    pub fn sample_mixture_all(&self, nb: &Neighbours, us: &[f64], out: &mut [(usize, f64)]) {
        debug_assert_eq!(us.len(), out.len());
        for (o, &u) in out.iter_mut().zip(us) {
            o.0 = self.mixture_index(nb, u);
        }
        for o in out.iter_mut() {
            o.1 = self.pmf(nb, o.0);
        }
    }

    /// The index [`Cache::sample_mixture`] draws for `u`.
    #[inline]
    fn mixture_index(&self, nb: &Neighbours, u: f64) -> usize {
        debug_assert!(self.v > 0);
        let mut t = u * nb.norm;
        for k in 0..nb.len {
            let w = nb.weight[k];
            if t < w {
                return self.invert_row(nb.index[k] as usize, (t / w).min(1.0 - f64::EPSILON));
            }
            t -= w;
        }
        ((t / self.blend.uniform as f64 * self.v as f64).max(0.0) as usize).min(self.v - 1)
    }

    /// The smallest index whose stored CMF of record `c` exceeds `u ∈ [0, 1)` (the last
    /// when none does): the block ends first, then one block, each by counting the entries
    /// at or below `u`.
    #[inline]
    fn invert_row(&self, c: usize, u: f64) -> usize {
        let blocks = self.v.div_ceil(BLOCK);
        let ends = &self.block_ends[c * blocks..(c + 1) * blocks];
        let u = f32_at_or_below(u);
        let block = count_at_or_below(ends, u).min(blocks - 1);
        let start = block * BLOCK;
        let row = &self.cmf[c * self.v + start..c * self.v + block_end(block, self.v) + 1];
        start + count_at_or_below(row, u).min(row.len() - 1)
    }

    /// A draw by the chosen inversion.
    #[inline]
    pub fn draw(&self, nb: &Neighbours, u: f64, sampling: PcSampling) -> (usize, f64) {
        match sampling {
            PcSampling::Cmf => self.sample(nb, u),
            PcSampling::Mixture => self.sample_mixture(nb, u),
        }
    }

    /// `P(y | z)` for MIS: the blended PMF of the light vertex `y = x_{s-1}` for the camera
    /// vertex `z = x_s` of a full path, with the target evaluated on the path (visibility 1,
    /// `alpha` the light throughput at `y` from [`light_throughputs`]) and this cache's records
    /// and normalisers. A function of the path alone.
    pub fn selection_pmf(&self, scene: &Scene, path: &FullPath, s: usize, alpha: Rgb) -> f32 {
        let (y, z) = (path.get(s - 1), path.get(s));
        let dir = |a: &Vertex, b: &Vertex| (b.p - a.p).normalize_or_zero();
        let wz = dir(z, path.get(s + 1));
        let nb = self.lookup(z.p, facing(z.frame.n, wz), wz);
        let uniform = 1.0 / self.v.max(1) as f64;
        let mut sum = self.blend.uniform as f64 * uniform;
        let wo = dir(y, path.get(s - 2));
        for k in 0..nb.len {
            let c = nb.index[k] as usize;
            let pmf = if self.totals[c] <= 0.0 {
                uniform
            } else if alpha == Rgb::ZERO {
                0.0
            } else {
                target(scene, y, alpha, wo, &self.records[c], self.clamp2) as f64 / self.totals[c]
            };
            sum += nb.weight[k] * pmf;
        }
        (sum / nb.norm) as f32
    }
}

/// A record's position and index, 16 bytes.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Site {
    p: [f32; 3],
    id: u32,
}

/// The `k` nearest of `sites`, ties to the lower record index. Each site becomes a key, its
/// squared distance's bits above its index (a non-negative `f32` orders as its bits), and
/// passes through the sorted `k` best by a min/max exchange at every place: no branch
/// depends on the distances.
#[inline]
fn scan_nearest<'a>(sites: impl ExactSizeIterator<Item = &'a Site>, p: Vec3, k: usize) -> Nearest {
    let k = k.min(sites.len()).min(MAX_NEIGHBOURS);
    let mut best = [u64::MAX; MAX_NEIGHBOURS];
    for site in sites {
        let [x, y, z] = site.p;
        let (dx, dy, dz) = (x - p.x, y - p.y, z - p.z);
        let e = dx * dx + dy * dy + dz * dz;
        // NaN (never from finite positions) sorts last; a sum of squares is never -0.
        let d = if e.is_nan() { f32::INFINITY } else { e };
        let mut key = (d.to_bits() as u64) << 32 | site.id as u64;
        for b in &mut best[..k] {
            let lo = key.min(*b);
            key = key.max(*b);
            *b = lo;
        }
    }
    let mut near = Nearest { index: [0; MAX_NEIGHBOURS], dist2: [0.0; MAX_NEIGHBOURS], len: k };
    for (j, &key) in best[..k].iter().enumerate() {
        near.index[j] = key as u32;
        near.dist2[j] = f32::from_bits((key >> 32) as u32);
    }
    near
}

/// A uniform grid over the bounding box of a small cache's records that lists, for each cell,
/// every record that can be among the `k` nearest of a point in the cell: those whose
/// distance to the cell is at most the `k`-th smallest of the records' farthest distances
/// to it. The scan over a cell's candidates finds exactly the neighbours (and the tie order)
/// of a scan over all records; points outside the box scan all records.
struct CandidateGrid {
    lo: Vec3,
    /// Cells per unit length.
    scale: Vec3,
    res: [usize; 3],
    /// Cell `c`'s candidates are the records `ids[start[c]..start[c + 1]]`, ascending: one
    /// byte each (at most [`LINEAR_SCAN`] records), so the lists stay in the nearer caches.
    start: Vec<u32>,
    ids: Vec<u8>,
}

/// Cells of a candidate grid, about.
const GRID_CELLS: f32 = 4096.0;

impl CandidateGrid {
    fn new(points: &[Site], k: usize) -> CandidateGrid {
        let n = points.len();
        let at = |i: usize| Vec3::from_array(points[i].p);
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for i in 0..n {
            lo = lo.min(at(i));
            hi = hi.max(at(i));
        }
        // A margin: camera vertices just outside the records still find their cell.
        let margin = (hi - lo).max_element().max(1e-3) * 0.05;
        let (lo, hi) = (lo - margin, hi + margin);
        let extent = hi - lo;
        let h = (extent.x * extent.y * extent.z / GRID_CELLS).cbrt().max(extent.max_element() / 64.0);
        let res = [0, 1, 2].map(|a| ((extent[a] / h).ceil() as usize).clamp(1, 64));
        let size = Vec3::new(extent.x / res[0] as f32, extent.y / res[1] as f32, extent.z / res[2] as f32);
        let mut grid = CandidateGrid { lo, scale: Vec3::ONE / size, res, start: vec![0], ids: Vec::new() };
        // Slabs of cells along z in parallel, each listing its cells in order.
        let slabs: Vec<(Vec<u32>, Vec<u32>)> = (0..res[2])
            .into_par_iter()
            .map(|z| {
                let (mut counts, mut ids) = (Vec::with_capacity(res[0] * res[1]), Vec::new());
                let (mut far, mut sorted) = (vec![0.0f32; n], vec![0.0f32; n]);
                for y in 0..res[1] {
                    for x in 0..res[0] {
                        // The cell, grown a little so that rounding in `cell` cannot put a
                        // point outside the box its candidates were chosen for.
                        let c0 = lo + Vec3::new(x as f32, y as f32, z as f32) * size - size * 1e-3;
                        let c1 = lo + Vec3::new((x + 1) as f32, (y + 1) as f32, (z + 1) as f32) * size + size * 1e-3;
                        for (i, f) in far.iter_mut().enumerate() {
                            let q = at(i);
                            *f = (q - c0).abs().max((q - c1).abs()).length_squared();
                        }
                        sorted.copy_from_slice(&far);
                        let bound = *sorted.select_nth_unstable_by(k - 1, f32::total_cmp).1;
                        let before = ids.len();
                        ids.extend((0..n as u32).filter(|&i| {
                            let q = at(i as usize);
                            (q - q.clamp(c0, c1)).length_squared() <= bound
                        }));
                        counts.push((ids.len() - before) as u32);
                    }
                }
                (counts, ids)
            })
            .collect();
        for (counts, ids) in slabs {
            let mut at_start = *grid.start.last().unwrap_or(&0);
            for c in counts {
                at_start += c;
                grid.start.push(at_start);
            }
            grid.ids.extend(ids.iter().map(|&i| i as u8));
        }
        grid
    }

    /// The cell of `p`, `None` outside the grid.
    #[inline]
    fn cell(&self, p: Vec3) -> Option<usize> {
        let f = (p - self.lo) * self.scale;
        let mut idx = [0usize; 3];
        for a in 0..3 {
            // Also false for NaN.
            if !(f[a] >= 0.0 && f[a] < self.res[a] as f32) {
                return None;
            }
            idx[a] = (f[a] as usize).min(self.res[a] - 1);
        }
        Some((idx[2] * self.res[1] + idx[1]) * self.res[0] + idx[0])
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::integrator::bidir::mis::Counts;
    use crate::integrator::pcbpt::DRAW_BATCH;
    use crate::sampling::chi2::discrete_chi2;
    use crate::scene::LoadOptions;

    /// `cornell-box` at 64×48.
    pub(crate) fn scene() -> Scene {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box/scene.xml");
        let overrides = vec![("resx".into(), "64".into()), ("resy".into(), "48".into())];
        Scene::load(&path, &LoadOptions { overrides, ..Default::default() }).unwrap()
    }

    fn cache(scene: &Scene, paths: usize, term: DistanceTerm) -> (Cache, LightPool) {
        let limits = WalkLimits::new(8, 3);
        let (pool, _, _) = LightPool::trace::<Counts>(scene, &limits, paths, 3, 0, None);
        let opts = PcOptions { stride: 8, ..PcOptions::default() };
        let (records, _) = trace_records(scene, &limits, &opts, 3, 0);
        let blend = Blend { neighbours: 6, uniform: 0.5, distance_term: term };
        let (cache, _) = Cache::build(scene, &pool, records, blend, true);
        (cache, pool)
    }

    #[test]
    fn the_linear_scan_finds_the_kd_trees_neighbours() {
        let scene = scene();
        let (cache, _) = cache(&scene, 50, DistanceTerm::Falloff);
        assert!(cache.records.len() > LINEAR_SCAN, "the tree path is taken: {} records", cache.records.len());
        let mut rng = crate::sampling::Sampler::new(&[7]);
        let (c, r) = (scene.bounds.center, scene.bounds.radius);
        for _ in 0..2000 {
            let u = Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d());
            let p = c + (u * 2.0 - 1.0) * r;
            let (tree, scan) = (cache.nearest_uncached(p), cache.nearest_by_scan(p));
            assert_eq!(tree.len, scan.len);
            for k in 0..tree.len {
                assert!((tree.dist2[k] - scan.dist2[k]).abs() <= 1e-6 * tree.dist2[k].max(1e-6), "{p}");
            }
        }
    }

    #[test]
    fn the_candidate_grid_finds_the_full_scans_neighbours() {
        let scene = scene();
        let limits = WalkLimits::new(8, 3);
        let (pool, _, _) = LightPool::trace::<Counts>(&scene, &limits, 50, 3, 0, None);
        let blend = Blend { neighbours: 6, uniform: 0.5, distance_term: DistanceTerm::Falloff };
        let opts = PcOptions { stride: 16, ..PcOptions::default() };
        let (mut records, _) = trace_records(&scene, &limits, &opts, 3, 0);
        // Two records at one position: ties must go to the lower index, as in the full scan.
        records.push(records[3]);
        let (cache, _) = Cache::build(&scene, &pool, records, blend, false);
        let n = cache.records.len();
        assert!(n > 12 && n <= LINEAR_SCAN, "{n} records");
        let grid = cache.grid.as_ref().expect("a small cache has a candidate grid");
        let cells = grid.start.len() - 1;
        assert!(grid.ids.len() < cells * n / 2, "{} candidates in {cells} cells of {n} records", grid.ids.len());
        let mut rng = Sampler::new(&[11]);
        // Points over the grid's box grown by a fifth of its size on each side.
        let size = Vec3::new(grid.res[0] as f32, grid.res[1] as f32, grid.res[2] as f32) / grid.scale;
        let (c, r) = (grid.lo + size * 0.5, size * 0.7);
        let mut inside = 0;
        for i in 0..20_000 {
            let p = if i % 4 == 0 {
                // Record positions themselves (zero distances, the duplicated pair).
                cache.records[i / 4 % n].vertex.p
            } else {
                let u = Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d());
                c + (u * 2.0 - 1.0) * r
            };
            inside += grid.cell(p).is_some() as usize;
            let (fast, full) = (cache.nearest_by_scan(p), scan_nearest(cache.sites.iter(), p, 6));
            assert_eq!(fast.len, full.len);
            assert_eq!(fast.index[..fast.len], full.index[..full.len], "{p}");
            assert_eq!(fast.dist2[..fast.len], full.dist2[..full.len], "{p}");
            // And the full scan is a sort by distance, ties by index.
            let mut sorted: Vec<(f32, u32)> = (0..n)
                .map(|i| {
                    let d = cache.records[i].vertex.p - p;
                    (d.x * d.x + d.y * d.y + d.z * d.z, i as u32)
                })
                .collect();
            sorted.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let expected: Vec<u32> = sorted[..6].iter().map(|e| e.1).collect();
            assert_eq!(full.index[..full.len], expected[..], "{p}");
        }
        assert!((7_000..19_000).contains(&inside), "{inside} of 20 000 points fell in the grid");
    }

    /// The blended CMF built eagerly, entry by entry over whole rows.
    fn eager(cache: &Cache, nb: &Neighbours) -> Vec<f64> {
        (0..cache.v)
            .map(|i| {
                let mut sum = cache.blend.uniform as f64 * (i + 1) as f64 / cache.v as f64;
                for k in 0..nb.len {
                    sum += nb.weight[k] * cache.row(nb.index[k] as usize)[i] as f64;
                }
                sum / nb.norm
            })
            .collect()
    }

    /// Lookups at camera vertices of the scene.
    fn lookups(scene: &Scene, cache: &Cache, count: usize) -> Vec<Neighbours> {
        let limits = WalkLimits::new(4, 3);
        let mut out = Vec::new();
        let mut path = Vec::new();
        let mut counters = Counters::default();
        for i in 0..count as u64 * 4 {
            let mut rng = Sampler::new(&[99, i]);
            let pos = rng.next_2d() * Vec2::new(64.0, 48.0);
            camera_subpath(scene, pos, &limits, &mut rng, &mut path, &mut counters);
            if let Some(z) = path.get(1 + (i as usize % 3)).filter(|v| v.is_connectible()) {
                out.push(cache.lookup_vertex(z));
            }
            if out.len() == count {
                break;
            }
        }
        assert_eq!(out.len(), count);
        out
    }

    #[test]
    fn lazy_cmf_is_monotone_ends_at_one_and_equals_the_eager_blend() {
        let scene = scene();
        for term in [DistanceTerm::Falloff, DistanceTerm::Printed] {
            let (cache, _) = cache(&scene, 300, term);
            assert!(cache.v > 300 && cache.records.len() > 30, "{} × {}", cache.records.len(), cache.v);
            let mut blended = 0;
            for nb in lookups(&scene, &cache, 40) {
                blended += (nb.len > 0) as usize;
                let e = eager(&cache, &nb);
                let mut prev = 0.0;
                for (i, &ei) in e.iter().enumerate() {
                    let lazy = cache.cmf_at(&nb, i);
                    assert!(lazy >= prev, "{term:?}: CMF decreases at {i}: {prev} → {lazy}");
                    assert!((lazy - ei).abs() < 1e-6, "{term:?}: lazy {lazy} vs eager {ei} at {i}");
                    let pmf = cache.pmf(&nb, i);
                    // The uniform blend keeps every vertex reachable.
                    let floor = cache.blend.uniform as f64 / (cache.v as f64 * nb.norm);
                    assert!(pmf >= floor * (1.0 - 1e-3), "{term:?}: vertex {i} has probability {pmf} < {floor}");
                    prev = lazy;
                }
                assert_eq!(cache.cmf_at(&nb, cache.v - 1), 1.0);
                assert!((e[cache.v - 1] - 1.0).abs() < 1e-6);
            }
            assert!(blended > 20, "only {blended} lookups found records");
        }
    }

    #[test]
    fn batched_mixture_draws_equal_single_draws() {
        let scene = scene();
        let (cache, _) = cache(&scene, 200, DistanceTerm::Falloff);
        let mut rng = Sampler::new(&[17]);
        let mut blended = 0;
        for nb in lookups(&scene, &cache, 40) {
            blended += (nb.len > 0) as usize;
            for m in [1, 3, DRAW_BATCH] {
                let us: Vec<f64> = (0..m).map(|_| rng.next_1d() as f64).collect();
                let mut out = vec![(usize::MAX, -1.0); m];
                cache.sample_mixture_all(&nb, &us, &mut out);
                for (&u, &o) in us.iter().zip(&out) {
                    assert_eq!(o, cache.sample_mixture(&nb, u), "u = {u}");
                }
            }
        }
        assert!(blended > 20, "only {blended} lookups found records");
    }

    #[test]
    fn drawn_vertices_follow_the_blended_pmf() {
        let scene = scene();
        let (cache, _) = cache(&scene, 60, DistanceTerm::Falloff);
        let nbs: Vec<Neighbours> = lookups(&scene, &cache, 40).into_iter().filter(|nb| nb.len >= 2).take(3).collect();
        assert_eq!(nbs.len(), 3);
        let n = 400_000u64;
        let mut rng = Sampler::new(&[5]);
        for (nb, sampling) in nbs.iter().flat_map(|nb| [(nb, PcSampling::Cmf), (nb, PcSampling::Mixture)]) {
            let mut counts = vec![0u64; cache.v];
            for _ in 0..n {
                let u = rng.next_1d() as f64 + rng.next_1d() as f64 / 16_777_216.0;
                let (i, pmf) = cache.draw(nb, u, sampling);
                assert!((pmf - cache.pmf(nb, i)).abs() < 1e-12);
                counts[i] += 1;
            }
            let expected: Vec<f64> = (0..cache.v).map(|i| cache.pmf(nb, i) * n as f64).collect();
            discrete_chi2(&counts, &expected).assert_pass();
            // Negative control: the rows' own PMFs without the uniform blend are rejected.
            let unblended: Vec<f64> = (0..cache.v)
                .map(|i| {
                    let mut sum = 0.0;
                    for k in 0..nb.len {
                        let row = cache.row(nb.index[k] as usize);
                        let below = if i == 0 { 0.0 } else { row[i - 1] as f64 };
                        sum += nb.weight[k] * (row[i] as f64 - below);
                    }
                    sum / (nb.norm - cache.blend.uniform as f64) * n as f64
                })
                .collect();
            assert!(!discrete_chi2(&counts, &unblended).passed(), "{sampling:?}: the unblended PMF was not rejected");
        }
    }

    #[test]
    fn counting_inversion_equals_the_binary_search() {
        let scene = scene();
        let (cache, _) = cache(&scene, 200, DistanceTerm::Falloff);
        assert!(cache.v > 3 * BLOCK, "{} vertices: one block would not test the block search", cache.v);
        let mut rng = Sampler::new(&[17]);
        for c in 0..cache.records.len() {
            let row = cache.row(c);
            let search = |u: f64| first_above(cache.v, u, |i| row[i] as f64);
            // Random points, the stored values themselves and their f64 neighbours (where the
            // comparison in single precision could go wrong), and the ends.
            let mut us: Vec<f64> =
                (0..200).map(|_| rng.next_1d() as f64 + rng.next_1d() as f64 / 16_777_216.0).collect();
            for &x in row.iter().step_by(7) {
                let x = x as f64;
                us.extend([x, x.next_down(), x.next_up()].into_iter().filter(|u| (0.0..1.0).contains(u)));
            }
            us.extend([0.0, 1.0 - f64::EPSILON]);
            for u in us {
                assert_eq!(cache.invert_row(c, u), search(u), "record {c}, u = {u:e}");
            }
        }
    }

    #[test]
    fn records_without_light_fall_back_to_uniform() {
        let scene = scene();
        let (full, pool) = cache(&scene, 200, DistanceTerm::Falloff);
        // A record that faces away from every pool vertex (seen from behind a wall).
        let mut rec = full.records[0];
        rec.vertex.p = Vec3::new(0.0, 0.0, -50.0);
        let blend = full.blend;
        let (cache, _) = Cache::build(&scene, &pool, vec![rec], blend, true);
        assert_eq!(cache.totals[0], 0.0);
        for (i, &c) in cache.row(0).iter().enumerate() {
            assert!((c as f64 - (i + 1) as f64 / cache.v as f64).abs() < 1e-6);
        }
        let nb = cache.lookup(rec.vertex.p, rec.n, rec.vertex.wo);
        assert_eq!(nb.len, 1);
        for i in [0, cache.v / 2, cache.v - 1] {
            assert!((cache.pmf(&nb, i) - 1.0 / cache.v as f64).abs() < 1e-6);
        }
        // No records at all: the uniform distribution alone.
        let empty = Cache::uniform(10, blend);
        let nb = empty.lookup(Vec3::ZERO, Vec3::Z, Vec3::Z);
        assert_eq!(nb.len, 0);
        assert!((0..10).all(|i| (empty.pmf(&nb, i) - 0.1).abs() < 1e-12));
        assert_eq!(empty.sample(&nb, 0.55).0, 5);
        assert_eq!(empty.sample_mixture(&nb, 0.55).0, 5);
    }
}
