//! Measures how well candidate estimates of a render's relMSE, computed from groups of its
//! own iterations, track the relMSE measured against a reference: the study behind
//! `src/integrator/noise.rs` (`docs/results/noise.md`).
//!
//! ```sh
//! cargo run --profile ci --example noise_estimate -- veach-ajar path 64,256 0,1,2,3
//! ```
//!
//! Arguments: the scene (`cornell-ply` or `veach-ajar`), the integrator, the sample counts
//! to report (ascending) and the seeds. Each iteration is rendered on its own
//! ([`pcbpt::integrator::render_iterations`]) and its film added to group `i mod 8`, so that
//! the estimates from 2 groups (the render's halves) and 8 of one render can be set side by
//! side. Prints one
//! line per seed and sample count, then each estimate's mean ratio to the measured relMSE.

use std::path::PathBuf;

use pcbpt::compare::RELMSE_EPSILON;
use pcbpt::film::Film;
use pcbpt::image_io::{self, Image};
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions, noise};
use pcbpt::math::Rgb;
use pcbpt::scene::{LoadOptions, Scene};

/// Groups of iterations each render keeps.
const GROUPS: usize = 8;

/// A shipped scene and its reference.
fn scene(name: &str) -> (Scene, Image) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let (file, defines, reference): (&str, &[(&str, &str)], &str) = match name {
        "cornell-ply" => {
            ("scenes/cornell-ply/cornell_mi.xml", &[], "cornell-ply_mitsuba3-path_4096spp_maxdepth8_box.exr")
        }
        "veach-ajar" => {
            ("scenes/veach-ajar/scene.xml", &[("resx", "160"), ("resy", "90"), ("max_depth", "-1")], "veach-ajar.exr")
        }
        _ => panic!("unknown scene {name}"),
    };
    let overrides = defines.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
    let scene = Scene::load(&root.join(file), &LoadOptions { overrides, ..Default::default() })
        .unwrap_or_else(|e| panic!("{e}"));
    let reference = image_io::read_exr(&root.join("tests/data").join(reference)).unwrap_or_else(|e| panic!("{e}"));
    (scene, reference)
}

/// The relMSE of `image` against `reference`, per channel.
fn measured(image: &[Rgb], reference: &Image) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (t, r) in image.iter().zip(&reference.pixels) {
        for c in 0..3 {
            let (t, r) = (t[c] as f64, r[c] as f64);
            sum += (t - r).powi(2) / (r * r + RELMSE_EPSILON);
        }
        n += 3;
    }
    sum / n as f64
}

/// The developed images of `k` groups (iterations `i mod k`) from the eight kept ones.
fn groups(films: &[Film], k: usize) -> Vec<Vec<Rgb>> {
    (0..k)
        .map(|g| {
            let mut f = films[g].clone();
            for other in (g + k..GROUPS).step_by(k) {
                f.merge_film(&films[other]);
            }
            f.develop()
        })
        .collect()
}

/// Per pixel and channel of `k` group images: their mean, the estimated variance of that
/// mean, and their median.
struct Stats {
    mean: Vec<[f64; 3]>,
    var: Vec<[f64; 3]>,
    median: Vec<[f64; 3]>,
}

fn stats(g: &[Vec<Rgb>]) -> Stats {
    let k = g.len() as f64;
    let n = g[0].len();
    let mut s = Stats { mean: vec![[0.0; 3]; n], var: vec![[0.0; 3]; n], median: vec![[0.0; 3]; n] };
    for p in 0..n {
        for c in 0..3 {
            let mut v: Vec<f64> = g.iter().map(|img| img[p][c] as f64).collect();
            let m = v.iter().sum::<f64>() / k;
            s.mean[p][c] = m;
            s.var[p][c] = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (k * (k - 1.0));
            v.sort_by(f64::total_cmp);
            s.median[p][c] =
                if v.len().is_multiple_of(2) { 0.5 * (v[v.len() / 2 - 1] + v[v.len() / 2]) } else { v[v.len() / 2] };
        }
    }
    s
}

