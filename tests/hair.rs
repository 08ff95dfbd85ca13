//! Mitsuba 0.6's `hair` shape: the traced strands against analytic cylinders, the two
//! backends against each other ray by ray, a hair scene with the path tracer and BDPT, and
//! the loader's errors (the reader's own checks: `src/scene/hair.rs`).

mod common;

use glam::Vec3;
#[cfg(feature = "obvhs")]
use pcbpt::accel::Hit;
use pcbpt::accel::{Accel, Backend, BuildOptions, Ray};
use pcbpt::integrator::IntegratorKind;
use pcbpt::math::{Frame, Transform};
use pcbpt::sampling::{Sampler, square_to_uniform_sphere};
use pcbpt::scene::hair::{Hair, HairParams, Strands, hair_to_ascii, hair_to_binary};
use pcbpt::scene::shape::{Shape, ShapeGeometry};
use pcbpt::scene::{LoadOptions, Scene};
use std::path::Path;

/// The backends this build has.
fn backends() -> Vec<Backend> {
    let mut b = vec![Backend::Embree];
    if cfg!(feature = "obvhs") {
        b.push(Backend::Obvhs);
    }
    b
}

/// A furball: `n` curly strands of 12 vertices growing out of the unit sphere.
fn furball(n: usize, seed: u64) -> Strands {
    let mut s = Sampler::new(&[seed]);
    let mut strands = Strands::default();
    for _ in 0..n {
        let dir = square_to_uniform_sphere(s.next_2d());
        let frame = Frame::from_normal(dir);
        let phase = s.next_1d() * 6.0;
        strands.starts.push(strands.vertices.len());
        for k in 0..12 {
            let a = phase + k as f32 * 0.8;
            let curl = (frame.s * a.cos() + frame.t * a.sin()) * 0.08;
            strands.vertices.push(dir * (1.0 + 0.06 * k as f32) + curl);
        }
    }
    strands
}

fn build(strands: &Strands, radius: f32) -> Hair {
    Hair::build(strands, &Transform::default(), HairParams { radius, ..HairParams::default() }).unwrap()
}

#[test]
fn hits_lie_on_the_analytic_cylinders() {
    // A bent strand: two segments, radius 0.1.
    let strands =
        Strands { vertices: vec![Vec3::ZERO, Vec3::new(4.0, 0.0, 0.0), Vec3::new(8.0, 1.0, 0.0)], starts: vec![0] };
    let r = 0.1;
    let hair = build(&strands, r);
    let shape = Shape::new(ShapeGeometry::Hair(hair.clone()), 0, false, "hair".into());
    let mut s = Sampler::new(&[3]);
    for backend in backends() {
        let accel = Accel::build(backend, &[shape.accel_geometry()], BuildOptions::default()).unwrap();
        for i in 0..2000 {
            // A ray perpendicular to segment `seg`'s axis, `b` off it, away from the joint.
            let seg = i % 2;
            let (a, e) = hair.segment(seg);
            let axis = (e - a).normalize();
            let frame = Frame::from_normal(axis);
            let phi = s.next_1d() * std::f32::consts::TAU;
            let (toward, side) = (
                frame.to_world(Vec3::new(phi.cos(), phi.sin(), 0.0)),
                frame.to_world(Vec3::new(-phi.sin(), phi.cos(), 0.0)),
            );
            let along = 0.2 + 0.6 * s.next_1d();
            let b = (2.0 * s.next_1d() - 1.0) * 0.99 * r;
            let c = a + (e - a) * along;
            let ray = Ray::new(c + toward * 3.0 + side * b, -toward);
            let hit = accel.intersect(&ray).unwrap_or_else(|| panic!("{backend}: ray {i} misses"));
            let expected = 3.0 - (r * r - b * b).sqrt();
            assert!((hit.t - expected).abs() < 2e-4, "{backend}, ray {i}: t {} against {expected}", hit.t);
            assert_eq!(hit.prim as usize, seg);
            let si = shape.interaction(&ray, &hit);
            let normal = (toward * (r * r - b * b).sqrt() + side * b) / r;
            assert!((si.ng - normal).length() < 2e-3 && (si.shading.n - normal).length() < 2e-3, "{}", si.ng);
            assert!(si.ng.dot(axis).abs() < 1e-5 && si.shading.s.dot(axis) > 0.9999);
            assert!(((si.p - c).length() - r).abs() < 1e-5 * (1.0 + c.length()));
            // u runs along the strand by length (segment lengths 4 and √17).
            let total = 4.0 + 17f32.sqrt();
            let u = if seg == 0 { 4.0 * along / total } else { (4.0 + 17f32.sqrt() * along) / total };
            assert!((si.uv.x - u).abs() < 1e-3, "u {} against {u}", si.uv.x);
            // Past the radius: a miss.
            let wide = Ray::new(c + toward * 3.0 + side * (r * 1.01), -toward);
            assert!(accel.intersect(&wide).is_none() && !accel.occluded(&wide));
        }
    }
}

