//! Lights at infinity (`constant`, `envmap`) and directional lights in every integrator
//! (MEMLT with its direct-light pass and with the direct light in its chains),
//! against analytic answers: empty space under a constant sky is the sky; a convex diffuse
//! object of albedo ρ under radiance `L` reflects `ρ L`; a diffuse plane under a directional
//! light of irradiance `E` at angle θ has radiance `ρ E cos θ / π`. The bidirectional
//! integrators reach these through every strategy (an escaped camera ray, next-event
//! estimation to the sky, light paths from the disk facing the light, connections), so a
//! wrong density at either end of a path moves the image.

mod common;

use common::*;
use glam::Vec3;
use pcbpt::accel::Backend;
use pcbpt::integrator::budget::BudgetMode;
use pcbpt::integrator::pcbpt::PcMis;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::Scene;

/// Every integrator, PCBPT and SPCBPT with each MIS option.
fn methods() -> Vec<(String, RenderOptions)> {
    use IntegratorKind::*;
    let mut out: Vec<(String, RenderOptions)> =
        [Path, Guided, Lighttrace, Bdpt, Eorr, Lvc, Vcm].into_iter().map(|k| (format!("{k:?}"), options(k))).collect();
    // Each MIS option with the connections it weighs (no budget), and the defaults (a budget).
    for mis in [PcMis::Harmonic, PcMis::Uniform, PcMis::Resampling, PcMis::Correlated] {
        let mut o = options(Pcbpt);
        o.method.pcbpt_mut().pc.mis = mis;
        o.method.pool_mut().light_paths = 200;
        o.method.pcbpt_mut().pc.stride = 8;
        o.method.budget_mut().mode = BudgetMode::Off;
        out.push((format!("Pcbpt {mis:?}"), o));
        let mut o = options(Spcbpt);
        o.method.spcbpt_mut().sp.mis = mis;
        o.method.pool_mut().light_paths = 200;
        o.method.spcbpt_mut().sp.eye_subspaces = 32;
        o.method.spcbpt_mut().sp.light_subspaces = 64;
        o.method.budget_mut().mode = BudgetMode::Off;
        out.push((format!("Spcbpt {mis:?}"), o.clone()));
        // SPCBPT's own count option.
        if mis == PcMis::Resampling {
            o.method.spcbpt_mut().sp.mis = PcMis::Subspace;
            out.push(("Spcbpt Subspace".into(), o));
        }
    }
    out.push(("Pcbpt, defaults".into(), options(Pcbpt)));
    out.push(("Spcbpt, defaults".into(), options(Spcbpt)));
    let mut o = options(Pssmlt);
    o.method.chain_mut().bootstrap = 20_000;
    out.push(("Pssmlt".into(), o));
    // MEMLT with its direct-light pass (the path tracer's), and with the direct light in
    // the chains, so that every path length is the chains' own.
    for direct in [16, -1] {
        let mut o = options(Memlt);
        o.method.chain_mut().bootstrap = 20_000;
        o.method.memlt_mut().direct_samples = direct;
        out.push((if direct > 0 { "Memlt".into() } else { "Memlt, direct light in the chains".into() }, o));
    }
    out
}

fn options(kind: IntegratorKind) -> RenderOptions {
    // Light tracing and the Markov chains are the noisiest here: more samples.
    let spp = match kind {
        IntegratorKind::Lighttrace => 1024,
        IntegratorKind::Pssmlt | IntegratorKind::Memlt => 256,
        _ => 64,
    };
    let mut o = RenderOptions::new(kind, Budget::Spp(spp));
    o.run.seed = 5;
    o.run.threads = 2;
    o
}

fn scene(body: &str) -> (tempfile::TempDir, Scene) {
    let dir = tempfile::tempdir().unwrap();
    let xml = format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="30"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/><rfilter type="box"/></film>
    </sensor>
{body}
</scene>"#
    );
    let path = dir.path().join("scene.xml");
    std::fs::write(&path, xml).unwrap();
    let scene = load(&path, &[], Backend::Embree);
    (dir, scene)
}

/// Mean of the pixels for which `keep(x, y)`.
fn mean_where(img: &[Vec3], keep: impl Fn(u32, u32) -> bool) -> (Vec3, usize) {
    let mut sum = Vec3::ZERO;
    let mut n = 0;
    for (i, p) in img.iter().enumerate() {
        if keep(i as u32 % 24, i as u32 / 24) {
            sum += *p;
            n += 1;
        }
    }
    (sum / n.max(1) as f32, n)
}

