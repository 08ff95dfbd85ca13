//! Mitsuba 0.6's `coating` and `roughcoating` in whole renders: a coated plane under a
//! uniform sky shows the albedo Fresnel's and Snell's laws give; coated spheres render to
//! the same image with the path tracer (radiance transport) and BDPT (which adds light
//! paths, in importance transport, and weights every strategy by the densities); an
//! index-matched clear layer renders exactly as its nested BSDF.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::bsdf::BsdfModel;
use pcbpt::bsdf::fresnel::fresnel_dielectric;
use pcbpt::image_io::Image;
use pcbpt::integrator::IntegratorKind;
use pcbpt::scene::Scene;

/// A Mitsuba 0.6 scene file in `dir` with `body` after a camera looking down -z from
/// `origin` with field of view `fov`.
fn scene(dir: &tempfile::TempDir, name: &str, origin: &str, fov: f32, size: u32, body: &str) -> Scene {
    let xml = format!(
        r#"<scene version="0.6.0">
    <integrator type="path"><integer name="maxDepth" value="8"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="{fov}"/>
        <transform name="toWorld"><lookat origin="{origin}" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sampleCount" value="16"/></sampler>
        <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/><rfilter type="box"/></film>
    </sensor>
    {body}
</scene>"#
    );
    let path = dir.path().join(name);
    std::fs::write(&path, xml).unwrap();
    load(&path, &[], Backend::Embree)
}

/// `2 ∫ g(μ) μ dμ` over [0, 1] by the midpoint rule.
fn hemispherical(g: impl Fn(f64) -> f64) -> f64 {
    let n = 20_000;
    (0..n).map(|i| (i as f64 + 0.5) / n as f64).map(|mu| 2.0 * g(mu) * mu).sum::<f64>() / n as f64
}

