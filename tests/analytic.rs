//! Scenes with exact answers: furnaces (closed emitting, reflecting enclosures, where
//! every ray sees `Le Σ_{k<d} ρ^k`) and a point light over a diffuse plane.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::integrator::IntegratorKind;
use std::path::PathBuf;

const LE: f32 = 1.5;
const RHO: f32 = 0.6;

fn write_scene(dir: &tempfile::TempDir, name: &str, body: &str, max_depth: i32) -> PathBuf {
    let xml = format!(
        r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="70"/>
        <transform name="to_world"><lookat origin="0.1, 0.2, 0.05" target="1, 0.5, 0.3" up="0, 0, 1"/></transform>
        <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/><rfilter type="box"/></film>
    </sensor>
    {body}
</scene>"#
    );
    let path = dir.path().join(name);
    std::fs::write(&path, xml).unwrap();
    path
}

fn enclosure(shape: &str) -> String {
    format!(
        r#"<shape type="{shape}">
        <transform name="to_world"><scale value="2"/></transform>
        <boolean name="flip_normals" value="true"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="{RHO}"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="{LE}"/></emitter>
    </shape>"#
    )
}

fn furnace(shape: &str, max_depth: i32, spp: u32) -> (f64, f64) {
    let dir = tempfile::tempdir().unwrap();
    let path = write_scene(&dir, "furnace.xml", &enclosure(shape), max_depth);
    let scene = load(&path, &[], Backend::Embree);
    let img = image(render(&scene, IntegratorKind::Path, spp, 7, 0));
    let depth = if max_depth < 0 { f64::INFINITY } else { max_depth as f64 };
    let expected = LE as f64 * (1.0 - (RHO as f64).powf(depth)) / (1.0 - RHO as f64);
    (img.mean(), expected)
}

#[test]
fn sphere_furnace_every_depth() {
    for (d, tol) in [(1, 1e-6), (2, 0.01), (3, 0.01), (5, 0.01), (-1, 0.01)] {
        let (mean, expected) = furnace("sphere", d, 64);
        eprintln!("sphere furnace, max_depth {d}: {mean:.5} (exact {expected:.5})");
        assert!((mean / expected - 1.0).abs() < tol, "max_depth {d}: mean {mean}, exact {expected}");
    }
}

#[test]
fn cube_furnace_unlimited_depth() {
    let (mean, expected) = furnace("cube", -1, 64);
    assert!((mean / expected - 1.0).abs() < 0.01, "mean {mean}, exact {expected}");
}

#[test]
fn furnace_detects_a_missing_bounce() {
    // Negative control: the furnace tolerance separates neighbouring depths.
    let (mean, _) = furnace("sphere", 4, 64);
    let expected5 = LE as f64 * (1.0 - (RHO as f64).powi(5)) / (1.0 - RHO as f64);
    assert!((mean / expected5 - 1.0).abs() > 0.03);
}

#[test]
fn point_light_over_a_diffuse_plane() {
    // Camera and light 2 units above a plane of albedo ρ, looking straight down through a
    // narrow field of view: the centre pixel sees ρ/π · I / h².
    let dir = tempfile::tempdir().unwrap();
    let xml = r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="0.5"/>
        <transform name="to_world"><lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="3"/><integer name="height" value="3"/><rfilter type="box"/></film>
    </sensor>
    <emitter type="point"><point name="position" value="0, 0, 2"/><rgb name="intensity" value="4, 2, 1"/></emitter>
    <shape type="rectangle"><transform name="to_world"><scale value="10"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.25, 0.8"/></bsdf></shape>
</scene>"#;
    let path = dir.path().join("point.xml");
    std::fs::write(&path, xml).unwrap();
    let scene = load(&path, &[], Backend::Embree);
    let img = image(render(&scene, IntegratorKind::Path, 16, 0, 1));
    let c = img.get(1, 1);
    let expected = glam::Vec3::new(0.5 * 4.0, 0.25 * 2.0, 0.8 * 1.0) / std::f32::consts::PI / 4.0;
    assert!((c - expected).abs().max_element() < 1e-4 * expected.max_element(), "{c} vs {expected}");
}

/// A sphere filling the view, under a uniform environment of radiance 1.
fn sphere_in_constant_environment(bsdf: &str, max_depth: i32) -> pcbpt::image_io::Image {
    let dir = tempfile::tempdir().unwrap();
    let xml = format!(
        r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="10"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/><rfilter type="box"/></film>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
    <shape type="sphere"><float name="radius" value="1"/>{bsdf}</shape>
</scene>"#
    );
    let path = dir.path().join("env.xml");
    std::fs::write(&path, xml).unwrap();
    let scene = load(&path, &[], Backend::Embree);
    image(render(&scene, IntegratorKind::Path, 64, 3, 0))
}

#[test]
fn convex_diffuse_object_in_a_uniform_environment_reflects_rho() {
    // Nothing occludes a convex object's view of the sky: every point sees radiance ρ L.
    let img = sphere_in_constant_environment(
        r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.5, 0.7"/></bsdf>"#,
        -1,
    );
    let m = img.pixels.iter().fold(glam::Vec3::ZERO, |a, p| a + *p) / img.pixels.len() as f32;
    assert!((m - glam::Vec3::new(0.3, 0.5, 0.7)).abs().max_element() < 0.01, "{m}");
}

#[test]
fn glass_sphere_vanishes_in_a_uniform_environment() {
    // A lossless dielectric in a uniform field of radiance: everything seen is radiance 1.
    for bsdf in [r#"<bsdf type="dielectric"/>"#, r#"<bsdf type="thindielectric"/>"#] {
        let img = sphere_in_constant_environment(bsdf, -1);
        let mean = img.mean();
        assert!((mean - 1.0).abs() < 0.01, "{bsdf}: {mean}");
    }
    // Negative control: with too few bounces, light is lost inside the glass.
    let img = sphere_in_constant_environment(r#"<bsdf type="dielectric"/>"#, 2);
    assert!(img.mean() < 0.9, "{}", img.mean());
}

#[test]
fn white_rough_conductor_sphere_reflects_at_most_what_it_receives() {
    // A white rough mirror under a uniform sky: single-scattering microfacets lose energy
    // (more as roughness grows) but never create it; a nearly smooth one loses almost none.
    let mut previous = f64::INFINITY;
    for alpha in ["0.01", "0.3", "0.8"] {
        let img = sphere_in_constant_environment(
            &format!(
                r#"<bsdf type="roughconductor"><float name="alpha" value="{alpha}"/><string name="distribution" value="ggx"/></bsdf>"#
            ),
            -1,
        );
        let mean = img.mean();
        eprintln!("alpha {alpha}: {mean}");
        assert!(mean <= 1.0 + 0.005 && mean < previous + 0.005, "alpha {alpha}: {mean}");
        if alpha == "0.01" {
            assert!(mean > 0.98, "{mean}");
        }
        previous = mean;
    }
}
