//! Participating media against exact answers: Beer's law through an absorbing slab, single
//! scattering of a point light in fog (a quadrature of the volume rendering equation), and
//! a furnace (a non-absorbing medium in a uniformly lit world, where every ray sees the
//! world's radiance whatever the scattering) — each with a control showing the test would
//! notice a missing factor. Heterogeneous media (grids written here as `.vol` files): a grid
//! of one value renders as the homogeneous medium (in Mitsuba 3's and Mitsuba 0.6's
//! placements), and an absorbing ramp keeps `exp(-∫σt)` of the light crossing it.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::vol::{VolFile, vol_to_bytes};
use std::f64::consts::PI;
use std::path::PathBuf;

fn write(dir: &tempfile::TempDir, name: &str, xml: &str) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, xml).unwrap();
    path
}

fn sensor(fov: f32, size: u32, origin: &str, medium: &str) -> String {
    // Towards the origin, or along +z from it.
    let target = if origin == "0, 0, 0" { "0, 0, 1" } else { "0, 0, 0" };
    format!(
        r#"<sensor type="perspective"><float name="fov" value="{fov}"/>
        <transform name="to_world"><lookat origin="{origin}" target="{target}" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/><rfilter type="box"/></film>
        {medium}</sensor>"#
    )
}

/// A camera on the axis of a cube of side 2 whose interior absorbs, against a uniform
/// environment: each ray keeps `exp(-σt · 2 / cos θ)` of it (θ below 0.5° here).
#[test]
fn an_absorbing_slab_follows_beers_law() {
    let dir = tempfile::tempdir().unwrap();
    let sigma = [0.2f32, 0.5, 1.0];
    let xml = format!(
        r#"<scene version="3.0.0">
        {}
        <emitter type="constant"><rgb name="radiance" value="2"/></emitter>
        <shape type="cube"><bsdf type="null"/><medium type="homogeneous" name="interior">
            <rgb name="sigma_t" value="{}, {}, {}"/><float name="albedo" value="0"/></medium></shape>
        </scene>"#,
        sensor(1.0, 4, "0, 0, 5", ""),
        sigma[0],
        sigma[1],
        sigma[2]
    );
    let scene = load(&write(&dir, "slab.xml", &xml), &[], Backend::Embree);
    let img = image(render(&scene, IntegratorKind::Path, 4, 1, 1));
    for p in &img.pixels {
        for c in 0..3 {
            let exact = 2.0 * (-2.0 * sigma[c]).exp();
            assert!((p[c] / exact - 1.0).abs() < 1e-3, "channel {c}: {} against {exact}", p[c]);
        }
    }
    // Control: without the medium the pixels keep the environment's 2.
    let clear = xml.replace(
        r#"<float name="albedo" value="0"/>"#,
        r#"<float name="albedo" value="0"/><float name="scale" value="0"/>"#,
    );
    let scene = load(&write(&dir, "clear.xml", &clear), &[], Backend::Embree);
    let img = image(render(&scene, IntegratorKind::Path, 4, 1, 1));
    assert!(img.pixels.iter().all(|p| (p[0] - 2.0).abs() < 1e-4), "{:?}", img.pixels[0]);
}

const SIGMA_T: [f64; 3] = [0.4, 0.6, 0.8];
const ALBEDO: [f64; 3] = [0.8, 0.5, 0.9];
const G: f64 = 0.6;
const LIGHT: [f64; 3] = [0.5, 0.0, 3.0];
const INTENSITY: f64 = 10.0;