/// Mean of an image and the standard error of that mean, its pixels taken as independent.
fn mean_and_error(pixels: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = pixels.clone().count() as f64;
    let mean = pixels.clone().sum::<f64>() / n;
    let var = pixels.map(|p| (p - mean) * (p - mean)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

#[test]
fn a_coated_plane_under_a_uniform_sky_shows_the_layered_albedo() {
    // Seen head-on under radiance 1 from every direction, a layer of index η and absorption
    // σa d over a Lambertian base ρ shows F(1) + (1 - F(1)) (ρ/η²) e^{-σd} 2∫(1 - F) e^{-σd/μ'} μ dμ
    // (μ' the cosine inside, by Snell's law).
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        // (layer, η, ρ, σa d)
        (
            r#"<bsdf type="coating"><bsdf type="diffuse"><spectrum name="reflectance" value="0.8"/></bsdf></bsdf>"#,
            1.5046 / 1.000277,
            0.8,
            0.0,
        ),
        (
            r#"<bsdf type="coating"><float name="intIOR" value="1.8"/><float name="extIOR" value="1"/>
                <spectrum name="sigmaA" value="0.25"/><float name="thickness" value="2"/>
                <bsdf type="twosided"><bsdf type="diffuse"><spectrum name="reflectance" value="0.6"/></bsdf></bsdf></bsdf>"#,
            1.8,
            0.6,
            0.5,
        ),
    ];
    for (i, (layer, eta, rho, sigma_d)) in cases.into_iter().enumerate() {
        let body = format!(
            r#"<emitter type="constant"><spectrum name="radiance" value="1"/></emitter>
    <shape type="rectangle">{layer}</shape>"#
        );
        let s = scene(&dir, &format!("plane{i}.xml"), "0, 0, 10", 1.0, 16, &body);
        let img = image(render(&s, IntegratorKind::Path, 256, 11, 0));
        let (mean, err) = mean_and_error(img.pixels.iter().map(|p| ((p.x + p.y + p.z) / 3.0) as f64));
        let f = |mu: f64| fresnel_dielectric(mu as f32, eta as f32) as f64;
        let inside = |mu: f64| (1.0 - (1.0 - mu * mu) / (eta * eta)).sqrt();
        let transmitted = hemispherical(|mu| (1.0 - f(mu)) * (-sigma_d / inside(mu)).exp());
        let base = (1.0 - f(1.0)) * rho / (eta * eta) * (-sigma_d).exp() * transmitted;
        let expected = f(1.0) + base;
        eprintln!("plane {i}: mean {mean:.5} ± {err:.5}, expected {expected:.5}");
        assert!((mean - expected).abs() < 4.0 * err + 1e-4, "plane {i}: {mean} ± {err} vs {expected}");
        // Negative control: without the 1/η² of the layer, the base would show η² brighter.
        let wrong = f(1.0) + base * eta * eta;
        assert!((mean - wrong).abs() > 4.0 * err + 1e-4, "plane {i}: {mean} also passes for {wrong}");
    }
}

/// Two coated spheres (a varnished rough metal, a tinted rough coat over a coloured
/// Lambertian base) on a diffuse floor under a small area light.
fn spheres(dir: &tempfile::TempDir, name: &str, thickness: &str) -> Scene {
    let body = format!(
        r#"<shape type="rectangle">
        <transform name="toWorld"><scale value="4"/><translate z="-1"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.2, 0.2"/></bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="toWorld"><scale value="0.6"/><rotate x="1" angle="180"/><translate x="-1" y="0.3" z="2.5"/></transform>
        <emitter type="area"><rgb name="radiance" value="20, 20, 20"/></emitter>
    </shape>
    <shape type="sphere"><point name="center" x="-0.55" y="0" z="0"/><float name="radius" value="0.5"/>
        <bsdf type="coating"><float name="intIOR" value="1.5"/>
            <rgb name="sigmaA" value="0.2, 0.4, 0.8"/><float name="thickness" value="{thickness}"/>
            <bsdf type="roughconductor"><string name="material" value="Cu"/><float name="alpha" value="0.2"/></bsdf>
        </bsdf>
    </shape>
    <shape type="sphere"><point name="center" x="0.55" y="0" z="0"/><float name="radius" value="0.5"/>
        <bsdf type="roughcoating"><string name="intIOR" value="polypropylene"/><string name="distribution" value="ggx"/>
            <float name="alpha" value="0.15"/><rgb name="sigmaA" value="0.3, 0.1, 0.0"/><float name="thickness" value="{thickness}"/>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.5, 0.3"/></bsdf>
        </bsdf>
    </shape>"#
    );
    scene(dir, name, "0, -1.5, 3", 26.0, 32, &body)
}

/// The difference of two renders' means over the pixels of the left or the right half of
/// the image (one sphere each) and its standard error, from the per-pixel differences; and
/// the first render's mean there.
fn mean_difference(a: &Image, b: &Image, right: bool) -> (f64, f64, f64) {
    let w = a.width as usize;
    let half = |i: &usize| (i % w >= w / 2) == right;
    let diffs = (0..a.pixels.len()).filter(half).map(|i| ((a.pixels[i] - b.pixels[i]).element_sum() / 3.0) as f64);
    let (d, err) = mean_and_error(diffs);
    let (mean, _) = mean_and_error((0..a.pixels.len()).filter(half).map(|i| (a.pixels[i].element_sum() / 3.0) as f64));
    (d, err, mean)
}

/// Whether two renders agree on each half of the image (a sphere each): the difference of
/// their means there within 4 standard errors and within 1.5% of the mean.
fn halves_agree(what: &str, a: &Image, b: &Image) -> bool {
    let mut agree = true;
    for (right, name) in [(false, "coating over rough copper"), (true, "roughcoating over diffuse")] {
        let (d, err, mean) = mean_difference(a, b, right);
        eprintln!("{what}, {name}: {mean:.5} against {:.5}, difference {d:.5} ± {err:.5}", mean - d);
        agree &= d.abs() < 4.0 * err && d.abs() < 0.015 * mean;
    }
    agree
}

#[test]
fn path_tracing_and_bdpt_agree_on_coated_spheres() {
    // The path tracer samples the layers in radiance transport and weights its two
    // strategies by their densities; BDPT also traces light paths (importance transport)
    // and connects them, weighting every strategy by forward and reverse densities. A wrong
    // density, a value the sampler does not reproduce, or an importance BSDF that is not the
    // adjoint makes the two converge to different images.
    let dir = tempfile::tempdir().unwrap();
    let s = spheres(&dir, "spheres.xml", "1");
    let spp = 1024;
    let pt = image(render(&s, IntegratorKind::Path, spp, 1, 0));
    let bdpt = image(render(&s, IntegratorKind::Bdpt, spp, 2, 0));
    assert!(halves_agree("path against BDPT", &pt, &bdpt));
    // Negative control: layers half as thick again (absorbing more) are told apart.
    let thicker = spheres(&dir, "thicker.xml", "1.5");
    let bdpt_thicker = image(render(&thicker, IntegratorKind::Bdpt, spp, 2, 0));
    assert!(!halves_agree("path against BDPT of thicker layers", &pt, &bdpt_thicker));
}

#[test]
fn an_index_matched_clear_layer_renders_as_its_nested_bsdf() {
    // A layer whose index matches the exterior and that absorbs nothing neither reflects
    // nor bends: the path tracer's and BDPT's images are its nested BSDF's, bit for bit.
    // (Scene files cannot say so — Mitsuba 0.6 refuses matched indices — so the loaded
    // layer's index is set to 1.)
    let dir = tempfile::tempdir().unwrap();
    let room = r#"<shape type="rectangle">
        <transform name="toWorld"><scale value="0.5"/><rotate x="1" angle="180"/><translate x="-1" y="1" z="3"/></transform>
        <emitter type="area"><rgb name="radiance" value="30, 30, 30"/></emitter>
    </shape>
    <shape type="rectangle"><transform name="toWorld"><scale value="4"/><translate z="-1"/></transform>"#;
    let nested =
        r#"<bsdf type="roughconductor"><string name="material" value="Au"/><float name="alpha" value="0.3"/></bsdf>"#;
    let plain = scene(&dir, "plain.xml", "0, -1.5, 3", 45.0, 16, &format!("{room}{nested}</shape>"));
    let layered = format!(r#"{room}<bsdf type="coating"><float name="intIOR" value="1.5"/>{nested}</bsdf></shape>"#);
    let mut coated = scene(&dir, "coated.xml", "0, -1.5, 3", 45.0, 16, &layered);
    let before = image(render(&coated, IntegratorKind::Path, 16, 3, 1));
    for b in &mut coated.bsdfs {
        if let BsdfModel::Coating(c) = &mut b.model {
            c.eta = 1.0;
        }
    }
    for kind in [IntegratorKind::Path, IntegratorKind::Bdpt] {
        let a = image(render(&plain, kind, 16, 3, 1));
        let b = image(render(&coated, kind, 16, 3, 1));
        assert!(a.mean() > 0.01, "{kind:?}: a black image");
        assert!(a.pixels == b.pixels, "{kind:?}: means {} and {}", a.mean(), b.mean());
    }
    // Negative control: the layer of index 1.5 is not its nested BSDF.
    let a = image(render(&plain, IntegratorKind::Path, 16, 3, 1));
    assert!((before.mean() / a.mean() - 1.0).abs() > 0.05, "{} vs {}", before.mean(), a.mean());
}
