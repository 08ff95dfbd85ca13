//! What directional guiding can gain at a path's vertices: the variance of the path
//! tracer's one-sample estimate of the light a vertex reflects, split into the part the
//! choice of direction makes (what a guiding distribution can remove) and the part the
//! radiance estimate along each direction carries (what it cannot).
//!
//! For each scene a guided render's tree is trained (`--passes`, the training of a render
//! of twice their sum), and vertices are picked at random: a camera ray through a random
//! pixel, continued by BSDF sampling to its `k`-th surface vertex (`--depths`), on a
//! non-Dirac surface that is no light. At each, `--directions` uniform directions `ω` of the
//! sphere each get the path tracer's estimate `L̂(ω)` of the radiance arriving along them,
//! and the integrand `ĝ = f(ω) |cos θ| L̂(ω)`. From these, for a sampling density `q`, the
//! relative variance of the one-sample estimate `ĝ / q`:
//! - `bsdf`: `q` the BSDF's (the path tracer);
//! - `mixture`: the guided path tracer's, the trained tree's with the BSDF fraction its leaf
//!   learnt;
//! - `radiance mixture`: half BSDF, half a density proportional to `L̄`, the mean of `L̂`
//!   over each of `--cells` × `--cells` cells of directions at this very point: the best a
//!   guide of incident radiance (what the tree learns) can do in a half-BSDF mixture;
//! - `product mixture`: half BSDF, half a density proportional to `f |cos θ| L̄`.
//!
//! The cells' means come from half of the directions and the variances from the other half,
//! so that the ideal densities are not fitted to the samples they are judged on. It prints,
//! per depth, the medians over the vertices of these relative variances and of the gains
//! (the BSDF's variance over each density's).
//!
//! ```sh
//! cargo bench --profile release --bench guiding_bound -- \
//!     [--resolution WxH] [--passes 1,2,4,...] [--vertices N] [--directions N] [--depths 1,2,3] \
//!     [--cells N] [--spatial-threshold C] [SCENE.xml ...]
//! ```
//! Without scenes: `veach-ajar` and `sunlit-room`, at 320×180.

use glam::{Vec2, Vec3};
use pcbpt::bsdf::TransportMode;
use pcbpt::integrator::guided::sdtree::{from_square, sphere_pdf, to_square};
use pcbpt::integrator::guided::{GuidedOptions, train_tree};
use pcbpt::integrator::path::PathTracer;
use pcbpt::integrator::stats::Counters;
use pcbpt::sampling::Sampler;

use pcbpt::scene::shape::SurfaceInteraction;
use pcbpt::scene::{LoadOptions, Scene, parse_resolution};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

struct Args {
    resolution: (u32, u32),
    passes: Vec<u32>,
    vertices: usize,
    directions: usize,
    depths: Vec<u32>,
    /// Cells of directions per side of the unit square, for the ideal densities.
    cells: usize,
    /// The tree's spatial threshold (`--guided-spatial-threshold`).
    spatial_threshold: f64,
    scenes: Vec<PathBuf>,
}

fn usage(message: &str) -> ! {
    eprintln!("guiding_bound: {message}");
    eprintln!(
        "usage: guiding_bound [--resolution WxH] [--passes 1,2,4,...] [--vertices N] [--directions N] [--depths 1,2,3] [--cells N] [--spatial-threshold C] [SCENE.xml ...]"
    );
    std::process::exit(2)
}

fn list(name: &str, v: &str) -> Vec<u32> {
    v.split(',')
        .map(|x| {
            x.trim().parse().ok().filter(|&n| n > 0).unwrap_or_else(|| usage(&format!("{name}: bad number {x:?}")))
        })
        .collect()
}

/// The one positive number `v` gives.
fn one(name: &str, v: &str) -> u32 {
    match list(name, v)[..] {
        [n] => n,
        _ => usage(&format!("{name} takes one number, not {v:?}")),
    }
}

