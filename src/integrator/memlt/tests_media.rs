//! The chains' densities in participating media, against what they sample (as in
//! [`super::tests`]): the whole-path generator's free flights, every mutator's detailed
//! balance, and the separate passes and the chains sharing every path, on the fog box
//! (`scenes/fog-caustic`: fog behind a null front, a glass ball, a small light).

use super::tests::{balance, bootstrap_estimate, generator_matches_bdpt, pass, scene};
use crate::integrator::bidir::VertexKind;
use crate::integrator::memlt::*;
use crate::integrator::metropolis::bootstrap::ChainPaths;

fn fog() -> Scene {
    scene("scenes/fog-caustic/scene.xml", &[("resx", "16"), ("resy", "16"), ("max_depth", "5")])
}

/// The number of scattering events in the medium on path `y`.
fn events(y: &[Vertex]) -> i32 {
    y.iter().filter(|v| v.kind == VertexKind::Medium).count() as i32
}

#[test]
fn whole_path_density_holds_in_media() {
    // Paths through the fog, with scattering events in it: the generator's `f / p` against
    // BDPT's estimate. A density off by a factor per scattering event must be caught.
    let scene = fog();
    let uniform = Strategies::uniform(lengths(&scene));
    let per_event = |y: &[Vertex], p: f64| p * 2f64.powi(events(y));
    generator_matches_bdpt(
        &scene,
        &uniform,
        (3, 300_000),
        per_event,
        "paths in fog",
        "a density doubled per scattering event",
    );
}

#[test]
fn every_mutator_is_in_detailed_balance_in_media() {
    // In the fog box the lens perturbation moves points on the walls seen through the fog
    // (their edges' transmittance in `f`), the caustic perturbation turns the direction
    // leaving a scattering event or a wall, the bidirectional and independent mutations
    // regenerate paths with scattering events. The manifold perturbation does not run where
    // there are media.
    let scene = fog();
    for (m, n) in [
        (Mutator::Bidirectional, 1_200_000),
        (Mutator::Lens, 300_000),
        (Mutator::Caustic, 300_000),
        (Mutator::Independent, 1_200_000),
    ] {
        let (good, se) = balance(&scene, m, false, (50.0, 1.0, n));
        eprintln!("{m:?}: {good} ± {se}");
        assert!(good.abs() < 4.0 * se && se < 0.03, "{m:?}: E[r] - P(r > 0) = {good} ± {se} of P(r > 0)");
        let (skewed, se) = balance(&scene, m, true, (50.0, 1.0, n));
        assert!(skewed.abs() > 6.0 * se, "{m:?}: a skewed forward density was not caught: {skewed} ± {se}");
    }
}

#[test]
fn the_direct_and_specular_passes_and_the_chains_share_every_path_in_media() {
    // MEMLT's direct-light pass (the path tracer: paths of one edge and of two through a
    // rough vertex or a scattering event), its specular pass (through Dirac lobes alone,
    // each edge's transmittance taken) and the chains' paths make the whole image in fog.
    // A direct pass that also takes the paths of three edges must be caught.
    use crate::integrator::path::PathTracer;
    use specular_pass::SpecularPass;
    let scene = fog();
    let bdpt = |paths: ChainPaths| bootstrap_estimate(&scene, paths, (41, 1_000_000));
    let chains = ChainPaths { min_edges: 3, dirac_two_edges: false, dirac_only: false };
    let (all, chains) = (bdpt(ChainPaths::ALL), bdpt(chains));
    let direct_to = |max_depth| PathTracer { max_depth, dirac_emission: false, ..PathTracer::new(&scene.integrator) };
    let specular = pass(&scene, SpecularPass { max_edges: 5 }, 1024);
    let gap = |direct: (f64, f64)| {
        let gap = direct.0 + specular.0 + chains.0 - all.0;
        let error = [direct.1, specular.1, chains.1, all.1].iter().map(|e| e * e).sum::<f64>().sqrt();
        eprintln!("direct {direct:?} specular {specular:?} chains {chains:?} all {all:?}: gap {gap} ± {error}");
        (gap, error)
    };
    let (good, error) = gap(pass(&scene, direct_to(2), 2048));
    assert!(
        good.abs() < 4.0 * error && good.abs() < 0.01 * all.0,
        "passes and chains against {all:?}: {good} ± {error}"
    );
    let (three, error) = gap(pass(&scene, direct_to(3), 512));
    assert!(three.abs() > 6.0 * error, "a direct pass of three edges was not caught: {three} ± {error}");
}
