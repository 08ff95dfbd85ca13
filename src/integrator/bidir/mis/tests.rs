//! MIS weights on constructed paths: for every split of a path into a light and a camera
//! subpath (built the way the walks build them, with the densities the connection must
//! patch poisoned), the weights sum to one; for paths without Dirac deltas they equal the
//! weights computed from full path densities.

use crate::bsdf::microfacet::{Microfacet, MicrofacetType, Roughness};
use crate::bsdf::{Bsdf, BsdfModel};
use crate::integrator::Counters;
use crate::integrator::bidir::mis::*;
use crate::integrator::bidir::pool::LightPool;
use crate::integrator::bidir::walk::{WalkLimits, camera_subpath, light_subpath};
use crate::integrator::budget::{Shares, mis_shares};
use crate::integrator::lvc::LvcCounts;
use crate::integrator::pcbpt::{Blend, Cache, DistanceTerm, PcCounts, PcMis, PcOptions, PoolOptions, trace_records};
use crate::integrator::spcbpt::{Measured, Model, SpCounts, test_model};
use crate::light::{Light, LightSampler};
use crate::math::{Frame, Rgb};
use crate::sampling::Sampler;
use crate::scene::{LoadOptions, Scene};
use crate::texture::Texture;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Variant {
    Diffuse,
    Glossy,
    Mirror,
    PointLight,
    SphereLight,
    /// `veach-ajar` itself: textures, rough conductors, glass, two-sided BSDFs, a light
    /// seen through a gap (where PCBPT's resampling counts vary most).
    VeachAjar,
    /// An importance-sampled environment map and a constant one, beside the area light.
    Envmap,
    /// A directional light (a delta direction) beside the area light.
    Directional,
    /// Mitsuba 3's sun and sky (`sunsky`) beside the area light: the sun a small cone of
    /// directions, the sky a tabulated density, combined as one sky.
    Sunsky,
    /// Fog filling the box (the camera's medium, bounded by nothing): medium vertices
    /// between the surface ones, with a forward-scattering phase function.
    Fog,
}

fn scene(variant: Variant) -> Scene {
    let file =
        if variant == Variant::VeachAjar { "scenes/veach-ajar/scene.xml" } else { "scenes/cornell-box/scene.xml" };
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
    let overrides = vec![("resx".into(), "48".into()), ("resy".into(), "40".into())];
    let mut scene = Scene::load(&path, &LoadOptions { overrides, ..Default::default() }).unwrap();
    let shape = |scene: &Scene, name: &str| scene.shapes.iter().position(|s| s.name == name).unwrap();
    let rough = |a: f32, kind| BsdfModel::RoughConductor {
        distribution: Roughness::Fixed(Microfacet { kind, alpha_u: a, alpha_v: a * 0.6, sample_visible: true }),
        eta: Rgb::new(0.2, 0.9, 1.1),
        k: Rgb::new(3.9, 2.4, 2.2),
        specular_reflectance: Texture::Constant(Rgb::ONE),
    };
    let set = |scene: &mut Scene, name: &str, model: BsdfModel| {
        let s = shape(scene, name);
        scene.bsdfs.push(Bsdf { model, two_sided: true, perturbation: None, opacity: None });
        scene.shapes[s].bsdf = scene.bsdfs.len() - 1;
    };
    match variant {
        Variant::Diffuse | Variant::VeachAjar => {}
        Variant::Fog => {
            let phase = crate::medium::Phase::HenyeyGreenstein { g: 0.4 };
            scene.media.push(crate::medium::Medium::new(
                Rgb::new(0.1, 0.15, 0.2),
                Rgb::splat(0.7),
                phase,
                "fog".into(),
            ));
            scene.camera_medium = Some(0);
            scene.volumetric = true;
        }
        Variant::Glossy => {
            set(&mut scene, "TallBox", rough(0.15, MicrofacetType::Ggx));
            set(&mut scene, "BackWall", rough(0.4, MicrofacetType::Beckmann));
        }
        Variant::Mirror => {
            set(
                &mut scene,
                "ShortBox",
                BsdfModel::Conductor {
                    eta: Rgb::splat(0.2),
                    k: Rgb::splat(3.0),
                    specular_reflectance: Texture::Constant(Rgb::ONE),
                },
            );
            set(&mut scene, "LeftWall", rough(0.2, MicrofacetType::Ggx));
        }
        Variant::Envmap | Variant::Directional | Variant::Sunsky => {
            if variant == Variant::Sunsky {
                // The sun shines in through the open front of the box, the sky's +z up is +y.
                let to_world = glam::Mat3::from_rotation_x(-0.5 * std::f32::consts::PI);
                let params = crate::light::sunsky::SunSkyParams {
                    to_world,
                    sun_local: to_world.inverse() * Vec3::new(-0.3, 0.5, 1.0).normalize(),
                    turbidity: 3.0,
                    albedo: Rgb::splat(0.3),
                    sun_scale: 0.3,
                    sky_scale: 0.2,
                    sun_aperture: crate::light::sunsky::SUN_APERTURE_DEG,
                    complex_sun: false,
                    sun06: false,
                };
                let sky = crate::light::sunsky::Sky::new(&params);
                let sun = crate::light::sunsky::Sun::new(&params);
                scene.lights.push(Light::Sky(std::sync::Arc::new(sky)));
                scene.lights.push(Light::Sun(std::sync::Arc::new(sun)));
            } else if variant == Variant::Envmap {
                let (w, h) = (32, 16);
                let texels = (0..w * h)
                    .map(|i| {
                        let (x, y) = ((i % w) as f32, (i / w) as f32);
                        let hot = if (10.0..12.0).contains(&x) && (4.0..6.0).contains(&y) { 20.0 } else { 0.0 };
                        Vec3::new(1.0 + hot + x / 8.0, 2.0 - y / 8.0 + hot, 0.5 + hot)
                    })
                    .collect();
                let bm = std::sync::Arc::new(crate::texture::Bitmap::new(
                    w as u32,
                    h as u32,
                    texels,
                    crate::texture::FilterType::Bilinear,
                    crate::texture::WrapMode::Repeat,
                ));
                let env = crate::light::EnvMap::new(bm, glam::Mat3::from_rotation_x(0.4), 0.05);
                scene.lights.push(Light::Envmap(std::sync::Arc::new(env)));
                scene.lights.push(Light::Constant { radiance: Rgb::new(0.02, 0.03, 0.04) });
            } else {
                let direction = Vec3::new(0.3, -0.5, -1.0).normalize();
                scene.lights.push(Light::Directional { direction, irradiance: Rgb::splat(0.5) });
            }
            scene.infinite_lights = (0..scene.lights.len()).filter(|&i| scene.lights[i].is_infinite()).collect();
            scene.light_sampler = LightSampler::new(&scene.lights, &scene.shapes, &scene.bounds);
        }
        Variant::PointLight => {
            scene.lights.push(Light::Point { position: Vec3::new(0.3, 1.5, 0.2), intensity: Rgb::splat(2.0) });
            scene.light_sampler = LightSampler::new(&scene.lights, &scene.shapes, &scene.bounds);
        }
        Variant::SphereLight => {
            // A sphere emitter: next-event estimation samples its cone, light paths its area.
            let mut sph = crate::scene::shape::Shape::new(
                crate::scene::shape::ShapeGeometry::Sphere { center: Vec3::new(-0.4, 1.2, 0.3), radius: 0.2 },
                0,
                false,
                "sphere".into(),
            );
            sph.prepare_sampling();
            sph.light = Some(scene.lights.len());
            scene.lights.push(Light::Area { shape: scene.shapes.len(), radiance: Texture::Constant(Rgb::splat(3.0)) });
            scene.shapes.push(sph);
            let geometry: Vec<_> = scene.shapes.iter().map(|s| s.accel_geometry()).collect();
            scene.accel = crate::accel::Accel::build(Default::default(), &geometry, Default::default()).unwrap();
            scene.light_sampler = LightSampler::new(&scene.lights, &scene.shapes, &scene.bounds);
        }
    }
    scene
}