/// Whether `p` lies on the tube of hit `h`'s segment (within `eps`).
#[cfg(feature = "obvhs")]
fn on_segment(hair: &Hair, h: &Hit, p: Vec3, eps: f32) -> bool {
    let (a, b) = hair.segment(h.prim as usize);
    let (c, _) = pcbpt::accel::curve::closest_on_segment(p, a, b);
    ((p - c).length() - hair.radius).abs() <= eps
}

/// How close the ray's line passes to the tube's surface around segment `seg` (zero for a
/// ray that touches the tube tangentially): its distance from the segment, less the radius.
#[cfg(feature = "obvhs")]
fn grazing(hair: &Hair, seg: usize, r: &Ray) -> f64 {
    let (a, b) = hair.segment(seg);
    let (a, axis, o, d) = (a.as_dvec3(), (b - a).as_dvec3(), r.o.as_dvec3(), r.d.as_dvec3().normalize());
    // The segment's parameter closest to the line (the distance is convex in it).
    let w = a - o;
    let (aa, ad) = (axis.length_squared(), axis.dot(d));
    let denom = aa - ad * ad;
    let s = if denom > 0.0 { ((ad * w.dot(d) - w.dot(axis)) / denom).clamp(0.0, 1.0) } else { 0.0 };
    let q = a + axis * s - o;
    ((q - d * q.dot(d)).length() - hair.radius as f64).abs()
}

#[cfg(feature = "obvhs")]
#[test]
fn obvhs_and_embree_agree_ray_by_ray_on_a_furball() {
    // Thin hair, and hair as thick as its segments are long (more rays meet the joints).
    for radius in [0.01, 0.04] {
        compare_on_furball(radius);
    }
}

#[cfg(feature = "obvhs")]
fn compare_on_furball(radius: f32) {
    let hair = build(&furball(150, 1), radius);
    let geometry = [hair.accel_geometry()];
    let embree = Accel::build(Backend::Embree, &geometry, BuildOptions::default()).unwrap();
    let obvhs = Accel::build(Backend::Obvhs, &geometry, BuildOptions::default()).unwrap();
    let mut s = Sampler::new(&[11]);
    let (n, mut hits, mut joints, mut ties) = (20_000, 0, 0, 0);
    for i in 0..n {
        // From around the furball towards a point inside it: most rays meet hair.
        let o = square_to_uniform_sphere(s.next_2d()) * 2.5;
        let target = square_to_uniform_sphere(s.next_2d()) * (1.0 + 0.7 * s.next_1d());
        let ray = Ray::new(o, (target - o).normalize());
        let (e, b) = (embree.intersect(&ray), obvhs.intersect(&ray));
        match (e, b) {
            (None, None) => {}
            (Some(x), Some(y)) if (x.t - y.t).abs() <= 1e-4 * x.t => {
                hits += 1;
                if x.prim != y.prim {
                    // A joint's sphere: each segment's tube holds the other's point.
                    assert!(on_segment(&hair, &x, ray.at(y.t), 1e-5) && on_segment(&hair, &y, ray.at(x.t), 1e-5));
                    joints += 1;
                }
            }
            _ => {
                // Only a ray that grazes the tube (within 1e-4 of the radius) may differ.
                let near = [e, b].into_iter().flatten().min_by(|x, y| x.t.total_cmp(&y.t)).unwrap();
                let g = grazing(&hair, near.prim as usize, &ray);
                assert!(g < 1e-4 * hair.radius as f64, "ray {i} {ray:?}: Embree {e:?}, obvhs {b:?} ({g})");
                ties += 1;
            }
        }
        let seg = Ray { tmax: 3.0 * s.next_1d(), ..ray };
        if embree.occluded(&seg) != obvhs.occluded(&seg) {
            ties += 1;
        }
    }
    eprintln!(
        "radius {radius}, {n} rays: {hits} hits agree ({joints} at joints, reported by either segment); {ties} grazing ties"
    );
    assert!(hits > n / 4, "only {hits} of {n} rays hit the furball");
    assert!(ties <= n / 1000, "{ties} grazing ties in {n} rays");
}