/// The radiance single scattering brings to a camera at the origin looking along +z
/// through fog filling space, lit by a point light at [`LIGHT`]: ∫ T(t) σs p(θ(t)) I T(r) / r²
/// dt by Simpson's rule. `phase_sign` -1 mirrors the phase function (the control).
fn single_scattering(c: usize, phase_sign: f64) -> f64 {
    let (st, ss) = (SIGMA_T[c], SIGMA_T[c] * ALBEDO[c]);
    let f = |t: f64| {
        let d = [LIGHT[0], LIGHT[1], LIGHT[2] - t];
        let r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let r = r2.sqrt();
        // wo = -z (towards the camera), wi towards the light: wo · wi = -d.z / r.
        let dot = phase_sign * -d[2] / r;
        let p = (1.0 - G * G) / (4.0 * PI * (1.0 + G * G + 2.0 * G * dot).powf(1.5));
        (-st * t).exp() * ss * p * INTENSITY * (-st * r).exp() / r2
    };
    let (end, n) = (100.0, 200_000);
    let h = end / n as f64;
    let mut sum = f(0.0) + f(end);
    for i in 1..n {
        sum += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    sum * h / 3.0
}

#[test]
fn single_scattering_of_a_point_light_matches_the_quadrature() {
    let dir = tempfile::tempdir().unwrap();
    let medium = format!(
        r#"<medium type="homogeneous"><rgb name="sigma_t" value="{}, {}, {}"/><rgb name="albedo" value="{}, {}, {}"/>
        <phase type="hg"><float name="g" value="{G}"/></phase></medium>"#,
        SIGMA_T[0], SIGMA_T[1], SIGMA_T[2], ALBEDO[0], ALBEDO[1], ALBEDO[2]
    );
    let xml = format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="2"/></integrator>
        {}
        <emitter type="point"><point name="position" x="{}" y="{}" z="{}"/><rgb name="intensity" value="{INTENSITY}"/></emitter>
        </scene>"#,
        sensor(0.2, 1, "0, 0, 0", &medium),
        LIGHT[0],
        LIGHT[1],
        LIGHT[2]
    );
    let scene = load(&write(&dir, "fog.xml", &xml), &[], Backend::Embree);
    let passes: Vec<f64> = (0..8)
        .map(|seed| {
            let out = render(&scene, IntegratorKind::Path, 20_000, seed, 2);
            out.image[0][1] as f64
        })
        .collect();
    let (mean, err) = mean_and_standard_error(&passes);
    let exact = single_scattering(1, 1.0);
    let mirrored = single_scattering(1, -1.0);
    eprintln!("single scattering: {mean:.5} ± {err:.5}, exact {exact:.5}, mirrored phase {mirrored:.5}");
    assert!((mean - exact).abs() < 4.0 * err + 2e-3 * exact, "{mean} ± {err} against {exact}");
    // Control: the mirrored phase function's answer is far outside the error.
    assert!((mean - mirrored).abs() > 20.0 * err && (mean / mirrored - 1.0).abs() > 0.2);
    // Every channel, from one longer render.
    let out = render(&scene, IntegratorKind::Path, 100_000, 99, 2);
    for c in 0..3 {
        let exact = single_scattering(c, 1.0);
        assert!(
            (out.image[0][c] as f64 / exact - 1.0).abs() < 0.02,
            "channel {c}: {} against {exact}",
            out.image[0][c]
        );
    }
}

/// A sphere of non-absorbing fog (a null boundary) under a uniform environment: radiance
/// is conserved, so every pixel sees the environment's value at every depth of scattering.
fn furnace(albedo: f32, g: f32) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let xml = format!(
        r#"<scene version="3.0.0">
        {}
        <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
        <shape type="sphere"><bsdf type="null"/><medium type="homogeneous" name="interior">
            <float name="sigma_t" value="3"/><float name="albedo" value="{albedo}"/>
            <phase type="hg"><float name="g" value="{g}"/></phase></medium></shape>
        </scene>"#,
        sensor(30.0, 8, "0, 0, 4", "")
    );
    let scene = load(&write(&dir, "furnace.xml", &xml), &[], Backend::Embree);
    image(render(&scene, IntegratorKind::Path, 1024, 5, 2)).mean()
}

#[test]
fn a_scattering_furnace_keeps_the_environments_radiance() {
    for g in [0.0, 0.7, -0.5] {
        let mean = furnace(1.0, g);
        eprintln!("furnace, g = {g}: {mean:.5}");
        assert!((mean - 1.0).abs() < 0.01, "g = {g}: {mean}");
    }
    // Control: light lost to absorption shows.
    let absorbing = furnace(0.8, 0.0);
    assert!(absorbing < 0.95, "{absorbing}");
}

