//! Embree's two BVH layouts (one BVH over all triangles, or one per shape under a BVH over
//! the shapes) run the same triangle test, so they report the same hits: the same
//! primitive at the same distance, except where two primitives lie at the same distance
//! (a shared edge, coplanar faces) and the traversal order picks one of them.

mod common;

use common::*;
use glam::Vec3;
use pcbpt::accel::{Accel, AccelError, Backend, BuildOptions, BuildQuality, BvhLayout, Geometry, Hit, Ray};
use pcbpt::sampling::{Sampler, square_to_uniform_sphere};

fn flat() -> BuildOptions {
    BuildOptions { layout: BvhLayout::Flat, ..BuildOptions::default() }
}

fn two_level() -> BuildOptions {
    BuildOptions { layout: BvhLayout::TwoLevel, ..BuildOptions::default() }
}

/// Compares the layouts on `n` random rays from the box `lo..hi`; returns how many hits
/// differed by a tie (another primitive at the same distance).
fn compare_layouts(geometry: &[Geometry<'_>], lo: Vec3, hi: Vec3, n: usize) -> usize {
    let a = Accel::build(Backend::Embree, geometry, flat()).unwrap();
    let b = Accel::build(Backend::Embree, geometry, two_level()).unwrap();
    let mut s = Sampler::new(&[77]);
    let mut ties = 0;
    let mut hits = 0;
    for i in 0..n {
        let o = lo + (hi - lo) * Vec3::new(s.next_1d(), s.next_1d(), s.next_1d());
        let r = Ray::new(o, square_to_uniform_sphere(s.next_2d()));
        let (ha, hb): (Option<Hit>, Option<Hit>) = (a.intersect(&r), b.intersect(&r));
        match (ha, hb) {
            (None, None) => {}
            (Some(x), Some(y)) if (x.geom, x.prim) == (y.geom, y.prim) => {
                hits += 1;
                assert_eq!((x.t, x.u, x.v), (y.t, y.u, y.v), "ray {i}: same primitive, different hit");
            }
            // Coplanar faces (a box standing on the floor) or a shared edge: the other
            // primitive at the same distance, to the last few bits.
            (Some(x), Some(y)) if (x.t - y.t).abs() <= 1e-6 * x.t => ties += 1,
            (x, y) => panic!("ray {i} {r:?}: flat {x:?}, two-level {y:?}"),
        }
        let seg = Ray { tmax: s.next_1d() * (hi - lo).length(), ..r };
        assert_eq!(a.occluded(&seg), b.occluded(&seg), "segment {i}: occlusion differs");
    }
    assert!(hits > n / 2, "too few hits ({hits} of {n}) for the comparison to mean much");
    ties
}

#[test]
fn both_layouts_find_the_same_hits_in_the_cornell_box() {
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[], Backend::Embree);
    let geometry: Vec<Geometry> = scene.shapes.iter().map(|s| s.accel_geometry()).collect();
    assert!(geometry.len() > 5, "the comparison needs several shapes");
    let ties = compare_layouts(&geometry, Vec3::new(-0.9, 0.1, -0.9), Vec3::new(0.9, 1.9, 0.9), 50_000);
    assert!(ties <= 50, "{ties} ties in 50 000 rays");
}

#[test]
fn both_layouts_find_the_same_hits_in_the_door_ajar_room() {
    let scene = load(&root().join("scenes/veach-ajar/scene.xml"), &[], Backend::Embree);
    let geometry: Vec<Geometry> = scene.shapes.iter().map(|s| s.accel_geometry()).collect();
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for g in &geometry {
        if let Geometry::Triangles { positions, .. } = g {
            for p in positions.iter() {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
    }
    let ties = compare_layouts(&geometry, lo, hi, 50_000);
    assert!(ties <= 50, "{ties} ties in 50 000 rays");
}

#[test]
fn a_flat_layout_has_no_low_quality_build() {
    let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let geometry = [Geometry::Triangles { positions: &p, indices: &[[0, 1, 2]] }];
    let low = |layout| BuildOptions { quality: BuildQuality::Low, layout, ..BuildOptions::default() };
    assert!(matches!(Accel::build(Backend::Embree, &geometry, low(BvhLayout::Flat)), Err(AccelError::Unsupported(_))));
    assert!(Accel::build(Backend::Embree, &geometry, low(BvhLayout::TwoLevel)).is_ok());
    for layout in [BvhLayout::Flat, BvhLayout::TwoLevel] {
        for quality in [BuildQuality::Medium, BuildQuality::High] {
            let accel =
                Accel::build(Backend::Embree, &geometry, BuildOptions { quality, layout, ..BuildOptions::default() })
                    .unwrap();
            let hit = accel.intersect(&Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z)).expect("the ray hits");
            assert_eq!((hit.geom, hit.prim), (0, 0));
            assert!((hit.t - 1.0).abs() < 1e-6);
        }
    }
}