/// `x_0` as the end of a camera subpath: a surface point of an area light, or the sky
/// where the camera walk leaves the scene towards a light at infinity.
fn as_surface(scene: &Scene, v: &Vertex) -> Option<Vertex> {
    let VertexKind::Light(l) = v.kind else { return Some(*v) };
    if scene.lights[l as usize].at_infinity() {
        return (!scene.lights[l as usize].is_unreachable()).then_some(Vertex {
            kind: VertexKind::Sky,
            connectible: false,
            ..*v
        });
    }
    let Light::Area { shape, .. } = &scene.lights[l as usize] else { return None };
    let mut s = *v;
    s.kind = VertexKind::Surface;
    s.shape = *shape as u32;
    s.bsdf = scene.shapes[*shape].bsdf as u32;
    s.frame = Frame::from_normal(v.ng);
    s.connectible = !s.bsdf(scene).is_delta();
    Some(s)
}

fn as_light(scene: &Scene, v: &Vertex) -> Vertex {
    match v.kind {
        VertexKind::Light(_) => *v,
        _ => {
            let l = scene.shapes[v.shape as usize].light.unwrap();
            Vertex::light(l, v.p, v.ng, v.uv, Rgb::ONE, 0.0)
        }
    }
}

fn is_delta_surface(scene: &Scene, v: &Vertex) -> bool {
    v.kind == VertexKind::Surface && v.bsdf(scene).is_delta()
}

/// The subpaths strategy `s` uses for the full path `x` (light end first), with the
/// densities a walk writes and NaN where the connection must patch them.
fn subpaths(scene: &Scene, x: &[Vertex], s: usize) -> Option<(Vec<Vertex>, Vec<Vertex>)> {
    let n = x.len();
    let t = n - s;
    let mut light: Vec<Vertex> = Vec::new();
    for i in 0..s {
        let mut v = if i == 0 { as_light(scene, &x[0]) } else { x[i] };
        v.pdf_fwd = match i {
            0 => v.pdf_light_origin(scene),
            1 => light[0].pdf_light(scene, &x[1]),
            _ => x[i - 1].pdf(scene, Some(&x[i - 2]), &x[i]),
        };
        v.pdf_rev = if i + 3 <= s { x[i + 1].pdf(scene, Some(&x[i + 2]), &x[i]) } else { f32::NAN };
        if i == 1 && x[0].at_infinity() {
            v.wo = x[0].ng;
            v.to_prev = 1.0;
        } else if i > 0 {
            v.wo = (x[i - 1].p - x[i].p).normalize();
            v.to_prev = x[i - 1].cos_area(v.wo) / x[i - 1].p.distance_squared(x[i].p);
        }
        v.delta = is_delta_surface(scene, &v);
        light.push(v);
    }
    let mut camera: Vec<Vertex> = Vec::new();
    for j in 0..t {
        let i = n - 1 - j;
        let mut v = if i == 0 { as_surface(scene, &x[0])? } else { x[i] };
        v.pdf_fwd = match j {
            0 => 1.0,
            1 => x[n - 1].pdf(scene, None, &x[i]),
            _ => x[i + 1].pdf(scene, Some(&x[i + 2]), &x[i]),
        };
        v.pdf_rev = if j + 3 <= t { x[i - 1].pdf(scene, Some(&x[i - 2]), &x[i]) } else { f32::NAN };
        if j > 0 {
            v.wo = (x[i + 1].p - x[i].p).normalize();
            v.to_prev = x[i + 1].cos_area(v.wo) / x[i + 1].p.distance_squared(x[i].p);
        }
        v.delta = is_delta_surface(scene, &v);
        camera.push(v);
    }
    Some((light, camera))
}