fn parse_args() -> Args {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut args = Args {
        resolution: (320, 180),
        passes: vec![1, 2, 4, 8, 16, 32, 64],
        vertices: 24,
        directions: 100_000,
        depths: vec![1, 2, 3],
        cells: 32,
        spatial_threshold: GuidedOptions::default().spatial_threshold,
        scenes: Vec::new(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = |name: &str| it.next().unwrap_or_else(|| usage(&format!("{name} needs a value")));
        match a.as_str() {
            "--bench" => {}
            "--resolution" => {
                args.resolution = parse_resolution(&value("--resolution")).unwrap_or_else(|e| usage(&e.to_string()))
            }
            "--passes" => args.passes = list("--passes", &value("--passes")),
            "--depths" => args.depths = list("--depths", &value("--depths")),
            "--vertices" => args.vertices = one("--vertices", &value("--vertices")) as usize,
            "--directions" => args.directions = one("--directions", &value("--directions")) as usize,
            "--cells" => args.cells = one("--cells", &value("--cells")) as usize,
            "--spatial-threshold" => {
                args.spatial_threshold = one("--spatial-threshold", &value("--spatial-threshold")) as f64
            }
            s if s.starts_with("--") => usage(&format!("unknown option {s}")),
            s => args.scenes.push(PathBuf::from(s)),
        }
    }
    if args.scenes.is_empty() {
        args.scenes =
            ["veach-ajar/scene.xml", "sunlit-room/scene.xml"].iter().map(|s| root.join("scenes").join(s)).collect();
    }
    args
}

/// A surface vertex: the `depth`-th of a camera ray through a random pixel continued by BSDF
/// sampling, where it is on a non-Dirac surface that is no light.
fn vertex(scene: &Scene, depth: u32, rng: &mut Sampler) -> Option<(SurfaceInteraction, Vec3)> {
    let film = Vec2::new(scene.film.width as f32, scene.film.height as f32);
    let mut ray = scene.camera.generate_ray(rng.next_2d() * film);
    for k in 1..=depth {
        let si = scene.intersect(&ray)?;
        let bsdf = scene.bsdf(&si);
        let wo = si.shading.to_local(si.wo);
        if k == depth {
            return (!bsdf.is_delta() && scene.area_light(&si).is_none()).then_some((si, wo));
        }
        let bs = bsdf.sample(wo, si.at(), rng.next_1d(), rng.next_2d(), TransportMode::Radiance)?;
        ray = si.spawn_ray(si.shading.to_world(bs.wi));
    }
    None
}

/// Relative variances at one vertex: BSDF, mixture, ideal radiance mixture, ideal product
/// mixture.
fn variances(
    scene: &Scene,
    pt: &PathTracer,
    tree: &pcbpt::integrator::guided::sdtree::SdTree,
    (si, wo): &(SurfaceInteraction, Vec3),
    directions: usize,
    cells_per_side: usize,
    seed: u64,
) -> Option<[f64; 4]> {
    let bsdf = scene.bsdf(si);
    let leaf = tree.leaf_at(si.p);
    let guide = tree.guide_in(leaf);
    // The fraction the leaf learnt (the default options learn one), else the default's.
    let a = tree.bsdf_fraction_in(leaf, GuidedOptions::default().bsdf_fraction) as f64;
    let mut rng = Sampler::new(&[seed, 0x6775_6964]);
    let mut counters = Counters::default();
    let u = 1.0 / (4.0 * PI);
    // (cell, ĝ, f |cos θ|, BSDF density, tree density) of each direction.
    let mut samples = Vec::with_capacity(directions);
    let side = cells_per_side as f32;
    for _ in 0..directions {
        let square = rng.next_2d();
        let d = from_square(square);
        let wi = si.shading.to_local(d);
        let cell = (square.x * side) as usize + cells_per_side * (square.y * side) as usize;
        let fc = bsdf.eval(*wo, wi, si.at(), TransportMode::Radiance) * wi.z.abs();
        let fc = ((fc.x + fc.y + fc.z) / 3.0) as f64;
        let l = if fc > 0.0 { pt.li(scene, si.spawn_ray(d), &mut rng, &mut counters) } else { Vec3::ZERO };
        let l = ((l.x + l.y + l.z) / 3.0) as f64;
        let p_bsdf = bsdf.pdf(*wo, wi, si.at(), TransportMode::Radiance) as f64;
        let p_tree = guide.map_or(p_bsdf, |g| sphere_pdf(g.pdf(to_square(d))) as f64);
        samples.push((cell, fc * l, fc, p_bsdf, p_tree));
    }
    // The cells' means from the even directions; the variances from the odd ones, so that
    // the ideal density is not fitted to the samples it is judged on.
    let mut cells = vec![(0.0f64, 0u32); cells_per_side * cells_per_side];
    for (i, &(cell, g, fc, _, _)) in samples.iter().enumerate() {
        if i % 2 == 0 && fc > 0.0 {
            cells[cell].0 += g / fc;
            cells[cell].1 += 1;
        }
    }
    let mean_l: Vec<f64> = cells.iter().map(|&(s, n)| if n > 0 { s / n as f64 } else { 0.0 }).collect();
    let (even, odd): (Vec<_>, Vec<_>) = samples.iter().enumerate().partition(|(i, _)| i % 2 == 0);
    let ideal_norm: f64 = even.iter().map(|(_, s)| s.2 * mean_l[s.0] / u).sum::<f64>() / even.len() as f64;
    let radiance_norm: f64 = even.iter().map(|(_, s)| mean_l[s.0] / u).sum::<f64>() / even.len() as f64;
    let n = odd.len() as f64;
    let mean: f64 = odd.iter().map(|(_, s)| s.1 / u).sum::<f64>() / n;
    if !(mean > 0.0 && ideal_norm > 0.0) {
        return None;
    }
    let mut m = [0.0f64; 4];
    for &(_, &(cell, g, fc, p_bsdf, p_tree)) in &odd {
        if g == 0.0 {
            continue;
        }
        let ideal = fc * mean_l[cell] / ideal_norm;
        let radiance = mean_l[cell] / radiance_norm;
        let q = [p_bsdf, a * p_bsdf + (1.0 - a) * p_tree, 0.5 * p_bsdf + 0.5 * radiance, 0.5 * p_bsdf + 0.5 * ideal];
        for (m, q) in m.iter_mut().zip(q) {
            *m += if q > 0.0 { g * g / (q * u) } else { f64::INFINITY };
        }
    }
    Some(m.map(|m| m / n / (mean * mean) - 1.0))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() { f64::NAN } else { v[v.len() / 2] }
}

fn main() {
    let args = parse_args();
    let load = LoadOptions { resolution: Some(args.resolution), ..Default::default() };
    for path in &args.scenes {
        let scene = Scene::load(path, &load).unwrap_or_else(|e| usage(&format!("{}: {e}", path.display())));
        let options = GuidedOptions { spatial_threshold: args.spatial_threshold, ..GuidedOptions::default() };
        let tree = train_tree(&scene, &options, &args.passes, 1).unwrap_or_else(|e| usage(&e.to_string()));
        let pt = PathTracer::new(&scene.integrator);
        println!(
            "{} ({}×{}, tree of passes {:?}: {} spatial leaves; {} vertices per depth, {} directions each)",
            path.display(),
            args.resolution.0,
            args.resolution.1,
            args.passes,
            tree.leaves.len(),
            args.vertices,
            args.directions
        );
        println!(
            "depth | relvar: bsdf | mixture | radiance mixture | product mixture | gain: mixture | radiance mixture | product mixture"
        );
        for &depth in &args.depths {
            let mut rng = Sampler::new(&[depth as u64, 17]);
            // At most a thousand tries per vertex wanted: a scene whose paths rarely reach
            // this depth on a surface that could be guided is said so, not waited on.
            let tries = 1000 * args.vertices;
            let picked: Vec<_> =
                (0..tries).filter_map(|_| vertex(&scene, depth, &mut rng)).take(args.vertices).collect();
            if picked.len() < args.vertices {
                usage(&format!(
                    "{}: only {} of {tries} camera paths reach a non-Dirac surface at depth {depth}",
                    path.display(),
                    picked.len()
                ));
            }
            let results: Vec<[f64; 4]> = picked
                .par_iter()
                .enumerate()
                .filter_map(|(i, v)| variances(&scene, &pt, &tree, v, args.directions, args.cells, i as u64))
                .collect();
            let column = |k: usize| median(results.iter().map(|r| r[k]).collect());
            let gain = |k: usize| median(results.iter().map(|r| r[0] / r[k]).collect());
            println!(
                "{depth} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2}",
                column(0),
                column(1),
                column(2),
                column(3),
                gain(1),
                gain(2),
                gain(3)
            );
        }
    }
}
