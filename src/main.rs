//! The `pcbpt` command line: `render` a Mitsuba scene, `compare` two images.

mod cli_reference;

use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand, ValueEnum};
use pcbpt::accel::{Backend, BuildOptions, BuildQuality, BvhLayout};
use pcbpt::compare;
use pcbpt::display::DisplayServer;
use pcbpt::error::{Error, Result};
use pcbpt::image_io::{self, Image};
use pcbpt::integrator::registry::{self, INTEGRATORS};
use pcbpt::integrator::{self, Budget, IntegratorKind, Preview, RenderOptions};
use pcbpt::sampling::SamplerKind;
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
    /// Render a Mitsuba XML scene (`pcbpt render --integrator NAME --help` lists the options
    /// of integrator NAME).
    #[command(disable_help_flag = true)]
    Render(RawArgs),
    /// Compare a test image with a reference: MSE, relMSE and the ratio of image means.
    Compare(CompareArgs),
    /// Run an equal-time experiment described by a TOML file (scenes × methods).
    Experiment(ExperimentArgs),
    /// Merge the partial renders of one render (`render --chunk`) into its image.
    Merge(MergeArgs),
    /// Print the command-line reference (docs/cli.md) in Markdown.
    #[command(hide = true)]
    CliReference,
}

/// The render command's arguments, read by [`render_command`]'s parser: which options it
/// takes depends on the integrator.
#[derive(Args)]
struct RawArgs {
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    args: Vec<String>,
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
    /// Only these of the file's scenes (their names, comma-separated).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Only these of the file's methods (their names, comma-separated).
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// These seeds instead of the file's: a range (1..=9, 1..10) or a list (1,2,5).
    #[arg(long, value_parser = parse_seeds)]
    seeds: Option<pcbpt::experiment::Seeds>,
    /// Seconds per run instead of the file's `time` or `spp`.
    #[arg(long, value_parser = parse_seconds)]
    time: Option<f64>,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

/// The render command's options that every integrator reads; each integrator's own come
/// from its options struct in the registry ([`render_command`]).
#[derive(Args)]
struct RenderArgs {
    /// The scene file (Mitsuba 3 XML; version 0.x files are upgraded).
    scene: PathBuf,
    /// Output image; `.exr` (linear float RGB) or `.png` (sRGB, or tonemapped as the scene's
    /// `ldrfilm` says), and `.tif` (linear float RGB) in a build with `--features oiio`.
    /// Default: the scene's name with `.exr` (`.png` for an `ldrfilm`).
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
    /// Where the path tracer's random numbers come from: independent streams, or an
    /// Owen-scrambled Sobol sequence per pixel (default: the scene's sampler; the other
    /// integrators draw independent numbers).
    #[arg(long, value_enum)]
    sampler: Option<SamplerKind>,
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
    /// Write one EXR per bidirectional strategy (s,t) into this folder (they sum to the image).
    #[arg(long, value_name = "DIR")]
    strategy_images: Option<PathBuf>,
    /// Write these AOVs as extra channels of the output EXR, a comma-separated list of
    /// albedo (Albedo.R/G/B), normal (Ns.X/Y/Z), depth (Z), position (P.X/Y/Z) and variance
    /// (Variance.R/G/B, the image's per-pixel variance; not for pssmlt and memlt).
    #[arg(long, value_name = "LIST", value_parser = parse_aovs)]
    aov: Option<AovList>,
    /// Stop once the render's own relMSE estimate (from two half-images of its even and odd
    /// iterations) falls below this, or at --spp/--time, whichever comes first; the estimate
    /// is in --stats (not for pssmlt and memlt).
    #[arg(long, value_name = "RELMSE", allow_negative_numbers = true, value_parser = parse_relmse)]
    noise_threshold: Option<f64>,
    /// Write render statistics as JSON to this file.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
    /// Stream the image to the tev viewer listening at HOST:PORT as it renders (tev's default
    /// port is 14158); without a viewer there the render goes on with a warning.
    #[arg(long, value_name = "HOST:PORT", value_parser = pcbpt::display::parse_address)]
    display_server: Option<String>,
    /// Also write the image denoised by Intel Open Image Denoise beside the output
    /// (`NAME.denoised.EXT`; the output itself is unchanged). Needs a build with
    /// `--features oidn`.
    #[arg(long, conflicts_with_all = ["chunk", "iterations"])]
    denoise: bool,
    /// Where standard error is not a terminal (a Slurm log, a pipe), print a progress line
    /// every this many seconds instead of a progress bar.
    #[arg(long, value_name = "SECONDS", default_value_t = 10.0, value_parser = parse_seconds)]
    log_interval: f64,
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

/// A non-negative, finite number of seconds.
fn parse_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("expected a non-negative number of seconds, got {s:?}")),
    }
}

