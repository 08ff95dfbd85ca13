//! The Embree library linked at run time is the one the bindings were generated for: the
//! same major version as the headers (and as `cfg(embree4)`), no older than the headers,
//! and with the headers' struct layout: a batch of queries on adjacent structs, every one
//! a hit, reports what the single-ray queries report (a library whose hit record is
//! longer than the headers' writes into the next ray of the batch).

use glam::Vec3;
use pcbpt::accel::embree::{self, EMBREE4, HEADERS_VERSION, Version};
use pcbpt::accel::{Accel, Backend, BuildOptions, Geometry, Ray};
use std::path::Path;

#[test]
fn the_linked_embree_has_the_headers_major_version() {
    let linked = embree::version().unwrap();
    let headers = Version::from_number(HEADERS_VERSION);
    println!("Embree {linked} linked, headers {headers}, cfg(embree4) {EMBREE4}");
    assert_eq!(linked.major, headers.major, "linked Embree {linked}, headers {headers}");
    assert_eq!(linked.major, if EMBREE4 { 4 } else { 3 }, "linked Embree {linked}, cfg(embree4) {EMBREE4}");
    assert!(linked >= headers, "the linked Embree {linked} is older than its headers {headers}");
    // Built with EMBREE_DIR pointing at Embree 4 headers, the Embree 4 path must be what ran.
    if let Some(dir) = option_env!("EMBREE_DIR")
        && Path::new(dir).join("include/embree4/rtcore.h").is_file()
    {
        assert_eq!(linked.major, 4, "EMBREE_DIR={dir} holds Embree 4, but Embree {linked} ran");
    }
}

#[test]
fn version_numbers_split_into_major_minor_patch() {
    let v = Version::from_number(40400);
    assert_eq!((v.major, v.minor, v.patch), (4, 4, 0));
    assert_eq!(Version::from_number(31302).to_string(), "3.13.2");
}

#[test]
fn batches_of_hits_equal_single_queries() {
    // Two quads (z = 2 in front of z = 5) of two triangles each; every ray hits the near one.
    let p =
        [Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(-1.0, 1.0, 0.0)];
    let far: Vec<Vec3> = p.iter().map(|v| *v + Vec3::Z * 5.0).collect();
    let near: Vec<Vec3> = p.iter().map(|v| *v + Vec3::Z * 2.0).collect();
    let indices = [[0, 1, 2], [0, 2, 3]];
    let geometry = [
        Geometry::Triangles { positions: &far, indices: &indices },
        Geometry::Triangles { positions: &near, indices: &indices },
    ];
    let accel = Accel::build(Backend::Embree, &geometry, BuildOptions::default()).unwrap();
    // No ray meets the quads' shared diagonal (x = y), where the two triangles' hits tie
    // and which one Embree reports may differ between a batch and a single query (it does
    // on AVX-512).
    let rays: Vec<Ray> = (0..64)
        .map(|i| {
            let (x, y) = ((i % 8) as f32 / 4.0 - 0.9, (i / 8) as f32 / 4.0 - 0.85);
            Ray::new(Vec3::new(x, y, 0.0), Vec3::Z)
        })
        .collect();
    // (-0.5, 0.25) lies in triangle 1 (vertices 0, 2, 3): p = p0 + u (p2 - p0) + v (p3 - p0).
    let h = accel.intersect(&Ray::new(Vec3::new(-0.5, 0.25, 0.0), Vec3::Z)).unwrap();
    assert_eq!((h.geom, h.prim), (1, 1), "{h:?}");
    let close = |a: f32, b: f32| (a - b).abs() <= 1e-6;
    assert!(close(h.t, 2.0) && close(h.u, 0.25) && close(h.v, 0.375), "{h:?}");
    for coherent in [false, true] {
        let mut batch = Vec::new();
        accel.intersect_batch(&rays, coherent, &mut batch);
        let mut occluded = Vec::new();
        accel.occluded_batch(&rays, coherent, &mut occluded);
        for (i, r) in rays.iter().enumerate() {
            let single = accel.intersect(r);
            assert!(single.is_some_and(|h| h.geom == 1 && close(h.t, 2.0)), "ray {i}: {single:?}");
            assert_eq!(batch[i], single, "ray {i} (coherent {coherent}): batch and single query differ");
            assert!(occluded[i] && accel.occluded(r), "ray {i} (coherent {coherent}) is not occluded");
        }
    }
}