/// A small sphere light inside a ball of fog (a null sphere), seen from outside: light
/// subpaths must start in the fog (the medium found at the light's position, which no
/// boundary of its own names), or light tracing and BDPT would carry its light unattenuated
/// to the ball's edge. The integrators agree with the path tracer (whose two 4096-spp renders
/// differ by about 1%: the tolerance is 2.5%); the control, the ball without fog, differs.
/// (A point light in fog gives next-event estimation from nearby medium points an unbounded
/// variance, 1/d², which no test of means at these sample counts survives.)
#[test]
fn a_light_inside_a_medium_starts_its_paths_there() {
    let dir = tempfile::tempdir().unwrap();
    let ball = |inside: &str| {
        format!(
            r#"<scene version="3.0.0">
            {}
            <shape type="sphere"><bsdf type="null"/><medium type="homogeneous" name="interior">
                <float name="sigma_t" value="{inside}"/><float name="albedo" value="0.9"/></medium></shape>
            <shape type="rectangle"><transform name="to_world"><scale value="4"/><translate z="-2"/></transform>
                <bsdf type="diffuse"/></shape>
            <shape type="sphere"><point name="center" x="0" y="0.2" z="-0.3"/><float name="radius" value="0.15"/>
                <emitter type="area"><rgb name="radiance" value="30"/></emitter></shape>
            </scene>"#,
            sensor(40.0, 16, "0, 0, 4", "")
        )
    };
    let scene = load(&write(&dir, "ball.xml", &ball("1.5")), &[], Backend::Embree);
    let mean = |kind, spp, seed| image(render(&scene, kind, spp, seed, 2)).mean();
    let reference = (mean(IntegratorKind::Path, 4096, 1) + mean(IntegratorKind::Path, 4096, 2)) / 2.0;
    for (kind, spp) in [(IntegratorKind::Lighttrace, 512), (IntegratorKind::Bdpt, 256), (IntegratorKind::Pcbpt, 256)] {
        let m = (mean(kind, spp, 3) + mean(kind, spp, 4)) / 2.0;
        eprintln!("{}: {m:.5} against the path tracer's {reference:.5}", kind.name());
        assert!((m / reference - 1.0).abs() < 0.025, "{}: {m} against {reference}", kind.name());
    }
    let clear = load(&write(&dir, "clear.xml", &ball("0")), &[], Backend::Embree);
    let m = image(render(&clear, IntegratorKind::Bdpt, 256, 3, 2)).mean();
    assert!((m / reference - 1.0).abs() > 0.1, "{m} against {reference}");
}

/// Writes a one-channel grid of `res` cells, `value(i, j, k)` each, with the bounding box
/// `bbox` in its header.
fn write_grid(
    dir: &tempfile::TempDir,
    name: &str,
    res: [usize; 3],
    bbox: f32,
    value: impl Fn(usize, usize, usize) -> f32,
) {
    let mut data = Vec::new();
    for k in 0..res[2] {
        for j in 0..res[1] {
            for i in 0..res[0] {
                data.push(value(i, j, k));
            }
        }
    }
    let vol = VolFile { res, channels: 1, bbox: (glam::Vec3::splat(-bbox), glam::Vec3::splat(bbox)), data };
    std::fs::write(dir.path().join(name), vol_to_bytes(&vol)).unwrap();
}

/// A cube of side 2 at the origin filled with `medium`, under a uniform environment, seen
/// from z = 4 (a Mitsuba 3 file, or a 0.6 one with `legacy`).
fn medium_cube(medium: &str, fov: f32, legacy: bool) -> String {
    let version = if legacy { "0.6.0" } else { "3.0.0" };
    format!(
        r#"<scene version="{version}">
        {}
        <emitter type="constant"><rgb name="radiance" value="2"/></emitter>
        <shape type="cube"><bsdf type="null"/>{medium}</shape>
        </scene>"#,
        sensor(fov, 8, "0, 0, 4", "")
    )
}

/// The per-pixel differences of two renders: their mean and its standard error.
fn difference(a: &pcbpt::image_io::Image, b: &pcbpt::image_io::Image) -> (f64, f64) {
    let d: Vec<f64> = a.pixels.iter().zip(&b.pixels).map(|(p, q)| (p - q).element_sum() as f64 / 3.0).collect();
    mean_and_standard_error(&d)
}

/// A grid of one value (0.6, scaled by 2) over the cube renders as the homogeneous medium of
/// σt 1.2 — placed by Mitsuba 3's `to_world` over the unit cube, and by a Mitsuba 0.6 file
/// (the grid's own box) — with the path tracer and BDPT; the control (the grid's scale
/// halved) differs.
#[test]
fn a_constant_grid_renders_as_the_homogeneous_medium() {
    let dir = tempfile::tempdir().unwrap();
    write_grid(&dir, "constant.vol", [3, 4, 5], 1.0, |_, _, _| 0.6);
    let homogeneous = r#"<medium type="homogeneous" name="interior"><float name="sigma_t" value="1.2"/>
        <float name="albedo" value="0.8"/><phase type="hg"><float name="g" value="0.5"/></phase></medium>"#;
    let grid = |scale: f32| {
        format!(
            r#"<medium type="heterogeneous" name="interior">
            <volume type="gridvolume" name="sigma_t"><string name="filename" value="constant.vol"/>
                <transform name="to_world"><translate value="-0.5, -0.5, -0.5"/><scale value="2"/></transform></volume>
            <float name="scale" value="{scale}"/>
            <float name="albedo" value="0.8"/><phase type="hg"><float name="g" value="0.5"/></phase></medium>"#
        )
    };
    let legacy = r#"<medium type="heterogeneous" name="interior">
        <volume type="gridvolume" name="density"><string name="filename" value="constant.vol"/></volume>
        <volume type="constvolume" name="albedo"><spectrum name="value" value="0.8"/></volume>
        <float name="scale" value="2"/><phase type="hg"><float name="g" value="0.5"/></phase></medium>"#;
    let render_of = |name: &str, xml: String, kind, seed| {
        let scene = load(&write(&dir, name, &xml), &[], Backend::Embree);
        image(render(&scene, kind, 512, seed, 2))
    };
    for kind in [IntegratorKind::Path, IntegratorKind::Bdpt] {
        let reference = render_of("homogeneous.xml", medium_cube(homogeneous, 40.0, false), kind, 1);
        for (name, xml) in
            [("grid.xml", medium_cube(&grid(2.0), 40.0, false)), ("legacy.xml", medium_cube(legacy, 40.0, true))]
        {
            let (d, se) = difference(&render_of(name, xml, kind, 2), &reference);
            eprintln!("{} {name}: mean difference {d:.5} ± {se:.5} (image mean {:.4})", kind.name(), reference.mean());
            assert!(d.abs() < 4.0 * se, "{} {name}: {d} ± {se}", kind.name());
        }
        let (d, se) = difference(&render_of("thin.xml", medium_cube(&grid(1.0), 40.0, false), kind, 3), &reference);
        assert!(d.abs() > 8.0 * se, "control, {}: {d} ± {se}", kind.name());
    }
}

