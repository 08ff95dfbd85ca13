//! The `pcbpt` command line: `render` a Mitsuba scene, `compare` two images.

use clap::{Args, Parser, Subcommand, ValueEnum};
use pcbpt::accel::{Backend, BuildOptions, BuildQuality, BvhLayout};
use pcbpt::compare;
use pcbpt::error::{Error, Result};
use pcbpt::image_io::{self, Image};
use pcbpt::integrator::bidir::budget::{BudgetMode, BudgetModel, Independence};
use pcbpt::integrator::bidir::mis::Heuristic;
use pcbpt::integrator::bidir::pcbpt::{DistanceTerm, PcMis, PcOptions, PcSampling};
use pcbpt::integrator::bidir::spcbpt::SpOptions;
use pcbpt::integrator::mlt::{MltBase, MltOptions};
use pcbpt::integrator::{self, BidirOptions, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::{LoadOptions, Scene};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "pcbpt",
    version,
    about = "A CPU renderer for probabilistic connections in bidirectional path tracing and the methods it is compared against"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

// Parsed once per process: the size of the render's arguments does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Command {
    /// Render a Mitsuba XML scene.
    Render(RenderArgs),
    /// Compare a test image with a reference: MSE, relMSE and the ratio of image means.
    Compare(CompareArgs),
    /// Run an equal-time experiment described by a TOML file (scenes × methods).
    Experiment(ExperimentArgs),
    /// Merge the partial renders of one render (`render --chunk`) into its image.
    Merge(MergeArgs),
}

#[derive(Args)]
struct MergeArgs {
    /// The parts (EXR files written by `render --chunk` or `--iterations`).
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// The merged image (`.exr` or `.png`).
    #[arg(short, long)]
    output: PathBuf,
    /// Merge the parts that exist even if iterations are missing (a preview).
    #[arg(long)]
    partial: bool,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Args)]
