//! The ray-bound rate of the path tracer: how fast the backend alone answers the very rays a
//! render asks, against how fast the render asks them.
//!
//! Each scene is rendered once on one thread with its queries recorded
//! (`pcbpt::accel::record`), and then, alternating round by round on the same threads:
//! - the render itself (`--spp` samples per pixel): its rays (camera, extension, shadow) per
//!   second;
//! - the recorded queries replayed one at a time, in the render's order, in chunks of 4096
//!   spread over the threads: what the scalar path tracer asks of the backend;
//! - the same chunks replayed as batches (each chunk's closest-hit rays in one
//!   `intersect_batch`, its occlusion rays in one `occluded_batch`: Embree's stream
//!   interface), as a wavefront that groups its queries by kind would ask them.
//!
//! It prints the medians over the rounds and the render's share of each replay's rate: the
//! share of its time a render would save if everything but the ray queries cost nothing is
//! one minus that.
//!
//! ```sh
//! cargo bench --profile release --features ray-record --bench ray_bound -- \
//!     [--threads N] [--spp N] [--record-spp N] [--rounds N] [--resolution WxH] [SCENE.xml ...]
//! ```
//! Without scenes: `staircase2`, `living-room` and `cornell-ply`, at 320×180.

use pcbpt::accel::record::{self, Query};
use pcbpt::accel::{Accel, Ray};
use pcbpt::integrator::{Budget, IntegratorKind, RenderOptions, render};
use pcbpt::scene::{LoadOptions, Scene, parse_resolution};
use rayon::prelude::*;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Queries per chunk of a replay (a batch of the batched replay).
const CHUNK: usize = 4096;

struct Args {
    threads: usize,
    spp: u32,
    record_spp: u32,
    rounds: usize,
    resolution: (u32, u32),
    scenes: Vec<PathBuf>,
}

fn usage(message: &str) -> ! {
    eprintln!("ray_bound: {message}");
    eprintln!(
        "usage: ray_bound [--threads N] [--spp N] [--record-spp N] [--rounds N] [--resolution WxH] [SCENE.xml ...]"
    );
    std::process::exit(2)
}

fn parse_args() -> Args {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut args = Args { threads: 2, spp: 16, record_spp: 4, rounds: 5, resolution: (320, 180), scenes: Vec::new() };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = |name: &str| it.next().unwrap_or_else(|| usage(&format!("{name} needs a value")));
        let number = |name: &str, v: String| -> u64 {
            v.parse().ok().filter(|&n| n > 0).unwrap_or_else(|| usage(&format!("{name} needs a positive integer")))
        };
        match a.as_str() {
            "--threads" => args.threads = number("--threads", value("--threads")) as usize,
            "--spp" => args.spp = number("--spp", value("--spp")) as u32,
            "--record-spp" => args.record_spp = number("--record-spp", value("--record-spp")) as u32,
            "--rounds" => args.rounds = number("--rounds", value("--rounds")) as usize,
            "--resolution" => {
                args.resolution = parse_resolution(&value("--resolution")).unwrap_or_else(|e| usage(&e));
            }
            // What `cargo bench` passes to every benchmark.
            "--bench" => {}
            _ if a.starts_with('-') => usage(&format!("unknown option {a}")),
            _ => args.scenes.push(PathBuf::from(a)),
        }
    }
    if args.scenes.is_empty() {
        for s in ["scenes/staircase2/scene.xml", "scenes/living-room/scene.xml", "scenes/cornell-ply/cornell_mi.xml"] {
            args.scenes.push(root.join(s));
        }
    }
    args
}

/// A render's rays per second and samples per second.
fn render_rate(scene: &Scene, spp: u32, threads: usize) -> (f64, f64) {
    let mut opts = RenderOptions::new(IntegratorKind::Path, Budget::Spp(spp));
    opts.run.threads = threads;
    let out = render(scene, &opts).expect("the scene renders");
    let c = &out.stats.counters;
    (c.rays() as f64 / out.stats.seconds, c.samples as f64 / out.stats.seconds)
}