/// A positive, finite relMSE.
fn parse_seeds(s: &str) -> Result<pcbpt::experiment::Seeds, String> {
    pcbpt::experiment::Seeds::parse(s)
}

fn parse_relmse(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("expected a positive relMSE (e.g. 0.01), got {s:?}")),
    }
}

/// The AOVs `--aov` lists (one argument, commas between names).
#[derive(Clone)]
struct AovList(Vec<pcbpt::aov::Aov>);

fn parse_aovs(s: &str) -> Result<AovList, String> {
    pcbpt::aov::parse_list(s).map(AovList)
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

/// The `render` command for `kind`'s options (its own, under their heading), or, without
/// an integrator, every integrator's options hidden (what is read before the scene names
/// the integrator).
fn render_command(kind: Option<IntegratorKind>) -> clap::Command {
    let cmd = RenderArgs::augment_args(
        clap::Command::new("render")
            .bin_name("pcbpt render")
            .about("Render a Mitsuba XML scene")
            .version(env!("CARGO_PKG_VERSION")),
    );
    match kind {
        Some(k) => (registry::registration(k).args)(cmd.next_help_heading(format!("Options of {}", k.name()))),
        None => {
            let names: Vec<&str> = INTEGRATORS.iter().map(|r| r.kind.name()).collect();
            let mut cmd = cmd.after_help(format!(
                "Each integrator has options of its own: `pcbpt render --integrator NAME --help` lists them \
                 (NAME: {}; the reference: docs/cli.md).",
                names.join(", ")
            ));
            for r in INTEGRATORS {
                let theirs = (r.args)(clap::Command::new(r.kind.name()));
                for arg in theirs.get_arguments() {
                    if !cmd.get_arguments().any(|a| a.get_id() == arg.get_id()) {
                        cmd = cmd.arg(arg.clone().hide(true).default_value(None::<&str>).required(false));
                    }
                }
            }
            cmd
        }
    }
}

/// The integrator `--integrator` names among the render command's arguments, if any.
fn integrator_argument(args: &[String]) -> Option<IntegratorKind> {
    let value = args.iter().enumerate().find_map(|(i, a)| match a.strip_prefix("--integrator") {
        Some("") => args.get(i + 1).map(String::as_str),
        Some(v) => v.strip_prefix('='),
        None => None,
    })?;
    IntegratorKind::from_str(value, true).ok()
}

/// Parses the render command's arguments for `kind` (or for any integrator), exiting as clap
/// does on `--help` and bad arguments; an option of another integrator is refused naming the
/// integrators that read it.
fn parse_render(args: &[String], kind: Option<IntegratorKind>, whose: &str) -> clap::ArgMatches {
    let argv = std::iter::once("pcbpt render".to_string()).chain(args.iter().cloned());
    match render_command(kind).try_get_matches_from(argv) {
        Ok(m) => m,
        Err(e) => {
            use clap::error::{ContextKind, ContextValue, ErrorKind};
            if let (Some(k), ErrorKind::UnknownArgument, Some(ContextValue::String(flag))) =
                (kind, e.kind(), e.get(ContextKind::InvalidArg))
            {
                let flag = flag.split('=').next().unwrap_or(flag);
                if flag.starts_with("--") && !registry::readers(&flag[2..]).is_empty() {
                    eprintln!(
                        "error: {} ({whose}; `pcbpt render --integrator {} --help` lists its options)",
                        registry::not_an_option_of(flag, k),
                        k.name()
                    );
                    std::process::exit(2);
                }
            }
            e.exit()
        }
    }
}

/// Writes `text` to standard output. A reader that has stopped reading (`pcbpt compare … |
/// head`) is no error: what it did not take is dropped.
fn out(text: &str) -> Result<()> {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match stdout.write_all(text.as_bytes()).and_then(|()| stdout.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(Error::Output { path: PathBuf::from("standard output"), msg: e.to_string() })
        }
        _ => Ok(()),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render(a.args),
        Command::CliReference => {
            out(&cli_reference::markdown(&Cli::command(), render_command)).map(|()| ExitCode::SUCCESS)
        }
        Command::Compare(a) => compare_images(a),
        Command::Merge(a) => merge_parts(a),
        Command::Experiment(a) => {
            let selection =
                pcbpt::experiment::Selection { scenes: a.scenes, methods: a.methods, seeds: a.seeds, time: a.time };
            let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
            pcbpt::experiment::run_selected(&a.file, &selection, a.output.as_deref(), a.quiet, &stop)
        }
        .map(|r| {
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

fn render(args: Vec<String>) -> Result<ExitCode> {
    let named = integrator_argument(&args);
    let matches = parse_render(&args, named, "the integrator --integrator names");
    let a = RenderArgs::from_arg_matches(&matches).map_err(|e| Error::Usage(e.to_string()))?;
    if a.denoise {
        pcbpt::denoise::check_available()?;
    }
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
    if let Some(k) = a.sampler {
        scene.sampler.kind = k;
    }
    let load_seconds = t0.elapsed().as_secs_f64();
    if !a.quiet {
        for w in &scene.stats.warnings {
            eprintln!("warning: {w}");
        }
        if let Some(w) = a.denoise.then(|| pcbpt::denoise::filter_warning(&scene.film.filter)).flatten() {
            eprintln!("warning: {w}");
        }
        let l = &scene.stats;
        eprintln!(
            "loaded {}: {} triangles{} ({:.1} MiB of mesh arrays) in {:.2} s: reading {:.2} s, {} BVH {:.2} s",
            a.scene.display(),
            pcbpt::scene::load::group_thousands(l.triangles as u64),
            if l.hair_segments > 0 {
                format!(", {} hair segments", pcbpt::scene::load::group_thousands(l.hair_segments as u64))
            } else {
                String::new()
            },
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
    if scene.sampler.kind == SamplerKind::Sobol && kind != IntegratorKind::Path {
        if a.sampler.is_some() {
            return Err(Error::Usage(format!(
                "--sampler sobol is the path tracer's; {} draws independent random numbers",
                kind.name()
            )));
        }
        if !a.quiet {
            eprintln!(
                "warning: the scene's sobol sampler is the path tracer's; {} draws independent random numbers",
                kind.name()
            );
        }
    }
    let budget = match (a.spp, a.time) {
        (_, Some(t)) if !(t > 0.0 && t.is_finite()) => {
            return Err(Error::Usage(format!("--time must be a positive number of seconds, got {t}")));
        }
        (_, Some(t)) => Budget::Time(t),
        (Some(0), _) => return Err(Error::Usage("--spp must be at least 1".into())),
        (Some(s), None) => Budget::Spp(s),
        (None, None) => Budget::Spp(scene.sampler.spp),
    };
    // By default the film's format: a PNG for an `ldrfilm`, an EXR otherwise.
    let output = a.output.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "{}.{}",
            a.scene.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "render".into()),
            if scene.film.ldr.is_some() { "png" } else { "exr" }
        ))
    });
    image_io::Format::from_path(&output)?;
    // The integrator's options, read for the integrator the render uses.
    let matches = match named {
        Some(_) => matches,
        None => parse_render(&args, Some(kind), "the scene's integrator"),
    };
    let mut opts = RenderOptions::new(kind, budget);
    opts.method = (registry::registration(kind).parse)(&matches).map_err(|e| Error::Usage(e.to_string()))?;
    opts.run.seed = a.seed.unwrap_or(scene.sampler.seed);
    opts.run.threads = a.threads;
    opts.run.progress = !a.quiet;
    opts.run.log_interval = a.log_interval;
    opts.run.stop = Some(stop);
    opts.run.strategy_images = a.strategy_images.is_some();
    opts.run.aovs = a.aov.clone().map(|l| l.0).unwrap_or_default();
    opts.run.noise_threshold = a.noise_threshold;
    if !opts.run.aovs.is_empty() && image_io::Format::from_path(&output)? != image_io::Format::Exr {
        return Err(Error::Usage(format!("--aov writes channels of an EXR file, not {}", output.display())));
    }
    if let Some(dir) = &a.strategy_images {
        if !kind.is_bidirectional() {
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
            if opts.run.strategy_images {
                return Err(Error::Usage("--strategy-images are not kept in partial renders".into()));
            }
            if image_io::Format::from_path(&output)? != image_io::Format::Exr {
                return Err(Error::Usage(format!("{}: a partial render is written as an EXR file", output.display())));
            }
            let hash = pcbpt::partial::scene_hash(&scene, &a.define)?;
            Some((iterations, total, pcbpt::partial::render_identity(&scene, &opts, &hash)))
        }
    };
    let display = a.display_server.as_deref().and_then(|address| {
        let name = output.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "pcbpt".into());
        DisplayServer::connect(address, &name, scene.film.width, scene.film.height, a.quiet).map(Arc::new)
    });
    opts.run.preview = display.clone().map(|d| d as Arc<dyn Preview>);
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
        None if !out.aovs.is_empty() => {
            image_io::write_exr_channels(&output, &Image::new(out.width, out.height, out.image.clone()), &out.aovs)?
        }
        None => image_io::write_film(
            &output,
            &Image::new(out.width, out.height, out.image.clone()),
            scene.film.ldr.as_ref(),
        )?,
    }
    if let Some(d) = &display {
        d.finish(&out.image);
    }
    if a.denoise {
        // Guided by the first hits' albedo and normal, as Open Image Denoise's RT filter wants.
        let (albedo, normal) = pcbpt::denoise::guides(&scene, &out.aovs, opts.run.seed, opts.run.threads)?;
        let aux = pcbpt::denoise::Aux { albedo: Some(&albedo), normal: Some(&normal) };
        let denoised = pcbpt::denoise::denoise(out.width, out.height, &out.image, aux)?;
        let path = pcbpt::denoise::denoised_path(&output);
        image_io::write_film(&path, &Image::new(out.width, out.height, denoised), scene.film.ldr.as_ref())?;
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
    if let (false, Some(e)) = (a.quiet, s.relmse_estimate) {
        let stop = match (a.noise_threshold, s.noise_threshold_reached) {
            (Some(t), Some(true)) => format!(" (below --noise-threshold {t} after {} spp)", s.spp),
            (Some(t), _) => format!(" (not below --noise-threshold {t} within the budget)"),
            _ => String::new(),
        };
        eprintln!("  relMSE estimate from the half-images: {e:.3e}{stop}");
    }
    if !a.quiet && kind.is_bidirectional() {
        let c = &s.counters;
        let cache = s.phases.cache > 0.0 || s.shadow_rays.cache > 0;
        eprintln!(
            "  {} light paths, {} connections traced ({} occluded); time: light pool {:.2} s, {}camera pass {:.2} s, merge and splats {:.2} s; shadow rays: pool {}, {}camera pass {}",
            c.light_paths,
            c.connections,
            c.connections_occluded,
            s.phases.light_pool,
            if cache { format!("cache {:.2} s, ", s.phases.cache) } else { String::new() },
            s.phases.camera_pass,
            s.phases.merge,
            s.shadow_rays.light_pool,
            if cache { format!("cache {}, ", s.shadow_rays.cache) } else { String::new() },
            s.shadow_rays.camera_pass,
        );
    }
    if !a.quiet {
        for line in s.details.lines(s) {
            eprintln!("{line}");
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
            out(&format!("{}\n", serde_json::json!({ "metric": metric, "value": v })))?;
        } else {
            out(&format!("{v:.6e}\n"))?;
        }
    } else if a.json {
        out(&format!("{}\n", serde_json::to_string_pretty(&m).unwrap_or_default()))?;
    } else {
        let mut text = format!(
            "MSE        {:.6e}\nrelMSE     {:.6e}\nmean ratio {:.6} (test {:.6} / reference {:.6})\n",
            m.mse, m.relmse, m.mean_ratio, m.test_mean, m.reference_mean
        );
        if m.non_finite > 0 {
            text += &format!("non-finite pixels in the test image: {}\n", m.non_finite);
        }
        out(&text)?;
    }
    if let Some(path) = &a.error_image {
        let bytes = compare::error_image(&r, &t, a.error_scale)?;
        image_io::write_png_rgb8(path, r.width, r.height, &bytes)?;
    }
    Ok(ExitCode::SUCCESS)
}