fn scene_with(dir: &Path, hair_file: &str, hair: &str) -> std::path::PathBuf {
    let text = format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 1.5, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/></film>
    </sensor>
    <shape type="sphere"><point name="center" x="1" y="3" z="2"/><float name="radius" value="0.4"/>
        <emitter type="area"><rgb name="radiance" value="15"/></emitter></shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="5"/><translate y="-1.5"/></transform>
    </shape>
    <shape type="hair">
        <string name="filename" value="{hair_file}"/>
        {hair}
    </shape>
</scene>"#
    );
    let path = dir.join("scene.xml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn path_tracing_and_bdpt_agree_on_a_furball() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("fur.mitshair"), hair_to_binary(&furball(400, 2))).unwrap();
    let diffuse = r#"<float name="radius" value="0.015"/><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.5, 0.3"/></bsdf>"#;
    let path = scene_with(dir.path(), "fur.mitshair", diffuse);
    let scene = common::load(&path, &[], Backend::Embree);
    let mean = |kind, seed| {
        let img = common::image(common::render(&scene, kind, 64, seed, 0));
        img.pixels.iter().map(|p| p.element_sum() as f64).sum::<f64>() / (3 * img.pixels.len()) as f64
    };
    let (pt, bd) = (mean(IntegratorKind::Path, 1), mean(IntegratorKind::Bdpt, 2));
    eprintln!("image mean: path {pt:.5}, bdpt {bd:.5} (ratio {:.4})", bd / pt);
    assert!(pt > 0.01 && (bd / pt - 1.0).abs() < 0.02, "path {pt}, bdpt {bd}");
    // The hair is there: without it, the image changes.
    std::fs::write(dir.path().join("far.mitshair"), "100 100 100\n100 100 101\n").unwrap();
    let bare = common::load(&scene_with(dir.path(), "far.mitshair", diffuse), &[], Backend::Embree);
    let img = common::image(common::render(&bare, IntegratorKind::Path, 64, 1, 0));
    let bare_mean = img.pixels.iter().map(|p| p.element_sum() as f64).sum::<f64>() / (3 * img.pixels.len()) as f64;
    assert!((bare_mean / pt - 1.0).abs() > 0.05, "with hair {pt}, without {bare_mean}");
}

