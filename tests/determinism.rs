//! A fixed seed gives bit-identical images whatever the number of threads.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::integrator::IntegratorKind;

/// Whether two images are the same bit for bit.
fn same_bits(a: &[glam::Vec3], b: &[glam::Vec3]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits))
}

#[test]
fn path_tracer_is_bit_identical_with_1_and_2_threads() {
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "48"), ("resy", "40")], Backend::Embree);
    let one = render(&scene, IntegratorKind::Path, 8, 42, 1);
    let two = render(&scene, IntegratorKind::Path, 8, 42, 2);
    assert!(same_bits(&one.image, &two.image));
    let other = render(&scene, IntegratorKind::Path, 8, 43, 2);
    assert_ne!(one.image, other.image, "the seed must change the image");
}

#[test]
fn bidirectional_integrators_are_bit_identical_with_1_and_2_threads() {
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "48"), ("resy", "40")], Backend::Embree);
    for kind in [
        IntegratorKind::Lighttrace,
        IntegratorKind::Bdpt,
        IntegratorKind::Eorr,
        IntegratorKind::Lvc,
        IntegratorKind::Pcbpt,
        IntegratorKind::Spcbpt,
        IntegratorKind::Vcm,
        IntegratorKind::Bpm,
        IntegratorKind::Guided,
    ] {
        // Several passes where an integrator keeps state between them, so EORR's
        // thresholds and LVC's and PCBPT's pools come from earlier passes (light tracing
        // and BDPT keep none and render all 4 spp in one pass).
        let one = render(&scene, kind, 4, 42, 1);
        let two = render(&scene, kind, 4, 42, 2);
        let stateless = matches!(kind, IntegratorKind::Lighttrace | IntegratorKind::Bdpt);
        assert_eq!(one.stats.passes > 1, !stateless, "{kind:?}: {} passes", one.stats.passes);
        assert!(same_bits(&one.image, &two.image), "{kind:?} differs between 1 and 2 threads");
        // And so do the files.
        let dir = tempfile::tempdir().unwrap();
        let bytes = |name: &str, out: &pcbpt::integrator::RenderOutput| {
            let path = dir.path().join(name);
            let image = pcbpt::image_io::Image::new(out.width, out.height, out.image.clone());
            pcbpt::image_io::write(&path, &image).unwrap();
            std::fs::read(path).unwrap()
        };
        assert!(bytes("one.exr", &one) == bytes("two.exr", &two), "{kind:?}: the EXR files differ");
        let other = render(&scene, kind, 4, 43, 2);
        assert_ne!(one.image, other.image, "{kind:?}: the seed must change the image");
    }
}

/// PCBPT with guided camera walks: the guide's training and the guided walks give the same
/// image with 1 and 2 threads, and a different one without the guide.
#[test]
fn guided_pcbpt_is_bit_identical_with_1_and_2_threads() {
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "48"), ("resy", "40")], Backend::Embree);
    let render = |threads: usize, guided: bool| {
        let mut o = pcbpt::integrator::RenderOptions::new(IntegratorKind::Pcbpt, pcbpt::integrator::Budget::Spp(8));
        o.run.seed = 42;
        o.run.threads = threads;
        o.method.pcbpt_mut().guiding.enabled = guided;
        o.method.pcbpt_mut().guiding.tree.learn_fraction = false;
        pcbpt::integrator::render(&scene, &o).unwrap()
    };
    let (one, two) = (render(1, true), render(2, true));
    let guiding = one.stats.details.get::<pcbpt::integrator::pcbpt::PcbptStats>().and_then(|s| s.guiding);
    assert!(guiding.is_some_and(|g| g.training_spp == 1), "{guiding:?}");
    assert!(same_bits(&one.image, &two.image), "guided PCBPT differs between 1 and 2 threads");
    assert_ne!(one.image, render(2, false).image, "the guide changed nothing");
}

/// PCBPT's and SPCBPT's budgets are chosen from counts and moments summed in a fixed order:
/// the same plan, and the same image, whatever the number of threads.
#[test]
fn budgeted_pool_integrators_are_bit_identical_with_1_and_2_threads() {
    use pcbpt::integrator::budget::{BudgetMode, BudgetModel, Independence};
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "48"), ("resy", "40")], Backend::Embree);
    // The defaults, smoothed means with the measured independence, and the realized model.
    for (smoothing, independence, model) in [
        (0, Independence::Fixed(0.35), BudgetModel::Moments),
        (2, Independence::MEASURED, BudgetModel::Moments),
        (2, Independence::Fixed(0.35), BudgetModel::Realized),
    ] {
        for kind in [IntegratorKind::Pcbpt, IntegratorKind::Spcbpt] {
            let set = |o: &mut pcbpt::integrator::RenderOptions| {
                o.method.budget_mut().mode = BudgetMode::Auto;
                o.method.budget_mut().smoothing = smoothing;
                o.method.budget_mut().independence = independence;
                o.method.budget_mut().model = model;
                if let pcbpt::integrator::Method::Spcbpt(s) = &mut o.method {
                    s.sp.training_iterations = 2;
                }
            };
            let one = render_with(&scene, kind, 6, 42, 1, &set);
            let two = render_with(&scene, kind, 6, 42, 2, &set);
            let (a, b) = (budget_of(&one.stats).unwrap(), budget_of(&two.stats).unwrap());
            assert!(a.chosen.is_some() && a.chosen == b.chosen, "{kind:?}: {a:?} against {b:?}");
            assert_eq!(a.independence.to_bits(), b.independence.to_bits(), "{kind:?}");
            let bits = |s: &pcbpt::integrator::budget::BudgetStats| -> Vec<(u64, u64)> {
                s.predictions.iter().map(|(m, r)| (m.to_bits(), r.to_bits())).collect()
            };
            assert_eq!(bits(a), bits(b), "{kind:?}: predictions differ between 1 and 2 threads");
            assert!(same_bits(&one.image, &two.image), "{kind:?} with a budget differs between 1 and 2 threads");
        }
    }
}
