//! The guided path tracer's tests on a tree trained on a Cornell box: the mixture samples
//! what its density says, and next-event estimation and the mixture's hits of the light
//! weigh each path to one.

use super::*;
use crate::integrator::guided::sdtree::{sphere_pdf, to_square};
use crate::integrator::path::{Continuation, light_sampling_weight};
use crate::sampling::chi2::{Chi2Test, SphereDomain};
use crate::scene::shape::SurfaceInteraction;
use glam::{Vec2, Vec3};

fn cornell() -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box/scene.xml");
    let load = crate::scene::LoadOptions { resolution: Some((16, 16)), ..Default::default() };
    Scene::load(&path, &load).unwrap()
}

/// A tree trained on `scene` in passes of 1, 2 and 4 samples per pixel, its spatial
/// threshold low enough that it splits.
fn trained(scene: &Scene) -> SdTree {
    trained_in_tiles(scene, 8, false)
}

/// [`trained`] with tiles of `tile_size` pixels, its leaves learning their BSDF fractions
/// or not.
fn trained_in_tiles(scene: &Scene, tile_size: u32, learn_fraction: bool) -> SdTree {
    let pt = PathTracer::new(&scene.integrator);
    let tile_list = tiles(scene.film.width, scene.film.height, tile_size);
    let options = GuidedOptions { spatial_threshold: 100.0, learn_fraction, ..GuidedOptions::default() };
    let t = options.training(&pt, &tile_list, None, Instant::now());
    let ctx = Ctx { scene, seed: 5, layers: false, planned_spp: None, start: 0 };
    let mut tree = SdTree::new(scene.bounds.center, scene.bounds.radius);
    let done = train(&ctx, &t, &mut tree, &[1, 2, 4], None);
    assert_eq!((done.passes, done.spp), (3, 7));
    assert!(tree.leaves.len() > 4, "the tree did not split: {} leaves", tree.leaves.len());
    tree
}

/// Surface points the camera sees on non-Dirac surfaces that are no lights, with their
/// outgoing direction in the shading frame.
fn vertices(scene: &Scene) -> Vec<(SurfaceInteraction, Vec3)> {
    let mut out = Vec::new();
    for y in 0..8 {
        for x in 0..8 {
            let pos = Vec2::new(x as f32 * 2.0 + 0.5, y as f32 * 2.0 + 0.5);
            let Some(si) = scene.intersect(&scene.camera.generate_ray(pos)) else { continue };
            if scene.bsdf(&si).is_delta() || scene.area_light(&si).is_some() {
                continue;
            }
            let wo = si.shading.to_local(si.wo);
            out.push((si, wo));
        }
    }
    out
}

#[test]
fn the_mixture_samples_what_its_density_says() {
    let scene = cornell();
    mixture_chi2(&scene, &trained(&scene));
}

/// With fractions learnt per leaf, the mixture at each vertex takes its leaf's.
#[test]
fn the_mixture_with_learnt_fractions_samples_what_its_density_says() {
    let scene = cornell();
    let tree = trained_in_tiles(&scene, 8, true);
    let learnt: Vec<f32> = tree.leaves.iter().filter_map(|l| l.bsdf_fraction).collect();
    assert!(learnt.iter().any(|&a| a != 0.5), "no leaf learnt a fraction of its own: {learnt:?}");
    mixture_chi2(&scene, &tree);
}

/// χ² of the mixture's samples against its density at two vertices.
fn mixture_chi2(scene: &Scene, tree: &SdTree) {
    let all = vertices(scene);
    // A point on the back wall and one on the floor, each guided by a trained quadtree.
    let picked: Vec<_> = all.iter().step_by(all.len() / 3).take(2).collect();
    for (si, wo) in picked {
        let bsdf = scene.bsdf(si);
        assert!(tree.guide_at(si.p).is_some());
        let mut guided = Guided::new(tree, 0.5, false);
        let mut rng = Sampler::new(&[9]);
        let mut t = Chi2Test::new(SphereDomain::default());
        t.samples = 200_000;
        t.tests = 2;
        let r = t.run(
            |_| guided.sample(si, bsdf, *wo, &mut rng).map(|bs| si.shading.to_world(bs.wi)),
            |d| {
                let wi = si.shading.to_local(d);
                let f = bsdf.eval(*wo, wi, si.at(), crate::bsdf::TransportMode::Radiance);
                if f == Vec3::ZERO { 0.0 } else { Guided::new(tree, 0.5, false).pdf(si, bsdf, *wo, wi) }
            },
        );
        r.assert_pass();
    }
}