/// The mean of `image` over the `(2r+1)² − 1` pixels around each pixel, the pixel left out.
fn around(image: &[[f64; 3]], w: usize, h: usize, r: i64) -> Vec<[f64; 3]> {
    let mut out = vec![[0.0; 3]; w * h];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let (mut sum, mut n) = ([0.0; 3], 0.0);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (xx, yy) = (x + dx, y + dy);
                    if (dx, dy) != (0, 0) && xx >= 0 && yy >= 0 && xx < w as i64 && yy < h as i64 {
                        let v = image[(yy * w as i64 + xx) as usize];
                        for c in 0..3 {
                            sum[c] += v[c];
                        }
                        n += 1.0;
                    }
                }
            }
            out[(y * w as i64 + x) as usize] = sum.map(|s| s / n);
        }
    }
    out
}

/// The mean of `image` over the `(2r+1)²` pixels around each pixel, the pixel included.
fn mean_box(image: &[[f64; 3]], w: usize, h: usize, r: i64) -> Vec<[f64; 3]> {
    let around = around(image, w, h, r);
    (0..w * h)
        .map(|p| {
            let (x, y) = ((p % w) as i64, (p / w) as i64);
            let side = |v: i64, n: usize| ((v + r).min(n as i64 - 1) - (v - r).max(0) + 1) as f64;
            let n = side(x, w) * side(y, h);
            [0, 1, 2].map(|c| (around[p][c] * (n - 1.0) + image[p][c]) / n)
        })
        .collect()
}

/// Mean of `var / (den + ε)` over pixels and channels.
fn estimate(var: &[[f64; 3]], den: impl Fn(usize, usize) -> f64) -> f64 {
    let mut sum = 0.0;
    for (p, v) in var.iter().enumerate() {
        for (c, v) in v.iter().enumerate() {
            sum += v / (den(p, c).max(0.0) + RELMSE_EPSILON);
        }
    }
    sum / (3 * var.len()) as f64
}

/// The candidate estimates of the render whose eight group films are `films`, each the mean
/// of `variance / (den + ε)`: the variance from 2 or 8 groups, the denominator from the
/// reference (what the estimate would be if it knew the image), from the pixel itself, or
/// from its neighbours (what `--noise-threshold` uses: [`noise::relmse_estimate`]).
fn candidates(films: &[Film], w: usize, h: usize, reference: &Image) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    let r: Vec<[f64; 3]> = reference.pixels.iter().map(|p| [p.x as f64, p.y as f64, p.z as f64]).collect();
    let s8 = stats(&groups(films, 8));
    out.push(("8 groups, reference I²".to_string(), estimate(&s8.var, |p, c| r[p][c].powi(2))));
    let ra = around(&r, w, h, 3);
    out.push(("8 groups, reference's 7×7 around²".to_string(), estimate(&s8.var, |p, c| ra[p][c].powi(2))));
    out.push(("8 groups, F² − Var".to_string(), estimate(&s8.var, |p, c| s8.mean[p][c].powi(2) - s8.var[p][c])));
    out.push(("8 groups, median²".to_string(), estimate(&s8.var, |p, c| s8.median[p][c].powi(2))));
    let g = groups(films, 2);
    let s2 = stats(&g);
    out.push(("halves, own A·B".to_string(), estimate(&s2.var, |p, c| g[0][p][c] as f64 * g[1][p][c] as f64)));
    out.push(("halves, own F²".to_string(), estimate(&s2.var, |p, c| s2.mean[p][c].powi(2))));
    let as_f64 = |img: &Vec<Rgb>| img.iter().map(|p| [p.x as f64, p.y as f64, p.z as f64]).collect::<Vec<_>>();
    let (a, b) = (as_f64(&g[0]), as_f64(&g[1]));
    let mean: Vec<[f64; 3]> = a.iter().zip(&b).map(|(a, b)| [0, 1, 2].map(|c| 0.5 * (a[c] + b[c]))).collect();
    let (ma, mb) = (mean_box(&a, w, h, 3), mean_box(&b, w, h, 3));
    out.push(("halves, 7×7 box Ā·B̄ (pixel in)".to_string(), estimate(&s2.var, |p, c| ma[p][c] * mb[p][c])));
    let fa = around(&mean, w, h, 3);
    out.push(("halves, 7×7 around F̄²".to_string(), estimate(&s2.var, |p, c| fa[p][c].powi(2))));
    let (na, nb) = (around(&a, w, h, 3), around(&b, w, h, 3));
    out.push(("8 groups, 7×7 around Ā·B̄".to_string(), estimate(&s8.var, |p, c| na[p][c] * nb[p][c])));
    for radius in [1, 2, 4] {
        let (na, nb) = (around(&a, w, h, radius), around(&b, w, h, radius));
        let name = format!("halves, {0}×{0} around Ā·B̄", 2 * radius + 1);
        out.push((name, estimate(&s2.var, |p, c| na[p][c] * nb[p][c])));
    }
    let var: Vec<Rgb> = s2.var.iter().map(|v| Rgb::new(v[0] as f32, v[1] as f32, v[2] as f32)).collect();
    out.push(("halves, 7×7 around Ā·B̄ (the render's)".to_string(), noise::relmse_estimate(&g[0], &g[1], &var, w)));
    out
}

