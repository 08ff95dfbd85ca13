//! The integrators against the Mitsuba 3 path-tracer references in `tests/data` (settings in
//! the JSON beside each EXR), as one table: each row renders a scene ([`Case`]) twice, with
//! seeds 1 and 2, with an integrator and its options written as on the command line (read by
//! the command line's own parser, [`registry::parse_options`]), and judges the two renders
//! against the scene's reference ([`Judge`]): the image mean within a tolerance, the relMSE
//! within 1.3× of what the renders' noise and the reference's explain. A negative control
//! must fail its check, so that a check which passes anything is caught.
//!
//! Every row is a trial of its own, named `scene/integrator/arguments`:
//! `cargo test --test reference -- veach-ajar/pcbpt` runs the rows whose names contain the
//! filter, `-- --list` lists them, `-- --ignored` runs the ignored ones.

mod common;

use clap::ValueEnum;
use common::*;
use libtest_mimic::{Arguments, Failed, Trial};
use pcbpt::accel::Backend;
use pcbpt::image_io::Image;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions, registry};
use pcbpt::sampling::SamplerKind;
use pcbpt::scene::Scene;

fn main() {
    let trials: Vec<Trial> = rows().into_iter().map(Row::trial).collect();
    let mut names: Vec<&str> = trials.iter().map(Trial::name).collect();
    names.sort_unstable();
    if let Some(twice) = names.windows(2).find(|w| w[0] == w[1]) {
        panic!("two rows named {}", twice[0]);
    }
    libtest_mimic::run(&Arguments::from_args(), trials).exit();
}

/// How a row's two renders are judged against the reference.
#[derive(Clone, Copy)]
enum Judge {
    /// Their average against the reference, whose own noise is the case's
    /// ([`Verdict::averaged`]).
    Averaged,
    /// The first against a reference of the same estimator with `ref_spp` samples, whose
    /// noise is the pair's scaled by spp / `ref_spp` ([`Verdict::new`]).
    SameEstimator { ref_spp: u32 },
    /// [`Judge::Averaged`] over the pixels light tracing can render
    /// ([`reachable_by_light_tracing`] with `min_alpha`), the others set to the reference's
    /// values, the reference's noise scaled to the share of pixels kept and the mean taken
    /// over the kept pixels. With `whole_image_fails`, the same check over the whole image
    /// must fail: it sees the absence of the pixels left out.
    LightTraced { min_alpha: f32, whole_image_fails: bool },
}

/// A rectangle of the film, columns `x0..x1` × rows `y0..y1`.
type Rect = ((u32, u32), (u32, u32));

/// One case of the table: what is rendered, and how it is judged.
struct Row {
    case: &'static Case,
    /// As `--integrator` takes it.
    integrator: &'static str,
    /// The integrator's options, as on the command line.
    options: &'static str,
    spp: u32,
    seeds: [u64; 2],
    /// Worker threads (0: all cores).
    threads: usize,
    /// Replaces the scene's `max_depth` (`--max-depth`).
    max_depth: Option<i32>,
    /// Replaces the scene's sampler (`--sampler`).
    sampler: Option<SamplerKind>,
    /// Scene parameters beside the case's (`-D`).
    defines: &'static [(&'static str, &'static str)],
    judge: Judge,
    /// How far the image mean may be from the reference's.
    mean_tol: f64,
    /// How far the relMSE may exceed what noise explains, as a factor.
    excess_tol: f64,
    /// Pixels brighter than this in the reference are left out of the mean.
    mean_cutoff: Option<f32>,
    /// Rectangles whose mean over the two renders must each be the reference's within
    /// `region_tol`.
    regions: &'static [Rect],
    region_tol: f64,
    /// A negative control: the check must fail.
    must_fail: bool,
    /// Why the row is left out of a plain run (`--ignored` runs it).
    ignored: Option<&'static str>,
}

/// `case` rendered with `integrator` and `options` at `spp`, judged as [`Judge::Averaged`]
/// with the case's tolerance and cutoff.
fn row(case: &'static Case, integrator: &'static str, spp: u32, options: &'static str) -> Row {
    Row {
        case,
        integrator,
        options,
        spp,
        seeds: [1, 2],
        threads: 0,
        max_depth: None,
        sampler: None,
        defines: &[],
        judge: Judge::Averaged,
        mean_tol: case.mean_tol,
        excess_tol: 1.3,
        mean_cutoff: case.mean_cutoff,
        regions: &[],
        region_tol: 0.0,
        must_fail: false,
        ignored: None,
    }
}

/// A Metropolis row: two threads (the image does not depend on their number), the mean
/// within 1%.
fn chains(case: &'static Case, integrator: &'static str, spp: u32, options: &'static str) -> Row {
    Row { threads: 2, mean_tol: 0.01, ..row(case, integrator, spp, options) }
}

