//! The per-strategy images of the bidirectional integrators: they sum to the image, and
//! BDPT's image without one of them fails the check against the reference that the whole
//! image passes (the integrators' own reference checks are rows of `tests/reference.rs`).

mod common;

use common::*;
use pcbpt::image_io::Image;
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};
use pcbpt::scene::Scene;

fn render_layers(scene: &Scene, kind: IntegratorKind, spp: u32, seed: u64) -> integrator::RenderOutput {
    let mut o = RenderOptions::new(kind, Budget::Spp(spp));
    o.run.seed = seed;
    o.run.strategy_images = true;
    integrator::render(scene, &o).unwrap()
}

#[test]
fn strategy_images_sum_to_the_image_and_a_missing_strategy_is_caught() {
    let scene = CORNELL_PLY.scene();
    let reference = reference(CORNELL_PLY.reference);
    for kind in [IntegratorKind::Bdpt, IntegratorKind::Lvc, IntegratorKind::Lighttrace] {
        let out = render_layers(&scene, kind, 4, 7);
        assert!(!out.strategy_images.is_empty());
        for (i, p) in out.image.iter().enumerate() {
            let sum = out.strategy_images.iter().fold(glam::Vec3::ZERO, |acc, (_, img)| acc + img[i]);
            assert!(
                (sum - *p).abs().max_element() <= 1e-4 * (1.0 + p.max_element()),
                "{kind:?} pixel {i}: {sum} vs {p}"
            );
        }
    }
    // Negative control: without the weighted `(s=1, t=2)` image (direct light by NEE), an
    // otherwise converged BDPT image fails the check, as any wrong weight would.
    let a = render_layers(&scene, IntegratorKind::Bdpt, 16, 1);
    let b = render_layers(&scene, IntegratorKind::Bdpt, 16, 2);
    let drop = |out: &integrator::RenderOutput| {
        let (_, layer) = out.strategy_images.iter().find(|(n, _)| n == "s1_t2").unwrap();
        Image::new(out.width, out.height, out.image.iter().zip(layer).map(|(p, l)| *p - *l).collect())
    };
    let (full, _) = Verdict::averaged(
        &reference,
        &Image::new(a.width, a.height, a.image.clone()),
        &Image::new(b.width, b.height, b.image.clone()),
        CORNELL_PLY.noise(),
    );
    full.check("cornell-ply, BDPT", 0.005, 1.3).unwrap();
    let (v, _) = Verdict::averaged(&reference, &drop(&a), &drop(&b), CORNELL_PLY.noise());
    assert!(v.check("cornell-ply, BDPT without s1_t2", 0.005, 1.3).is_err(), "a missing strategy went unnoticed");
}