/// A cube whose absorbing extinction rises along z from `A` to `B` (64 cells, centred
/// samples), seen along its axis: every pixel keeps `exp(-∫σt)` of the environment, ratio
/// tracking's estimates averaged to within four standard errors. The trilinear lookup is
/// linear between the outer cells' centres and constant beyond, so ∫σt over the side of 2
/// is `(A + B)` exactly. The control is the transmittance of the ramp's maximum.
#[test]
fn an_absorbing_ramp_keeps_the_exponential_of_its_integral() {
    const A: f64 = 0.1;
    const B: f64 = 0.9;
    let n = 64;
    let dir = tempfile::tempdir().unwrap();
    write_grid(&dir, "ramp.vol", [1, 1, n], 1.0, |_, _, k| (A + (B - A) * (k as f64 + 0.5) / n as f64) as f32);
    let xml = medium_cube(
        r#"<medium type="heterogeneous" name="interior">
        <volume type="gridvolume" name="sigma_t"><string name="filename" value="ramp.vol"/>
            <transform name="to_world"><translate value="-0.5, -0.5, -0.5"/><scale value="2"/></transform></volume>
        <float name="albedo" value="0"/></medium>"#,
        1.0,
        false,
    );
    let scene = load(&write(&dir, "ramp.xml", &xml), &[], Backend::Embree);
    let img = image(render(&scene, IntegratorKind::Path, 4096, 1, 2));
    let values: Vec<f64> = img.pixels.iter().map(|p| p.element_sum() as f64 / 3.0).collect();
    let (mean, se) = mean_and_standard_error(&values);
    let exact = 2.0 * (-(A + B)).exp();
    eprintln!("ramp: {mean:.5} ± {se:.5} against {exact:.5}");
    assert!((mean - exact).abs() < 4.0 * se, "{mean} ± {se} against {exact}");
    let control = 2.0 * (-2.0 * B).exp();
    assert!((mean - control).abs() > 8.0 * se, "control: {mean} ± {se} against {control}");
}

/// MEMLT renders homogeneous media (its rows in `tests/reference.rs`) and refuses a
/// heterogeneous one, naming it and the integrators that render it: its acceptance needs the
/// exact density of a free flight.
#[test]
fn memlt_refuses_heterogeneous_media() {
    let dir = tempfile::tempdir().unwrap();
    write_grid(&dir, "ramp.vol", [2, 2, 2], 1.0, |_, _, k| 0.2 + k as f32);
    let smoke = r#"<medium type="heterogeneous" name="interior" id="smoke">
        <volume type="gridvolume" name="sigma_t"><string name="filename" value="ramp.vol"/></volume>
        <float name="albedo" value="0.8"/></medium>"#;
    let scene = load(&write(&dir, "smoke.xml", &medium_cube(smoke, 40.0, false)), &[], Backend::Embree);
    let e =
        integrator::render(&scene, &RenderOptions::new(IntegratorKind::Memlt, Budget::Spp(1))).err().expect("refused");
    let text = e.to_string();
    assert!(text.contains("`smoke` is heterogeneous") && text.contains("--integrator path"), "{text}");
    // The bidirectional integrators render it.
    assert!(integrator::render(&scene, &RenderOptions::new(IntegratorKind::Bdpt, Budget::Spp(1))).is_ok());
}