/// Full paths of 2–8 vertices made from traced subpaths.
fn paths(scene: &Scene, seed: u64, want: usize) -> Vec<Vec<Vertex>> {
    let limits = WalkLimits::new(8, 100);
    let mut out = Vec::new();
    let mut counters = Counters::default();
    let (mut lp, mut cp) = (Vec::new(), Vec::new());
    let mut i = 0u64;
    while out.len() < want {
        i += 1;
        assert!(i < 100_000, "could not build enough paths");
        let mut rng = Sampler::new(&[seed, i]);
        let pos = Vec2::new(48.0, 40.0) * rng.next_2d();
        camera_subpath(scene, pos, &limits, &mut rng, &mut cp, &mut counters);
        light_subpath(scene, &limits, &mut rng, &mut lp, &mut counters);
        let a = 1 + (rng.next_u32() as usize % lp.len().clamp(1, 4));
        let b = 1 + (rng.next_u32() as usize % cp.len().clamp(1, 4));
        if lp.is_empty() || a > lp.len() || b > cp.len() || a + b < 2 {
            continue;
        }
        let mut x: Vec<Vertex> = lp[..a].to_vec();
        x.extend(cp[..b].iter().rev());
        // Every vertex must be reachable from both ends (the two subpaths were traced
        // independently, so their junction may not be): the vertex before the camera lies
        // on the image, and every generation density of the path is positive.
        if x.iter().skip(1).take(x.len() - 2).any(|v| !v.scatters()) || scene.camera.connect(x[x.len() - 2].p).is_none()
        {
            continue;
        }
        let has_delta = x.iter().any(|v| is_delta_surface(scene, v));
        let densities_positive = (0..x.len() - 1).all(|i| {
            let fwd = if i == 0 { x[0].pdf_light(scene, &x[1]) } else { x[i].pdf(scene, Some(&x[i - 1]), &x[i + 1]) };
            let n = x.len();
            let j = n - 1 - i;
            let rev = if j == n - 1 {
                x[n - 1].pdf(scene, None, &x[n - 2])
            } else {
                x[j].pdf(scene, Some(&x[j + 1]), &x[j - 1])
            };
            fwd > 0.0 && rev > 0.0
        });
        if !has_delta && !densities_positive {
            continue;
        }
        out.push(x);
    }
    out
}

/// Path-dependent counts, like PCBPT's `N M P(y | z)`.
struct Positional;

impl StrategyCounts for Positional {
    fn count(&self, path: &FullPath, s: usize, t: usize) -> f32 {
        if s >= 2 && t >= 2 { 0.3 + path.get(s - 1).p.x.abs() + 0.5 * path.get(s).p.z.abs() } else { 1.0 }
    }
}

/// A PCBPT cache over a pool of `m` light paths, with stride-8 records.
fn pc_cache(scene: &Scene, m: usize, term: DistanceTerm) -> Cache {
    let limits = WalkLimits::new(8, 3);
    let (pool, _, _) = LightPool::trace::<Counts>(scene, &limits, m, 7, 0, None);
    let opts = PcOptions { stride: 8, ..PcOptions::default() };
    let (records, _) = trace_records(scene, &limits, &opts, 7, 0);
    let blend = Blend { neighbours: 6, uniform: 0.5, distance_term: term };
    let (cache, _) = Cache::build(scene, &pool, records, blend, true);
    assert!(cache.records.len() > 20 && cache.v > 50, "{} records, {} vertices", cache.records.len(), cache.v);
    cache
}

/// An SPCBPT model over a pool of `m` light paths (its `Γ` far from uniform) and what the
/// counts measure from that pool (`V̄ = 3.1`, `κ` by depth).
fn sp_model(scene: &Scene, m: usize) -> (Model, Measured) {
    let (model, pool) = test_model(scene, m, 8, (8, 16), |x| 0.3 + 0.7 * x);
    let subspaces = model.sort_pool(scene, &pool);
    let kappa = std::array::from_fn(|k| 5.1 / (1.0 + k as f32));
    let measured = Measured::of_pool(&subspaces, pool.paths, 3.1, kappa);
    (model, measured)
}