fn close(what: &str, got: Vec3, want: Vec3, tol: f32) -> Result<(), String> {
    let err = ((got - want).abs() / want).max_element();
    eprintln!("{what}: {got} against {want} ({:.2}%)", err * 100.0);
    if err <= tol { Ok(()) } else { Err(format!("{what}: {got}, expected {want} (off by {:.2}%)", err * 100.0)) }
}

#[test]
fn empty_space_under_a_constant_sky_is_the_sky_in_every_integrator() {
    let l = Vec3::new(0.5, 0.7, 0.9);
    let (_d, scene) = scene(r#"<emitter type="constant"><rgb name="radiance" value="0.5, 0.7, 0.9"/></emitter>"#);
    let mut failures = Vec::new();
    for (name, o) in methods() {
        let out = integrator::render(&scene, &o).unwrap();
        if name == "Pssmlt" || name.starts_with("Memlt,") {
            // The chains' pixels are as noisy as their visits; their mean is the sky.
            if let Err(e) = close(&name, mean_where(&out.image, |_, _| true).0, l, 0.01) {
                failures.push(e);
            }
            continue;
        }
        // Every sample sees the sky alone, with weight one: exact.
        let worst = out.image.iter().map(|p| ((*p - l).abs() / l).max_element()).fold(0.0f32, f32::max);
        if worst > 1e-5 {
            failures.push(format!("{name}: a pixel off by {:.3}%", worst * 100.0));
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

#[test]
fn convex_diffuse_sphere_under_a_constant_sky_reflects_rho_l_in_every_integrator() {
    let (l, rho) = (Vec3::new(0.5, 0.7, 0.9), Vec3::new(0.3, 0.5, 0.7));
    let (_d, scene) = scene(
        r#"<emitter type="constant"><rgb name="radiance" value="0.5, 0.7, 0.9"/></emitter>
    <shape type="sphere"><float name="radius" value="1"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.5, 0.7"/></bsdf></shape>"#,
    );
    // Pixels whose four corners all see the sphere, or all miss it (its outline is convex).
    let hits = |x: f32, y: f32| {
        let ray = scene.camera.generate_ray(glam::Vec2::new(x, y));
        let oc = ray.o;
        let b = oc.dot(ray.d);
        b * b - (oc.length_squared() - 1.0) > 0.0
    };
    let corners = |x: u32, y: u32| {
        [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)].map(|(dx, dy)| hits(x as f32 + dx, y as f32 + dy))
    };
    let mut failures = Vec::new();
    // MEMLT with the direct light in its chains is left out here: its one-edge paths (the
    // sky) and two-edge paths (the sphere) are joined by the bidirectional mutation alone
    // (by its move and acceptance probabilities about one step in a hundred of it
    // crosses), so how its chains share their time between the two varies from seed to
    // seed: the sphere's mean by 3–4.6% at 256 mutations per pixel and 1.8% at 4 096 (eight
    // seeds, their mean 1.0007 of ρL), falling as the square root of the mutations, against
    // the 1% asked here. With its direct pass
    // the sphere and the sky are that pass's, checked here; its chains are checked under
    // lights at infinity by the other tests of this file.
    for (name, o) in methods().into_iter().filter(|(n, _)| !n.starts_with("Memlt,")) {
        let out = integrator::render(&scene, &o).unwrap();
        let (inside, n_in) = mean_where(&out.image, |x, y| corners(x, y).iter().all(|&h| h));
        let (outside, n_out) = mean_where(&out.image, |x, y| corners(x, y).iter().all(|&h| !h));
        assert!(n_in > 100 && n_out > 100, "{n_in} pixels inside, {n_out} outside");
        for r in
            [close(&format!("{name}, sphere"), inside, rho * l, 0.01), close(&format!("{name}, sky"), outside, l, 0.01)]
        {
            if let Err(e) = r {
                failures.push(e);
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

#[test]
fn diffuse_plane_under_a_directional_light_in_every_integrator() {
    // A plane facing the camera, lit at 60° from its normal: radiance ρ E cos θ / π.
    let (e, rho) = (Vec3::new(2.0, 3.0, 4.0), Vec3::new(0.6, 0.5, 0.4));
    let (_d, scene) = scene(
        r#"<emitter type="directional"><vector name="direction" value="0.8660254, 0, -0.5"/>
        <rgb name="irradiance" value="2, 3, 4"/></emitter>
    <shape type="rectangle"><transform name="to_world"><scale value="3"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf></shape>"#,
    );
    let want = rho * e * 0.5 / std::f32::consts::PI;
    let mut failures = Vec::new();
    for (name, o) in methods() {
        let out = integrator::render(&scene, &o).unwrap();
        let (m, n) = mean_where(&out.image, |_, _| true);
        assert_eq!(n, 24 * 24);
        if let Err(err) = close(&format!("{name}, plane"), m, want, 0.01) {
            failures.push(err);
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

/// A glossy sphere on a diffuse floor under an environment map, a constant sky and a
/// directional light: light reaches the floor after bounces off the sphere, so the
/// connections of light paths from infinity (`s, t >= 2`) carry part of the image. Each
/// integrator's image mean, and that of the floor under the sphere, match the path tracer's.
#[test]
fn interreflections_under_lights_at_infinity_match_the_path_tracer() {
    let dir = tempfile::tempdir().unwrap();
    // A small environment map: a bright band above a dim ground.
    let (w, h) = (16u32, 8u32);
    let texels: Vec<Vec3> =
        (0..w * h).map(|i| if i / w < 3 { Vec3::new(2.0, 1.8, 1.5) } else { Vec3::new(0.2, 0.25, 0.3) }).collect();
    pcbpt::image_io::write(&dir.path().join("sky.exr"), &pcbpt::image_io::Image::new(w, h, texels)).unwrap();
    let xml = r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1.5, 5" target="0, -0.3, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/><rfilter type="box"/></film>
    </sensor>
    <emitter type="envmap"><string name="filename" value="sky.exr"/><float name="scale" value="0.5"/></emitter>
    <emitter type="constant"><rgb name="radiance" value="0.05"/></emitter>
    <emitter type="directional"><vector name="direction" value="-0.4, -1, -0.3"/><rgb name="irradiance" value="1.5"/></emitter>
    <shape type="sphere"><float name="radius" value="0.8"/>
        <bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf></shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="4"/><translate y="-0.8"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf></shape>
</scene>"#;
    let path = dir.path().join("scene.xml");
    std::fs::write(&path, xml).unwrap();
    let scene = load(&path, &[], Backend::Embree);
    let mut o = options(IntegratorKind::Path);
    o.run.budget = Budget::Spp(2048);
    let reference = integrator::render(&scene, &o).unwrap().image;
    let floor = |_x: u32, y: u32| y >= 16;
    let (r_all, _) = mean_where(&reference, |_, _| true);
    let (r_floor, _) = mean_where(&reference, floor);
    let mut failures = Vec::new();
    for (name, mut o) in methods().into_iter().skip(1) {
        if let Budget::Spp(s) = o.run.budget {
            o.run.budget = Budget::Spp(s * if name == "Lighttrace" { 16 } else { 2 });
        }
        let img = integrator::render(&scene, &o).unwrap().image;
        for r in [
            close(&format!("{name}, image"), mean_where(&img, |_, _| true).0, r_all, 0.015),
            close(&format!("{name}, floor"), mean_where(&img, floor).0, r_floor, 0.015),
        ] {
            if let Err(e) = r {
                failures.push(e);
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

#[test]
fn renders_under_lights_at_infinity_do_not_depend_on_the_thread_count() {
    let (_d, scene) = scene(
        r#"<emitter type="constant"><rgb name="radiance" value="0.5, 0.7, 0.9"/></emitter>
    <emitter type="directional"><vector name="direction" value="0, -1, -1"/><rgb name="irradiance" value="1"/></emitter>
    <shape type="sphere"><float name="radius" value="1"/><bsdf type="diffuse"/></shape>"#,
    );
    for (name, mut o) in methods() {
        o.run.budget = Budget::Spp(4);
        o.run.threads = 1;
        let one = integrator::render(&scene, &o).unwrap().image;
        o.run.threads = 2;
        let two = integrator::render(&scene, &o).unwrap().image;
        let bits = |i: &[Vec3]| i.iter().map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        // PSSMLT runs one chain per thread: its image depends on the thread count by design
        // (MEMLT's chains do not).
        if name != "Pssmlt" {
            assert!(bits(&one) == bits(&two), "{name}: 1 and 2 threads differ");
        }
    }
}