/// Paths camera → surface → light, found both ways: the mixture's direction hitting the
/// light (weighed by the path tracer's emission weight with the density the sample
/// reported) and next-event estimation to the same point (weighed against the density
/// the continuation gives for that direction). The two weights of each path sum to one;
/// where the hit's weight is above 1e-4 it is also the complement of next-event
/// estimation's to 1%, which a wrong density (the tree's alone, the negative control) misses.
#[test]
fn nee_and_the_mixtures_hits_weigh_each_path_to_one() {
    let scene = cornell();
    weights_sum_to_one(&scene, &trained(&scene));
    weights_sum_to_one(&scene, &trained_in_tiles(&scene, 8, true));
}

fn weights_sum_to_one(scene: &Scene, tree: &SdTree) {
    let pt = PathTracer::new(&scene.integrator);
    let mut rng = Sampler::new(&[13]);
    let (mut paths, mut off) = (0, 0);
    for (si, wo) in vertices(scene) {
        let bsdf = scene.bsdf(&si);
        let mut guided = Guided::new(tree, 0.5, false);
        for _ in 0..2000 {
            let Some(bs) = guided.sample(&si, bsdf, wo, &mut rng) else { continue };
            let Some(hit) = scene.intersect(&si.spawn_ray(si.shading.to_world(bs.wi))) else { continue };
            let Some((light_index, light)) = scene.area_light(&hit) else { continue };
            let pdf_light = scene.light_sampler.pmf(light_index) * light.pdf_li(&scene.shapes, si.p, &hit);
            assert!(!bs.delta && pdf_light > 0.0);
            let w_hit = pt.emission_weight(1, false, bs.pdf, || pdf_light);
            let w_nee = light_sampling_weight(pdf_light, guided.pdf(&si, bsdf, wo, bs.wi));
            assert!((w_hit + w_nee - 1.0).abs() < 1e-4, "weights {w_hit} + {w_nee} at {}", si.p);
            if w_hit < 1e-4 {
                continue;
            }
            let complement = 1.0 - w_nee as f64;
            let relative = |w: f32| (w as f64 - complement).abs() / complement;
            assert!(relative(w_hit) < 1e-2, "weights {w_hit} + {w_nee} at {}", si.p);
            paths += 1;
            let p_tree = sphere_pdf(tree.guide_at(si.p).unwrap().pdf(to_square(si.shading.to_world(bs.wi))));
            if relative(pt.emission_weight(1, false, p_tree, || pdf_light)) > 5e-2 {
                off += 1;
            }
        }
    }
    assert!(paths > 20, "only {paths} paths reached the light with a weight above 1e-4");
    assert!(off > paths / 4, "the tree's density alone weighed {} of {paths} paths to one", paths - off);
}

/// Training is a function of the seed: the same tree from one thread and from two, with
/// tiles of 8 pixels and of 5.
#[test]
fn training_gives_the_same_tree_whatever_the_threads_and_tiles() {
    let scene = cornell();
    let one = crate::workers::render_pool(1).unwrap().install(|| trained(&scene));
    let two = crate::workers::render_pool(2).unwrap().install(|| trained(&scene));
    let tiled = crate::workers::render_pool(2).unwrap().install(|| trained_in_tiles(&scene, 5, false));
    let mut rng = Sampler::new(&[21]);
    for other in [&two, &tiled] {
        assert_eq!(one.leaves.len(), other.leaves.len());
        for _ in 0..2000 {
            let p = scene.bounds.center + (rng.next_2d().extend(rng.next_1d()) - 0.5) * scene.bounds.radius;
            let q = rng.next_2d();
            let (a, b) = (one.guide_at(p).map(|t| t.pdf(q)), other.guide_at(p).map(|t| t.pdf(q)));
            assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
        }
    }
    // The learnt fractions too.
    let fractions = |t: &SdTree| t.leaves.iter().map(|l| l.bsdf_fraction).collect::<Vec<_>>();
    let one = crate::workers::render_pool(1).unwrap().install(|| trained_in_tiles(&scene, 8, true));
    let two = crate::workers::render_pool(2).unwrap().install(|| trained_in_tiles(&scene, 5, true));
    assert_eq!(fractions(&one), fractions(&two));
}