/// The MIS shares of every strategy of `x` (what an efficiency-aware budget predicts moments
/// from) are the balance-heuristic weights of the path's strategies summed by kind, whichever
/// strategy sampled it.
fn check_shares(scene: &Scene, x: &[Vertex], counts: &impl StrategyCounts, what: &str) {
    let n = x.len();
    let usable = |s: usize| s == 0 || (x[s - 1].is_connectible() || s == 1 && n > 2) && x[s].is_connectible();
    let sub = |s: usize| subpaths(scene, x, s).filter(|_| usable(s));
    let mut by_class = [0.0f64; 3];
    for s in 0..n {
        if let Some((l, c)) = sub(s) {
            by_class[Shares::class(s, n - s)] += mis_weight(scene, &l, &c, Heuristic::Balance, counts) as f64;
        }
    }
    for s in 0..n {
        let Some((l, c)) = sub(s) else { continue };
        if mis_weight(scene, &l, &c, Heuristic::Balance, counts) <= 0.0 {
            continue;
        }
        let sh = mis_shares(scene, &l, &c, counts);
        let got = [sh.unidirectional as f64, sh.connection as f64, sh.light_trace as f64];
        assert!((got.iter().sum::<f64>() - 1.0).abs() < 1e-4, "{what} s={s} n={n}: shares {sh:?}");
        for k in 0..3 {
            assert!(
                (got[k] - by_class[k]).abs() < 1e-4 * (1.0 + by_class[k]),
                "{what} s={s} n={n}: shares {got:?} against the weights by kind {by_class:?}"
            );
        }
    }
}