impl Row {
    fn same_estimator(self, ref_spp: u32) -> Row {
        Row { judge: Judge::SameEstimator { ref_spp }, ..self }
    }

    fn light_traced(self, min_alpha: f32, whole_image_fails: bool) -> Row {
        Row { judge: Judge::LightTraced { min_alpha, whole_image_fails }, mean_cutoff: None, ..self }
    }

    /// The mean over the whole image, whatever the case's cutoff.
    fn whole_image_mean(self) -> Row {
        Row { mean_cutoff: None, ..self }
    }

    fn max_depth(self, max_depth: i32) -> Row {
        Row { max_depth: Some(max_depth), ..self }
    }

    fn sampler(self, sampler: SamplerKind) -> Row {
        Row { sampler: Some(sampler), ..self }
    }

    fn defines(self, defines: &'static [(&'static str, &'static str)]) -> Row {
        Row { defines, ..self }
    }

    fn regions(self, regions: &'static [Rect], region_tol: f64) -> Row {
        Row { regions, region_tol, ..self }
    }

    fn must_fail(self) -> Row {
        Row { must_fail: true, ..self }
    }

    fn ignored(self, reason: &'static str) -> Row {
        Row { ignored: Some(reason), ..self }
    }
}

fn rows() -> Vec<Row> {
    [path(), guided(), bidirectional(), merging(), pcbpt(), spcbpt(), budget(), metropolis(), bump(), media()]
        .into_iter()
        .flatten()
        .collect()
}

/// Vertex connection and merging, and its merges alone (consistent: at the default radius
/// the blur is below the noise). A radius that does not shrink, five times the default, must
/// fail (its relMSE is 2.5 times what noise explains).
fn merging() -> Vec<Row> {
    vec![
        row(&CORNELL_PLY, "vcm", 16, ""),
        row(&CORNELL_PLY, "bpm", 64, ""),
        row(&CORNELL_PLY, "bpm", 16, "--vcm-radius 0.015 --vcm-alpha 1").must_fail(),
        row(&VEACH_AJAR, "vcm", 128, ""),
        row(&GLASS_CAUSTIC, "vcm", 256, ""),
        row(&FOG_CAUSTIC, "vcm", 64, ""),
    ]
}

/// Participating media, against Mitsuba 3's `volpath`: every integrator that renders them
/// on fog with a glass sphere in it (the caustic's beam through the fog is light tracing's
/// and the connections' to find; the path tracer finds it through the small light). Light
/// tracing over the pixels it can render (not what the sphere shows): over the whole image
/// it must fail. The negative control leaves out the paths of more than 4 segments.
fn media() -> Vec<Row> {
    vec![
        row(&FOG_CAUSTIC, "path", 1024, ""),
        row(&FOG_CAUSTIC, "lighttrace", 256, "").light_traced(0.0, true),
        row(&FOG_CAUSTIC, "bdpt", 64, ""),
        row(&FOG_CAUSTIC, "bdpt", 64, "").max_depth(4).must_fail(),
        row(&FOG_CAUSTIC, "eorr", 64, ""),
        row(&FOG_CAUSTIC, "lvc", 64, ""),
        row(&FOG_CAUSTIC, "pcbpt", 64, ""),
        row(&FOG_CAUSTIC, "spcbpt", 64, ""),
        chains(&FOG_CAUSTIC, "pssmlt", 64, ""),
        chains(&FOG_CAUSTIC, "memlt", 256, "--direct-samples 256"),
        chains(&FOG_CAUSTIC, "memlt", 128, "--direct-samples -1"),
        // A heterogeneous medium: delta tracking in the walks, ratio tracking in the
        // connections and next-event estimation.
        row(&SMOKE, "path", 256, ""),
        row(&SMOKE, "bdpt", 64, ""),
        row(&SMOKE, "bdpt", 64, "").max_depth(3).must_fail(),
        row(&SMOKE, "pcbpt", 64, ""),
    ]
}