/// One render of `spps.last()` samples per pixel: at each of `spps`, the measured relMSE and
/// the candidates.
fn render_seed(scene: &Scene, reference: &Image, kind: IntegratorKind, spps: &[u64], seed: u64) -> Vec<Row> {
    let (w, h) = (scene.film.width as usize, scene.film.height as usize);
    let last = *spps.last().unwrap() as u32;
    let mut opts = RenderOptions::new(kind, Budget::Spp(last));
    opts.run.seed = seed;
    opts.run.threads = 2;
    let mut films: Vec<Film> = (0..GROUPS).map(|_| Film::new(w as u32, h as u32, scene.film.filter)).collect();
    let mut rows = Vec::new();
    for i in 0..last {
        let out = integrator::render_iterations(scene, &opts, Some(i..i + 1)).unwrap_or_else(|e| panic!("{e}"));
        films[i as usize % GROUPS].merge_film(&out.film.expect("an iterative render keeps its film"));
        if spps.contains(&(i as u64 + 1)) {
            let mut all = films[0].clone();
            films[1..].iter().for_each(|f| all.merge_film(f));
            let measured = measured(&all.develop(), reference);
            rows.push(Row { spp: i + 1, measured, candidates: candidates(&films, w, h, reference) });
        }
    }
    rows
}

/// What [`render_seed`] gives at one sample count.
struct Row {
    spp: u32,
    measured: f64,
    candidates: Vec<(String, f64)>,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [name, kind, spps, seeds] = &args[..] else {
        panic!("usage: noise_estimate SCENE INTEGRATOR SPP,SPP… SEED,SEED…");
    };
    let kind = integrator::registry::INTEGRATORS
        .iter()
        .map(|r| r.kind)
        .find(|k| k.name() == kind)
        .unwrap_or_else(|| panic!("unknown integrator {kind}"));
    let list = |s: &str| s.split(',').map(|x| x.parse::<u64>().unwrap()).collect::<Vec<_>>();
    let (spps, seeds) = (list(spps), list(seeds));
    let (scene, reference) = scene(name);
    let mut ratios: Vec<(String, Vec<f64>)> = Vec::new();
    for &seed in &seeds {
        for row in render_seed(&scene, &reference, kind, &spps, seed) {
            let m = row.measured;
            let (old, new) = (&row.candidates[4], row.candidates.last().unwrap());
            println!(
                "{name} {} seed {seed} spp {}: measured {m:.4}, estimate {:.4} (own A·B: {:.4})",
                kind.name(),
                row.spp,
                new.1,
                old.1
            );
            for (n, e) in row.candidates {
                let key = format!("spp {}: {n}", row.spp);
                match ratios.iter_mut().find(|(k, _)| *k == key) {
                    Some((_, v)) => v.push(e / m),
                    None => ratios.push((key, vec![e / m])),
                }
            }
        }
    }
    println!("estimate / measured, mean over seeds (lowest, highest):");
    for (k, v) in ratios {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let (lo, hi) = v.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        println!("{k}: {mean:.3} ({lo:.3}, {hi:.3})");
    }
}
