//! The chains' densities against what they sample: the importance-sampling identity
//! `E[f(y) / T(y)] = ∫ f` for the whole-path generator and for the bidirectional mutation
//! from a fixed path, against BDPT's estimate of the same integral, each with a skewed
//! density the check must reject; and every mutator's detailed balance, `E[r] = P(r > 0)`
//! for `x ∼ π`, on the glass ball's scene.

use crate::integrator::bidir::VertexKind;
use crate::integrator::memlt::*;
use crate::integrator::metropolis::bootstrap::ChainPaths;

/// A scene of the repository with `-D` style overrides.
pub(super) fn scene(file: &str, overrides: &[(&str, &str)]) -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
    let overrides = overrides.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
    Scene::load(&path, &crate::scene::LoadOptions { overrides, ..Default::default() }).unwrap()
}

fn cornell() -> Scene {
    scene("scenes/cornell-ply/cornell_mi.xml", &[("resx", "24"), ("resy", "24"), ("max_depth", "4")])
}

/// Mean and standard error of `n` values from `f(i)`.
pub(super) fn mean_and_error(n: usize, f: impl Fn(usize) -> f64 + Sync) -> (f64, f64) {
    let (s, s2) = (0..n)
        .into_par_iter()
        .map(|i| {
            let v = f(i);
            (v, v * v)
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let m = s / n as f64;
    (m, ((s2 / n as f64 - m * m) / n as f64).sqrt())
}

/// BDPT's estimate of the luminance of `paths` (the bootstrap's, `n` samples of stream
/// `seed`), with its standard error.
pub(super) fn bootstrap_estimate(scene: &Scene, paths: ChainPaths, (seed, n): (u64, usize)) -> (f64, f64) {
    let heuristic = MemltOptions::default().heuristic;
    let pool = crate::workers::render_pool(2).unwrap();
    crate::integrator::metropolis::bootstrap::bdpt_normalisation(scene, heuristic, &pool, n, paths, None, &|s, i| {
        vec![seed, s, i]
    })
    .0
}

/// BDPT's estimate of the luminance of paths of at least `min` edges.
pub(super) fn bdpt_reference(scene: &Scene, min: usize) -> f64 {
    bootstrap_estimate(scene, ChainPaths { min_edges: min, ..ChainPaths::ALL }, (11, 400_000)).0
}

/// The start paths' generator restricted to `lengths` (`Lengths::covers`): the mean of
/// `f / p` over `n` draws of stream `seed`, with its standard error; every path it gives
/// must be one of the chains' and pass `check`.
fn chains_estimate(
    scene: &Scene,
    lengths: Lengths,
    (seed, n): (u64, usize),
    check: impl Fn(&[Vertex]) -> bool + Sync,
) -> (f64, f64) {
    let uniform = Strategies::uniform(lengths);
    mean_and_error(n, |i| {
        let mut rng = Sampler::new(&[seed, i as u64]);
        let Some((y, m, p)) = independent_path(scene, lengths, &uniform, &mut rng, &mut Counters::default()) else {
            return 0.0;
        };
        assert!(lengths.covers(&y) && check(&y));
        scalar(&m) / p
    })
}

/// `|a - b|` in standard errors.
pub(super) fn sigmas(a: (f64, f64), b: f64) -> f64 {
    (a.0 - b).abs() / a.1
}

/// The whole-path generator's `f / p` over `n` paths (streams `[seed, i]`) against BDPT's
/// estimate of the same integral: within 4 standard errors, the error under 2% of it. With
/// each path's density replaced by `skew(path, p)` (the negative control, `control` naming
/// it) it must land more than 6 standard errors away.
pub(super) fn generator_matches_bdpt(
    scene: &Scene,
    strategies: &Strategies,
    (seed, n): (u64, usize),
    skew: impl Fn(&[Vertex], f64) -> f64 + Sync,
    what: &str,
    control: &str,
) {
    let lengths = lengths(scene);
    let b = bdpt_reference(scene, lengths.min);
    let run = |skewed: bool| {
        mean_and_error(n, |i| {
            let mut rng = Sampler::new(&[seed, i as u64]);
            let Some((y, m, p)) = independent_path(scene, lengths, strategies, &mut rng, &mut Counters::default())
            else {
                return 0.0;
            };
            let p = if skewed { skew(&y, p) } else { p };
            if p > 0.0 { scalar(&m) / p } else { 0.0 }
        })
    };
    let good = run(false);
    assert!(sigmas(good, b) < 4.0 && good.1 < 0.02 * b, "{what}: {good:?} against BDPT's {b}");
    let skewed = run(true);
    assert!(sigmas(skewed, b) > 6.0, "{control} was not caught: {skewed:?} against {b}");
}

#[test]
fn whole_path_density_is_what_the_generator_samples() {
    let scene = cornell();
    let lengths = lengths(&scene);
    // A density that forgets the other splits: the light walk's alone.
    let light_walk = |y: &[Vertex], _| {
        let k = y.len() - 1;
        seed_length_pmf(lengths, k) * (0..k).map(|j| path::pdf_from_light(&scene, y, j)).product::<f64>()
    };
    let uniform = Strategies::uniform(lengths);
    generator_matches_bdpt(
        &scene,
        &uniform,
        (3, 300_000),
        light_walk,
        "whole paths",
        "a density without the other splits",
    );
}

/// A generator far from the start paths' (long paths and late splits favoured), as the
/// independent mutation's learned one is: `found[k][s] ∝ (s + 1)² k`, a fifth uniform.
fn skewed_strategies(lengths: Lengths) -> Strategies {
    let found: Vec<Vec<f64>> =
        (lengths.min..=lengths.max).map(|k| (0..=k).map(|s| ((s + 1) * (s + 1) * k) as f64).collect()).collect();
    Strategies::learned(lengths, &found, 0.2)
}

#[test]
fn learned_strategies_sample_their_probabilities_chi2() {
    use crate::sampling::chi2::discrete_chi2;
    let lengths = Lengths { min: 2, max: 7, direct_separate: false, specular_separate: false };
    let strategies = skewed_strategies(lengths);
    let cells: Vec<(usize, usize)> = (lengths.min..=lengths.max).flat_map(|k| (0..=k).map(move |s| (k, s))).collect();
    let total: f64 = cells.iter().map(|&(k, s)| strategies.probability(k, s)).sum();
    assert!((total - 1.0).abs() < 1e-12, "the probabilities sum to {total}");
    let n = 400_000u64;
    let mut counts = vec![0u64; cells.len()];
    let mut rng = Sampler::new(&[17]);
    for _ in 0..n {
        let ks = strategies.sample(rng.next_1d() as f64, rng.next_1d());
        counts[cells.iter().position(|&c| c == ks).expect("a length and split of the table")] += 1;
    }
    let expected: Vec<f64> = cells.iter().map(|&(k, s)| strategies.probability(k, s) * n as f64).collect();
    discrete_chi2(&counts, &expected).assert_pass();
    // Negative control: the start paths' probabilities are rejected.
    let uniform = Strategies::uniform(lengths);
    let wrong: Vec<f64> = cells.iter().map(|&(k, s)| uniform.probability(k, s) * n as f64).collect();
    assert!(!discrete_chi2(&counts, &wrong).passed(), "the uniform generator's probabilities were not rejected");
    // Nothing found: the start paths' generator; everything defensive: the same.
    let none = Strategies::learned(lengths, &[], 0.2);
    let all = Strategies::learned(lengths, &[vec![1.0; 3]], 1.0);
    for (k, s) in cells {
        assert_eq!(none.probability(k, s), uniform.probability(k, s));
        assert_eq!(all.probability(k, s), uniform.probability(k, s));
    }
}

#[test]
fn whole_path_density_follows_learned_strategies() {
    // The independent mutation's generator, with lengths and splits far from uniform: its
    // `f / p` still averages to BDPT's estimate; a density that keeps the uniform
    // generator's probabilities must be caught.
    let scene = cornell();
    let lengths = lengths(&scene);
    let skewed = skewed_strategies(lengths);
    let uniform = Strategies::uniform(lengths);
    let as_uniform = |y: &[Vertex], _| whole_path_density(&scene, &uniform, y);
    generator_matches_bdpt(&scene, &skewed, (4, 300_000), as_uniform, "learned strategies", "the uniform density");
}

#[test]
fn whole_path_density_holds_with_camera_walks_to_the_light() {
    // Half the draws camera walks that go on until they find the light (paths of every
    // length): `f / p` still averages to BDPT's estimate; a density that leaves the walks
    // out (the lengths' and splits' share alone) must be caught.
    let scene = cornell();
    let lengths = lengths(&scene);
    let walks = skewed_strategies(lengths).with_camera_walks(0.5);
    let splits = skewed_strategies(lengths);
    let without = |y: &[Vertex], _| 0.5 * whole_path_density(&scene, &splits, y);
    generator_matches_bdpt(
        &scene,
        &walks,
        (5, 300_000),
        without,
        "camera walks to the light",
        "a density without them",
    );
}

#[test]
fn camera_walks_stop_at_the_first_light() {
    // Every walk ends on the light or the sky it found first, with no interior vertex on an
    // emitter; its density is the camera-only split's.
    let scene = cornell();
    let lengths = lengths(&scene);
    let mut found = 0;
    for i in 0..20_000u64 {
        let mut rng = Sampler::new(&[31, i]);
        let Some(y) = path::camera_walk_to_light(&scene, lengths.max, &mut rng, &mut Counters::default()) else {
            continue;
        };
        found += 1;
        assert!(matches!(y[0].kind, VertexKind::Light(_)));
        assert!(y.len() - 1 <= lengths.max && path::walks_to_light(&scene, &y));
        assert_eq!(y.last().map(|v| v.kind), Some(VertexKind::Camera));
    }
    // About 3% of them find the small light within the depth of 4.
    assert!(found > 300, "only {found} walks found the light");
}

/// A current path of three edges (light, two surfaces, pinhole).
fn three_edges(scene: &Scene, lengths: Lengths) -> Vec<Vertex> {
    (0..)
        .find_map(|i| {
            let mut rng = Sampler::new(&[5, i]);
            let (y, _, _) =
                independent_path(scene, lengths, &Strategies::uniform(lengths), &mut rng, &mut Counters::default())?;
            (y.len() == 4 && y[1].kind == VertexKind::Surface).then_some(y)
        })
        .unwrap()
}

#[test]
fn bidirectional_density_is_what_the_mutation_samples() {
    // The proposals that replace every vertex but the pinhole sample all of path space:
    // their `f / T(x → y)` averages (over all proposals, others counting zero) to BDPT's
    // estimate of the image's luminance. The deletion's and the length's probabilities
    // enter `T`; forgetting the place of the deletion must be caught.
    let scene = cornell();
    let lengths = lengths(&scene);
    let b = bdpt_reference(&scene, lengths.min);
    let x = three_edges(&scene, lengths);
    let k = x.len() - 1;
    let n = 400_000;
    let run = |skew: bool| {
        mean_and_error(n, |i| {
            let mut rng = Sampler::new(&[7, i as u64]);
            let Some(p) = bidirectional::propose(&scene, &x, lengths, &mut rng, &mut Counters::default()) else {
                return 0.0;
            };
            let y = &p.path;
            let whole = y[0].p != x[0].p && y[y.len() - 2].p != x[k - 1].p;
            let t = if skew { p.forward * (k + 1) as f64 } else { p.forward };
            if whole && t > 0.0 { scalar(&p.measured) / t } else { 0.0 }
        })
    };
    let good = run(false);
    assert!(sigmas(good, b) < 4.0 && good.1 < 0.03 * b, "bidirectional mutation: {good:?} against BDPT's {b}");
    let skewed = run(true);
    assert!(sigmas(skewed, b) > 6.0, "a skewed proposal density was not caught: {skewed:?} against {b}");
}

#[test]
fn regenerated_stretch_density_sums_its_splits() {
    // Between kept ends (the light point and the pinhole of a fixed path), the stretch of
    // two vertices regenerated with a uniform split has density `stretch_density`; its
    // `f / p` must average to what the light walk alone (one split, its own density)
    // estimates of the same integral. A sum that leaves out the camera walk's split is
    // caught.
    let scene = cornell();
    let lengths = lengths(&scene);
    let x = three_edges(&scene, lengths);
    let (prefix, suffix) = (&x[..1], &x[3..]);
    let n = 400_000;
    let estimate = |mode: u8| {
        mean_and_error(n, |i| {
            let mut rng = Sampler::new(&[9, i as u64]);
            let mut c = Counters::default();
            let s = if mode == 1 { 2 } else { ((rng.next_1d() * 3.0) as usize).min(2) };
            let Some(y) = path::regenerate(&scene, prefix, suffix, s, 2 - s, &mut rng, &mut c) else { return 0.0 };
            let Some(m) = path::contribution(&scene, &y) else { return 0.0 };
            let p = match mode {
                1 => path::pdf_from_light(&scene, &y, 1) * path::pdf_from_light(&scene, &y, 2),
                2 => {
                    // Skewed: the split `s = 0` (both vertices from the camera) left out.
                    let full = path::stretch_density(&scene, &y, 1, 2) * 3.0;
                    let camera_only = path::pdf_from_camera(&scene, &y, 1) * path::pdf_from_camera(&scene, &y, 2);
                    (full - camera_only) / 3.0
                }
                _ => path::stretch_density(&scene, &y, 1, 2),
            };
            if p > 0.0 { scalar(&m) / p } else { 0.0 }
        })
    };
    let light = estimate(1);
    let mixed = estimate(0);
    let skewed = estimate(2);
    let sigma = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).abs() / (a.1 * a.1 + b.1 * b.1).sqrt();
    assert!(sigma(mixed, light) < 4.0, "stretch density: {mixed:?} against the light walk's {light:?}");
    assert!(sigma(skewed, light) > 6.0, "a sum without a split was not caught: {skewed:?} against {light:?}");
}

fn glass_caustic() -> Scene {
    scene("scenes/glass-caustic/scene.xml", &[("resx", "64"), ("resy", "36"), ("max_depth", "7")])
}

/// Detailed balance of one mutator against its reported densities: for `x ∼ π ∝ f` and
/// `y ∼ T(x → ·)`, with `r = f(y) T(y → x) / (f(x) T(x → y))`, balance gives
/// `E[r] = P(r > 0)` (the pairs `(x, y)` weighted by `π(x) T(x → y) r` are the pairs
/// `(y, x)` weighted by `π(y) T(y → x)`, and both sides count the moves whose reverse
/// exists). `x` comes from the whole-path generator weighted by `f / p`. Returns the mean of
/// `w (r - [r > 0])` over `Σ w [r > 0]`, and its standard error, in those units; `skew`
/// scales each forward density by a factor that depends on the proposal; `theta_diff`
/// (degrees) and `lambda` are the manifold perturbation's, `n` the number of paths `x`.
pub(super) fn balance(scene: &Scene, mutator: Mutator, skew: bool, settings: (f64, f64, usize)) -> (f64, f64) {
    balance_of(scene, mutator, skew, settings, |_| true)
}

/// [`balance`] over the moves `kind` accepts by the manifold walks' statistics of the move
/// (a kind of move whose reverse is of the same kind).
fn balance_of(
    scene: &Scene,
    mutator: Mutator,
    skew: bool,
    (lambda, theta_diff, n): (f64, f64, usize),
    kind: impl Fn(&manifold_perturbation::WalkStats) -> bool + Sync,
) -> (f64, f64) {
    let lengths = lengths(scene);
    let radii = lens::Radii::for_film(scene.film.width, scene.film.height);
    // The current paths are drawn from the start paths' generator; the independent mutation
    // proposes from a learned one (its densities both ways are that one's).
    let (uniform, learned) = (Strategies::uniform(lengths), skewed_strategies(lengths).with_camera_walks(0.3));
    let (d, d2, valid) = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut rng = Sampler::new(&[21, mutator as u64, i as u64]);
            let mut c = Counters::default();
            let Some((x, mx, p)) = independent_path(scene, lengths, &uniform, &mut rng, &mut c) else {
                return (0.0, 0.0, 0.0);
            };
            let at = suitable(scene, &x, [true; Mutator::ALL.len()])[mutator as usize];
            let (fx, Some(at)) = (scalar(&mx), at) else { return (0.0, 0.0, 0.0) };
            let w = fx / p;
            let mut walks = manifold_perturbation::WalkStats::default();
            let proposal = match mutator {
                Mutator::Bidirectional => bidirectional::propose(scene, &x, lengths, &mut rng, &mut c),
                Mutator::Lens => lens::propose(scene, &x, mx.raster, at, radii, &mut rng, &mut c),
                Mutator::Caustic => caustic::propose(scene, &x, at, radii, &mut rng, &mut c),
                Mutator::MultiChain | Mutator::LightHit => {
                    multichain::propose(scene, &x, mx.raster, at, radii, &mut rng, &mut c)
                }
                Mutator::Independent => independent::propose(scene, &x, lengths, &learned, &mut rng, &mut c),
                Mutator::Manifold => manifold_perturbation::propose(
                    scene,
                    &x,
                    (lambda, theta_diff.to_radians()),
                    &mut rng,
                    &mut c,
                    &mut walks,
                ),
            };
            if !kind(&walks) {
                return (0.0, 0.0, 0.0);
            }
            let r = proposal.map_or(0.0, |q| {
                let fy = scalar(&q.measured);
                let suits = suitable(scene, &q.path, [true; Mutator::ALL.len()])[mutator as usize].is_some();
                let k = if skew { 1.0 + 2.0 * q.measured.raster.x as f64 / scene.film.width as f64 } else { 1.0 };
                let r = fy * q.backward / (fx * q.forward * k);
                if suits && r.is_finite() && r > 0.0 { r } else { 0.0 }
            });
            let v = w * (r - if r > 0.0 { 1.0 } else { 0.0 });
            (v, v * v, if r > 0.0 { w } else { 0.0 })
        })
        .reduce(|| (0.0, 0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
    let m = d / n as f64;
    let se = ((d2 / n as f64 - m * m) / n as f64).sqrt();
    let scale = valid / n as f64;
    (m / scale, se / scale)
}

#[test]
fn every_mutator_is_in_detailed_balance() {
    // On the glass ball's scene the lens perturbation has the floor seen directly and
    // through the ball to work on, the caustic perturbation the caustic seen directly, the
    // multi-chain perturbation the floor seen directly and lit through the ball by another
    // floor point, the light hit the caustic seen directly and the light seen in the ball
    // (re-traced on to the light), the manifold perturbation the caustic through the ball
    // too. The bidirectional mutation's
    // ratios are too heavy-tailed there (whole new paths through the ball) for a tight
    // check: it is checked on the Cornell box, with the perturbations again (the caustic
    // perturbation there with empty chains: the seen point moved from the light's side).
    let checks = [
        (
            glass_caustic(),
            &[Mutator::Lens, Mutator::Caustic, Mutator::MultiChain, Mutator::LightHit, Mutator::Manifold][..],
        ),
        (
            cornell(),
            &[Mutator::Bidirectional, Mutator::Lens, Mutator::Caustic, Mutator::Manifold, Mutator::Independent][..],
        ),
    ];
    for (scene, mutators) in &checks {
        for &m in *mutators {
            // The bidirectional mutation's ratios spread widest (with 1.2 million
            // samples one stream gave a standard error of 0.066, another under 0.03), the
            // independent mutation's from a skewed generator next (0.036 with 1.2 million);
            // few paths suit the multi-chain perturbation.
            let n = match m {
                Mutator::Bidirectional => 4_800_000,
                Mutator::Independent => 3_600_000,
                Mutator::MultiChain => 4_000_000,
                Mutator::LightHit => 1_200_000,
                _ => 300_000,
            };
            let (good, se) = balance(scene, m, false, (50.0, 1.0, n));
            assert!(good.abs() < 4.0 * se && se < 0.03, "{m:?}: E[r] - P(r > 0) = {good} ± {se} of P(r > 0)");
            let (skewed, se) = balance(scene, m, true, (50.0, 1.0, n));
            assert!(skewed.abs() > 6.0 * se, "{m:?}: a skewed forward density was not caught: {skewed} ± {se}");
        }
    }
}

#[test]
fn the_light_point_perturbation_is_in_detailed_balance() {
    // The manifold perturbation's moves of the light point on its surface alone (the
    // Cornell box's light over a diffuse box), with their Gaussian densities both ways; a
    // blunt λ makes the moves as wide as the light (many leave it), so that the
    // contribution changes.
    let scene = cornell();
    let only = |w: &manifold_perturbation::WalkStats| w.light_points > 0;
    let (good, se) = balance_of(&scene, Mutator::Manifold, false, (2.0, 1.0, 600_000), only);
    assert!(good.abs() < 4.0 * se && se < 0.03, "E[r] - P(r > 0) = {good} ± {se} of P(r > 0)");
    let (skewed, se) = balance_of(&scene, Mutator::Manifold, true, (2.0, 1.0, 600_000), only);
    assert!(skewed.abs() > 6.0 * se, "a skewed forward density was not caught: {skewed} ± {se}");
}

#[test]
fn the_light_point_perturbation_through_a_specular_chain_is_in_detailed_balance() {
    // On the glass ball's scene: the light point moved on the small spherical light with the
    // first rough vertex after it kept (the floor's caustic point), the chain through the
    // ball walked onto its manifold from there to the moved point. Only those moves (a walk
    // tried) count; a skewed forward density must be caught.
    let scene = glass_caustic();
    let only = |w: &manifold_perturbation::WalkStats| w.light_points > 0 && w.tried > 0;
    let (good, se) = balance_of(&scene, Mutator::Manifold, false, (50.0, 1.0, 1_200_000), only);
    assert!(good.abs() < 4.0 * se && se < 0.03, "E[r] - P(r > 0) = {good} ± {se} of P(r > 0)");
    let (skewed, se) = balance_of(&scene, Mutator::Manifold, true, (50.0, 1.0, 1_200_000), only);
    assert!(skewed.abs() > 6.0 * se, "a skewed forward density was not caught: {skewed} ± {se}");
}

/// A tilted glass cube over a diffuse floor under a small area light: the light walk
/// refracts into one face and out of another at different angles (a sphere's two crossings
/// would mirror each other).
fn glass_cube() -> Scene {
    let shapes = r#"<shape type="cube"><transform name="to_world"><scale value="0.6"/><rotate y="1" angle="35"/><rotate x="1" angle="20"/><translate z="1.2"/></transform>
  <bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf></shape>
<shape type="rectangle"><transform name="to_world"><scale value="4"/></transform><bsdf type="diffuse"/></shape>
<shape type="rectangle"><transform name="to_world"><scale value="0.5"/><rotate x="1" angle="180"/><translate x="0.5" z="3"/></transform>
  <emitter type="area"><rgb name="radiance" value="5"/></emitter></shape>"#;
    inline_scene("glass-cube.xml", (4, 50.0), ("0, -4, 3", "0, 0, 0"), (24, 24), shapes)
}

/// A scene of `shapes` seen by a pinhole (`lookat` origin and target, `z` up) through a film
/// of `size`, paths of at most `max_depth` edges.
fn inline_scene(
    name: &str,
    (max_depth, fov): (i32, f32),
    lookat: (&str, &str),
    size: (u32, u32),
    shapes: &str,
) -> Scene {
    let text = format!(
        r#"<scene version="3.0.0">
<integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>
<sensor type="perspective"><float name="fov" value="{fov}"/>
  <transform name="to_world"><lookat origin="{}" target="{}" up="0, 0, 1"/></transform>
  <film type="hdrfilm"><integer name="width" value="{}"/><integer name="height" value="{}"/></film></sensor>
{shapes}
</scene>"#,
        lookat.0, lookat.1, size.0, size.1
    );
    Scene::load_str(&text, std::path::Path::new(name), &crate::scene::LoadOptions::default()).unwrap()
}

#[test]
fn whole_path_density_holds_through_flat_refractions() {
    // The whole-path generator's `f / p` through refractions (both walks' densities of
    // Dirac vertices, each with its camera-side cosine) against BDPT's estimate. (Light
    // entering the top face and leaving by the bottom one, the most of it, crosses parallel
    // faces, whose cosine ratios cancel: a light-side cosine would be off here by only
    // about 1e-5 of the total, too little to catch.)
    let scene = glass_cube();
    let lengths = lengths(&scene);
    let b = bdpt_reference(&scene, lengths.min);
    let good = mean_and_error(2_000_000, |i| {
        let mut rng = Sampler::new(&[23, i as u64]);
        let Some((_, m, p)) =
            independent_path(&scene, lengths, &Strategies::uniform(lengths), &mut rng, &mut Counters::default())
        else {
            return 0.0;
        };
        scalar(&m) / p
    });
    assert!(sigmas(good, b) < 4.0 && good.1 < 0.02 * b, "glass cube: {good:?} against BDPT's {b}");
}

/// A rough metal floor and a rough metal ball on it under a small area light, with a
/// diffuse wall behind: paths with glossy reflections. (A rough glass ball makes the
/// generator's `f / p` too heavy-tailed for the balance check's sample means; refractions
/// keeping their half-vectors are checked in `integrator::manifold`'s tests.)
fn glossy() -> Scene {
    let shapes = r#"<shape type="rectangle"><transform name="to_world"><scale value="4"/></transform>
  <bsdf type="roughconductor"><string name="distribution" value="ggx"/><float name="alpha" value="0.08"/></bsdf></shape>
<shape type="sphere"><point name="center" x="0.3" y="0" z="0.6"/><float name="radius" value="0.6"/>
  <bsdf type="roughconductor"><string name="distribution" value="beckmann"/><float name="alpha" value="0.1"/></bsdf></shape>
<shape type="rectangle"><transform name="to_world"><scale value="4"/><rotate x="1" angle="90"/><translate y="2" z="2"/></transform><bsdf type="diffuse"/></shape>
<shape type="rectangle"><transform name="to_world"><scale value="0.3"/><rotate x="1" angle="180"/><translate x="-0.8" y="0.5" z="2.5"/></transform>
  <emitter type="area"><rgb name="radiance" value="20"/></emitter></shape>"#;
    inline_scene("glossy.xml", (5, 45.0), ("0, -4, 1.6", "0, 0, 0.5"), (32, 24), shapes)
}

#[test]
fn the_manifold_perturbation_is_in_detailed_balance_through_glossy_vertices() {
    // At θ_diff = 10° the floor (GGX, α 0.08) is treated as specular two times in three,
    // the ball (Beckmann, α 0.1) four in five: reflections keep their half-vectors on the way
    // from `a` and in the walked chains, and the treatments' probabilities, plans and walks
    // back must agree in both directions. (The kept half-vectors' densities change little
    // over a move of λ = 50 and this check cannot see them: the tests of
    // `integrator::manifold` hold them against finite differences.)
    let scene = glossy();
    let (good, se) = balance(&scene, Mutator::Manifold, false, (50.0, 10.0, 3_000_000));
    assert!(good.abs() < 4.0 * se && se < 0.02, "E[r] - P(r > 0) = {good} ± {se} of P(r > 0)");
    let (skewed, se) = balance(&scene, Mutator::Manifold, true, (50.0, 10.0, 3_000_000));
    assert!(skewed.abs() > 6.0 * se, "a skewed forward density was not caught: {skewed} ± {se}");
}

/// An open box under a point light and a spot light (lights with a Dirac position), a
/// rough metal ball and a diffuse block.
fn spot_point() -> Scene {
    scene("scenes/spot-point/scene.xml", &[("resx", "24"), ("resy", "18"), ("max_depth", "4")])
}

#[test]
fn whole_path_density_holds_for_point_and_spot_lights() {
    // Paths from a point or spot light take its position by the light's discrete
    // probability, and no camera walk reaches it: the generator's `f / p` against BDPT's
    // estimate. A density that lets the camera walk reach the light's position (one more
    // split in the sum) must be caught.
    let scene = spot_point();
    assert!(scene.lights.iter().all(|l| l.is_delta_position()));
    let lengths = lengths(&scene);
    let reaching = |y: &[Vertex], p: f64| {
        let k = y.len() - 1;
        if k < 2 {
            return p;
        }
        // The camera walk's density of `x_0` as if a ray could find it.
        let to = |a: usize, b: usize| (y[b].p - y[a].p).normalize();
        let reach = path::lobe_pdf(&scene, &y[1], to(1, 2), to(1, 0), crate::bsdf::TransportMode::Radiance) as f64
            * path::area_factor(y, 0, 1);
        let camera: f64 = (1..k).map(|j| path::pdf_from_camera(&scene, y, j)).product();
        p + seed_length_pmf(lengths, k) * reach * camera / (k + 1) as f64
    };
    let control = "a camera walk reaching a point light";
    generator_matches_bdpt(
        &scene,
        &Strategies::uniform(lengths),
        (29, 600_000),
        reaching,
        "point and spot lights",
        control,
    );
}

#[test]
fn every_mutator_is_in_detailed_balance_with_point_and_spot_lights() {
    // The bidirectional mutation regenerates the light's position (a point, drawn by its
    // discrete probability) and leaves it in the light's own directions; the caustic and
    // manifold perturbations turn the direction leaving it; the lens perturbation
    // connects to it. (No Dirac chains here: the multi-chain perturbation has no path.)
    let scene = spot_point();
    for m in [Mutator::Bidirectional, Mutator::Lens, Mutator::Caustic, Mutator::Manifold] {
        let n = if m == Mutator::Bidirectional { 9_600_000 } else { 300_000 };
        let (good, se) = balance(&scene, m, false, (50.0, 1.0, n));
        assert!(good.abs() < 4.0 * se && se < 0.03, "{m:?}: E[r] - P(r > 0) = {good} ± {se} of P(r > 0)");
        let (skewed, se) = balance(&scene, m, true, (50.0, 1.0, n));
        assert!(skewed.abs() > 6.0 * se, "{m:?}: a skewed forward density was not caught: {skewed} ± {se}");
    }
}

/// A mirror floor under a small area light before a diffuse wall: the camera sees the
/// light's reflection (two-edge paths through a Dirac lobe) and the wall lit directly and
/// through the mirror.
fn mirror() -> Scene {
    let shapes = r#"<shape type="rectangle"><transform name="to_world"><scale value="3"/></transform>
  <bsdf type="conductor"/></shape>
<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="90"/><translate y="2" z="2"/></transform><bsdf type="diffuse"/></shape>
<shape type="rectangle"><transform name="to_world"><scale value="0.4"/><rotate x="1" angle="180"/><translate y="0.5" z="1.5"/></transform>
  <emitter type="area"><rgb name="radiance" value="8"/></emitter></shape>"#;
    inline_scene("mirror.xml", (4, 50.0), ("0, -3, 1", "0, 0.5, -0.6"), (24, 18), shapes)
}

#[test]
fn chains_beside_the_direct_pass_take_the_two_edge_paths_through_dirac_lobes() {
    // With the direct light separate, the chains' paths are those of three edges or more
    // and the two-edge paths through a Dirac lobe (the light seen in the mirror): the
    // generator restricted to them (`Lengths::covers`) must estimate what the BDPT
    // bootstrap counts for them. Leaving the mirror's two-edge paths out of the bootstrap
    // must be caught.
    let scene = mirror();
    let mut lengths = lengths(&scene);
    lengths.min = 2;
    lengths.direct_separate = true;
    let b = |dirac_two_edges: bool| {
        let paths = ChainPaths { min_edges: 3, dirac_two_edges, dirac_only: true };
        bootstrap_estimate(&scene, paths, (31, 400_000)).0
    };
    let chains = chains_estimate(&scene, lengths, (33, 4_000_000), |_| true);
    let (with, without) = (b(true), b(false));
    assert!(sigmas(chains, with) < 4.0 && chains.1 < 0.02 * with, "chains' paths: {chains:?} against BDPT's {with}");
    assert!(sigmas(chains, without) > 6.0, "the mirror's two-edge paths were not missed: {chains:?} against {without}");
}

/// A glass ball and a rough metal ball on a diffuse floor before a diffuse wall, open to a
/// constant sky and lit by a directional light at 40° from the zenith: paths whose light vertex lies at
/// infinity, in a direction rays can find (the sky) or in a Dirac one (the directional
/// light), through rough and Dirac vertices (the directional light's caustic under the
/// glass ball).
fn sky() -> Scene {
    let shapes = r#"<emitter type="constant"><rgb name="radiance" value="0.4, 0.5, 0.6"/></emitter>
<emitter type="directional"><vector name="direction" value="-0.45, -0.54, -0.71"/><rgb name="irradiance" value="3"/></emitter>
<shape type="rectangle"><transform name="to_world"><scale value="3"/></transform><bsdf type="diffuse"/></shape>
<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="90"/><translate y="1.5" z="1"/></transform>
  <bsdf type="diffuse"><rgb name="reflectance" value="0.7"/></bsdf></shape>
<shape type="sphere"><point name="center" x="-0.3" y="0" z="0.5"/><float name="radius" value="0.5"/>
  <bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf></shape>
<shape type="sphere"><point name="center" x="0.9" y="0.3" z="0.35"/><float name="radius" value="0.35"/>
  <bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf></shape>"#;
    inline_scene("sky.xml", (5, 50.0), ("0.3, -3.5, 2.2", "0.2, 0, 0.3"), (24, 18), shapes)
}

#[test]
fn chains_beside_the_specular_pass_take_the_paths_with_a_rough_vertex() {
    // Beside the direct-light and specular passes the chains' paths have three edges or
    // more and a rough vertex: the generator restricted to them (`Lengths::covers`) must
    // estimate what the BDPT bootstrap counts for them (`Lengths::chain_paths`). Counting
    // the sky seen through the glass ball (paths through Dirac lobes alone) there must be
    // caught.
    let scene = sky();
    let mut lengths = lengths(&scene);
    lengths.min = 3;
    lengths.specular_separate = true;
    let b = |paths: ChainPaths| bootstrap_estimate(&scene, paths, (37, 1_000_000)).0;
    let rough = |y: &[Vertex]| y[1..y.len() - 1].iter().any(|v| !v.delta);
    let chains = chains_estimate(&scene, lengths, (39, 4_000_000), rough);
    let (without, with) = (b(lengths.chain_paths()), b(ChainPaths { dirac_only: true, ..lengths.chain_paths() }));
    assert!(
        sigmas(chains, without) < 4.0 && chains.1 < 0.02 * without,
        "chains' paths: {chains:?} against BDPT's {without}"
    );
    assert!(
        sigmas(chains, with) > 6.0,
        "the paths through the glass alone were not left out: {chains:?} against {with}"
    );
}

/// A pass's mean luminance and its standard error over four seeds.
pub(super) fn pass<M: crate::integrator::render_loop::Iterative + Clone>(
    scene: &Scene,
    method: M,
    spp: u32,
) -> (f64, f64) {
    let means: Vec<f64> = (0..4)
        .map(|seed| {
            let mut o = RunOptions::new(Budget::Spp(spp));
            (o.threads, o.progress, o.seed) = (2, false, 43 + seed);
            let out = crate::integrator::render_loop::run(scene, &o, method.clone(), false, None).unwrap();
            let image = out.film.unwrap().develop();
            image.iter().map(|p| luminance(*p) as f64).sum::<f64>() / image.len() as f64
        })
        .collect();
    let m = means.iter().sum::<f64>() / 4.0;
    (m, (means.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / 12.0).sqrt())
}

#[test]
fn the_direct_and_specular_passes_and_the_chains_share_every_path() {
    // MEMLT's direct-light pass (paths of one edge and of two through a rough vertex), its
    // specular pass (paths through Dirac lobes alone: the sky seen through the glass ball)
    // and the chains' paths (three edges or more, a rough vertex) make the whole image: the
    // passes' mean luminances plus BDPT's estimate of the chains' part is BDPT's estimate of
    // every path. A specular pass that stops at two edges must be caught.
    use crate::integrator::path::PathTracer;
    use specular_pass::SpecularPass;
    let scene = sky();
    let bdpt = |paths: ChainPaths| bootstrap_estimate(&scene, paths, (41, 1_000_000));
    let chains = ChainPaths { min_edges: 3, dirac_two_edges: false, dirac_only: false };
    let (all, chains) = (bdpt(ChainPaths::ALL), bdpt(chains));
    let direct =
        pass(&scene, PathTracer { max_depth: 2, dirac_emission: false, ..PathTracer::new(&scene.integrator) }, 512);
    let check = |specular: (f64, f64)| {
        let gap = direct.0 + specular.0 + chains.0 - all.0;
        let error = [direct.1, specular.1, chains.1, all.1].iter().map(|e| e * e).sum::<f64>().sqrt();
        (gap, error)
    };
    let good = pass(&scene, SpecularPass { max_edges: 5 }, 256);
    let (gap, error) = check(good);
    assert!(
        gap.abs() < 4.0 * error && gap.abs() < 0.01 * all.0,
        "passes {direct:?} + {good:?} + chains {chains:?} against {all:?}"
    );
    let short = pass(&scene, SpecularPass { max_edges: 2 }, 256);
    let (gap, error) = check(short);
    assert!(gap.abs() > 6.0 * error, "a specular pass stopped at two edges was not caught: {short:?} against {good:?}");
}

#[test]
fn whole_path_density_holds_for_lights_at_infinity() {
    // The generator's `f / p` against BDPT's estimate under the sky and the directional
    // light. A density that counts the light walk's whole-path split twice where the light
    // is at infinity must be caught.
    let scene = sky();
    let lengths = lengths(&scene);
    let twice = |y: &[Vertex], p: f64| {
        if !y[0].infinite {
            return p;
        }
        // The light walk's whole-path split counted twice.
        let k = y.len() - 1;
        let light: f64 = (0..k).map(|j| path::pdf_from_light(&scene, y, j)).product();
        p + seed_length_pmf(lengths, k) * light / (k + 1) as f64
    };
    generator_matches_bdpt(
        &scene,
        &Strategies::uniform(lengths),
        (37, 1_200_000),
        twice,
        "lights at infinity",
        "a split counted twice",
    );
}

#[test]
fn every_mutator_is_in_detailed_balance_under_lights_at_infinity() {
    // The bidirectional mutation regenerates the light's direction and the point on the
    // disk it enters from, or a camera walk leaving the scene; the lens and multi-chain
    // perturbations join moved vertices to the kept direction; the caustic and manifold
    // perturbations work on the paths' other vertices (a light at infinity stays out of
    // their plans).
    let scene = sky();
    for m in [Mutator::Bidirectional, Mutator::Lens, Mutator::Caustic, Mutator::MultiChain, Mutator::Manifold] {
        let n = match m {
            Mutator::Bidirectional => 4_800_000,
            Mutator::MultiChain => 4_000_000,
            _ => 300_000,
        };
        let (good, se) = balance(&scene, m, false, (50.0, 1.0, n));
        assert!(good.abs() < 4.0 * se && se < 0.03, "{m:?}: E[r] - P(r > 0) = {good} ± {se} of P(r > 0)");
        let (skewed, se) = balance(&scene, m, true, (50.0, 1.0, n));
        assert!(skewed.abs() > 6.0 * se, "{m:?}: a skewed forward density was not caught: {skewed} ± {se}");
    }
}

/// A glass ball over a diffuse floor under a directional light alone: the camera sees the
/// ball's caustic (light, two refractions, floor, pinhole).
fn sun_caustic() -> Scene {
    let shapes = r#"<emitter type="directional"><vector name="direction" value="-0.3, -0.2, -0.93"/><rgb name="irradiance" value="3"/></emitter>
<shape type="rectangle"><transform name="to_world"><scale value="3"/></transform><bsdf type="diffuse"/></shape>
<shape type="sphere"><point name="center" x="0" y="0" z="0.8"/><float name="radius" value="0.5"/>
  <bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf></shape>"#;
    inline_scene("sun-caustic.xml", (4, 40.0), ("0.3, -3.0, 2.5", "-0.3, 0, 0.2"), (24, 18), shapes)
}

#[test]
fn the_sky_point_perturbation_is_in_detailed_balance() {
    // The manifold perturbation's moves of the line light from infinity arrives along
    // (displaced across the light's direction, the direction kept), the light followed
    // from the surface it finds to the next rough vertex (through the glass ball's two
    // refractions for the caustic), joined to the vertex after that or walked to it through
    // the ball, with their Gaussian densities both ways.
    for scene in [sky(), sun_caustic()] {
        let only = |w: &manifold_perturbation::WalkStats| w.sky_points > 0;
        let (good, se) = balance_of(&scene, Mutator::Manifold, false, (50.0, 1.0, 600_000), only);
        assert!(good.abs() < 4.0 * se && se < 0.03, "E[r] - P(r > 0) = {good} ± {se} of P(r > 0)");
        let (skewed, se) = balance_of(&scene, Mutator::Manifold, true, (50.0, 1.0, 600_000), only);
        assert!(skewed.abs() > 6.0 * se, "a skewed forward density was not caught: {skewed} ± {se}");
    }
}