struct ExperimentArgs {
    /// The experiment file (TOML; see experiments/).
    file: PathBuf,
    /// Output folder (default: the file's `output`, or its name beside it).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Args)]
struct RenderArgs {
    /// The scene file (Mitsuba 3 XML; version 0.x files are upgraded).
    scene: PathBuf,
    /// Output image; `.exr` (linear float RGB) or `.png` (sRGB), and `.tif` (linear float RGB) in a
    /// build with `--features oiio`. Default: the scene's name with `.exr`.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Integrator (default: the one the scene names).
    #[arg(long, value_enum)]
    integrator: Option<IntegratorKind>,
    /// Samples per pixel (default: the scene's sample_count).
    #[arg(long, conflicts_with = "time")]
    spp: Option<u32>,
    /// Render for this many seconds instead of a sample count (whole passes of 1 spp).
    #[arg(long)]
    time: Option<f64>,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Seed of the random number streams (default: the scene sampler's seed).
    #[arg(long)]
    seed: Option<u64>,
    /// Render chunk I of N (0-based) of the render's iterations and write a partial render
    /// (an EXR with the film's sums) for `pcbpt merge`.
    #[arg(long, value_name = "I/N", value_parser = parse_chunk, conflicts_with_all = ["time", "iterations"])]
    chunk: Option<(u32, u32)>,
    /// Render iterations A..B (end excluded) of the render and write a partial render.
    #[arg(long, value_name = "A..B", value_parser = parse_range, conflicts_with = "time")]
    iterations: Option<(u32, u32)>,
    /// Scene parameter overrides, `-D name=value` (e.g. `-D spp=64 -D resx=320`).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    define: Vec<(String, String)>,
    /// Film size, replacing the scene's (e.g. `320x180`), for scenes that fix it in the XML.
    #[arg(long, value_name = "WxH", value_parser = pcbpt::scene::parse_resolution)]
    resolution: Option<(u32, u32)>,
    /// Override the integrator's max_depth (path segments from the camera; -1 = unlimited).
    #[arg(long, allow_negative_numbers = true)]
    max_depth: Option<i32>,
    /// Override the depth from which Russian roulette may end paths.
    #[arg(long)]
    rr_depth: Option<u32>,
    /// Ray-tracing backend.
    #[arg(long, value_enum, default_value_t = Backend::Embree)]
    backend: Backend,
    /// Acceleration structure build quality (with the two-level layout: of each shape's BVH).
    #[arg(long, value_enum, default_value_t = BuildQuality::Medium)]
    bvh_quality: BuildQuality,
    /// Embree's BVH layout: one BVH over all triangles, or one per shape under a BVH over
    /// the shapes (ignored by obvhs).
    #[arg(long, value_enum, default_value_t = BvhLayout::TwoLevel)]
    bvh_layout: BvhLayout,
    /// Embree's robust traversal mode (slower, fewer arithmetic shortcuts).
    #[arg(long)]
    robust: bool,
    /// Embree device configuration, `key=value` pairs separated by commas (after those of
    /// the PCBPT_EMBREE_CONFIG environment variable): `max_isa=sse4.2|avx|avx2|avx512` runs
    /// the kernels another CPU would, `verbose=1` prints the ISA Embree selected.
    #[arg(long, value_name = "CONFIG")]
    embree_config: Option<String>,
    /// MIS heuristic of the bidirectional integrators.
    #[arg(long, value_enum, default_value_t = Heuristic::Power)]
    heuristic: Heuristic,
    /// EORR: Russian-roulette threshold as a fraction of the pixel's mean luminance.
    #[arg(long, default_value_t = 0.1)]
    eorr_fraction: f32,
    /// EORR: the pixel means come from the first this many samples per pixel (0: from every
    /// earlier pass, a running mean, which a render cut into chunks cannot use).
    #[arg(long, default_value_t = BidirOptions::default().eorr_pilot_spp)]
    eorr_pilot_spp: u32,
    /// LVC: light paths per iteration (0 = one per pixel).
    #[arg(long, default_value_t = 0)]
    lvc_light_paths: usize,
    /// LVC: connections to pool vertices per camera vertex.
    #[arg(long, default_value_t = 1)]
    lvc_connections: u32,
    /// PSSMLT: probability of a large step.
    #[arg(long, default_value_t = 0.3)]
    large_step_prob: f32,
    /// PSSMLT: independent samples for the normalisation and the chains' start states.
    #[arg(long, default_value_t = 100_000)]
    bootstrap: usize,
    /// PSSMLT: the estimator the Markov chains drive.
    #[arg(long, value_enum, default_value_t = MltBase::Bdpt)]
    mlt_path_integrator: MltBase,
    /// MEMLT: samples per pixel of a separate direct-lighting estimate by the path tracer
    /// (paths of one edge, and of two through a rough vertex; those through a Dirac lobe are
    /// the chains'); -1 leaves every path to the Markov chains.
    #[arg(long, default_value_t = MltOptions::default().direct_samples, allow_negative_numbers = true)]
    direct_samples: i32,
    /// MEMLT with --time: the direct-light pass goes on past --direct-samples for the share
    /// of the time that balances its noise against the chains' (both measured, each from two
    /// independent halves, a tenth into the chains' time; at most half of the time then left)
    #[arg(long, default_value_t = MltOptions::default().direct_balance, action = clap::ArgAction::Set)]
    direct_balance: bool,
    /// MEMLT beside the direct-light pass: samples per pixel, in stratified cells, of a
    /// specular pass that renders the paths through Dirac lobes alone (the light seen in
    /// mirrors and through glass); 0 leaves them to the chains.
    #[arg(long, default_value_t = MltOptions::default().specular_samples)]
    specular_samples: u32,
    /// MEMLT with --time: the BDPT bootstrap goes on in batches of --bootstrap samples until
    /// this fraction of the time is spent (`b`, the image's brightness, is its estimate).
    #[arg(long, default_value_t = MltOptions::default().bootstrap_fraction)]
    bootstrap_fraction: f64,
    /// MEMLT: the manifold perturbation among the mutations (`false` gives Veach's MLT).
    #[arg(long, default_value_t = MltOptions::default().manifold_perturbation, action = clap::ArgAction::Set)]
    manifold_perturbation: bool,
    /// MEMLT: the bidirectional mutation among the mutations.
    #[arg(long, default_value_t = MltOptions::default().bidirectional_mutation, action = clap::ArgAction::Set)]
    bidirectional_mutation: bool,
    /// MEMLT: Veach's lens perturbation among the mutations.
    #[arg(long, default_value_t = MltOptions::default().lens_perturbation, action = clap::ArgAction::Set)]
    lens_perturbation: bool,
    /// MEMLT: Veach's caustic perturbation among the mutations.
    #[arg(long, default_value_t = MltOptions::default().caustic_perturbation, action = clap::ArgAction::Set)]
    caustic_perturbation: bool,
    /// MEMLT: Veach's multi-chain perturbation among the mutations.
    #[arg(long, default_value_t = MltOptions::default().multichain_perturbation, action = clap::ArgAction::Set)]
    multichain_perturbation: bool,
    /// MEMLT: the multi-chain perturbation re-traced on to the light, for paths whose light end
    /// no shadow ray joins (`L S+ D S+ E`: a caustic seen in glass; `L S+ E`); not Mitsuba 0.6's.
    #[arg(long, default_value_t = MltOptions::default().light_hit_perturbation, action = clap::ArgAction::Set)]
    light_hit_perturbation: bool,
    /// MEMLT: the independent mutation among the mutations (a whole new path from the
    /// bidirectional generator, Kelemen's large step in path space; not Mitsuba 0.6's).
    ///
    /// Default `auto`: on where `--bootstrap` camera walks to the first light find at least
    /// 1.5% of their light in paths that only such a walk makes (no edge takes a shadow ray:
    /// a caustic seen in a glass ball at its rim), off elsewhere (the statistics print the
    /// share and the choice).
    #[arg(long, action = clap::ArgAction::Set)]
    independent_mutation: Option<bool>,
    /// MEMLT: the share of the independent mutation's path lengths and splits drawn as the
    /// start paths' generator draws them (length ∝ 2^-k, split uniform); the rest follow
    /// what each length and split found among the start-path candidates. 1: all uniform.
    #[arg(long, default_value_t = MltOptions::default().independent_defensive)]
    independent_defensive: f64,
    /// MEMLT: the share of the learned generator's draws (the independent mutation's and the
    /// learned start paths') that are camera walks going on until they find a light, making a
    /// path of any length, as a path tracer's sample does; the rest draw a length and a split.
    #[arg(long, default_value_t = MltOptions::default().independent_camera_walks)]
    independent_camera_walks: f64,
    /// MEMLT: draw the chains' start paths from a second set of candidates made by the
    /// learned generator of the independent mutation (their weights spread less), instead of
    /// the first set (lengths ∝ 2^-k, uniform splits).
    #[arg(long, default_value_t = MltOptions::default().learned_starts, action = clap::ArgAction::Set)]
    learned_starts: bool,
    /// MEMLT: the manifold perturbation's sharpness (its von Mises–Fisher lobe's peak
    /// density is the current direction's scattering density times λ²).
    #[arg(long, default_value_t = MltOptions::default().lambda)]
    lambda: f64,
    /// MEMLT: the half-vector change, in degrees, against which the manifold perturbation
    /// judges a glossy lobe (a lobe much wider than it is treated as diffuse, one much
    /// narrower as specular; 0: glossy vertices are never treated as specular).
    #[arg(long, default_value_t = MltOptions::default().theta_diff)]
    theta_diff: f64,
    /// PSSMLT and MEMLT: Markov chains, each started from a bootstrap path drawn in
    /// proportion to its contribution (the image does not depend on the thread count).
    #[arg(long, default_value_t = MltOptions::default().chains)]
    chains: usize,
    /// PSSMLT and MEMLT: two-stage Metropolis (Mitsuba 0.6's `twoStage`): a first stage of
    /// BDPT samples estimates the image at a reduced resolution, and the chains sample paths
    /// in proportion to their luminance over it, so that dim pixels get as many mutations
    /// as bright ones. On for memlt, off for pssmlt unless given.
    #[arg(long, action = clap::ArgAction::Set)]
    two_stage: Option<bool>,
    /// Two-stage Metropolis: pixels per side of the first stage's cells.
    #[arg(long, default_value_t = MltOptions::default().first_stage_reduction)]
    first_stage_reduction: u32,
    /// Memory limit of a light pool (lvc, pcbpt), in MiB.
    #[arg(long, default_value_t = 4096)]
    max_pool_mb: usize,
    /// PCBPT: light paths per iteration (M), the least (see --pc-pool-vertices).
    #[arg(long, default_value_t = PcOptions::default().light_paths)]
    pc_light_paths: usize,
    /// PCBPT: add light paths per iteration until a pool holds about this many vertices
    /// (judged on a pilot pool), up to one per pixel; 0 keeps --pc-light-paths exactly.
    #[arg(long, default_value_t = PcOptions::default().pool_vertices)]
    pc_pool_vertices: usize,
    /// PCBPT and SPCBPT: connections drawn per camera vertex (N; 0, with --pc-budget off:
    /// none, the pool only light traces). With --pc-budget auto (the default), the number the
    /// budget is measured with.
    #[arg(long, default_value_t = PcOptions::default().connections)]
    pc_connections: u32,
    /// PCBPT: one cache record pixel per stride × stride tile.
    #[arg(long, default_value_t = PcOptions::default().stride)]
    pc_cache_stride: u32,
    /// PCBPT: camera vertices per record pixel that become records.
    #[arg(long, default_value_t = PcOptions::default().cache_depth)]
    pc_cache_depth: u32,
    /// PCBPT: shadow rays in the cache's target (true/false).
    #[arg(long, default_value_t = PcOptions::default().visibility, action = clap::ArgAction::Set)]
    pc_visibility: bool,
    /// PCBPT: weight of the uniform distribution blended into every lookup.
    #[arg(long, default_value_t = PcOptions::default().uniform_blend)]
    pc_uniform_blend: f32,
    /// PCBPT: nearest records blended per lookup.
    #[arg(long, default_value_t = PcOptions::default().neighbours)]
    pc_neighbours: usize,
    /// PCBPT: distance term of the interpolation weights.
    #[arg(long, value_enum, default_value_t = PcOptions::default().distance_term)]
    pc_distance_term: DistanceTerm,
    /// PCBPT: MIS strategy counts of the probabilistic connections.
    #[arg(long, value_enum, default_value_t = PcOptions::default().mis)]
    pc_mis: PcMis,
    /// PCBPT: how a draw inverts the blended PMF (the same distribution either way).
    #[arg(long, value_enum, default_value_t = PcOptions::default().sampling)]
    pc_sampling: PcSampling,
    /// PCBPT: memory limit of the cache (records × pool vertices floats), in MiB.
    #[arg(long, default_value_t = PcOptions::default().max_cache_mb)]
    pc_max_cache_mb: usize,
    /// PCBPT and SPCBPT: choose the connections per camera vertex (0-8) and the light paths
    /// that are light traced from the second moments and costs of measured iterations
    /// (auto), or keep --pc-connections and the pool's light paths (off).
    #[arg(long, value_enum, default_value_t = PcOptions::default().budget)]
    pc_budget: BudgetMode,
    /// PCBPT and SPCBPT: iterations measured before the budget is chosen.
    #[arg(long, default_value_t = PcOptions::default().budget_iterations)]
    pc_budget_iterations: u32,
    /// PCBPT and SPCBPT: the share of the connections' predicted change of second moment
    /// between budgets that counts, 0 to 1 (1 if the draws of a camera vertex were
    /// independent), or `measured` (from their spread about each camera vertex's mean).
    #[arg(long, default_value_t = PcOptions::default().budget_independence)]
    pc_budget_independence: Independence,
    /// PCBPT and SPCBPT: measured pixels each side whose means are averaged for the relMSE
    /// weights of the budget's choice (0: each pixel's own mean).
    #[arg(long, default_value_t = PcOptions::default().budget_smoothing)]
    pc_budget_smoothing: u32,
    /// PCBPT and SPCBPT: how the budget predicts a plan's variance: the change of the
    /// contributions' second moments (moments), or each measured camera sample re-weighted
    /// as the plan would weigh it, with its connections' spread (realized).
    #[arg(long, value_enum, default_value_t = PcOptions::default().budget_model)]
    pc_budget_model: BudgetModel,
    /// PCBPT and SPCBPT: samples per pixel the budget plans for (default: the render's
    /// --spp but at least 256, which --time takes). A path that a plan would sample less than (measured
    /// iterations / horizon) times as densely as the measured plan counts by its chance of
    /// being found in the render, as the typical render shows it, not by its expected
    /// variance; 0 counts every path by its expected variance.
    #[arg(long)]
    pc_budget_horizon: Option<u32>,
    /// PCBPT and SPCBPT: the least predicted efficiency gain over the measured plan for
    /// which the budget leaves it (1: any gain; the predictions are within about a third
    /// of what renders measure, so smaller gains are noise).
    #[arg(long, default_value_t = PcOptions::default().budget_margin)]
    pc_budget_margin: f32,
    /// PCBPT and SPCBPT: pixels whose moments the budget measures, at most about (those of
    /// every k-th row and column).
    #[arg(long, default_value_t = PcOptions::default().budget_pixels)]
    pc_budget_pixels: usize,
    /// PCBPT and SPCBPT: whether each measured pixel's largest contribution counts, at the
    /// horizon, as rarely as its value against the pixel's mean says (false: as a region the
    /// measured iterations found once, like every other sample).
    #[arg(long, default_value_t = PcOptions::default().budget_rarity, action = clap::ArgAction::Set)]
    pc_budget_rarity: bool,
    /// SPCBPT: eye subspaces (leaves of the k-d tree over camera vertices' positions and
    /// normals).
    #[arg(long, default_value_t = SpOptions::default().eye_subspaces)]
    sp_eye_subspaces: usize,
    /// SPCBPT: light subspaces (leaves of the k-d tree over light vertices).
    #[arg(long, default_value_t = SpOptions::default().light_subspaces)]
    sp_light_subspaces: usize,
    /// SPCBPT: iterations whose connections train the subspace matrix (0: it stays uniform).
    #[arg(long, default_value_t = SpOptions::default().training_iterations)]
    sp_training_iterations: u32,
    /// SPCBPT: share of the uniform distribution mixed into each trained row of the matrix.
    #[arg(long, default_value_t = SpOptions::default().uniform)]
    sp_uniform: f32,
    /// SPCBPT: MIS strategy counts of the connections (as --pc-mis; resampling is the
    /// selection density itself, subspace the same with the draw within a light subspace
    /// taken as uniform).
    #[arg(long, value_enum, default_value_t = SpOptions::default().mis)]
    sp_mis: PcMis,
    /// SPCBPT: memory limit of the matrix and the training samples, in MiB.
    #[arg(long, default_value_t = SpOptions::default().max_mb)]
    sp_max_mb: usize,
    /// SPCBPT: whether the budget measures the last training iterations (the choice comes
    /// sooner) or the iterations after them.
    #[arg(long, default_value_t = SpOptions::default().budget_in_training, action = clap::ArgAction::Set)]
    sp_budget_in_training: bool,
    /// Write one EXR per bidirectional strategy (s,t) into this folder (they sum to the image).
    #[arg(long, value_name = "DIR")]
    strategy_images: Option<PathBuf>,
    /// Write render statistics as JSON to this file.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Args)]
struct CompareArgs {
    /// The reference image (EXR; PNG/JPEG decoded from sRGB; with `--features oiio`, any format
    /// OpenImageIO reads; `PCBPT_IMAGE_IO` = auto, native or oiio picks the library).
    reference: PathBuf,
    /// The image to test (formats as for the reference).
    test: PathBuf,
    /// Write a false-colour image of the per-pixel relMSE (PNG).
    #[arg(long)]
    error_image: Option<PathBuf>,
    /// relMSE shown as white in the error image.
    #[arg(long, default_value_t = 1.0)]
    error_scale: f64,
    /// Print the metrics as JSON.
    #[arg(long)]
    json: bool,
    /// Print only this metric's value (`flip` is computed only when asked for).
    #[arg(long, value_enum)]
    metric: Option<compare::Metric>,
    /// Compare only this part of the images: x,y,width,height.
    #[arg(long, value_parser = parse_crop)]
    crop: Option<[u32; 4]>,
    /// Compare only the pixels that are white (brighter than 0.5) in this image.
    #[arg(long)]
    mask: Option<PathBuf>,
}

fn parse_crop(s: &str) -> std::result::Result<[u32; 4], String> {
    let v: Vec<u32> = s
        .split(',')
        .map(|x| x.trim().parse::<u32>().map_err(|_| format!("\"{s}\" is not x,y,width,height")))
        .collect::<std::result::Result<_, _>>()?;
    v.try_into().map_err(|_| format!("\"{s}\" is not x,y,width,height"))
}

fn parse_chunk(s: &str) -> std::result::Result<(u32, u32), String> {
    let (i, n) = s.split_once('/').ok_or_else(|| format!("\"{s}\" is not I/N"))?;
    let num = |x: &str| x.trim().parse::<u32>().map_err(|_| format!("\"{s}\" is not I/N"));
    Ok((num(i)?, num(n)?))
}

fn parse_range(s: &str) -> std::result::Result<(u32, u32), String> {
    let (a, b) = s.split_once("..").ok_or_else(|| format!("\"{s}\" is not A..B"))?;
    let num = |x: &str| x.trim().parse::<u32>().map_err(|_| format!("\"{s}\" is not A..B"));
    Ok((num(a)?, num(b)?))
}

fn parse_define(s: &str) -> std::result::Result<(String, String), String> {
    let (k, v) = s.split_once('=').ok_or_else(|| format!("\"{s}\" is not NAME=VALUE"))?;
    if k.is_empty() || !k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(format!("\"{k}\" is not a parameter name"));
    }
    Ok((k.to_string(), v.to_string()))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render(a),
        Command::Compare(a) => compare_images(a),
        Command::Merge(a) => merge_parts(a),
        Command::Experiment(a) => pcbpt::experiment::run(&a.file, a.output.as_deref(), a.quiet).map(|r| {
            if !a.quiet {
                eprintln!("{} runs done", r.len());
            }
            ExitCode::SUCCESS
        }),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Exit status of a render stopped by a signal (as a shell reports SIGINT).
const INTERRUPTED: u8 = 130;

fn install_signal_handlers() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // A second signal while the first is being handled exits at once.
        signal_hook::flag::register_conditional_shutdown(sig, INTERRUPTED as i32, stop.clone())
            .map_err(|e| Error::Usage(format!("cannot install signal handler: {e}")))?;
        signal_hook::flag::register(sig, stop.clone())
            .map_err(|e| Error::Usage(format!("cannot install signal handler: {e}")))?;
    }
    Ok(stop)
}

fn render(a: RenderArgs) -> Result<ExitCode> {
    let stop = install_signal_handlers()?;
    let t0 = Instant::now();
    let build = BuildOptions {
        quality: a.bvh_quality,
        layout: a.bvh_layout,
        robust: a.robust,
        compact: false,
        embree_config: a.embree_config.clone(),
    };
    let load = LoadOptions {
        overrides: a.define.clone(),
        backend: a.backend,
        build,
        progress: !a.quiet,
        integrator_override: a
            .integrator
            .and_then(|k| k.to_possible_value())
            .map(|v| format!("--integrator {}", v.get_name())),
        resolution: a.resolution,
        threads: a.threads,
    };
    let mut scene = Scene::load(&a.scene, &load)?;
    if let Some(d) = a.max_depth {
        if d < -1 {
            return Err(Error::Usage(format!("--max-depth must be -1 (unlimited) or at least 0, got {d}")));
        }
        scene.integrator.max_depth = d;
    }
    if let Some(d) = a.rr_depth {
        scene.integrator.rr_depth = d;
    }
    let load_seconds = t0.elapsed().as_secs_f64();
    if !a.quiet {
        for w in &scene.stats.warnings {
            eprintln!("warning: {w}");
        }
        let l = &scene.stats;
        eprintln!(
            "loaded {}: {} triangles ({:.1} MiB of mesh arrays) in {:.2} s: reading {:.2} s, {} BVH {:.2} s",
            a.scene.display(),
            pcbpt::scene::load::group_thousands(l.triangles as u64),
            l.mesh_bytes as f64 / (1024.0 * 1024.0),
            load_seconds,
            l.read_seconds,
            a.backend,
            l.bvh_seconds
        );
    }
    let kind = match a.integrator {
        Some(k) => k,
        None => IntegratorKind::from_plugin(&scene.integrator.plugin).ok_or_else(|| {
            Error::Usage(format!(
                "the scene's integrator \"{}\" has no implementation here; pick one with --integrator",
                scene.integrator.plugin
            ))
        })?,
    };
    let budget = match (a.spp, a.time) {
        (_, Some(t)) if !(t > 0.0 && t.is_finite()) => {
            return Err(Error::Usage(format!("--time must be a positive number of seconds, got {t}")));
        }
        (_, Some(t)) => Budget::Time(t),
        (Some(0), _) => return Err(Error::Usage("--spp must be at least 1".into())),
        (Some(s), None) => Budget::Spp(s),
        (None, None) => Budget::Spp(scene.sampler.spp),
    };
    let output = a.output.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "{}.exr",
            a.scene.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "render".into())
        ))
    });
    image_io::Format::from_path(&output)?;
    let mut opts = RenderOptions::new(kind, budget);
    opts.seed = a.seed.unwrap_or(scene.sampler.seed);
    opts.threads = a.threads;
    opts.progress = !a.quiet;
    opts.stop = Some(stop);
    if !(a.eorr_fraction >= 0.0 && a.eorr_fraction.is_finite()) {
        return Err(Error::Usage(format!("--eorr-fraction must be a non-negative number, got {}", a.eorr_fraction)));
    }
    opts.bidir = BidirOptions {
        heuristic: a.heuristic,
        eorr_fraction: a.eorr_fraction,
        eorr_pilot_spp: a.eorr_pilot_spp,
        lvc_light_paths: a.lvc_light_paths,
        lvc_connections: a.lvc_connections,
        max_pool_mb: a.max_pool_mb,
        pc: PcOptions {
            light_paths: a.pc_light_paths,
            pool_vertices: a.pc_pool_vertices,
            connections: a.pc_connections,
            stride: a.pc_cache_stride,
            cache_depth: a.pc_cache_depth,
            visibility: a.pc_visibility,
            uniform_blend: a.pc_uniform_blend,
            neighbours: a.pc_neighbours,
            distance_term: a.pc_distance_term,
            mis: a.pc_mis,
            sampling: a.pc_sampling,
            max_cache_mb: a.pc_max_cache_mb,
            budget: a.pc_budget,
            budget_iterations: a.pc_budget_iterations,
            budget_independence: a.pc_budget_independence,
            budget_smoothing: a.pc_budget_smoothing,
            budget_model: a.pc_budget_model,
            budget_horizon: a.pc_budget_horizon,
            budget_margin: a.pc_budget_margin,
            budget_pixels: a.pc_budget_pixels,
            budget_rarity: a.pc_budget_rarity,
        },
        sp: SpOptions {
            eye_subspaces: a.sp_eye_subspaces,
            light_subspaces: a.sp_light_subspaces,
            training_iterations: a.sp_training_iterations,
            uniform: a.sp_uniform,
            mis: a.sp_mis,
            max_mb: a.sp_max_mb,
            budget_in_training: a.sp_budget_in_training,
        },
    };
    opts.mlt = MltOptions {
        large_step_prob: a.large_step_prob,
        bootstrap: a.bootstrap,
        base: a.mlt_path_integrator,
        direct_samples: a.direct_samples,
        direct_balance: a.direct_balance,
        specular_samples: a.specular_samples,
        bootstrap_fraction: a.bootstrap_fraction,
        bidirectional_mutation: a.bidirectional_mutation,
        lens_perturbation: a.lens_perturbation,
        caustic_perturbation: a.caustic_perturbation,
        multichain_perturbation: a.multichain_perturbation,
        light_hit_perturbation: a.light_hit_perturbation,
        independent_mutation: a.independent_mutation,
        independent_defensive: a.independent_defensive,
        independent_camera_walks: a.independent_camera_walks,
        learned_starts: a.learned_starts,
        manifold_perturbation: a.manifold_perturbation,
        lambda: a.lambda,
        theta_diff: a.theta_diff,
        chains: a.chains,
        two_stage: a.two_stage.unwrap_or(MltOptions::for_integrator(kind).two_stage),
        first_stage_reduction: a.first_stage_reduction,
    };
    opts.strategy_images = a.strategy_images.is_some();
    if let Some(dir) = &a.strategy_images {
        if matches!(kind, IntegratorKind::Path | IntegratorKind::Pssmlt | IntegratorKind::Memlt) {
            return Err(Error::Usage("--strategy-images needs a bidirectional integrator".into()));
        }
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::Output { path: dir.clone(), msg: format!("cannot create the folder: {e}") })?;
    }
    // A chunk of a distributed render: its iterations, and what identifies the render.
    let part = match (a.chunk, a.iterations) {
        (None, None) => None,
        (chunk, range) => {
            let Budget::Spp(total) = budget else { unreachable!("--chunk and --iterations conflict with --time") };
            let iterations = match (chunk, range) {
                (Some((i, n)), _) => pcbpt::partial::chunk(i, n, total)?,
                (_, Some((start, end))) => start..end,
                (None, None) => unreachable!(),
            };
            if opts.strategy_images {
                return Err(Error::Usage("--strategy-images are not kept in partial renders".into()));
            }
            if image_io::Format::from_path(&output)? != image_io::Format::Exr {
                return Err(Error::Usage(format!("{}: a partial render is written as an EXR file", output.display())));
            }
            let hash = pcbpt::partial::scene_hash(&scene, &a.define)?;
            Some((iterations, total, pcbpt::partial::render_identity(&scene, &opts, &hash)))
        }
    };
    let out = integrator::render_iterations(&scene, &opts, part.as_ref().map(|p| p.0.clone()))?;
    let s = &out.stats;
    // The Embree library linked at run time (e.g. "4.4.0"), for the summary and the stats.
    let embree_version =
        (a.backend == Backend::Embree).then(|| pcbpt::accel::embree::version().map(|v| v.to_string()).ok()).flatten();
    if let Some(dir) = &a.strategy_images {
        for (name, pixels) in &out.strategy_images {
            image_io::write(&dir.join(format!("{name}.exr")), &Image::new(out.width, out.height, pixels.clone()))?;
        }
    }
    match part {
        Some((_, total, render)) if !s.interrupted => {
            let info = pcbpt::partial::part_info(&out, render, total, scene.film.filter)?;
            let film = out.film.as_ref().expect("a render keeps its film");
            pcbpt::partial::write_part(&output, &out.image, film, &info)?;
        }
        // An interrupted chunk writes no part: a merge would take it for a whole one.
        Some(_) => {}
        None => image_io::write(&output, &Image::new(out.width, out.height, out.image))?,
    }
    if let Some(path) = &a.stats {
        let json = serde_json::json!({ "scene": a.scene, "output": output, "load_seconds": load_seconds, "triangles": scene.stats.triangles, "load": { "read_seconds": scene.stats.read_seconds, "bvh_seconds": scene.stats.bvh_seconds, "vertices": scene.stats.vertices, "mesh_bytes": scene.stats.mesh_bytes }, "degenerate_triangles": scene.stats.degenerate_triangles, "embree_version": embree_version, "render": s });
        image_io::write_text(path, &serde_json::to_string_pretty(&json).unwrap_or_default())?;
    }
    if !a.quiet || s.interrupted {
        eprintln!(
            "{}{}: {}×{} at {} spp ({:?}, {}, {} threads) in {:.2} s (+{:.2} s loading): {:.3} M samples/s, {:.2} M rays/s, {} NaN/Inf samples dropped → {}",
            if s.interrupted { "interrupted" } else { "rendered" },
            match &s.iterations {
                Some(r) if a.chunk.is_some() || a.iterations.is_some() => format!(" iterations {}..{}", r.start, r.end),
                _ => String::new(),
            },
            s.width,
            s.height,
            s.spp,
            s.integrator,
            match &embree_version {
                Some(v) => format!("{} {v}", s.backend),
                None => s.backend.clone(),
            },
            s.threads,
            s.seconds,
            load_seconds,
            s.samples_per_second / 1e6,
            s.rays_per_second / 1e6,
            s.invalid_samples,
            output.display()
        );
    }
    if let (false, Some(m)) = (a.quiet, &s.mlt) {
        eprintln!(
            "  PSSMLT: b = {:.5}, {} chains, {} mutations ({:.3} M/s), acceptance small {:.1}% large {:.1}%, bootstrap {:.2} s",
            m.normalisation,
            m.chains,
            m.mutations,
            m.mutations_per_second / 1e6,
            m.small_acceptance * 100.0,
            m.large_acceptance * 100.0,
            m.bootstrap_seconds
        );
        print_first_stage(m.first_stage_samples, m.mean_luminance);
        print_longest_stay("pssmlt", m.longest_stay.as_ref());
    } else if let (false, Some(m)) = (a.quiet, &s.memlt) {
        let acceptance: Vec<String> = m
            .mutators
            .iter()
            .map(|x| format!("{:?} {:.1}% of {}", x.mutator, x.acceptance * 100.0, x.proposed))
            .collect();
        eprintln!(
            "  MEMLT: b = {:.5} ± {:.5} (start paths: {:.5}, effective {:.0} of {}), {} chains, {} mutations ({:.3} M/s), paths of {}..={} edges, acceptance: {}; manifold walks: {} tried, {} converged, {} irreversible; {} perturbations kept glossy half-vectors, {} moved the light point, {} the line light from infinity arrives along; bootstrap {:.2} s",
            m.normalisation,
            m.normalisation_error,
            m.seed_normalisation,
            m.start_ess,
            m.start_candidates,
            m.chains,
            m.mutations,
            m.mutations_per_second / 1e6,
            m.min_edges,
            m.max_edges,
            acceptance.join(", "),
            m.manifold_walks.tried,
            m.manifold_walks.converged,
            m.manifold_walks.irreversible,
            m.manifold_walks.glossy,
            m.manifold_walks.light_points,
            m.manifold_walks.sky_points,
            m.bootstrap_seconds
        );
        eprintln!(
            "  MEMLT: {:.2}% of the light camera walks find in paths only such a walk makes; independent mutation {}",
            m.walk_only_share * 100.0,
            if m.independent_mutation { "on" } else { "off" }
        );
        if let Some(d) = &m.direct_balance {
            eprintln!(
                "  MEMLT: direct light {} samples per pixel in {:.2} s ({} added after {:.2} s of the chains: relative variance per second, direct {:.3e}, chains {:.3e})",
                m.direct_samples, m.direct_seconds, d.extra_samples, d.measured_after, d.direct_noise, d.chain_noise
            );
        }
        print_first_stage(m.first_stage_samples, m.mean_luminance);
        print_longest_stay("memlt", m.longest_stay.as_ref());
    } else if !a.quiet && s.bidir.is_some() {
        let c = &s.counters;
        eprintln!(
            "  {} light paths, {} connections traced ({} occluded, {} skipped by roulette, {} repeated draws merged){}; time: light pool {:.2} s, {}camera pass {:.2} s, merge and splats {:.2} s; shadow rays: pool {}, {}camera pass {}",
            c.light_paths,
            c.connections,
            c.connections_occluded,
            c.connections_skipped,
            c.draws_merged,
            s.pool.map(|(m, v)| format!(", pool of {m} paths with {v} connectible vertices")).unwrap_or_default(),
            s.phases.light_pool,
            if s.cache.is_some() { format!("cache {:.2} s, ", s.phases.cache) } else { String::new() },
            s.phases.camera_pass,
            s.phases.merge,
            s.shadow_rays.light_pool,
            if s.cache.is_some() { format!("cache {}, ", s.shadow_rays.cache) } else { String::new() },
            s.shadow_rays.camera_pass,
        );
        if let Some(k) = &s.cache {
            eprintln!(
                "  PCBPT cache: {} records ({} empty, {} dropped for the memory limit) × {} pool vertices, {:.1} MiB; unoccluded draws' harmonic mean V·PMF {:.2}",
                k.records,
                k.empty_records,
                k.dropped_records,
                k.pool_vertices,
                k.megabytes,
                c.concentration().map_or(1.0, |(all, _)| all)
            );
        }
        if let Some(b) = &s.budget
            && let (Some(p), Some(m)) = (b.chosen, b.measured_with)
        {
            let why = match b.best {
                Some(best) if best != p => format!(
                    "kept: the best, {} and {}, predicted {:.2}×, is within the margin {:.2}",
                    best.connections, best.splat_paths, b.best_gain, b.margin
                ),
                _ => format!("predicted efficiency {:.2}× theirs", b.predicted_gain),
            };
            eprintln!(
                "  budget: {} connections per camera vertex and {} light-traced paths per iteration (measured with {} and {}; {why}, {})",
                p.connections,
                p.splat_paths,
                m.connections,
                m.splat_paths,
                if b.horizon == 0 { "expected moments".to_string() } else { format!("planned for {} spp", b.horizon) }
            );
        }
        if let Some(k) = &s.subspaces {
            eprintln!(
                "  SPCBPT: {} eye × {} light subspaces ({} light subspaces in the last pool), {} trained rows from {} connections, {:.2} s building and training, matrix and trees {:.2} MiB",
                k.eye_subspaces,
                k.light_subspaces,
                k.light_subspaces_used,
                k.trained_rows,
                k.training_samples,
                k.training_seconds,
                k.megabytes
            );
        }
    }
    Ok(if s.interrupted { ExitCode::from(INTERRUPTED) } else { ExitCode::SUCCESS })
}

