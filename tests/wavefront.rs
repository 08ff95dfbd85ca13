//! The path tracer as a wavefront (`--wavefront true`, the default) against the path
//! tracer one path at a time: with the same seed every path draws the same random numbers,
//! so the two give the same image wherever the batched ray queries report the hits single
//! queries report (bit for bit with the pure-Rust backend: `tests/backends.rs`). Embree's
//! stream traversal may round a hit differently from its single-ray traversal on some CPU,
//! so with Embree the two must agree as renders of one estimator do: image means within
//! 0.2%, and a difference far below the noise of one render.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::compare::metrics;
use pcbpt::image_io::Image;
use pcbpt::integrator::IntegratorKind;
use pcbpt::integrator::RenderOutput;
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

fn path(scene: &Scene, seed: u64, wavefront: bool) -> RenderOutput {
    render_with(scene, IntegratorKind::Path, 8, seed, 2, &|o| o.method.path_mut().wavefront = wavefront)
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
fn the_wavefront_renders_the_image_of_one_path_at_a_time() {
    let mut failures = Vec::new();
    for name in SCENES {
        let scene = scene(name);
        let scalar = path(&scene, 3, false);
        let other_seed = path(&scene, 4, false);
        let noise = difference(&scalar, &other_seed);
        assert!(noise > 0.0, "{name}: two seeds give the same image");
        if let Err(e) = agrees(&path(&scene, 3, true), &scalar, noise) {
            failures.push(format!("{name}: {e}"));
        }
    }
    assert!(failures.is_empty(), "the wavefront differs:\n{}", failures.join("\n"));
}

#[test]
fn a_missing_bounce_or_another_seed_does_not_agree() {
    let mut scene = scene("cornell-box/scene.xml");
    let scalar = path(&scene, 3, false);
    let noise = difference(&scalar, &path(&scene, 4, false));
    assert!(agrees(&path(&scene, 3, true), &scalar, noise).is_ok());
    assert!(agrees(&path(&scene, 5, true), &scalar, noise).is_err());
    // Paths cut after their third segment (the scene's are cut after 30).
    scene.integrator.max_depth = 3;
    assert!(agrees(&path(&scene, 3, true), &scalar, noise).is_err());
}

#[test]
fn the_wavefront_traces_the_rays_one_path_at_a_time_traces() {
    let scene = scene("staircase2/scene.xml");
    let (w, s) = (path(&scene, 3, true), path(&scene, 3, false));
    let rays = |o: &RenderOutput| {
        let c = &o.stats.counters;
        (c.camera_rays, c.extension_rays, c.shadow_rays, c.samples)
    };
    assert_eq!(rays(&w), rays(&s));
    assert!(w.stats.counters.shadow_rays > 0 && w.stats.counters.extension_rays > w.stats.counters.camera_rays);
}