fn check_variant(variant: Variant, seed: u64) {
    let scene = scene(variant);
    let pool = LvcCounts { light_trace: 0.37, connect: 2.5 };
    // Light paths from infinity mostly meet the box's outside: more of them fill the pool.
    let k = if matches!(variant, Variant::Envmap | Variant::Directional | Variant::Sunsky) { 6 } else { 1 };
    let caches = [pc_cache(&scene, 120 * k, DistanceTerm::Falloff), pc_cache(&scene, 40 * k, DistanceTerm::Printed)];
    // Each `--pc-mis` option as the renderer sets it up, with V̄ = 3.1 and κ = 7.3 measured
    // by a previous iteration.
    let pc = |mis, previous, n: u32, m: usize| {
        let opts =
            PcOptions { mis, pool: PoolOptions { connections: n, ..PoolOptions::default() }, ..PcOptions::default() };
        // κ differs by camera depth.
        let kappa = std::array::from_fn(|k| 7.3 / (1.0 + k as f32));
        PcCounts::for_iteration(&scene, &opts, m, 48.0 * 40.0, 3.1, &kappa, previous)
    };
    let pc_options = [
        ("pc uniform", pc(PcMis::Uniform, Some(&caches[0]), 3, 120)),
        ("pc harmonic", pc(PcMis::Harmonic, Some(&caches[0]), 3, 120)),
        ("pc resampling", pc(PcMis::Resampling, Some(&caches[0]), 3, 120)),
        ("pc resampling printed", pc(PcMis::Resampling, Some(&caches[1]), 5, 40)),
        ("pc correlated", pc(PcMis::Correlated, Some(&caches[0]), 3, 120)),
    ];
    let k_sp = if matches!(variant, Variant::Envmap | Variant::Directional | Variant::Sunsky) { 6 } else { 1 };
    let (model, measured) = sp_model(&scene, 150 * k_sp);
    let sp = |mis| SpCounts::for_iteration(&scene, mis, 3, 150 * k_sp, &measured, &model);
    let sp_options = [
        ("sp uniform", sp(PcMis::Uniform)),
        ("sp harmonic", sp(PcMis::Harmonic)),
        ("sp resampling", sp(PcMis::Resampling)),
        ("sp correlated", sp(PcMis::Correlated)),
        ("sp subspace", sp(PcMis::Subspace)),
    ];
    assert!(pc_options[0].1.previous.is_none() && pc_options[1].1.previous.is_none());
    assert!((pc_options[1].1.connect[0] / pc_options[0].1.connect[0] - 7.3).abs() < 1e-5);
    assert!((pc_options[1].1.connect[3] / pc_options[0].1.connect[3] - 7.3 / 4.0).abs() < 1e-5);
    let mut checked = 0;
    let mut merged = 0;
    let mut with_delta = 0;
    let mut resampled = Vec::new();
    let mut sp_resampled = Vec::new();
    // Paths whose pool connections `--pc-mis correlated` weighs otherwise than `harmonic`.
    let mut decorrelated = 0;
    for x in paths(&scene, seed, 300) {
        if let Some((l, c)) =
            subpaths(&scene, &x, 2).filter(|_| x.len() >= 5 && x[1].is_connectible() && x[2].is_connectible())
        {
            let w = |counts: &PcCounts| mis_weight(&scene, &l, &c, Heuristic::Balance, counts);
            decorrelated += ((w(&pc_options[4].1) - w(&pc_options[1].1)).abs() > 1e-3) as usize;
        }
        if x.len() >= 4 && !x.iter().any(|v| is_delta_surface(&scene, v)) {
            let (l, c) = subpaths(&scene, &x, 2).unwrap();
            resampled.push(pc_options[2].1.count(&FullPath { light: &l, camera: &c }, 2, x.len() - 2));
            sp_resampled.push(sp_options[2].1.count(&FullPath { light: &l, camera: &c }, 2, x.len() - 2));
        }
        check_shares(&scene, &x, &pool, "pool");
        check_shares(&scene, &x, &pc_options[1].1, "pc harmonic");
        check_shares(&scene, &x, &pc_options[2].1, "pc resampling");
        check_shares(&scene, &x, &pc_options[4].1, "pc correlated");
        check_shares(&scene, &x, &sp_options[2].1, "sp resampling");
        check_shares(&scene, &x, &sp_options[4].1, "sp subspace");
        let n = x.len();
        let has_delta = x.iter().any(|v| is_delta_surface(&scene, v));
        with_delta += has_delta as usize;
        for heuristic in [Heuristic::Balance, Heuristic::Power] {
            let check = |counts: &dyn Fn(&[Vertex], &[Vertex]) -> f32, reference: Option<Vec<f64>>, what: &str| {
                let mut sum = 0.0f64;
                let mut ws = Vec::new();
                for s in 0..n {
                    // Strategies that would connect at a specular vertex are never evaluated;
                    // next-event estimation (`s = 1`, `t >= 2`) reaches lights at infinity,
                    // which nothing else connects to.
                    let usable = s == 0 || (x[s - 1].is_connectible() || s == 1 && n > 2) && x[s].is_connectible();
                    let Some((l, c)) = subpaths(&scene, &x, s).filter(|_| usable) else {
                        ws.push(0.0);
                        continue;
                    };
                    let w = counts(&l, &c) as f64;
                    assert!(w.is_finite() && w >= 0.0, "{variant:?} {what} s={s} n={n}: weight {w}");
                    ws.push(w);
                    sum += w;
                }
                assert!(
                    (sum - 1.0).abs() < 1e-4,
                    "{variant:?} {what} {heuristic:?} n={n}: weights {ws:?} sum to {sum}; brute force {reference:?}; x0 {:?}",
                    x[0].kind
                );
                if let Some(r) = reference {
                    for (s, (a, b)) in ws.iter().zip(&r).enumerate() {
                        assert!(
                            (a - b).abs() < 1e-4 * (1.0 + b.abs()) + 1e-5,
                            "{variant:?} {what} {heuristic:?} n={n} s={s}: ratio walk {a} vs brute force {b} ({ws:?} vs {r:?})"
                        );
                    }
                }
            };
            let mut x0 = x.clone();
            x0[0] = as_light(&scene, &x[0]);
            let brute = |r: Vec<f64>| (!has_delta).then_some(r);
            let b = brute(brute_force_weights(&scene, &x0, heuristic, &Counts::Bdpt));
            check(&|l, c| mis_weight(&scene, l, c, heuristic, &Counts::Bdpt), b, "bdpt");
            let b = brute(brute_force_weights(&scene, &x0, heuristic, &pool));
            check(&|l, c| mis_weight(&scene, l, c, heuristic, &pool), b, "pool");
            let b = brute(brute_force_weights(&scene, &x0, heuristic, &Positional));
            check(&|l, c| mis_weight(&scene, l, c, heuristic, &Positional), b, "positional");
            for (what, counts) in &pc_options {
                let b = brute(brute_force_weights(&scene, &x0, heuristic, counts));
                check(&|l, c| mis_weight(&scene, l, c, heuristic, counts), b, what);
            }
            for (what, counts) in &sp_options {
                let b = brute(brute_force_weights(&scene, &x0, heuristic, counts));
                check(&|l, c| mis_weight(&scene, l, c, heuristic, counts), b, what);
            }
            // Light tracing alone: the t = 1 strategy carries everything it can sample.
            let lt: f32 = (1..n)
                .filter_map(|s| subpaths(&scene, &x, s))
                .map(|(l, c)| mis_weight(&scene, &l, &c, heuristic, &Counts::LightTrace))
                .sum();
            assert!((lt - 1.0).abs() < 1e-5 || !x[n - 2].scatters(), "light tracing: {lt}");
            merged += check_merging(&scene, &x, heuristic, variant) as usize;
        }
        checked += 1;
    }
    assert_eq!(checked, 300);
    assert!(merged > 100, "{variant:?}: only {merged} weighings with a merge of weight over 0.05");
    if matches!(variant, Variant::Envmap | Variant::Directional | Variant::Sunsky) {
        let far = paths(&scene, seed, 300).iter().filter(|x| x[0].at_infinity()).count();
        assert!(far > 30, "{variant:?}: only {far} paths from a light at infinity");
    }
    if variant == Variant::Sunsky {
        let from_sun = |x: &Vec<Vertex>| matches!(x[0].kind, VertexKind::Light(l) if matches!(scene.lights[l as usize], Light::Sun(_)));
        let sun = paths(&scene, seed, 300).iter().filter(|x| from_sun(x)).count();
        assert!(sun > 10, "only {sun} paths from the sun");
    }
    assert!(decorrelated > 10, "{variant:?}: the correlation changed only {decorrelated} weights");
    // The resampling counts follow the cached PMFs: far from constant.
    let (lo, hi) = resampled.iter().fold((f32::MAX, 0.0f32), |(a, b), &c| (a.min(c), b.max(c)));
    assert!(resampled.len() > 20 && lo > 0.0 && hi > 20.0 * lo, "{variant:?}: resampling counts {lo}..{hi}");
    // So do SPCBPT's, with the subspaces' matrix entries and the vertices' flux.
    let (lo, hi) = sp_resampled.iter().fold((f32::MAX, 0.0f32), |(a, b), &c| (a.min(c), b.max(c)));
    assert!(sp_resampled.len() > 20 && lo > 0.0 && hi > 10.0 * lo, "{variant:?}: SPCBPT resampling counts {lo}..{hi}");
    if variant == Variant::Mirror {
        assert!(with_delta > 10, "only {with_delta} paths through the mirror");
    }
    if variant == Variant::Fog {
        let in_fog = paths(&scene, seed, 300).iter().filter(|x| x.iter().any(|v| v.kind == VertexKind::Medium)).count();
        assert!(in_fog > 100, "only {in_fog} paths with a medium vertex");
    }
}