#[test]
fn bad_options_are_refused_naming_the_option() {
    let bad = [
        (GuidedOptions { bsdf_fraction: 0.0, ..GuidedOptions::default() }, "--guided-bsdf-fraction"),
        (GuidedOptions { bsdf_fraction: 1.5, ..GuidedOptions::default() }, "--guided-bsdf-fraction"),
        (GuidedOptions { spatial_threshold: f64::NAN, ..GuidedOptions::default() }, "--guided-spatial-threshold"),
        (GuidedOptions { flux_fraction: 0.0, ..GuidedOptions::default() }, "--guided-flux-fraction"),
        (GuidedOptions { max_tree_depth: 0, ..GuidedOptions::default() }, "--guided-max-depth"),
    ];
    for (options, flag) in bad {
        let e = options.check().unwrap_err().to_string();
        assert!(e.contains(flag), "{e}");
    }
    assert!(GuidedOptions::default().check().is_ok());
}

/// The guide of the bidirectional core's camera walks ([`TreeGuide`]) samples what its
/// density says at vertices a trained tree guides, its density is the guided path tracer's
/// there, and the tree's density alone (the negative control) is rejected.
#[test]
fn the_camera_walks_guide_samples_what_its_density_says() {
    use crate::integrator::bidir::Vertex;
    use crate::integrator::bidir::guide::Guide;
    let scene = cornell();
    let guide = TreeGuide { tree: trained(&scene), bsdf_fraction: 0.5 };
    let all = vertices(&scene);
    for (si, wo) in all.iter().step_by(all.len() / 3).take(2) {
        let bsdf = scene.bsdf(si);
        let mut v = Vertex::surface(si, scene.bsdf_index(si) as u32, crate::math::Rgb::ONE, true);
        v.cell = guide.cell(v.p);
        assert!(guide.guides(&v, bsdf), "the vertex at {} is not guided", si.p);
        let pdf = |d: Vec3| {
            let wi = si.shading.to_local(d);
            let f = bsdf.eval(*wo, wi, si.at(), crate::bsdf::TransportMode::Radiance);
            let p_bsdf = bsdf.pdf(*wo, wi, si.at(), crate::bsdf::TransportMode::Radiance);
            if f == Vec3::ZERO { 0.0 } else { guide.pdf(&v, bsdf, d, p_bsdf) }
        };
        let path_tracer = Guided::new(&guide.tree, 0.5, false);
        let mut rng = Sampler::new(&[23]);
        for _ in 0..100 {
            let d = crate::sampling::square_to_uniform_sphere(rng.next_2d());
            let wi = si.shading.to_local(d);
            let p_bsdf = bsdf.pdf(*wo, wi, si.at(), crate::bsdf::TransportMode::Radiance);
            let (a, b) = (guide.pdf(&v, bsdf, d, p_bsdf), path_tracer.pdf(si, bsdf, *wo, wi));
            assert!((a - b).abs() <= 1e-5 * b.max(1e-3), "densities {a} and {b} of {d}");
        }
        let chi2 = |density: &dyn Fn(Vec3) -> f32| {
            let mut rng = Sampler::new(&[9]);
            let mut t = Chi2Test::new(SphereDomain::default());
            t.samples = 200_000;
            t.tests = 2;
            t.run(
                |_| {
                    let (u, u2, u3) = (rng.next_1d(), rng.next_2d(), rng.next_2d());
                    guide.sample(&v, bsdf, *wo, u, u2, u3).map(|bs| si.shading.to_world(bs.wi))
                },
                density,
            )
        };
        chi2(&pdf).assert_pass();
        let tree_alone = |d: Vec3| sphere_pdf(guide.tree.guide_in(v.cell).unwrap().pdf(to_square(d)));
        assert!(!chi2(&tree_alone).passed(), "the tree's density alone passed at {}", si.p);
    }
}
