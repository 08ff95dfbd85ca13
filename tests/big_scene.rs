//! The big-scene generator (`examples/big_scene.rs`) at a small size: its files are the
//! same for the same triangle count, and the scene loads and renders with the path tracer,
//! BDPT and PCBPT.

#[path = "../examples/big_scene.rs"]
#[allow(dead_code)]
mod big_scene;
mod common;

use pcbpt::accel::Backend;
use pcbpt::integrator::IntegratorKind;

#[test]
fn generated_scene_is_reproducible_and_renders_with_every_integrator() {
    let dir = tempfile::tempdir().unwrap();
    let summary = big_scene::generate(dir.path(), 20_000).unwrap();
    assert!(summary.triangles >= 20_000 && summary.triangles < 22_000, "{summary:?}");
    let again = tempfile::tempdir().unwrap();
    big_scene::generate(again.path(), 20_000).unwrap();
    for name in ["big.xml", "terrain.ply", "torus0.ply", "torus7.ply"] {
        let (a, b) = (std::fs::read(dir.path().join(name)).unwrap(), std::fs::read(again.path().join(name)).unwrap());
        assert!(a == b, "{name} differs between two runs");
    }

    let scene = common::load(&summary.scene, &[("resx", "96"), ("resy", "54")], Backend::Embree);
    // The meshes plus the room's six rectangles of two triangles.
    assert_eq!(scene.stats.triangles as u64, summary.triangles + 12);
    assert_eq!(scene.stats.vertices as u64, summary.vertices + 24);
    assert_eq!(scene.stats.degenerate_triangles, 0);
    assert!(scene.stats.mesh_bytes as u64 >= summary.triangles * 12 + summary.vertices * 32, "{:?}", scene.stats);
    assert_eq!((scene.film.width, scene.film.height), (96, 54));
    for kind in [IntegratorKind::Path, IntegratorKind::Bdpt, IntegratorKind::Pcbpt] {
        let img = common::image(common::render(&scene, kind, 1, 7, 2));
        assert!(img.pixels.iter().all(|p| p.is_finite()), "{kind:?}");
        // Most of the picture is lit terrain, tori and walls, not black.
        let lit = img.pixels.iter().filter(|p| p.max_element() > 0.0).count();
        assert!(lit * 2 > img.pixels.len(), "{kind:?}: {lit} of {} pixels lit", img.pixels.len());
    }
}