fn load_error(dir: &Path, hair_file: &str, hair: &str) -> String {
    let path = scene_with(dir, hair_file, hair);
    match Scene::load(&path, &LoadOptions::default()) {
        Ok(_) => panic!("{hair} loaded"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_hair_gives_errors_naming_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("ok.mitshair"), hair_to_ascii(&furball(3, 1))).unwrap();
    // The scene's <shape type="hair"> is on line 11, its filename on line 12, the extra
    // properties on line 13.
    let e = load_error(d, "missing.mitshair", "");
    assert!(
        e.contains("scene.xml:12:") && e.contains("hair file") && e.contains("missing.mitshair does not exist"),
        "{e}"
    );
    for (prop, needle) in [
        (r#"<float name="radius" value="0"/>"#, "radius must be positive, got 0"),
        (r#"<float name="radius" value="-0.1"/>"#, "radius must be positive, got -0.1"),
        (r#"<float name="reduction" value="1"/>"#, "reduction must lie in [0, 1)"),
    ] {
        let e = load_error(d, "ok.mitshair", prop);
        assert!(e.contains("scene.xml:13:") && e.contains("ok.mitshair") && e.contains(needle), "{e}");
    }
    let e = load_error(d, "ok.mitshair", r#"<emitter type="area"/>"#);
    assert!(e.contains("scene.xml:13:") && e.contains("not an area light"), "{e}");
    let e = load_error(d, "ok.mitshair", r#"<float name="radious" value="0.1"/>"#);
    assert!(e.contains("radious"), "{e}");
    std::fs::write(d.join("bad.mitshair"), "0 0 0\n1 0 0\n\n2 0 zero\n").unwrap();
    let e = load_error(d, "bad.mitshair", "");
    assert!(e.contains("scene.xml:12:") && e.contains("bad.mitshair:4:") && e.contains("\"2 0 zero\""), "{e}");
    let mut truncated = hair_to_binary(&furball(2, 1));
    truncated.truncate(truncated.len() - 3);
    std::fs::write(d.join("cut.mitshair"), truncated).unwrap();
    let e = load_error(d, "cut.mitshair", "");
    assert!(e.contains("cut.mitshair") && e.contains("ends after 23 of its 24 vertices"), "{e}");
}

#[test]
fn mitsuba_06_property_names_are_read() {
    // A 0.6 file: angleThreshold and toWorld, upgraded; the radius scales with toWorld.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("h.mitshair"), "0 0 0\n1 0 0\n2 0.01 0\n").unwrap();
    let text = r#"<scene version="0.6.0">
    <sensor type="perspective"><float name="fov" value="45"/><film type="hdrfilm"/></sensor>
    <emitter type="constant"/>
    <shape type="hair"><string name="filename" value="h.mitshair"/><float name="radius" value="0.1"/>
        <float name="angleThreshold" value="0.1"/><transform name="toWorld"><scale value="2"/></transform></shape>
</scene>"#;
    let scene = Scene::load_str(text, &dir.path().join("scene.xml"), &LoadOptions::default()).unwrap();
    let ShapeGeometry::Hair(h) = &scene.shapes[0].geometry else { panic!("not hair") };
    // The bend of 0.57° is above the threshold of 0.1°: no merge.
    assert_eq!(h.vertices.len(), 3);
    assert!((h.radius - 0.2).abs() < 1e-6 && (h.vertices[2] - Vec3::new(4.0, 0.02, 0.0)).length() < 1e-6);
}

#[test]
fn every_integrator_renders_hair() {
    use clap::ValueEnum;
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("fur.mitshair"), hair_to_ascii(&furball(60, 3))).unwrap();
    let glossy =
        r#"<float name="radius" value="0.02"/><bsdf type="roughconductor"><float name="alpha" value="0.3"/></bsdf>"#;
    let path = scene_with(dir.path(), "fur.mitshair", glossy);
    let options = LoadOptions { resolution: Some((12, 12)), ..Default::default() };
    let scene = Scene::load(&path, &options).unwrap();
    for kind in IntegratorKind::value_variants() {
        // Merging alone finds the 144 light paths of an iteration here only with a radius
        // far above the default (a tenth of the scene's): light reaches the image through
        // merges and nothing else.
        let out = common::render_with(&scene, *kind, 2, 1, 2, &|o| {
            if *kind == IntegratorKind::Bpm {
                let args = ["--vcm-radius".to_string(), "0.1".to_string()];
                o.method = pcbpt::integrator::registry::parse_options(*kind, &args).unwrap();
            }
        });
        assert!(
            out.image.iter().all(|p| p.is_finite() && p.min_element() >= 0.0),
            "{}: a pixel is negative or not finite",
            kind.name()
        );
        assert!(out.image.iter().any(|p| p.max_element() > 0.0), "{}: a black image", kind.name());
    }
}
