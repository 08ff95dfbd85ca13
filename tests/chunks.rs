//! A render cut into chunks of iterations, written as partial renders, read back and merged,
//! gives the one-process image bit for bit (every iterating integrator and option); the
//! merge refuses parts of other renders, missing and overlapping iterations; PSSMLT's parts
//! merge to the reference.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::integrator::budget::BudgetMode;
use pcbpt::integrator::pcbpt::PcMis;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::partial::{self, Part};
use pcbpt::scene::Scene;
use std::ops::Range;
use std::path::Path;

fn options(kind: IntegratorKind, spp: u32, seed: u64) -> RenderOptions {
    let mut o = RenderOptions::new(kind, Budget::Spp(spp));
    o.run.seed = seed;
    o.run.threads = 2;
    o
}

/// Renders `range` of the render `o` describes as a part file in `dir`, and reads it back.
fn part(scene: &Scene, o: &RenderOptions, range: Range<u32>, dir: &Path) -> Part {
    let Budget::Spp(total) = o.run.budget else { unreachable!() };
    let out = integrator::render_iterations(scene, o, Some(range.clone())).unwrap();
    let identity = partial::render_identity(scene, o, &partial::scene_hash(scene, &[]).unwrap());
    let info = partial::part_info(&out, identity, total, scene.film.filter).unwrap();
    let path = dir.join(format!("part_{}_{}.exr", range.start, range.end));
    partial::write_part(&path, &out.image, out.film.as_ref().unwrap(), &info).unwrap();
    partial::read_part(&path).unwrap()
}

fn bits(image: &[glam::Vec3]) -> Vec<[u32; 3]> {
    image.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
}

fn cornell() -> Scene {
    load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "40"), ("resy", "32")], Backend::Embree)
}

/// Chunkings of 7 iterations: whole, two uneven, three uneven (one of a single iteration,
/// one starting inside EORR's pilot and one after it for `eorr_pilot_spp = 4`).
const CUTS: [&[u32]; 3] = [&[], &[5], &[1, 3]];

#[test]
fn merged_chunks_equal_one_process_bit_for_bit() {
    use IntegratorKind::*;
    let scene = cornell();
    let dir = tempfile::tempdir().unwrap();
    let mut cases: Vec<(String, RenderOptions)> = [Path, Guided, Lighttrace, Bdpt, Eorr, Lvc, Vcm, Bpm]
        .into_iter()
        .map(|k| (format!("{k:?}"), options(k, 7, 11)))
        .collect();
    let mut eorr = options(Eorr, 7, 11);
    eorr.method.eorr_mut().pilot_spp = 4;
    cases.push(("Eorr with a 4-spp pilot".into(), eorr));
    for mis in [PcMis::Harmonic, PcMis::Uniform, PcMis::Resampling, PcMis::Correlated] {
        let mut o = options(Pcbpt, 7, 11);
        o.method.pcbpt_mut().pc.mis = mis;
        o.method.pool_mut().light_paths = 300;
        cases.push((format!("Pcbpt {mis:?}"), o));
        // SPCBPT trains its matrix in iterations 0 and 1 and fixes its state after 2: the
        // cuts fall inside the training, right after the state is fixed, and beyond.
        let mut o = options(Spcbpt, 7, 11);
        o.method.spcbpt_mut().sp.mis = mis;
        o.method.spcbpt_mut().sp.training_iterations = 2;
        o.method.spcbpt_mut().sp.eye_subspaces = 16;
        o.method.spcbpt_mut().sp.light_subspaces = 32;
        o.method.pool_mut().light_paths = 300;
        cases.push((format!("Spcbpt {mis:?}"), o.clone()));
        // SPCBPT's own count option, whose vertices are labelled with their subspaces.
        if mis == PcMis::Resampling {
            o.method.spcbpt_mut().sp.mis = PcMis::Subspace;
            cases.push(("Spcbpt Subspace".into(), o));
        }
    }
    // Guided camera walks: every chunk trains the same guide before its iterations.
    let mut o = options(Pcbpt, 7, 11);
    o.method.pool_mut().light_paths = 300;
    o.method.pcbpt_mut().guiding.enabled = true;
    o.method.pcbpt_mut().guiding.training = 0.5;
    o.method.pcbpt_mut().guiding.tree.learn_fraction = false;
    cases.push(("Pcbpt with guided camera walks".into(), o));
    // Budgets measured in iterations 1 and 2 (PCBPT) and 2 and 3 (SPCBPT, after training):
    // the cuts fall inside the measurement, at its end, and beyond.
    let mut o = options(Pcbpt, 7, 11);
    o.method.pool_mut().light_paths = 300;
    o.method.budget_mut().mode = BudgetMode::Auto;
    cases.push(("Pcbpt with a budget".into(), o));
    let mut o = options(Spcbpt, 7, 11);
    o.method.spcbpt_mut().sp.training_iterations = 2;
    o.method.spcbpt_mut().sp.eye_subspaces = 16;
    o.method.spcbpt_mut().sp.light_subspaces = 32;
    o.method.pool_mut().light_paths = 300;
    o.method.budget_mut().mode = BudgetMode::Auto;
    cases.push(("Spcbpt with a budget".into(), o));
    for (name, o) in &cases {
        let whole = integrator::render(&scene, o).unwrap();
        for cuts in CUTS {
            let mut bounds = vec![0];
            bounds.extend_from_slice(cuts);
            bounds.push(7);
            // Rendered last chunk first: nothing depends on the order.
            let parts: Vec<Part> = bounds.windows(2).rev().map(|b| part(&scene, o, b[0]..b[1], dir.path())).collect();
            let merged = partial::merge(parts, false).unwrap();
            assert!(
                bits(&merged.image) == bits(&whole.image),
                "{name}, chunks cut at {cuts:?}: not the one-process image"
            );
        }
    }
}