/// The queries of a one-thread render of `spp` samples per pixel, and the render's own count
/// of its rays.
fn record_render(scene: &Scene, spp: u32) -> (Vec<Query>, u64) {
    let mut opts = RenderOptions::new(IntegratorKind::Path, Budget::Spp(spp));
    opts.run.threads = 1;
    record::start();
    let out = render(scene, &opts).expect("the scene renders");
    let log = record::stop();
    (log, out.stats.counters.rays())
}

/// Seconds to answer every query of `log`, one at a time, in chunks spread over the pool's
/// threads.
fn replay_single(pool: &rayon::ThreadPool, accel: &Accel, log: &[Query]) -> f64 {
    let t = Instant::now();
    pool.install(|| {
        log.par_chunks(CHUNK).for_each(|chunk| {
            for q in chunk {
                match q {
                    Query::Intersect(r) => {
                        black_box(accel.intersect(r));
                    }
                    Query::Occluded(r) => {
                        black_box(accel.occluded(r));
                    }
                }
            }
        })
    });
    t.elapsed().as_secs_f64()
}

/// Each chunk's closest-hit and occlusion rays, apart.
fn batches(log: &[Query]) -> Vec<(Vec<Ray>, Vec<Ray>)> {
    log.chunks(CHUNK)
        .map(|chunk| {
            let mut batch = (Vec::new(), Vec::new());
            for q in chunk {
                match *q {
                    Query::Intersect(r) => batch.0.push(r),
                    Query::Occluded(r) => batch.1.push(r),
                }
            }
            batch
        })
        .collect()
}

/// Seconds to answer `batches` through the stream interface, the batches over the threads.
fn replay_batched(pool: &rayon::ThreadPool, accel: &Accel, batches: &[(Vec<Ray>, Vec<Ray>)]) -> f64 {
    let t = Instant::now();
    pool.install(|| {
        batches.par_iter().for_each_init(
            || (Vec::new(), Vec::new()),
            |(hits, blocked), (rays, shadow)| {
                accel.intersect_batch(rays, false, hits);
                accel.occluded_batch(shadow, false, blocked);
                black_box((&hits, &blocked));
            },
        )
    });
    t.elapsed().as_secs_f64()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args = parse_args();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(args.threads).build().expect("a thread pool");
    println!(
        "path tracer, {}x{}, {} spp a render, {} threads, {} rounds alternating (medians); queries of a {}-spp \
         one-thread render replayed",
        args.resolution.0, args.resolution.1, args.spp, args.threads, args.rounds, args.record_spp
    );
    println!(
        "| scene | rays a sample | render: M samples/s | render: M rays/s | replay one at a time: M rays/s | replay \
         batched: M rays/s | render / one at a time | render / batched |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for path in &args.scenes {
        let load = LoadOptions { resolution: Some(args.resolution), ..Default::default() };
        let scene = Scene::load(path, &load).unwrap_or_else(|e| usage(&format!("{}: {e}", path.display())));
        let (log, counted) = record_render(&scene, args.record_spp);
        assert_eq!(
            log.len() as u64,
            counted,
            "{}: the log holds {} queries, the render counted {counted} rays",
            path.display(),
            log.len()
        );
        let batched = batches(&log);
        let (mut render_rays, mut render_samples, mut single, mut batch) = (vec![], vec![], vec![], vec![]);
        for _ in 0..args.rounds {
            let (rays, samples) = render_rate(&scene, args.spp, args.threads);
            render_rays.push(rays);
            render_samples.push(samples);
            single.push(log.len() as f64 / replay_single(&pool, &scene.accel, &log));
            batch.push(log.len() as f64 / replay_batched(&pool, &scene.accel, &batched));
        }
        let samples = args.resolution.0 as f64 * args.resolution.1 as f64 * args.record_spp as f64;
        let (r, s, one, b) = (median(render_rays), median(render_samples), median(single), median(batch));
        let name = path
            .parent()
            .and_then(|p| p.file_name())
            .map_or(path.display().to_string(), |n| n.to_string_lossy().into_owned());
        println!(
            "| {name} | {:.2} | {:.3} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            log.len() as f64 / samples,
            s / 1e6,
            r / 1e6,
            one / 1e6,
            b / 1e6,
            r / one,
            r / b
        );
    }
}