/// The path tracer, judged as the references' own estimator. The negative control, one
/// bounce fewer than the reference, must fail the same check.
fn path() -> Vec<Row> {
    vec![
        row(&CORNELL_PLY, "path", 64, "").same_estimator(4096),
        row(&CORNELL_PLY, "path", 64, "").max_depth(7).same_estimator(4096).must_fail(),
        // The Sobol sampler converges to the same image; the reference's own noise (an
        // independent sampler's at 64 times the samples) stays a small share of its error.
        row(&CORNELL_PLY, "path", 64, "").sampler(SamplerKind::Sobol).same_estimator(4096),
        row(&CORNELL_PLY, "path", 64, "").sampler(SamplerKind::Sobol).max_depth(7).same_estimator(4096).must_fail(),
        row(&CORNELL_BOX, "path", 128, "").same_estimator(8192),
        // The smallest light (radius 0.05, radiance 3040) is seen directly by a handful of
        // pixels: they are left out of the mean.
        row(&VEACH_MIS, "path", 128, "").same_estimator(8192),
        row(&VEACH_AJAR, "path", 1024, "").same_estimator(16384),
        row(&MATERIALS, "path", 128, "").same_estimator(4096),
        // Lit by `sunsky` alone, through a window: the sun patch on the floor lights the room.
        row(&SUNLIT_ROOM, "path", 32, ""),
        // Mitsuba 0.6's sun, sky and both, as Mitsuba 0.6 renders them. Direct light alone
        // must fail.
        row(&SUN06, "path", 64, "").same_estimator(1024),
        row(&SKY06, "path", 64, "").same_estimator(1024),
        row(&SUNSKY06, "path", 64, "").same_estimator(1024),
        row(&SUNSKY06, "path", 64, "").max_depth(2).same_estimator(1024).must_fail(),
        // Glass, glossy floors, 13 area lights on disks and rectangles.
        row(&STAIRCASE2, "path", 128, "").same_estimator(1024),
        row(&STAIRCASE2, "path", 128, "").sampler(SamplerKind::Sobol).same_estimator(1024),
        // The envmap through the windows, rough plastic, the potted plants' leaves cut out by
        // leaf.png's alpha (the reference got the same alpha).
        row(&LIVING_ROOM, "path", 48, "").same_estimator(1024),
    ]
}

/// The guided path tracer. Its image is its final pass's alone, about half the samples (the
/// rest train the tree), so it renders twice what a path-tracer row of the same noise would.
/// On veach-ajar the means of single 512-spp renders spread by about ±1% (seeds 3–6:
/// 0.992–1.010), too much for a 0.5% check of two; at 1024 spp (513 in the final pass) the
/// average of two renders with learnt fractions came out 0.6% high, within that spread, so
/// the row renders 2048 (1025 in the final pass).
fn guided() -> Vec<Row> {
    vec![row(&CORNELL_PLY, "guided", 128, ""), row(&VEACH_AJAR, "guided", 2048, "")]
}

/// Light tracing, BDPT, EORR and LVC.
fn bidirectional() -> Vec<Row> {
    vec![
        row(&CORNELL_PLY, "lighttrace", 32, ""),
        row(&CORNELL_PLY, "bdpt", 16, ""),
        row(&CORNELL_PLY, "eorr", 16, ""),
        row(&CORNELL_PLY, "lvc", 16, ""),
        row(&SUN06, "bdpt", 32, ""),
        row(&SKY06, "bdpt", 32, ""),
        row(&SUNSKY06, "bdpt", 32, ""),
        row(&SPOT_POINT, "lighttrace", 64, ""),
        row(&SPOT_POINT, "bdpt", 32, ""),
        row(&VEACH_MIS, "lighttrace", 256, ""),
        row(&VEACH_MIS, "bdpt", 32, ""),
        row(&VEACH_MIS, "eorr", 32, ""),
        row(&VEACH_MIS, "lvc", 32, ""),
        row(&VEACH_AJAR, "lighttrace", 1024, ""),
        row(&VEACH_AJAR, "bdpt", 128, ""),
        row(&VEACH_AJAR, "eorr", 128, ""),
        row(&VEACH_AJAR, "lvc", 128, ""),
        // Light tracing on the real scenes, over the pixels it can render: the camera sees
        // glass, chrome or the sky in all three, and no light subpath reaches the camera
        // through a Dirac surface or from a light at infinity directly. staircase2's whole
        // image is 4.4% low (the glass pane, the chrome and the lights behind frosted glass),
        // sunlit-room's 1.7% (the sky seen through the window): both must fail over it.
        row(&STAIRCASE2, "lighttrace", 64, "").light_traced(0.0, true),
        row(&SUNLIT_ROOM, "lighttrace", 32, "").light_traced(0.0, true),
        // living-room's varnished table (GGX α 0.05) is left out as well: light subpaths
        // reach the camera through its narrow lobe rarely and with huge weights (±1.3% on the
        // image mean from one 512-spp render to the next, ±0.6% without those pixels). The
        // windows are 11% of the pixels but a small share of the mean, so the whole image
        // does not fail at this noise.
        row(&LIVING_ROOM, "lighttrace", 512, "").light_traced(0.1, false),
        // The edges of staircase2's glass pane, seen through short segments inside the glass,
        // each within 3%: when the walks took the direction back to a vertex after a Dirac
        // delta from the two points rather than from the ray (the offset ray origin makes
        // them differ by several degrees on millimetre segments), BDPT, LVC and PCBPT
        // rendered the left strip 12–14% dark and the right one 5% bright; the image mean
        // hid it.
        row(&STAIRCASE2, "bdpt", 64, "").regions(&[((110, 120), (90, 160)), ((150, 160), (90, 160))], 0.03),
        row(&STAIRCASE2, "eorr", 64, ""),
        row(&STAIRCASE2, "lvc", 32, ""),
        row(&SUNLIT_ROOM, "bdpt", 16, ""),
        row(&SUNLIT_ROOM, "eorr", 16, ""),
        row(&SUNLIT_ROOM, "lvc", 16, ""),
        // The envmap through the windows (lights at infinity in every strategy) and the
        // leaves' cut-outs (light subpaths, connections and shadow rays pass them as camera
        // rays do). These catch next-event estimation to the sky tracing its shadow ray from
        // the far end: it stopped short of the surface, and the paneling beside the windows
        // came out 3–4× too bright.
        row(&LIVING_ROOM, "bdpt", 32, ""),
        row(&LIVING_ROOM, "eorr", 32, ""),
        row(&LIVING_ROOM, "lvc", 32, ""),
    ]
}