/// Vertex connection and merging (and its merges alone, with the camera subpath's emission
/// hits): the weights of the connections and of the merges at every rough surface vertex
/// inside the path sum to one, whichever strategy is asked. With merges weighing next to
/// nothing the connections' weights are BDPT's. Whether some merge weighs over 0.05.
fn check_merging(scene: &Scene, x: &[Vertex], heuristic: Heuristic, variant: Variant) -> bool {
    use crate::integrator::bidir::mis::merging::merge_weight;
    use crate::integrator::vcm::VcmCounts;
    let n = x.len();
    let usable = |s: usize| s == 0 || (x[s - 1].is_connectible() || s == 1 && n > 2) && x[s].is_connectible();
    let connections = |counts: &VcmCounts| -> Vec<f64> {
        (0..n)
            .map(|s| {
                subpaths(scene, x, s)
                    .filter(|_| usable(s))
                    .map_or(0.0, |(l, c)| mis_weight(scene, &l, &c, heuristic, counts) as f64)
            })
            .collect()
    };
    let merges = |counts: &VcmCounts| -> Vec<f64> {
        (1..n.saturating_sub(1))
            .filter(|&i| x[i].kind == VertexKind::Surface && x[i].is_connectible())
            .filter_map(|i| Some((subpaths(scene, x, i + 1)?.0, subpaths(scene, x, i)?.1)))
            .map(|(l, c)| merge_weight::<CAP>(scene, &l, &c, heuristic, counts) as f64)
            .collect()
    };
    let mut heavy = false;
    for (connect, eta) in [(true, 0.37f32), (true, 40.0), (false, 2.0)] {
        let counts = VcmCounts { connections: connect, light_trace: 0.6, eta };
        let (c, m) = (connections(&counts), merges(&counts));
        let sum = c.iter().sum::<f64>() + m.iter().sum::<f64>();
        // Merges alone cannot make every path (a point light's seen in a mirror).
        if connect || sum > 0.0 {
            assert!(
                (sum - 1.0).abs() < 1e-4,
                "{variant:?} {heuristic:?} η {eta} n={n}: connections {c:?}, merges {m:?}"
            );
        }
        heavy |= m.iter().any(|&w| w > 0.05);
    }
    let faint = connections(&VcmCounts { connections: true, light_trace: 1.0, eta: 1e-9 });
    for (s, w) in faint.iter().enumerate() {
        let bdpt = subpaths(scene, x, s)
            .filter(|_| usable(s))
            .map_or(0.0, |(l, c)| mis_weight(scene, &l, &c, heuristic, &Counts::Bdpt) as f64);
        assert!((w - bdpt).abs() < 1e-4, "{variant:?} {heuristic:?} s={s} n={n}: {w} against BDPT's {bdpt}");
    }
    heavy
}

#[test]
fn weights_sum_to_one_with_medium_vertices() {
    check_variant(Variant::Fog, 10);
}

#[test]
fn weights_sum_to_one_on_diffuse_paths() {
    check_variant(Variant::Diffuse, 1);
}

#[test]
fn weights_sum_to_one_on_glossy_paths() {
    check_variant(Variant::Glossy, 2);
}

#[test]
fn weights_sum_to_one_through_a_mirror() {
    check_variant(Variant::Mirror, 3);
}

#[test]
fn weights_sum_to_one_with_a_point_light() {
    check_variant(Variant::PointLight, 4);
}

#[test]
fn weights_sum_to_one_with_a_sphere_light_sampled_by_cone() {
    check_variant(Variant::SphereLight, 5);
}

#[test]
fn weights_sum_to_one_with_lights_at_infinity() {
    check_variant(Variant::Envmap, 7);
}

#[test]
fn weights_sum_to_one_with_a_directional_light() {
    check_variant(Variant::Directional, 8);
}

#[test]
fn weights_sum_to_one_with_sun_and_sky() {
    check_variant(Variant::Sunsky, 9);
}

#[test]
fn weights_sum_to_one_on_veach_ajar_paths() {
    check_variant(Variant::VeachAjar, 6);
}

#[test]
fn balance_heuristic_of_two_strategies_is_their_density_ratio() {
    // Hand-made densities: p_0 = pE0 pE1, p_1 = pL0 pE1 (t = 1 is x_1 = camera only).
    let mut p = PathPdfs::<CAP>::new(3);
    p.pl[..3].copy_from_slice(&[0.5, 2.0, 0.0]);
    p.pe[..3].copy_from_slice(&[4.0, 3.0, 1.0]);
    // Strategy densities: p_0 = pE0 pE1 pE2 = 12, p_1 = pL0 pE1 pE2 = 1.5, p_2 = pL0 pL1 pE2 = 1.
    let w = |s| weight_from_pdfs(&p, s, Heuristic::Balance, &|_| 1.0);
    assert!((w(0) - 12.0 / 14.5).abs() < 1e-6);
    assert!((w(1) - 1.5 / 14.5).abs() < 1e-6);
    assert!((w(2) - 1.0 / 14.5).abs() < 1e-6);
    // Counts multiply densities.
    let w = |s| weight_from_pdfs(&p, s, Heuristic::Power, &|k| if k == 2 { 3.0 } else { 1.0 });
    let d = 144.0 + 2.25 + 9.0;
    assert!((w(2) - 9.0 / d).abs() < 1e-6 && (w(0) - 144.0 / d).abs() < 1e-6);
}