#[test]
fn the_merge_refuses_mixed_renders_gaps_and_overlaps() {
    let scene = cornell();
    let dir = tempfile::tempdir().unwrap();
    let o = options(IntegratorKind::Bdpt, 6, 1);
    let a = || part(&scene, &o, 0..2, dir.path());
    let b = || part(&scene, &o, 2..6, dir.path());
    assert!(partial::merge(vec![a(), b()], false).is_ok());
    // Missing iterations: an error, unless merging what has arrived.
    let err = partial::merge(vec![a()], false).err().unwrap().to_string();
    assert!(err.contains("missing 2..6"), "{err}");
    let preview = partial::merge(vec![b()], true).unwrap();
    assert_eq!(preview.missing, vec![0..2]);
    // Overlapping iterations name both files.
    let odir = tempfile::tempdir().unwrap();
    let c = part(&scene, &o, 1..3, odir.path());
    let err = partial::merge(vec![a(), c, b()], false).err().unwrap().to_string();
    assert!(err.contains("overlap") && err.contains("part_0_2.exr") && err.contains("part_1_3.exr"), "{err}");
    // Another seed, integrator or sample count is another render.
    for other in [options(IntegratorKind::Bdpt, 6, 2), options(IntegratorKind::Path, 6, 1)] {
        let odir = tempfile::tempdir().unwrap();
        let err = partial::merge(vec![a(), part(&scene, &other, 2..6, odir.path())], false).err().unwrap().to_string();
        assert!(err.contains("another render"), "{err}");
    }
    // Another scene (a parameter override) too.
    let small = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "40"), ("resy", "32")], Backend::Embree);
    let out = integrator::render_iterations(&small, &o, Some(2..6)).unwrap();
    let hash = partial::scene_hash(&small, &[("max_depth".into(), "3".into())]).unwrap();
    let info = partial::part_info(&out, partial::render_identity(&small, &o, &hash), 6, small.film.filter).unwrap();
    let path = odir.path().join("other_scene.exr");
    partial::write_part(&path, &out.image, out.film.as_ref().unwrap(), &info).unwrap();
    let err = partial::merge(vec![a(), partial::read_part(&path).unwrap()], false).err().unwrap().to_string();
    assert!(err.contains("another render") && err.contains("scene"), "{err}");
    // A plain image is not a part.
    let plain = odir.path().join("plain.exr");
    pcbpt::image_io::write(&plain, &pcbpt::image_io::Image::new(2, 2, vec![glam::Vec3::ONE; 4])).unwrap();
    let err = partial::read_part(&plain).err().unwrap().to_string();
    assert!(err.contains("plain.exr") && err.contains("not a partial render"), "{err}");
}

/// PSSMLT's chunks are chains of their own; merged, they converge to the reference as one
/// process does (as in `tests/reference.rs`: two merged renders, seeds 1 and 2, averaged).
/// With two-stage Metropolis (the default) every chunk builds the same first-stage map.
#[test]
fn pssmlt_chunks_merge_to_the_reference() {
    pssmlt_chunks(true, "cornell-ply, PSSMLT in chunks, 2 × 16 spp");
}

#[test]
fn pssmlt_chunks_in_one_stage_merge_to_the_reference() {
    pssmlt_chunks(false, "cornell-ply, PSSMLT in one stage in chunks, 2 × 16 spp");
}

fn pssmlt_chunks(two_stage: bool, what: &str) {
    let scene = load(&root().join("scenes/cornell-ply/cornell_mi.xml"), &[], Backend::Embree);
    let dir = tempfile::tempdir().unwrap();
    let merged = |seed, cuts: &[u32]| {
        let mut o = options(IntegratorKind::Pssmlt, 16, seed);
        *o.method.two_stage_mut() = two_stage;
        let mut bounds = vec![0];
        bounds.extend_from_slice(cuts);
        bounds.push(16);
        let d = dir.path().join(format!("seed{seed}"));
        std::fs::create_dir_all(&d).unwrap();
        let parts = bounds.windows(2).map(|b| part(&scene, &o, b[0]..b[1], &d)).collect();
        let m = partial::merge(parts, false).unwrap();
        pcbpt::image_io::Image::new(m.width, m.height, m.image)
    };
    let (a, b) = (merged(1, &[8]), merged(2, &[3, 10]));
    let reference = reference("cornell-ply_mitsuba3-path_4096spp_maxdepth8_box.exr");
    let (v, _) = Verdict::averaged(&reference, &a, &b, 8.0e-5);
    v.check(what, 0.01, 1.3).unwrap();
}