fn merge_parts(a: MergeArgs) -> Result<ExitCode> {
    let t0 = Instant::now();
    image_io::Format::from_path(&a.output)?;
    let parts = a.parts.iter().map(|p| pcbpt::partial::read_part(p)).collect::<Result<Vec<_>>>()?;
    let n = parts.len();
    let read_seconds = t0.elapsed().as_secs_f64();
    let m = pcbpt::partial::merge(parts, a.partial)?;
    image_io::write(&a.output, &Image::new(m.width, m.height, m.image))?;
    if !a.quiet {
        let missing: Vec<String> = m.missing.iter().map(|r| format!("{}..{}", r.start, r.end)).collect();
        eprintln!(
            "merged {n} parts of {}×{} ({} of {} iterations{}) in {:.2} s ({:.2} s reading); the parts rendered for {:.1} s → {}",
            m.width,
            m.height,
            m.total - m.missing.iter().map(|r| r.len() as u32).sum::<u32>(),
            m.total,
            if missing.is_empty() { String::new() } else { format!("; missing {}", missing.join(", ")) },
            t0.elapsed().as_secs_f64(),
            read_seconds,
            m.render_seconds,
            a.output.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn compare_images(a: CompareArgs) -> Result<ExitCode> {
    let mut r = image_io::read(&a.reference)?;
    let mut t = image_io::read(&a.test)?;
    compare::check_same_size(&r, &t)?;
    let mut keep = match &a.mask {
        Some(p) => {
            let m = image_io::read(p)?;
            compare::check_same_size(&r, &m).map_err(|e| Error::Usage(format!("{}: {e}", p.display())))?;
            Some(compare::mask(&m))
        }
        None => None,
    };
    if let Some(c) = a.crop {
        if let Some(k) = &keep {
            let img = Image::new(r.width, r.height, k.iter().map(|&x| glam::Vec3::splat(x as u8 as f32)).collect());
            keep = Some(compare::mask(&compare::crop(&img, c)?));
        }
        r = compare::crop(&r, c)?;
        t = compare::crop(&t, c)?;
    }
    let m = compare::metrics_masked(&r, &t, keep.as_deref())?;
    if let Some(metric) = a.metric {
        let v = match metric {
            compare::Metric::Relmse => m.relmse,
            compare::Metric::Mse => m.mse,
            compare::Metric::Flip => compare::flip(&r, &t, keep.as_deref())?,
        };
        if a.json {
            println!("{}", serde_json::json!({ "metric": metric, "value": v }));
        } else {
            println!("{v:.6e}");
        }
    } else if a.json {
        println!("{}", serde_json::to_string_pretty(&m).unwrap_or_default());
    } else {
        println!("MSE        {:.6e}", m.mse);
        println!("relMSE     {:.6e}", m.relmse);
        println!("mean ratio {:.6} (test {:.6} / reference {:.6})", m.mean_ratio, m.test_mean, m.reference_mean);
        if m.non_finite > 0 {
            println!("non-finite pixels in the test image: {}", m.non_finite);
        }
    }
    if let Some(path) = &a.error_image {
        let bytes = compare::error_image(&r, &t, a.error_scale)?;
        image_io::write_png_rgb8(path, r.width, r.height, &bytes)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Two-stage Metropolis' line of the summary (nothing without a first stage).
fn print_first_stage(samples: u64, mean_luminance: f64) {
    if samples > 0 {
        eprintln!(
            "  two-stage: the chains' target is luminance over a map from a first stage of {samples} BDPT samples (b above is its mean); the chains' image is scaled to mean luminance {mean_luminance:.5}"
        );
    }
}

/// The summary's line on a Metropolis render's longest stay of a chain around one pixel, and
/// a warning when that stay carries most of the light in the pixels around it.
fn print_longest_stay(integrator: &str, stay: Option<&pcbpt::integrator::stays::LongestStay>) {
    let Some(l) = stay else { return };
    let [x, y] = l.pixel;
    eprintln!(
        "  longest stay of a chain around one pixel: {} mutations within a pixel of ({x}, {y}), {:.0}% of the light in those 3×3 pixels",
        l.mutations,
        l.share * 100.0
    );
    if l.dominates() {
        eprintln!(
            "warning: {integrator}: one chain stayed {} mutations within a pixel of ({x}, {y}) and put {:.0}% of the light \
             in those 3×3 pixels there: their values rest on a single visit (a longer render, or another --seed, averages it out)",
            l.mutations,
            l.share * 100.0
        );
    }
}