/// The ignored `veach-ajar` rows of `--pc-mis harmonic`.
const HARMONIC_SPREAD: &str = "harmonic MIS on veach-ajar: pool-correlated error spreads single 128-spp image \
    means by about ±1.8%, too much for a 0.5% check of two renders; its mean is checked on same-seed pairs against \
    uniform (tests/pcbpt_reference.rs)";

/// The ignored `veach-ajar` rows of `--pc-mis resampling`.
const RESAMPLING_SPREAD: &str = "resampling MIS on veach-ajar: single 128-spp image means spread by ±1% (heavy \
    tail), too much for a 0.5% check of two renders; unbiased on 180 same-seed pairs (BENCHMARKS.md)";

/// PCBPT for each MIS option, each distance term of the interpolation and each way of
/// inverting the blended PMF, without a budget (`budget()` has it).
#[rustfmt::skip]
fn pcbpt() -> Vec<Row> {
    vec![
        row(&CORNELL_PLY, "pcbpt", 24, "--pc-mis uniform --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&CORNELL_PLY, "pcbpt", 24, "--pc-mis uniform --pc-distance-term printed --pc-sampling mixture --budget off"),
        row(&CORNELL_PLY, "pcbpt", 24, "--pc-mis resampling --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&CORNELL_PLY, "pcbpt", 24, "--pc-mis resampling --pc-distance-term printed --pc-sampling mixture --budget off"),
        row(&VEACH_MIS, "pcbpt", 32, "--pc-mis uniform --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&VEACH_MIS, "pcbpt", 32, "--pc-mis uniform --pc-distance-term printed --pc-sampling mixture --budget off"),
        row(&VEACH_MIS, "pcbpt", 32, "--pc-mis resampling --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&VEACH_MIS, "pcbpt", 32, "--pc-mis resampling --pc-distance-term printed --pc-sampling mixture --budget off"),
        // On veach-ajar, `uniform` renders 2 × 512 spp: the image means of single 128-spp
        // renders (160×90) spread by 0.72% (56 seeds: 1.0010 ± 0.0010 against the reference,
        // where BDPT gives 1.0008 ± 0.0003 and the path tracer 1.0011 ± 0.0003), so two of
        // them leave the 0.5% check no margin; four times the samples halve that spread.
        row(&VEACH_AJAR, "pcbpt", 512, "--pc-mis uniform --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&VEACH_AJAR, "pcbpt", 512, "--pc-mis uniform --pc-distance-term printed --pc-sampling mixture --budget off"),
        // `resampling`'s heavy tail spreads the image means of single 128-spp renders
        // (160×90) by about ±1%, so the mean of two cannot be held to 0.5% with a safe margin
        // (a different CPU's intersection rounding can move one firefly). Its mean was
        // measured on 180 same-seed pairs against `uniform` instead: resampling / uniform
        // 1.0006 ± 0.0009 (BENCHMARKS.md, `scripts/paired_means.py`).
        row(&VEACH_AJAR, "pcbpt", 128, "--pc-mis resampling --pc-distance-term falloff --pc-sampling mixture --budget off")
            .ignored(RESAMPLING_SPREAD),
        row(&VEACH_AJAR, "pcbpt", 128, "--pc-mis resampling --pc-distance-term printed --pc-sampling mixture --budget off")
            .ignored(RESAMPLING_SPREAD),
        // `harmonic` (the default) weighs the pool connections of each camera depth by how
        // concentrated the previous iteration's draws that reached a vertex were.
        row(&CORNELL_PLY, "pcbpt", 24, "--pc-mis harmonic --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&CORNELL_PLY, "pcbpt", 24, "--pc-mis harmonic --pc-distance-term printed --pc-sampling mixture --budget off"),
        row(&VEACH_MIS, "pcbpt", 32, "--pc-mis harmonic --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&VEACH_MIS, "pcbpt", 32, "--pc-mis harmonic --pc-distance-term printed --pc-sampling mixture --budget off"),
        // Giving the shared pool's connections more weight makes more of the error common to
        // many pixels: single 128-spp image means (160×90) spread by about ±1.8% (seeds 3–8
        // with M = 1000: 1.0236, 1.0031, 1.0113, 1.0182, 0.9720, 0.9912; `uniform` on the same
        // seeds ±1.1%): with seeds 1 and 2 the mean of two moved about the 0.5% bound as the
        // options changed (1.0050 and 1.0056 with the defaults). Its mean is checked for each
        // distance term on 40 same-seed pairs against `uniform` (`tests/pcbpt_reference.rs`).
        row(&VEACH_AJAR, "pcbpt", 128, "--pc-mis harmonic --pc-distance-term falloff --pc-sampling mixture --budget off")
            .ignored(HARMONIC_SPREAD),
        row(&VEACH_AJAR, "pcbpt", 128, "--pc-mis harmonic --pc-distance-term printed --pc-sampling mixture --budget off")
            .ignored(HARMONIC_SPREAD),
        row(&CORNELL_PLY, "pcbpt", 24, "--pc-mis uniform --pc-distance-term falloff --pc-sampling cmf --budget off"),
        row(&VEACH_MIS, "pcbpt", 32, "--pc-mis uniform --pc-distance-term falloff --pc-sampling cmf --budget off"),
        // `cmf` draws from the same distribution as `mixture` (both χ²-tested against the
        // blended PMF in the cache's tests) and is rendered on cornell-ply and veach-mis; on
        // veach-ajar the 2 × 512-spp `uniform` row goes to the guided camera walks instead.
        // With the fraction fixed at 0.5 every guided leaf samples its tree half the time
        // (learnt, the leaves of these short trainings mostly take 1: the BSDF alone).
        row(&VEACH_AJAR, "pcbpt", 512, "--pc-mis uniform --pc-guiding true --guided-learn-fraction false --budget off"),
        row(&CORNELL_PLY, "pcbpt", 24, "--pc-guiding true --guided-learn-fraction false --budget off"),
        row(&SUNLIT_ROOM, "pcbpt", 16, "--pc-guiding true --budget off"),
        row(&STAIRCASE2, "pcbpt", 32, "--pc-mis harmonic --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&SUNLIT_ROOM, "pcbpt", 16, "--pc-mis harmonic --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&SUNLIT_ROOM, "pcbpt", 16, "--pc-mis uniform --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&SUNLIT_ROOM, "pcbpt", 8, "--pc-mis resampling --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&LIVING_ROOM, "pcbpt", 32, "--pc-mis harmonic --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&LIVING_ROOM, "pcbpt", 32, "--pc-mis uniform --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&LIVING_ROOM, "pcbpt", 16, "--pc-mis resampling --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&STAIRCASE2, "pcbpt", 32, "--pc-mis uniform --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&STAIRCASE2, "pcbpt", 16, "--pc-mis resampling --pc-distance-term falloff --pc-sampling mixture --budget off"),
        // `correlated`: harmonic's counts corrected for the correlation of the connections
        // that share a camera vertex; on veach-ajar it is checked on same-seed pairs too.
        row(&CORNELL_PLY, "pcbpt", 24, "--pc-mis correlated --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&VEACH_MIS, "pcbpt", 32, "--pc-mis correlated --pc-distance-term falloff --pc-sampling mixture --budget off"),
        row(&STAIRCASE2, "pcbpt", 32, "--pc-mis correlated --pc-distance-term falloff --pc-sampling mixture --budget off"),
    ]
}

/// SPCBPT for every `--sp-mis` option on cornell-ply and veach-mis; the default
/// (`subspace`), `harmonic` and the selection density (`resampling`) on the real scenes;
/// without a budget (`budget()` has it). With 4 training iterations of the default, these
/// renders spend a quarter to half of their samples with a matrix still being trained.
fn spcbpt() -> Vec<Row> {
    vec![
        row(&CORNELL_PLY, "spcbpt", 24, "--sp-mis harmonic --budget off"),
        row(&CORNELL_PLY, "spcbpt", 24, "--sp-mis uniform --budget off"),
        row(&CORNELL_PLY, "spcbpt", 24, "--sp-mis resampling --budget off"),
        row(&CORNELL_PLY, "spcbpt", 24, "--sp-mis correlated --budget off"),
        row(&CORNELL_PLY, "spcbpt", 24, "--sp-mis subspace --budget off"),
        row(&VEACH_MIS, "spcbpt", 32, "--sp-mis harmonic --budget off"),
        row(&VEACH_MIS, "spcbpt", 32, "--sp-mis uniform --budget off"),
        row(&VEACH_MIS, "spcbpt", 32, "--sp-mis resampling --budget off"),
        row(&VEACH_MIS, "spcbpt", 32, "--sp-mis correlated --budget off"),
        row(&VEACH_MIS, "spcbpt", 32, "--sp-mis subspace --budget off"),
        // On veach-ajar every pixel connects to the same pool, whose error is common to the
        // whole image: single 128-spp renders (160×90) had image means from 0.9959 to 1.0256,
        // the spread PCBPT has there. So `uniform` is checked with 2 × 512 spp, and
        // `harmonic`, `resampling` and `subspace` against it on same-seed pairs
        // (`tests/spcbpt_reference.rs`).
        row(&VEACH_AJAR, "spcbpt", 512, "--sp-mis uniform --budget off"),
        row(&LIVING_ROOM, "spcbpt", 32, "--sp-mis harmonic --budget off"),
        row(&LIVING_ROOM, "spcbpt", 32, "--sp-mis resampling --budget off"),
        row(&LIVING_ROOM, "spcbpt", 32, "--sp-mis subspace --budget off"),
        row(&STAIRCASE2, "spcbpt", 32, "--sp-mis harmonic --budget off"),
        row(&STAIRCASE2, "spcbpt", 32, "--sp-mis resampling --budget off"),
        row(&STAIRCASE2, "spcbpt", 32, "--sp-mis subspace --budget off"),
        row(&SUNLIT_ROOM, "spcbpt", 16, "--sp-mis harmonic --budget off"),
        row(&SUNLIT_ROOM, "spcbpt", 16, "--sp-mis resampling --budget off"),
        row(&SUNLIT_ROOM, "spcbpt", 16, "--sp-mis subspace --budget off"),
    ]
}

/// PCBPT and SPCBPT with efficiency-aware budgets. The budget is measured in two iterations
/// (PCBPT's 1 and 2, SPCBPT's last two of training) and then changes the number of
/// connections and light-traced paths: the iterations before and after the change are each
/// unbiased, so the image converges whichever plan is chosen. On veach-ajar, whose pool
/// error is common to the image, PCBPT with a budget is compared with PCBPT without one on
/// same-seed pairs (`tests/budget_reference.rs`).
fn budget() -> Vec<Row> {
    vec![
        row(&CORNELL_PLY, "pcbpt", 24, "--budget auto --budget-model realized"),
        row(&CORNELL_PLY, "spcbpt", 24, "--budget auto --budget-model realized"),
        row(&VEACH_MIS, "pcbpt", 32, "--budget auto --budget-model realized"),
        row(&VEACH_MIS, "spcbpt", 32, "--budget auto --budget-model realized"),
        row(&STAIRCASE2, "pcbpt", 32, "--budget auto --budget-model realized"),
        row(&STAIRCASE2, "spcbpt", 32, "--budget auto --budget-model realized"),
        row(&LIVING_ROOM, "pcbpt", 32, "--budget auto --budget-model realized"),
        row(&SUNLIT_ROOM, "pcbpt", 16, "--budget auto --budget-model realized"),
        row(&SUNLIT_ROOM, "spcbpt", 16, "--budget auto --budget-model realized"),
        // The moments with each pixel's own mean and no margin (the default before the
        // realized model) choose other plans: light tracing without connections for PCBPT on
        // cornell-ply, one connection for SPCBPT on staircase2.
        row(&CORNELL_PLY, "pcbpt", 24, "--budget auto --budget-model moments --budget-smoothing 0 --budget-margin 1"),
        row(&STAIRCASE2, "spcbpt", 32, "--budget auto --budget-model moments --budget-smoothing 0 --budget-margin 1"),
    ]
}

/// PSSMLT (over BDPT) and MEMLT (path-space Metropolis with the bidirectional mutation and
/// the lens, caustic and manifold perturbations), with independent chains and bootstraps
/// for each seed.
fn metropolis() -> Vec<Row> {
    vec![
        chains(&CORNELL_PLY, "pssmlt", 16, ""),
        chains(&VEACH_AJAR, "pssmlt", 64, ""),
        chains(&STAIRCASE2, "pssmlt", 16, ""),
        // Sky and sun through a window: the sky seen through it counts in the mean.
        chains(&SUNLIT_ROOM, "pssmlt", 16, "").whole_image_mean(),
        chains(&LIVING_ROOM, "pssmlt", 32, ""),
        // MEMLT with the direct light separate (the default) and in the chains (-1).
        chains(&CORNELL_PLY, "memlt", 64, "--direct-samples 16"),
        // The chains' target the plain luminance (two-stage Metropolis off).
        chains(&CORNELL_PLY, "memlt", 64, "--two-stage false"),
        chains(&CORNELL_PLY, "memlt", 64, "--direct-samples -1"),
        chains(&VEACH_AJAR, "memlt", 256, "--direct-samples 16"),
        // A point light and a spot light: light positions no ray finds, taken by their
        // discrete probability.
        chains(&SPOT_POINT, "memlt", 128, "--direct-samples -1"),
        chains(&SPOT_POINT, "memlt", 128, "--direct-samples 16"),
        // An envmap through windows, leaves cut out by a texture's alpha, glass, glossy
        // surfaces.
        chains(&LIVING_ROOM, "memlt", 64, "--direct-samples 16"),
        // The sun and the sky through a window: paths whose light vertex lies at infinity,
        // started from the disk facing the sun or the sky, found by camera walks leaving the
        // room, joined to moved vertices by the lens and multi-chain perturbations.
        chains(&SUNLIT_ROOM, "memlt", 64, "--direct-samples 16"),
    ]
}

/// Bump and normal mapping, rendered by the path tracer, by light tracing (the adjoint BSDF
/// alone, with its shading-normal correction) and by BDPT. The scenes without the
/// perturbation must fail the check.
fn bump() -> Vec<Row> {
    vec![
        row(&BUMPMAP, "path", 64, ""),
        row(&BUMPMAP, "lighttrace", 64, ""),
        row(&BUMPMAP, "bdpt", 32, ""),
        row(&BUMPMAP, "path", 64, "").defines(&[("bump_scale", "0")]).must_fail(),
        row(&NORMALMAP, "path", 64, ""),
        row(&NORMALMAP, "lighttrace", 64, ""),
        row(&NORMALMAP, "bdpt", 32, ""),
        row(&NORMALMAP, "path", 64, "").defines(&[("normals", "textures/flat.png")]).must_fail(),
    ]
}

impl Row {
    /// `scene/integrator/arguments`, the arguments as on the command line.
    fn name(&self) -> String {
        let mut args: Vec<String> = Vec::new();
        args.extend((!self.options.is_empty()).then(|| self.options.to_string()));
        args.extend(self.max_depth.map(|d| format!("--max-depth {d}")));
        args.extend(self.sampler.map(|k| format!("--sampler {}", k.to_possible_value().unwrap().get_name())));
        args.extend(self.defines.iter().map(|(k, v)| format!("-D {k}={v}")));
        let name = format!("{}/{}", self.case.name, self.integrator);
        if args.is_empty() { name } else { format!("{name}/{}", args.join(" ")) }
    }

    fn trial(self) -> Trial {
        let ignored = self.ignored.is_some();
        Trial::test(self.name(), move || self.run().map_err(Failed::from)).with_ignored_flag(ignored)
    }

    fn run(&self) -> Result<(), String> {
        let start = std::time::Instant::now();
        let scene = self.scene();
        let [a, b] = self.seeds.map(|seed| self.render(&scene, seed));
        let (a, b) = (a?, b?);
        let result = match (self.check(&scene, &a, &b), self.must_fail) {
            (Ok(()), true) => Err("a negative control passed the check it must fail".to_string()),
            (Err(_), true) => Ok(()),
            (verdict, false) => verdict.and_then(|()| self.check_regions(&a, &b)),
        };
        println!("{}: {:.1} s", self.name(), start.elapsed().as_secs_f64());
        result.map_err(|e| match self.ignored {
            Some(reason) => format!("{e}\n(ignored by default: {reason})"),
            None => e,
        })
    }

    fn scene(&self) -> Scene {
        let defines = [self.case.defines, self.defines].concat();
        let mut scene = load_at(&root().join(self.case.scene), &defines, self.case.resolution, Backend::Embree);
        if let Some(max_depth) = self.max_depth {
            scene.integrator.max_depth = max_depth;
        }
        if let Some(sampler) = self.sampler {
            scene.sampler.kind = sampler;
        }
        scene
    }

    fn kind(&self) -> Result<IntegratorKind, String> {
        let mut kinds = registry::INTEGRATORS.iter().map(|r| r.kind);
        kinds.find(|k| k.name() == self.integrator).ok_or(format!("no integrator {}", self.integrator))
    }

    fn render(&self, scene: &Scene, seed: u64) -> Result<Image, String> {
        let kind = self.kind()?;
        let args: Vec<String> = self.options.split_whitespace().map(String::from).collect();
        let mut o = RenderOptions::new(kind, Budget::Spp(self.spp));
        o.method = registry::parse_options(kind, &args)?;
        o.run.seed = seed;
        o.run.threads = self.threads;
        let out = integrator::render(scene, &o).map_err(|e| e.to_string())?;
        if let Some(b) = budget_of(&out.stats) {
            println!("{} seed {seed}: plan {:?}, measured with {:?}", self.name(), b.chosen, b.measured_with);
        }
        Ok(image(out))
    }

    fn check(&self, scene: &Scene, a: &Image, b: &Image) -> Result<(), String> {
        let reference = reference(self.case.reference);
        let verdict = match self.judge {
            Judge::Averaged => {
                let (v, avg) = Verdict::averaged(&reference, a, b, self.ref_noise()?);
                self.cut(v, &reference, &avg)
            }
            Judge::SameEstimator { ref_spp } => {
                self.cut(Verdict::new(&reference, a, b, self.spp, ref_spp), &reference, a)
            }
            Judge::LightTraced { min_alpha, whole_image_fails } => {
                let keep = reachable_by_light_tracing(scene, min_alpha);
                return self.check_light_traced(&reference, a, b, &keep, whole_image_fails);
            }
        };
        verdict.check(&self.name(), self.mean_tol, self.excess_tol)
    }

    /// The check of [`Judge::LightTraced`] over the pixels `keep` marks.
    fn check_light_traced(
        &self,
        reference: &Image,
        a: &Image,
        b: &Image,
        keep: &[bool],
        whole_image_fails: bool,
    ) -> Result<(), String> {
        let what = self.name();
        self.kept(reference, a, b, keep)?.check(&what, self.mean_tol, self.excess_tol)?;
        if whole_image_fails {
            let whole = self.kept(reference, a, b, &vec![true; keep.len()])?;
            if whole.check(&format!("{what}, whole image"), self.mean_tol, self.excess_tol).is_ok() {
                return Err("light tracing passed on pixels it cannot render".to_string());
            }
        }
        Ok(())
    }

    /// `v` with the mean of `judged` taken below the row's cutoff, if it has one.
    fn cut(&self, v: Verdict, reference: &Image, judged: &Image) -> Verdict {
        match self.mean_cutoff {
            Some(cutoff) => v.excluding_emitters(reference, judged, cutoff),
            None => v,
        }
    }

    fn ref_noise(&self) -> Result<f64, String> {
        self.case.ref_noise.ok_or(format!("{}: the reference's noise is not measured", self.case.name))
    }

    /// The averaged verdict over the pixels `keep` marks (see [`Judge::LightTraced`]).
    fn kept(&self, reference: &Image, a: &Image, b: &Image, keep: &[bool]) -> Result<Verdict, String> {
        let fill = |img: &Image| {
            let pixels = img.pixels.iter().zip(&reference.pixels).zip(keep).map(|((p, r), k)| if *k { *p } else { *r });
            Image::new(img.width, img.height, pixels.collect())
        };
        let share = keep.iter().filter(|k| **k).count() as f64 / keep.len() as f64;
        let (v, avg) = Verdict::averaged(reference, &fill(a), &fill(b), self.ref_noise()? * share);
        Ok(v.mean_over(reference, &avg, keep))
    }

    fn check_regions(&self, a: &Image, b: &Image) -> Result<(), String> {
        let reference = reference(self.case.reference);
        for &(columns, rows) in self.regions {
            let r = region_mean(&reference, columns, rows);
            let ratio = (region_mean(a, columns, rows) + region_mean(b, columns, rows)) / 2.0 / r;
            eprintln!("{}: columns {columns:?}, rows {rows:?}: renders / reference = {ratio:.4}", self.name());
            if (ratio - 1.0).abs() >= self.region_tol {
                return Err(format!("columns {columns:?}, rows {rows:?}: renders / reference = {ratio:.4}"));
            }
        }
        Ok(())
    }
}

/// Mean of `img` over the rectangle `x0..x1` × `y0..y1`.
fn region_mean(img: &Image, (x0, x1): (u32, u32), (y0, y1): (u32, u32)) -> f64 {
    let mut sum = 0.0;
    for y in y0..y1 {
        for x in x0..x1 {
            let p = img.pixels[(y * img.width + x) as usize];
            sum += (p.x + p.y + p.z) as f64;
        }
    }
    sum / ((x1 - x0) * (y1 - y0)) as f64
}