/// Sums the contributions of the `s = 0` and `s, t >= 2` strategies of sampled subpaths
/// on `veach-ajar`, weighted by the ratio walk over the densities the walks recorded and by
/// the weights from full path densities (which sum to one by construction); also counts
/// the strategies whose two weights differ. `perturb` scales the recorded forward density
/// of each light subpath's third vertex (a negative control).
fn sampled_weights(perturb: f32) -> (f64, f64, usize, usize) {
    let scene = scene(Variant::VeachAjar);
    sampled_weights_of(&scene, &WalkLimits::new(u32::MAX, 3), perturb, true, 150_000)
}

/// [`sampled_weights`] on `scene` of `samples` camera samples whose walks are made with
/// `limits` (a guide's, where it has one); the full path densities follow that guide, or
/// (`judge_guided` false) the BSDFs alone.
fn sampled_weights_of(
    scene: &Scene,
    limits: &WalkLimits,
    perturb: f32,
    judge_guided: bool,
    samples: u64,
) -> (f64, f64, usize, usize) {
    let guide = limits.guide();
    let mut counters = Counters::default();
    let (mut lp, mut cp) = (Vec::new(), Vec::new());
    let (mut walk, mut full, mut differ, mut total) = (0.0f64, 0.0f64, 0usize, 0usize);
    for i in 0..samples {
        let mut rng = Sampler::new(&[17, i]);
        let pos = Vec2::new(48.0, 40.0) * rng.next_2d();
        camera_subpath(scene, pos, limits, &mut rng, &mut cp, &mut counters);
        light_subpath(scene, limits, &mut rng, &mut lp, &mut counters);
        if lp.len() > 2 {
            lp[2].pdf_fwd *= perturb;
        }
        for t in 2..=cp.len() {
            for s in (0..=lp.len()).filter(|&s| s != 1) {
                let (l, c) = (&lp[..s], &cp[..t]);
                let mut x: Vec<Vertex> = l.iter().chain(c.iter().rev()).copied().collect();
                if x.iter().any(|v| is_delta_surface(scene, v)) {
                    continue;
                }
                let pt = &c[t - 1];
                let (contribution, conn) = if s == 0 {
                    let Some(light) = scene.shapes[pt.shape as usize].light else { continue };
                    x[0] = as_light(scene, pt);
                    (pt.beta * scene.lights[light].radiance(pt.ng, pt.uv, pt.wo), None)
                } else {
                    let qs = &l[s - 1];
                    let Some(conn) =
                        Connection::carrying(scene, qs, pt, guide).filter(|_| qs.connectible && pt.connectible)
                    else {
                        continue;
                    };
                    if !crate::integrator::bidir::walk::visible(scene, qs, pt, &mut counters) {
                        continue;
                    }
                    (qs.beta * conn.light_end.f * conn.camera_end.f * pt.beta / conn.dist2, Some(conn))
                };
                let y = crate::math::luminance(contribution) as f64;
                if y == 0.0 {
                    continue;
                }
                let w = mis_weight_with(scene, l, c, conn.as_ref(), Heuristic::Power, &Counts::Bdpt) as f64;
                let judge = if judge_guided { guide } else { None };
                let b = brute_force_weights_with(scene, &x, Heuristic::Power, &Counts::Bdpt, judge)[s];
                walk += y * w;
                full += y * b;
                total += 1;
                differ += ((w - b).abs() > 1e-3 * (1.0 + b)) as usize;
            }
        }
    }
    (walk, full, differ, total)
}

#[test]
fn weights_of_sampled_veach_ajar_paths_are_those_of_their_full_path_densities() {
    // The walks record densities between the points they find: in veach-ajar's corners,
    // where segments are about as short as the offset a ray leaves a surface with, densities
    // taken from the sampled directions made the weights of different strategies of one path
    // disagree, and the weighted contributions 0.2% too small.
    let (walk, full, differ, total) = sampled_weights(1.0);
    assert!(total > 80_000, "{total} strategies");
    assert!((walk / full - 1.0).abs() < 1e-5, "weighted sums {walk} vs {full}: ratio {}", walk / full);
    assert!(differ * 10_000 < total, "{differ} of {total} weights differ");
    // One density 1% off in the third light vertex is seen.
    let (walk, full, differ, total) = sampled_weights(1.01);
    assert!(differ * 20 > total, "a 1% density error changed only {differ} of {total} weights");
    assert!((walk / full - 1.0).abs() > 1e-4, "a 1% density error left the weighted sum at {}", walk / full);
}

/// Walks guided by a tree trained on `veach-ajar` (every leaf sampling the tree half the
/// time): the ratio walk over the densities the guided walks and connections record gives
/// the weights of the full path densities with the guide's camera side, and not those
/// with the BSDFs' (the negative control).
#[test]
fn weights_of_guided_walks_are_those_of_their_full_path_densities() {
    use crate::integrator::guided::camera_guide::TreeGuide;
    use crate::integrator::guided::{GuidedOptions, train_tree};
    let scene = scene(Variant::VeachAjar);
    let options = GuidedOptions { learn_fraction: false, spatial_threshold: 300.0, ..GuidedOptions::default() };
    let tree = train_tree(&scene, &options, &[1, 2, 4, 8], 3).unwrap();
    assert!(tree.leaves.len() > 4, "the tree did not split: {} leaves", tree.leaves.len());
    let mut limits = WalkLimits::new(u32::MAX, 3);
    limits.guide = Some(std::sync::Arc::new(TreeGuide { tree, bsdf_fraction: 0.5 }));
    let (walk, full, differ, total) = sampled_weights_of(&scene, &limits, 1.0, true, 60_000);
    assert!(total > 30_000, "{total} strategies");
    assert!((walk / full - 1.0).abs() < 1e-5, "weighted sums {walk} vs {full}: ratio {}", walk / full);
    assert!(differ * 10_000 < total, "{differ} of {total} weights differ");
    let (walk, full, differ, total) = sampled_weights_of(&scene, &limits, 1.0, false, 60_000);
    assert!(differ * 5 > total, "the BSDFs' densities gave the guided weights for {} of {total}", total - differ);
    assert!((walk / full - 1.0).abs() > 1e-3, "the BSDFs' densities left the weighted sum at {}", walk / full);
}

