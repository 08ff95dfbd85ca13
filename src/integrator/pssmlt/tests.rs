//! PSSMLT's tests: two-stage Metropolis' normalisation over its map, and the
//! primary-sample-space sampler (the small step's symmetry, its range, rejected proposals
//! restored).

use crate::integrator::metropolis::bootstrap::bdpt_normalisation;
use crate::integrator::metropolis::primary::{PrimarySampler, perturb};
use crate::integrator::metropolis::two_stage::{Grid, Importance};
use crate::integrator::pssmlt::*;
use crate::sampling::Random;

#[test]
fn two_stage_normalisation_is_the_image_over_the_map() {
    // b' = E[Σ luminance / I(position)] over the bootstrap's samples must be the
    // image's mean of luminance over the map, the image rendered independently (BDPT
    // at 2 048 spp, box filter so that each sample stays in its pixel); a map varying
    // 20-fold across a Cornell box makes the weighting matter, and the plain mean
    // luminance (the map left out) is the negative control.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-ply/cornell_mi.xml");
    let load = crate::scene::LoadOptions { resolution: Some((16, 16)), ..Default::default() };
    let scene = Scene::load(&path, &load).unwrap();
    assert!(matches!(scene.film.filter, crate::film::Filter::Box { radius } if radius <= 0.5));
    let grid = Grid::new(16, 16, 8);
    let pixels = 256.0;
    let sums: Vec<f64> = [1.0, 20.0, 5.0, 0.5].iter().map(|m| m * 64.0 / pixels).collect();
    let map = Importance::from_cells(grid, &sums, 1).unwrap();
    let mut opts = crate::integrator::RenderOptions::new(crate::integrator::IntegratorKind::Bdpt, Budget::Spp(2048));
    opts.run.seed = 3;
    opts.run.threads = 2;
    let image = crate::integrator::render(&scene, &opts).unwrap().image;
    let over_map: f64 = image
        .iter()
        .enumerate()
        .map(|(i, p)| luminance(*p) as f64 / map.pixel(((i % 16) as i32, (i / 16) as i32)) as f64)
        .sum::<f64>()
        / pixels;
    let plain = image.iter().map(|p| luminance(*p) as f64).sum::<f64>() / pixels;
    let pool = crate::workers::render_pool(2).unwrap();
    let key = |s: u64, i: u64| vec![17, s, i];
    let ((b, e), (l, le), _) =
        bdpt_normalisation(&scene, Default::default(), &pool, 400_000, ChainPaths::ALL, Some(&map), &key);
    // The image's own noise (2 048 spp) is far below the bootstrap's.
    assert!((b - over_map).abs() < 4.0 * e + 0.005 * over_map, "b' {b} ± {e} against the image's {over_map}");
    assert!((plain - over_map).abs() > 10.0 * e, "the map must matter here: {plain} against {over_map} ± {e}");
    let ((b0, e0), same, _) =
        bdpt_normalisation(&scene, Default::default(), &pool, 400_000, ChainPaths::ALL, None, &key);
    assert!((b0 - plain).abs() < 4.0 * e0 + 0.005 * plain, "b {b0} ± {e0} against the image's {plain}");
    assert_eq!(same, (b0, e0));
    // The same samples' plain mean luminance, beside b'.
    assert!((l - plain).abs() < 4.0 * le + 0.005 * plain, "mean luminance {l} ± {le} against the image's {plain}");
}

/// Probability mass of landing within `r` of `to` when perturbing `from`, by sampling.
fn mass(from: f32, to: f32, r: f32, n: usize, seed: u64, step: impl Fn(f32, f32) -> f32) -> f64 {
    let mut s = Sampler::new(&[seed]);
    let hits = (0..n)
        .filter(|_| {
            let y = step(from, s.next_1d());
            let d = (y - to).abs();
            d.min(1.0 - d) < r
        })
        .count();
    hits as f64 / n as f64
}

#[test]
fn small_step_is_symmetric() {
    // q(x → y) = q(y → x): the offset's distribution is symmetric and wrapping keeps
    // it so. Compared on pairs at several distances (also across the wrap at 0/1).
    let n = 2_000_000;
    for (x, y) in [(0.3f32, 0.305f32), (0.5, 0.49), (0.995, 0.004), (0.2, 0.21), (0.7, 0.6995)] {
        let a = mass(x, y, 0.0005, n, 1, perturb);
        let b = mass(y, x, 0.0005, n, 2, perturb);
        let sigma = ((a + b) / 2.0 / n as f64).sqrt();
        assert!(a > 0.0 && (a - b).abs() < 5.0 * sigma, "{x} → {y}: {a} vs {b} (σ {sigma})");
    }
    // Negative control: a perturbation that prefers one direction is caught.
    let skewed = |x: f32, u: f32| perturb(x, if u < 0.5 { u } else { 0.5 * u + 0.25 });
    let a = mass(0.3, 0.305, 0.0005, n, 1, skewed);
    let b = mass(0.305, 0.3, 0.0005, n, 2, skewed);
    let sigma = ((a + b) / 2.0 / n as f64).sqrt();
    assert!((a - b).abs() > 5.0 * sigma, "skewed perturbation not caught: {a} vs {b}");
}

#[test]
fn perturbation_stays_in_the_unit_interval() {
    let mut s = Sampler::new(&[3]);
    for x in [0.0f32, 1e-7, 0.5, 0.999_999_9] {
        for _ in 0..10_000 {
            let y = perturb(x, s.next_1d());
            assert!((0.0..1.0).contains(&y), "{x} -> {y}");
        }
    }
}

#[test]
fn rejected_proposals_restore_the_state() {
    let mut p = PrimarySampler::new(&[5], 1e-6);
    p.start_iteration(true);
    let first: Vec<f32> = (0..10).map(|_| p.next_1d()).collect();
    p.accept();
    p.start_iteration(false);
    let _ = (0..10).map(|_| p.next_1d()).collect::<Vec<_>>();
    p.reject();
    // Reading again in a rejected iteration's place: a fresh proposal, but the
    // restored values are what it perturbs (all within the small-step reach).
    p.start_iteration(false);
    assert!(!p.is_large_step());
    for (i, v) in (0..10).map(|_| p.next_1d()).enumerate() {
        let d = (v - first[i]).abs();
        assert!(d.min(1.0 - d) <= 1.0 / 64.0 + 1e-6, "coordinate {i}: {} -> {v}", first[i]);
    }
}
