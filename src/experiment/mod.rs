//! Equal-time experiments (`pcbpt experiment FILE.toml`): every method renders every scene
//! for the same wall time (or sample count); the relMSE against a reference is recorded at
//! checkpoints spread logarithmically over the run, so convergence curves come out of one
//! run. Outputs, in one folder: the EXR of every run, `results.md` (the table),
//! `convergence.csv`, one log–log plot per scene (`convergence_SCENE.svg`) and, where the
//! scene names crops, a comparison figure (`figure_SCENE.png`).
//!
//! Paths in the file are relative to the file's own folder. [`run_stoppable`] takes a stop
//! flag that another thread may set (Python's Ctrl-C): every render gets it, and the
//! experiment returns the runs done once the render under way has stopped.

use crate::accel::Backend;
use crate::compare;
use crate::error::{Error, Result};
use crate::image_io::{self, Image};
use crate::integrator::{self, Budget, IntegratorKind, Method, RenderOptions, RenderOutput, registry};
use crate::math::Rgb;
use crate::scene::{LoadOptions, Scene};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

mod seeds;
pub use seeds::Seeds;

/// An experiment file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentFile {
    pub name: Option<String>,
    /// Output folder (default: the file's name without extension, beside it).
    pub output: Option<PathBuf>,
    /// Worker threads per run (0 = all cores).
    #[serde(default)]
    pub threads: usize,
    /// Seconds per run.
    pub time: Option<f64>,
    /// Samples per pixel per run (instead of `time`).
    pub spp: Option<u32>,
    /// Checkpoints per run (time budgets only), spaced by factors of two up to the budget.
    #[serde(default = "default_checkpoints")]
    pub checkpoints: usize,
    /// The method the speed-up column compares against (default: the first).
    pub baseline: Option<String>,
    /// The seed of every run, or:
    pub seed: Option<u64>,
    /// the seeds each run is rendered with (`[1, 2, 3]` or `"1..=9"`): each seed's results
    /// land in `seed-N/` of the output folder, and `summary.md` summarises across them.
    pub seeds: Option<Seeds>,
    /// A relMSE: the table adds each run's time to reach it against the reference,
    /// interpolated on the run's convergence curve ([`time_to_relmse`]).
    pub noise_threshold: Option<f64>,
    pub scene: Vec<SceneEntry>,
    pub method: Vec<MethodEntry>,
}