#[test]
fn unit_count_walk_is_the_general_walk_with_unit_counts() {
    // Random densities (some zero, as deltas leave them), random delta flags, every
    // strategy, both heuristics: the specialised walk gives the same bits.
    let mut rng = Sampler::new(&[31]);
    for trial in 0..2000 {
        let n = 2 + trial % 14;
        let mut p = PathPdfs::<SHORT>::new(n);
        for i in 0..n {
            p.pl[i] = if rng.next_1d() < 0.1 { 0.0 } else { 10f32.powf(4.0 * rng.next_1d() - 2.0) };
            p.pe[i] = if rng.next_1d() < 0.1 { 0.0 } else { 10f32.powf(4.0 * rng.next_1d() - 2.0) };
            p.delta[i] = rng.next_1d() < 0.15;
        }
        p.delta_light = rng.next_1d() < 0.2;
        p.nee_ratio = if trial % 3 == 0 { 0.5 + rng.next_1d() } else { 1.0 };
        for s in 0..n {
            for h in [Heuristic::Balance, Heuristic::Power] {
                let general = weight_from_pdfs(&p, s, h, &|_| 1.0);
                assert_eq!(weight_unit_counts(&p, s, h).to_bits(), general.to_bits(), "trial {trial}, s = {s}, {h:?}");
            }
        }
    }
    // The comparison can fail: other counts give other weights.
    let mut p = PathPdfs::<SHORT>::new(4);
    p.pl[..4].copy_from_slice(&[1.0, 2.0, 3.0, 4.0]);
    p.pe[..4].copy_from_slice(&[4.0, 3.0, 2.0, 1.0]);
    assert_ne!(
        weight_unit_counts(&p, 2, Heuristic::Power),
        weight_from_pdfs(&p, 2, Heuristic::Power, &|i| i as f32 + 1.0)
    );
}

/// `--pc-mis correlated`'s factors on constructed densities: a path of 6 vertices
/// `x_0..x_5` (`x_5` the camera, `x_4` the primary hit) over a film of 100 pixels, so that
/// the footprint's area is `A = 1 / (100 pE(x_4))`.
#[test]
fn correlation_factors_follow_the_prefixes_randomness() {
    use crate::integrator::pcbpt::Correlation;
    let corr = Correlation { pixels: 100.0, connections: 4.0 };
    let factors = |pl: [f32; 6], pe: [f32; 6]| {
        let mut out = [0.0f32; 6];
        corr.factors(6, |i| pl[i], |i| pe[i], &mut out);
        out
    };
    // A = 1 / (100 * 0.01) = 1.
    let pe_primary = 0.01;
    // Strategies s' = 0, 1 and t' = 1 (s' = 5) are no pool connections; s' = 4 has no camera
    // vertex beyond the primary hit, so its camera prefix is determined.
    let f = factors([0.5; 6], [0.5, 0.5, 0.5, 0.5, pe_primary, 1.0]);
    assert_eq!([f[0], f[1], f[5]], [1.0; 3]);
    assert_eq!(f[4], 1.0);
    // s' = 3: P_E = min(A pE(x_3), 1) = 0.5, P_L = 0.5³ / 4.
    let (p_e, p_l) = (0.5f32, 0.125f32 / 4.0);
    assert!((f[3] - p_e / (p_e + p_l - p_e * p_l)).abs() < 1e-6, "{f:?}");
    // s' = 2: P_E = 0.25, P_L = 0.25 / 4.
    let (p_e, p_l) = (0.25f32, 0.0625f32);
    assert!((f[2] - p_e / (p_e + p_l - p_e * p_l)).abs() < 1e-6, "{f:?}");
    // A random camera prefix joined to a determined light prefix counts as one sample.
    let f = factors([2.0; 6], [1e-4, 1e-4, 1e-4, 1e-4, pe_primary, 1.0]);
    assert_eq!(f[2], 0.25);
    assert_eq!(f[3], 0.25);
    // A determined camera prefix (densities above 1/A, or Dirac vertices) keeps all N.
    let f = factors([1e-3; 6], [1e-3, 1e-3, 1e-3, 0.0, pe_primary, 1.0]);
    assert_eq!(f[3], 1.0);
    let f = factors([1e-3; 6], [1e-3, 1e-3, 5.0, 5.0, pe_primary, 1.0]);
    assert_eq!(f[2], 1.0);
    // Paths too short for a pool connection beyond the primary hit's, and a camera density
    // of zero, leave the counts alone.
    let mut out = [0.0f32; 3];
    corr.factors(3, |_| 1.0, |_| 1.0, &mut out);
    assert_eq!(out, [1.0; 3]);
    assert_eq!(factors([1e-3; 6], [1e-4, 1e-4, 1e-4, 1e-4, 0.0, 1.0]), [1.0; 6]);
}
