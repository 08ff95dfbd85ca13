//! The path tracer and BDPT (with EORR, its connections under a roulette) as wavefronts
//! (`--wavefront true`, the default) against themselves one sample at a time: with the same
//! seed every sample draws the same random numbers, so the two give the same image wherever
//! the batched ray queries report the hits single queries report (bit for bit with the
//! pure-Rust backend: `tests/backends.rs`). Embree's stream traversal may round a hit
//! differently from its single-ray traversal on some CPU, so with Embree the two must agree
//! as renders of one estimator do: image means within 0.2%, and a difference far below the
//! noise of one render.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::compare::metrics;
use pcbpt::image_io::Image;
use pcbpt::integrator::RenderOutput;
use pcbpt::integrator::{IntegratorKind, registry};
use pcbpt::scene::Scene;

/// Scenes that between them have every light, BSDF and texture kind the wavefront shades:
/// area, point, spot, sun, sky and environment lights, glass, masks, bump and normal maps,
/// the sobol sampler (`sunlit-room`) and a medium (traced one path at a time either way).
const SCENES: [&str; 10] = [
    "cornell-box/scene.xml",
    "materials/scene.xml",
    "staircase2/scene.xml",
    "sunlit-room/scene.xml",
    "cutout/scene.xml",
    "bumpmap/normalmap.xml",
    "spot-point/scene.xml",
    "sunsky/scene.xml",
    "glass-caustic/scene.xml",
    "smoke/scene.xml",
];

fn scene(name: &str) -> Scene {
    load_at(&root().join("scenes").join(name), &[], Some((64, 36)), Backend::Embree)
}

/// The integrators that trace wavefronts.
const KINDS: [IntegratorKind; 3] = [IntegratorKind::Path, IntegratorKind::Bdpt, IntegratorKind::Eorr];

fn render(scene: &Scene, kind: IntegratorKind, seed: u64, wavefront: bool) -> RenderOutput {
    let args = ["--wavefront".to_string(), wavefront.to_string()];
    render_with(scene, kind, 8, seed, 2, &|o| o.method = registry::parse_options(kind, &args).unwrap())
}

/// Whether `wavefront` agrees with `scalar` (the same seed) as the same render does: means
/// within 0.2%, and a relMSE between them under a hundredth of `noise` (the relMSE between
/// two scalar renders of different seeds).
fn agrees(wavefront: &RenderOutput, scalar: &RenderOutput, noise: f64) -> Result<(), String> {
    let m = metrics(&picture(scalar), &picture(wavefront)).unwrap();
    if (m.mean_ratio - 1.0).abs() > 0.002 || m.relmse > 0.01 * noise || m.non_finite > 0 {
        return Err(format!("mean ratio {}, relMSE {:e} against a render's noise {noise:e}", m.mean_ratio, m.relmse));
    }
    Ok(())
}

fn picture(o: &RenderOutput) -> Image {
    Image::new(o.width, o.height, o.image.clone())
}

/// The relMSE between two renders.
fn difference(a: &RenderOutput, b: &RenderOutput) -> f64 {
    metrics(&picture(a), &picture(b)).unwrap().relmse
}

#[test]
fn the_wavefront_renders_the_image_of_one_sample_at_a_time() {
    let mut failures = Vec::new();
    for name in SCENES {
        let scene = scene(name);
        for kind in KINDS {
            let scalar = render(&scene, kind, 3, false);
            let other_seed = render(&scene, kind, 4, false);
            let noise = difference(&scalar, &other_seed);
            assert!(noise > 0.0, "{name}, {kind:?}: two seeds give the same image");
            if let Err(e) = agrees(&render(&scene, kind, 3, true), &scalar, noise) {
                failures.push(format!("{name}, {kind:?}: {e}"));
            }
        }
    }
    assert!(failures.is_empty(), "the wavefront differs:\n{}", failures.join("\n"));
}

#[test]
fn a_missing_bounce_or_another_seed_does_not_agree() {
    for kind in KINDS {
        let mut scene = scene("cornell-box/scene.xml");
        let scalar = render(&scene, kind, 3, false);
        let noise = difference(&scalar, &render(&scene, kind, 4, false));
        assert!(agrees(&render(&scene, kind, 3, true), &scalar, noise).is_ok(), "{kind:?}");
        assert!(agrees(&render(&scene, kind, 5, true), &scalar, noise).is_err(), "{kind:?}");
        // Paths cut after their third segment (the scene's are cut after 30).
        scene.integrator.max_depth = 3;
        assert!(agrees(&render(&scene, kind, 3, true), &scalar, noise).is_err(), "{kind:?}");
    }
}

#[test]
fn the_wavefront_traces_the_rays_one_sample_at_a_time_traces() {
    let scene = scene("staircase2/scene.xml");
    for kind in KINDS {
        let (w, s) = (render(&scene, kind, 3, true), render(&scene, kind, 3, false));
        let rays = |o: &RenderOutput| {
            let c = &o.stats.counters;
            (
                c.camera_rays,
                c.extension_rays,
                c.shadow_rays,
                c.samples,
                c.light_paths,
                c.connections,
                c.connections_occluded,
            )
        };
        assert_eq!(rays(&w), rays(&s), "{kind:?}");
        assert!(w.stats.counters.shadow_rays > 0 && w.stats.counters.extension_rays > w.stats.counters.camera_rays);
    }
}