fn default_checkpoints() -> usize {
    8
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneEntry {
    pub name: String,
    pub file: PathBuf,
    /// `-D` parameter overrides.
    #[serde(default)]
    pub defines: BTreeMap<String, String>,
    pub max_depth: Option<i32>,
    /// The film size `"WxH"` instead of the scene's (as `render --resolution`), for scenes
    /// that fix it in the XML.
    #[serde(default, deserialize_with = "resolution")]
    pub resolution: Option<(u32, u32)>,
    /// A reference EXR, or:
    pub reference: Option<PathBuf>,
    /// a method (by name) to render the reference with, for `reference_time` seconds.
    pub reference_method: Option<String>,
    pub reference_time: Option<f64>,
    /// Crops `[x, y, width, height]` for the comparison figure.
    #[serde(default)]
    pub crops: Vec<[u32; 4]>,
    /// The same scene in LuxCore's format, for the LuxCore peer methods.
    pub luxcore_scene: Option<PathBuf>,
}

fn resolution<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Option<(u32, u32)>, D::Error> {
    let s = String::deserialize(d)?;
    crate::scene::parse_resolution(&s).map(Some).map_err(serde::de::Error::custom)
}

/// Peer renderers an experiment can run as methods (through `scripts/peer_render.py`).
const PEERS: [&str; 5] =
    ["mitsuba", "luxcore-path", "luxcore-bidir", "luxcore-path-metropolis", "luxcore-bidir-metropolis"];

/// A method: a name, an integrator (or a peer renderer) and the integrator's options, keyed
/// by their command-line names with underscores (`pc_cache_stride = 32` for
/// `--pc-cache-stride 32`), read by the same options struct as the command line.
#[derive(Debug, Deserialize, Clone)]
pub struct MethodEntry {
    pub name: String,
    pub integrator: String,
    #[serde(default = "default_backend")]
    pub backend: String,
    /// The integrator's options.
    #[serde(flatten)]
    pub options: toml::Table,
}

fn default_backend() -> String {
    "embree".into()
}

/// One run's results.
#[derive(Clone, Debug)]
pub struct RunResult {
    pub scene: String,
    pub method: String,
    /// The seed of the run's random numbers.
    pub seed: u64,
    pub spp: u32,
    pub seconds: f64,
    pub samples_per_second: f64,
    pub relmse: f64,
    /// FLIP of the final image (LDR, see [`compare::flip`]).
    pub flip: f64,
    pub mean_ratio: f64,
    /// `(seconds, spp, relMSE)` at each checkpoint, then at the end.
    pub curve: Vec<(f64, u32, f64)>,
    /// Seconds in light pools, cache, camera passes and merging (our integrators).
    pub phases: Option<integrator::PhaseTimes>,
}

fn usage(file: &Path, msg: impl std::fmt::Display) -> Error {
    Error::Usage(format!("{}: {msg}", file.display()))
}

fn value_enum<T: clap::ValueEnum>(file: &Path, what: &str, s: &str) -> Result<T> {
    T::from_str(s, true).map_err(|_| {
        let names: Vec<String> = T::value_variants()
            .iter()
            .filter_map(|v| v.to_possible_value())
            .map(|p| p.get_name().to_string())
            .collect();
        usage(file, format!("unknown {what} \"{s}\" (one of: {})", names.join(", ")))
    })
}

impl ExperimentFile {
    /// The method the speed-ups and ratios compare against.
    pub fn baseline(&self) -> String {
        self.baseline.clone().unwrap_or_else(|| self.method[0].name.clone())
    }

    /// Where the experiment in file `path` writes: `output` if given, else the file's
    /// `output` (relative to the file's folder), else the file's name beside it.
    pub fn output_folder(&self, path: &Path, output: Option<&Path>) -> PathBuf {
        let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        match output {
            Some(o) => o.to_path_buf(),
            None => match &self.output {
                Some(o) => base.join(o),
                None => base.join(path.file_stem().unwrap_or_default()),
            },
        }
    }

    pub fn load(path: &Path) -> Result<ExperimentFile> {
        let text = std::fs::read_to_string(path).map_err(|e| usage(path, format!("cannot read: {e}")))?;
        let f: ExperimentFile = toml::from_str(&text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start].matches('\n').count() + 1);
            match line {
                Some(l) => Error::Usage(format!("{}:{l}: {}", path.display(), e.message())),
                None => usage(path, e.message()),
            }
        })?;
        f.check(path)?;
        Ok(f)
    }

    /// Keeps the scenes and methods `selection` names and replaces the seeds and the budget
    /// it gives; a name the file does not have is an error listing the file's.
    pub fn select(&mut self, path: &Path, selection: &Selection) -> Result<()> {
        keep(path, &mut self.scene, &selection.scenes, "scene", |s| &s.name)?;
        keep(path, &mut self.method, &selection.methods, "method", |m| &m.name)?;
        if let Some(seeds) = &selection.seeds {
            self.seeds = Some(seeds.clone());
            self.seed = None;
        }
        if let Some(t) = selection.time {
            self.time = Some(t);
            self.spp = None;
            // The file's name may state its own budget: the tables say which one ran.
            let name = self.name.take().unwrap_or_else(|| "experiment".to_string());
            self.name = Some(format!("{name}, run at {t} s per render"));
        }
        if let Some(b) = &self.baseline
            && !self.method.iter().any(|m| &m.name == b)
        {
            return Err(usage(path, format!("the baseline method \"{b}\" is not among the selected methods")));
        }
        self.check(path)
    }

    /// The checks of a file's contents that [`ExperimentFile::load`] and
    /// [`ExperimentFile::select`] make.
    fn check(&self, path: &Path) -> Result<()> {
        let f = self;
        if f.seed.is_some() && f.seeds.is_some() {
            return Err(usage(path, "give `seed` (one seed) or `seeds` (a list or range), not both"));
        }
        if f.time.is_some() == f.spp.is_some() {
            return Err(usage(path, "give exactly one of `time` (seconds per run) and `spp`"));
        }
        if let Some(t) = f.time
            && !(t > 0.0 && t.is_finite())
        {
            return Err(usage(path, format!("`time` must be a positive number of seconds, got {t}")));
        }
        if let Some(x) = f.noise_threshold
            && !(x > 0.0 && x.is_finite())
        {
            return Err(usage(path, format!("`noise_threshold` must be a positive relMSE, got {x}")));
        }
        if f.scene.is_empty() || f.method.is_empty() {
            return Err(usage(path, "an experiment needs at least one [[scene]] and one [[method]]"));
        }
        for m in &f.method {
            if PEERS.contains(&m.integrator.as_str()) {
                if let Some(k) = m.options.keys().next() {
                    return Err(usage(path, format!("method {}: a peer renderer takes no option (`{k}`)", m.name)));
                }
                if m.integrator.starts_with("luxcore")
                    && let Some(s) = f.scene.iter().find(|s| s.luxcore_scene.is_none())
                {
                    return Err(usage(path, format!("method {} needs `luxcore_scene` in scene {}", m.name, s.name)));
                }
                continue;
            }
            method(path, m)?;
            value_enum::<Backend>(path, "backend", &m.backend)?;
        }
        let named = |n: &str| f.method.iter().any(|m| m.name == n);
        if let Some(b) = &f.baseline
            && !named(b)
        {
            return Err(usage(path, format!("baseline \"{b}\" is not one of the methods")));
        }
        for s in &f.scene {
            match (&s.reference, &s.reference_method, s.reference_time) {
                (Some(_), None, None) => {}
                (None, Some(m), Some(t)) if named(m) && t > 0.0 => {}
                (None, Some(m), Some(_)) if !named(m) => {
                    return Err(usage(path, format!("scene {}: reference method \"{m}\" is not a method", s.name)));
                }
                _ => {
                    return Err(usage(
                        path,
                        format!(
                            "scene {}: give `reference` (an EXR) or `reference_method` with `reference_time`",
                            s.name
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// A part of an experiment file to run, from the command line (`--scenes`, `--methods`,
/// `--seeds`, `--time`): empty lists keep every scene or method, `None` the file's seeds or
/// budget.
#[derive(Clone, Debug, Default)]
pub struct Selection {
    pub scenes: Vec<String>,
    pub methods: Vec<String>,
    pub seeds: Option<Seeds>,
    /// Seconds per run, instead of the file's `time` or `spp`.
    pub time: Option<f64>,
}

/// Keeps the entries of `items` that `names` names (all of them when `names` is empty), in
/// the file's order.
fn keep<T>(path: &Path, items: &mut Vec<T>, names: &[String], what: &str, name: impl Fn(&T) -> &String) -> Result<()> {
    if names.is_empty() {
        return Ok(());
    }
    if let Some(n) = names.iter().find(|n| !items.iter().any(|i| name(i) == *n)) {
        let known: Vec<&str> = items.iter().map(|i| name(i).as_str()).collect();
        return Err(usage(path, format!("no {what} \"{n}\" here (its {what}s: {})", known.join(", "))));
    }
    items.retain(|i| names.contains(name(i)));
    Ok(())
}

/// The command-line arguments a method's options stand for (`key = value` as `--key value`).
fn option_args(file: &Path, m: &MethodEntry) -> Result<Vec<(String, String)>> {
    m.options
        .iter()
        .map(|(k, v)| {
            let value = match v {
                toml::Value::String(s) => s.clone(),
                toml::Value::Integer(i) => i.to_string(),
                toml::Value::Float(x) => x.to_string(),
                toml::Value::Boolean(b) => b.to_string(),
                _ => return Err(usage(file, format!("method {}: `{k}` must be a string, number or boolean", m.name))),
            };
            Ok((k.clone(), value))
        })
        .collect()
}

/// The integrator and its options of method `m`, read by the integrator's options struct
/// (the command line's): a key another integrator reads, or none does, is an error naming it.
fn method(file: &Path, m: &MethodEntry) -> Result<Method> {
    let kind: IntegratorKind = value_enum(file, "integrator", &m.integrator)?;
    let mut args = Vec::new();
    for (k, v) in option_args(file, m)? {
        let flag = format!("--{}", k.replace('_', "-"));
        let known = registry::reads(kind, &flag[2..]);
        if !known {
            let why = registry::not_an_option_of(&flag, kind);
            return Err(usage(file, format!("method {}: `{k}`: {why}", m.name)));
        }
        args.push(flag);
        args.push(v);
    }
    registry::parse_options(kind, &args).map_err(|e| usage(file, format!("method {}: {e}", m.name)))
}

fn options(file: &Path, m: &MethodEntry, budget: Budget, seed: u64, threads: usize) -> Result<RenderOptions> {
    let mut o = RenderOptions::new(value_enum(file, "integrator", &m.integrator)?, budget);
    o.method = method(file, m)?;
    o.run.seed = seed;
    o.run.threads = threads;
    Ok(o)
}

/// Runs an experiment file; returns the results and writes the outputs.
pub fn run(path: &Path, output: Option<&Path>, quiet: bool) -> Result<Vec<RunResult>> {
    run_selected(path, &Selection::default(), output, quiet, &Arc::new(AtomicBool::new(false)))
}

/// [`run`], stopped when `stop` is set (from another thread): the render in progress ends
/// after its current pass and is dropped, and the runs done so far are returned, without
/// the tables and figures of the seed or scene left unfinished.
pub fn run_stoppable(
    path: &Path,
    output: Option<&Path>,
    quiet: bool,
    stop: &Arc<AtomicBool>,
) -> Result<Vec<RunResult>> {
    run_selected(path, &Selection::default(), output, quiet, stop)
}

/// [`run_stoppable`] over the part of the file that `selection` keeps.
pub fn run_selected(
    path: &Path,
    selection: &Selection,
    output: Option<&Path>,
    quiet: bool,
    stop: &Arc<AtomicBool>,
) -> Result<Vec<RunResult>> {
    let mut f = ExperimentFile::load(path)?;
    f.select(path, selection)?;
    let out = f.output_folder(path, output);
    let baseline = f.baseline();
    let Some(seeds) = &f.seeds else {
        return run_seed(path, &f, f.seed.unwrap_or(0), &out, quiet, stop);
    };
    let mut runs = Vec::new();
    for &seed in &seeds.0 {
        if !quiet {
            eprintln!("seed {seed}");
        }
        runs.push((seed, run_seed(path, &f, seed, &out.join(format!("seed-{seed}")), quiet, stop)?));
        if stop.load(Ordering::SeqCst) {
            return Ok(runs.into_iter().flat_map(|(_, r)| r).collect());
        }
    }
    let text = seeds::summary(f.name.as_deref().unwrap_or("experiment"), &runs, &baseline);
    image_io::write_text(&out.join("summary.md"), &text)?;
    if !quiet {
        eprint!("{text}");
    }
    Ok(runs.into_iter().flat_map(|(_, r)| r).collect())
}

/// Runs every method on every scene with `seed` and writes the outputs into `out`; returns
/// early, with the runs done, once `stop` is set.
fn run_seed(
    path: &Path,
    f: &ExperimentFile,
    seed: u64,
    out: &Path,
    quiet: bool,
    stop: &Arc<AtomicBool>,
) -> Result<Vec<RunResult>> {
    let stopped = || stop.load(Ordering::SeqCst);
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    std::fs::create_dir_all(out).map_err(|e| Error::Output { path: out.to_path_buf(), msg: e.to_string() })?;
    let budget = match (f.time, f.spp) {
        (Some(t), _) => Budget::Time(t),
        (_, Some(s)) => Budget::Spp(s),
        _ => unreachable!("checked on load"),
    };
    let checkpoints: Vec<f64> = match f.time {
        Some(t) => (0..f.checkpoints).rev().map(|k| t / 2f64.powi(k as i32)).filter(|&c| c < t).collect(),
        None => Vec::new(),
    };
    let mut results = Vec::new();
    for s in &f.scene {
        if stopped() {
            return Ok(results);
        }
        let defines: Vec<(String, String)> = s.defines.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
        let load = |backend: Backend| -> Result<Scene> {
            let mut scene = Scene::load(
                &base.join(&s.file),
                &LoadOptions {
                    overrides: defines.clone(),
                    backend,
                    integrator_override: Some("the experiment's methods".into()),
                    resolution: s.resolution,
                    threads: f.threads,
                    ..Default::default()
                },
            )?;
            if let Some(d) = s.max_depth {
                scene.integrator.max_depth = d;
            }
            Ok(scene)
        };
        // The scene once per backend the methods use.
        let mut scenes: BTreeMap<String, Scene> = BTreeMap::new();
        for m in f.method.iter().filter(|m| !PEERS.contains(&m.integrator.as_str())) {
            if !scenes.contains_key(&m.backend) {
                let b = value_enum::<Backend>(path, "backend", &m.backend)?;
                let scene = load(b)?;
                if scenes.is_empty() && !quiet {
                    for w in &scene.stats.warnings {
                        eprintln!("{}: warning: {w}", s.name);
                    }
                }
                scenes.insert(m.backend.clone(), scene);
            }
        }
        // The reference.
        let reference = match (&s.reference, &s.reference_method, s.reference_time) {
            (Some(r), _, _) => image_io::read_exr(&base.join(r))?,
            (None, Some(m), Some(t)) => {
                let me = f.method.iter().find(|x| &x.name == m).expect("checked on load");
                let scene = &scenes[&me.backend];
                let mut o = options(path, me, Budget::Time(t), seed ^ 0x0005_eed0_f7ef, f.threads)?;
                o.run.stop = Some(stop.clone());
                if !quiet {
                    eprintln!("{}: reference by {} for {t} s", s.name, me.name);
                }
                let r = integrator::render(scene, &o)?;
                if stopped() {
                    return Ok(results);
                }
                let img = Image::new(r.width, r.height, r.image);
                image_io::write(&out.join(format!("{}_reference.exr", s.name)), &img)?;
                img
            }
            _ => unreachable!("checked on load"),
        };
        let mut images: Vec<(String, Image)> = Vec::new();
        for m in &f.method {
            if stopped() {
                return Ok(results);
            }
            if PEERS.contains(&m.integrator.as_str()) {
                let Some(t) = f.time else {
                    return Err(usage(path, format!("peer method {} needs a `time` budget", m.name)));
                };
                let exr = out.join(format!("{}_{}.exr", s.name, m.name));
                let Some(peer) = run_peer(&base, s, m, t, (f, seed), &exr, (reference.width, reference.height), quiet)?
                else {
                    continue;
                };
                let metrics = compare::metrics(&reference, &peer.image)?;
                if !quiet {
                    eprintln!(
                        "{} / {}: {} spp in {:.1} s, relMSE {:.5}",
                        s.name, m.name, peer.spp, peer.seconds, metrics.relmse
                    );
                }
                results.push(RunResult {
                    scene: s.name.clone(),
                    method: m.name.clone(),
                    seed,
                    spp: peer.spp,
                    seconds: peer.seconds,
                    samples_per_second: peer.samples_per_second,
                    relmse: metrics.relmse,
                    flip: compare::flip(&reference, &peer.image, None)?,
                    mean_ratio: metrics.mean_ratio,
                    curve: vec![(peer.seconds, peer.spp, metrics.relmse)],
                    phases: None,
                });
                images.push((m.name.clone(), peer.image));
                continue;
            }
            let scene = &scenes[&m.backend];
            let mut o = options(path, m, budget, seed, f.threads)?;
            o.run.checkpoints = checkpoints.clone();
            o.run.stop = Some(stop.clone());
            let r: RenderOutput = integrator::render(scene, &o)?;
            if r.stats.interrupted {
                return Ok(results);
            }
            let img = Image::new(r.width, r.height, r.image.clone());
            let metrics = compare::metrics(&reference, &img)?;
            let mut curve = Vec::new();
            for snap in &r.snapshots {
                let m = compare::metrics(&reference, &Image::new(r.width, r.height, snap.image.clone()))?;
                curve.push((snap.seconds, snap.spp, m.relmse));
            }
            curve.push((r.stats.seconds, r.stats.spp, metrics.relmse));
            image_io::write(&out.join(format!("{}_{}.exr", s.name, m.name)), &img)?;
            if !quiet {
                eprintln!(
                    "{} / {}: {} spp in {:.1} s, relMSE {:.5}, mean ratio {:.4}",
                    s.name, m.name, r.stats.spp, r.stats.seconds, metrics.relmse, metrics.mean_ratio
                );
            }
            results.push(RunResult {
                scene: s.name.clone(),
                method: m.name.clone(),
                seed,
                spp: r.stats.spp,
                seconds: r.stats.seconds,
                samples_per_second: r.stats.samples_per_second,
                relmse: metrics.relmse,
                flip: compare::flip(&reference, &img, None)?,
                mean_ratio: metrics.mean_ratio,
                curve,
                phases: Some(r.stats.phases),
            });
            images.push((m.name.clone(), img));
        }
        if !s.crops.is_empty() {
            figure(&out.join(format!("figure_{}.png", s.name)), &reference, &images, &s.crops)?;
        }
        plot(&out.join(format!("convergence_{}.svg", s.name)), &s.name, results.iter().filter(|r| r.scene == s.name))?;
    }
    let baseline = f.baseline();
    image_io::write_text(
        &out.join("results.md"),
        &table(f.name.as_deref().unwrap_or("experiment"), &results, &baseline, f.noise_threshold),
    )?;
    image_io::write_text(&out.join("convergence.csv"), &csv(&results))?;
    Ok(results)
}

struct PeerRun {
    image: Image,
    spp: u32,
    seconds: f64,
    samples_per_second: f64,
}

/// Runs a peer renderer through `scripts/peer_render.py` (or `$PCBPT_PEER_SCRIPT`) for `time`
/// seconds; `None` (with a message) when the peer is not installed.
#[allow(clippy::too_many_arguments)]
fn run_peer(
    base: &Path,
    s: &SceneEntry,
    m: &MethodEntry,
    time: f64,
    (f, seed): (&ExperimentFile, u64),
    exr: &Path,
    size: (u32, u32),
    quiet: bool,
) -> Result<Option<PeerRun>> {
    let script = std::env::var_os("PCBPT_PEER_SCRIPT")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/peer_render.py"));
    let pfm = exr.with_extension("pfm");
    let scene = match m.integrator.as_str() {
        "mitsuba" => base.join(&s.file),
        _ => base.join(s.luxcore_scene.as_ref().expect("checked on load")),
    };
    let mut cmd = std::process::Command::new("python3");
    cmd.arg(&script)
        .args(["--renderer", &m.integrator, "--time", &time.to_string(), "--threads", &f.threads.to_string()])
        .args(["--width", &size.0.to_string(), "--height", &size.1.to_string(), "--seed", &seed.to_string()])
        .arg("--scene")
        .arg(&scene)
        .arg("--out")
        .arg(&pfm);
    for (k, v) in &s.defines {
        cmd.arg("--define").arg(format!("{k}={v}"));
    }
    if let Some(d) = s.max_depth {
        cmd.arg("--max-depth").arg(d.to_string());
    }
    if s.resolution.is_some() {
        // The film size is the reference's, which the scene's own film does not give.
        cmd.arg("--resize-film");
    }
    let out = cmd.output().map_err(|e| Error::Usage(format!("cannot run python3 {}: {e}", script.display())))?;
    if out.status.code() == Some(3) {
        if !quiet {
            eprintln!("{} / {}: skipped: {}", s.name, m.name, String::from_utf8_lossy(&out.stderr).trim());
        }
        return Ok(None);
    }
    if !out.status.success() {
        return Err(Error::Usage(format!(
            "peer {} failed on {}: {}",
            m.integrator,
            scene.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    // The statistics are the last line (a peer may print its own messages before).
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stats: serde_json::Value = serde_json::from_str(stdout.trim().lines().last().unwrap_or(""))
        .map_err(|e| Error::Usage(format!("peer {}: unreadable statistics: {e}", m.integrator)))?;
    let image = read_pfm(&pfm)?;
    let _ = std::fs::remove_file(&pfm);
    if (image.width, image.height) != size {
        return Err(Error::Usage(format!(
            "peer {} rendered {}×{}, the reference is {}×{}",
            m.integrator, image.width, image.height, size.0, size.1
        )));
    }
    image_io::write(exr, &image)?;
    Ok(Some(PeerRun {
        image,
        spp: stats["spp"].as_f64().unwrap_or(0.0) as u32,
        seconds: stats["seconds"].as_f64().unwrap_or(time),
        samples_per_second: stats["samples_per_second"].as_f64().unwrap_or(0.0),
    }))
}

/// Reads a little-endian float RGB PFM (rows bottom first).
fn read_pfm(path: &Path) -> Result<Image> {
    let bad = |msg: &str| Error::Usage(format!("{}: {msg}", path.display()));
    let data = std::fs::read(path).map_err(|e| bad(&e.to_string()))?;
    let mut fields = Vec::new();
    let mut pos = 0;
    while fields.len() < 4 {
        while pos < data.len() && data[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < data.len() && !data[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err(bad("truncated PFM header"));
        }
        fields.push(String::from_utf8_lossy(&data[start..pos]).into_owned());
    }
    pos += 1;
    let (w, h): (u32, u32) = match (fields[1].parse(), fields[2].parse()) {
        (Ok(w), Ok(h)) if fields[0] == "PF" => (w, h),
        _ => return Err(bad("not an RGB PFM")),
    };
    if !fields[3].starts_with('-') {
        return Err(bad("big-endian PFM is not supported"));
    }
    let n = w as usize * h as usize;
    if data.len() < pos + n * 12 {
        return Err(bad("truncated PFM data"));
    }
    let f = |i: usize| f32::from_le_bytes(data[pos + 4 * i..pos + 4 * i + 4].try_into().expect("4 bytes"));
    let mut pixels = vec![Rgb::ZERO; n];
    for y in 0..h as usize {
        let src = (h as usize - 1 - y) * w as usize;
        for x in 0..w as usize {
            let k = (src + x) * 3;
            pixels[y * w as usize + x] = Rgb::new(f(k), f(k + 1), f(k + 2));
        }
    }
    Ok(Image::new(w, h, pixels))
}

/// The time a run's convergence curve (`(seconds, spp, relMSE)`, in time order) first
/// reaches relMSE `x`: interpolated log–log between the checkpoints around the crossing
/// (relMSE falls as a power of time), the first checkpoint's time when it is already below;
/// `None` when the run never reaches it.
pub fn time_to_relmse(curve: &[(f64, u32, f64)], x: f64) -> Option<f64> {
    let i = curve.iter().position(|&(_, _, e)| e <= x)?;
    let (t1, _, e1) = curve[i];
    let Some(&(t0, _, e0)) = i.checked_sub(1).map(|j| &curve[j]) else { return Some(t1) };
    if !(t0 > 0.0 && e1 > 0.0 && e0 > e1) {
        return Some(t1);
    }
    let f = (x.ln() - e0.ln()) / (e1.ln() - e0.ln());
    Some((t0.ln() + f * (t1.ln() - t0.ln())).exp())
}

/// The Markdown table: per scene and method, with the speed-up over the baseline at equal
/// time (its relMSE over the method's), the inefficiency `relMSE × seconds` and, with a
/// noise threshold, the time to reach it ([`time_to_relmse`]; `> T` when the run of `T`
/// seconds did not).
pub fn table(name: &str, results: &[RunResult], baseline: &str, threshold: Option<f64>) -> String {
    let (extra, rule) = match threshold {
        Some(x) => (format!(" seconds to relMSE {x} |"), "---|"),
        None => (String::new(), ""),
    };
    let mut s = format!(
        "# {name}\n\n| scene | method | spp | M samples/s | seconds | relMSE | FLIP | mean ratio | speed-up over {baseline} | relMSE × s | seconds in pool / cache / camera / merge |{extra}\n|---|---|---|---|---|---|---|---|---|---|---|{rule}\n"
    );
    for r in results {
        let base = results.iter().find(|b| b.scene == r.scene && b.method == baseline);
        let speedup =
            base.map(|b| format!("{:.2}×", b.relmse * b.seconds / (r.relmse * r.seconds))).unwrap_or_default();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.3} | {:.1} | {:.5} | {:.4} | {:.4} | {} | {:.4} | {} |",
            r.scene,
            r.method,
            r.spp,
            r.samples_per_second / 1e6,
            r.seconds,
            r.relmse,
            r.flip,
            r.mean_ratio,
            speedup,
            r.relmse * r.seconds,
            r.phases
                .map(|p| format!("{:.1} / {:.1} / {:.1} / {:.1}", p.light_pool, p.cache, p.camera_pass, p.merge))
                .unwrap_or_default()
        );
        if let Some(x) = threshold {
            s.pop();
            let t = time_to_relmse(&r.curve, x).map_or(format!("> {:.1}", r.seconds), |t| format!("{t:.2}"));
            let _ = writeln!(s, " {t} |");
        }
    }
    s
}

fn csv(results: &[RunResult]) -> String {
    let mut s = String::from("scene,method,seconds,spp,relmse\n");
    for r in results {
        for (t, spp, e) in &r.curve {
            let _ = writeln!(s, "{},{},{t:.4},{spp},{e:.6e}", r.scene, r.method);
        }
    }
    s
}

/// relMSE over time, log–log, one curve per method.
fn plot<'a>(path: &Path, scene: &str, runs: impl Iterator<Item = &'a RunResult>) -> Result<()> {
    use plotters::prelude::*;
    let runs: Vec<&RunResult> = runs.collect();
    let pts = || runs.iter().flat_map(|r| r.curve.iter()).filter(|(t, _, e)| *t > 0.0 && *e > 0.0);
    let (t0, t1) = pts().fold((f64::MAX, f64::MIN), |(a, b), (t, _, _)| (a.min(*t), b.max(*t)));
    let (e0, e1) = pts().fold((f64::MAX, f64::MIN), |(a, b), (_, _, e)| (a.min(*e), b.max(*e)));
    if t0 >= t1 || e0 > e1 {
        return Ok(());
    }
    let err = |e: String| Error::Output { path: path.to_path_buf(), msg: e };
    let tmp = path.with_extension("tmp.svg");
    {
        let root = SVGBackend::new(&tmp, (720, 480)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("{scene}: relMSE over time"), ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((t0 * 0.9..t1 * 1.1).log_scale(), (e0 * 0.8..e1 * 1.25).log_scale())
            .map_err(|e| err(e.to_string()))?;
        chart.configure_mesh().x_desc("seconds").y_desc("relMSE").draw().map_err(|e| err(e.to_string()))?;
        for (i, r) in runs.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(
                    r.curve.iter().filter(|(t, _, e)| *t > 0.0 && *e > 0.0).map(|(t, _, e)| (*t, *e)),
                    color.stroke_width(2),
                ))
                .map_err(|e| err(e.to_string()))?
                .label(r.method.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| err(e.to_string()))?;
        root.present().map_err(|e| err(e.to_string()))?;
    }
    std::fs::rename(&tmp, path).map_err(|e| err(e.to_string()))
}

/// The comparison figure: the first method's full image with the crops outlined, then one
/// row per crop with the reference and every method side by side, enlarged.
fn figure(path: &Path, reference: &Image, images: &[(String, Image)], crops: &[[u32; 4]]) -> Result<()> {
    let (w, h) = (reference.width, reference.height);
    for c in crops {
        if c[2] == 0 || c[3] == 0 || c[0] + c[2] > w || c[1] + c[3] > h {
            return Err(Error::Usage(format!("crop {c:?} is not inside the {w}×{h} image")));
        }
    }
    let cols = images.len() as u32 + 1;
    let cell = crops.iter().map(|c| c[2].max(c[3])).max().unwrap_or(1);
    // Enlarged so that a row of crops is at least as wide as the image (and 480 pixels).
    let zoom = (w.max(480) / cols / cell).max(1);
    let fig_w = w.max(cols * cell * zoom + (cols - 1) * 4);
    let row_h = crops.iter().map(|c| c[3] * zoom + 4).collect::<Vec<_>>();
    let fig_h = h + 4 + row_h.iter().sum::<u32>();
    let mut px = vec![Rgb::splat(1.0); (fig_w * fig_h) as usize];
    let put = |px: &mut Vec<Rgb>, x: u32, y: u32, v: Rgb| {
        if x < fig_w && y < fig_h {
            px[(y * fig_w + x) as usize] = v;
        }
    };
    let first = images.first().map(|(_, i)| i).unwrap_or(reference);
    for y in 0..h {
        for x in 0..w {
            put(&mut px, x, y, first.pixels[(y * w + x) as usize]);
        }
    }
    let red = Rgb::new(4.0, 0.0, 0.0);
    for c in crops {
        for x in c[0]..c[0] + c[2] {
            put(&mut px, x, c[1], red);
            put(&mut px, x, c[1] + c[3] - 1, red);
        }
        for y in c[1]..c[1] + c[3] {
            put(&mut px, c[0], y, red);
            put(&mut px, c[0] + c[2] - 1, y, red);
        }
    }
    let mut y0 = h + 4;
    for (c, rh) in crops.iter().zip(&row_h) {
        let sources = std::iter::once(reference).chain(images.iter().map(|(_, i)| i));
        for (k, img) in sources.enumerate() {
            let x0 = k as u32 * (cell * zoom + 4);
            for y in 0..c[3] * zoom {
                for x in 0..c[2] * zoom {
                    let v = img.pixels[((c[1] + y / zoom) * w + c[0] + x / zoom) as usize];
                    put(&mut px, x0 + x, y0 + y, v);
                }
            }
        }
        y0 += rh;
    }
    image_io::write(path, &Image::new(fig_w, fig_h, px))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_time_to_a_relmse_is_interpolated_log_log_between_checkpoints() {
        // relMSE = 0.08 / t: 0.02 is reached at 4 s, between the checkpoints at 2 s and 8 s.
        let curve = [(1.0, 1, 0.08), (2.0, 2, 0.04), (8.0, 8, 0.01)];
        assert!((time_to_relmse(&curve, 0.02).unwrap() - 4.0).abs() < 1e-9);
        assert_eq!(time_to_relmse(&curve, 0.1), Some(1.0), "already below at the first checkpoint");
        assert_eq!(time_to_relmse(&curve, 0.04), Some(2.0));
        assert_eq!(time_to_relmse(&curve, 0.001), None);
    }

    #[test]
    fn the_table_has_the_time_to_the_threshold_only_when_asked() {
        let run = RunResult {
            scene: "s".into(),
            method: "m".into(),
            seed: 0,
            spp: 8,
            seconds: 8.0,
            samples_per_second: 1e6,
            relmse: 0.01,
            flip: 0.1,
            mean_ratio: 1.0,
            curve: vec![(2.0, 2, 0.04), (8.0, 8, 0.01)],
            phases: None,
        };
        let plain = table("x", std::slice::from_ref(&run), "m", None);
        assert!(!plain.contains("seconds to relMSE"), "{plain}");
        let with = table("x", std::slice::from_ref(&run), "m", Some(0.02));
        let lines: Vec<&str> = with.lines().collect();
        assert!(lines[2].ends_with("| seconds to relMSE 0.02 |") && lines[3].ends_with("|---|"), "{with}");
        assert!(lines[4].ends_with("| 4.00 |"), "{with}");
        let never = table("x", &[run], "m", Some(0.001));
        assert!(never.lines().nth(4).unwrap().ends_with("| > 8.0 |"), "{never}");
    }
}
