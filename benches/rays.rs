//! Ray throughput of each backend on scenes of over a million triangles, and BVH build time.
//!
//! Scenes: a closed sphere of 1.0 M triangles (camera rays from outside, incoherent rays
//! from inside) and a 1.0 M-triangle terrain (shadow rays between random points above it).
//! Rays are traced on all threads in chunks of 4096; throughput is rays per second.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use pcbpt::accel::{Accel, Backend, BuildOptions, BvhLayout, Geometry, Ray};
use pcbpt::sampling::{Sampler, square_to_uniform_sphere};
use rayon::prelude::*;
use std::f32::consts::PI;
use std::hint::black_box;
use std::time::Duration;

const N_RAYS: usize = 1 << 16;

struct Mesh {
    positions: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
}

/// A UV sphere with `n × 2n` quads (4 n² triangles).
fn sphere(n: u32) -> Mesh {
    let mut positions = Vec::new();
    for i in 0..=n {
        let theta = PI * i as f32 / n as f32;
        for j in 0..2 * n {
            let phi = PI * j as f32 / n as f32;
            positions.push(Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()));
        }
    }
    let mut indices = Vec::new();
    for i in 0..n {
        for j in 0..2 * n {
            let (a, b) = (i * 2 * n + j, i * 2 * n + (j + 1) % (2 * n));
            let (c, d) = (a + 2 * n, b + 2 * n);
            indices.push([a, c, b]);
            indices.push([b, c, d]);
        }
    }
    Mesh { positions, indices }
}

/// A bumpy height field of `n × n` quads (2 n² triangles) over `[-1,1]²`.
fn terrain(n: u32) -> Mesh {
    let mut positions = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let (x, y) = (2.0 * i as f32 / n as f32 - 1.0, 2.0 * j as f32 / n as f32 - 1.0);
            let h = 0.1 * (7.0 * x).sin() * (5.0 * y).cos() + 0.03 * (31.0 * x + 17.0 * y).sin();
            positions.push(Vec3::new(x, y, h));
        }
    }
    let mut indices = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let a = i * (n + 1) + j;
            indices.push([a, a + n + 1, a + 1]);
            indices.push([a + 1, a + n + 1, a + n + 2]);
        }
    }
    Mesh { positions, indices }
}

/// The accelerators compared: Embree in both BVH layouts, and obvhs when compiled in.
fn backends() -> Vec<(&'static str, Backend, BuildOptions)> {
    let flat = BuildOptions { layout: BvhLayout::Flat, ..BuildOptions::default() };
    let mut b = vec![("embree", Backend::Embree, BuildOptions::default()), ("embree-flat", Backend::Embree, flat)];
    if cfg!(feature = "obvhs") {
        b.push(("obvhs", Backend::Obvhs, BuildOptions::default()));
    }
    b
}

fn trace_closest(accel: &Accel, rays: &[Ray]) -> usize {
    rays.par_chunks(4096).map(|c| c.iter().filter(|r| accel.intersect(r).is_some()).count()).sum()
}

fn trace_closest_batch(accel: &Accel, rays: &[Ray], coherent: bool) -> usize {
    rays.par_chunks(4096)
        .map(|c| {
            let mut out = Vec::with_capacity(c.len());
            accel.intersect_batch(c, coherent, &mut out);
            out.iter().filter(|h| h.is_some()).count()
        })
        .sum()
}

fn trace_occluded(accel: &Accel, rays: &[Ray]) -> usize {
    rays.par_chunks(4096).map(|c| c.iter().filter(|r| accel.occluded(r)).count()).sum()
}

fn camera_rays() -> Vec<Ray> {
    // A 256×256 pinhole view of the sphere from outside, row by row (coherent).
    let o = Vec3::new(0.0, -3.0, 0.0);
    (0..N_RAYS)
        .map(|i| {
            let (x, y) = ((i % 256) as f32 / 256.0 - 0.5, (i / 256) as f32 / 256.0 - 0.5);
            Ray::new(o, Vec3::new(x * 0.8, 1.0, y * 0.8).normalize())
        })
        .collect()
}

fn incoherent_rays() -> Vec<Ray> {
    let mut s = Sampler::new(&[1]);
    (0..N_RAYS)
        .map(|_| {
            Ray::new(square_to_uniform_sphere(s.next_2d()) * 0.5 * s.next_1d(), square_to_uniform_sphere(s.next_2d()))
        })
        .collect()
}

fn shadow_rays() -> Vec<Ray> {
    let mut s = Sampler::new(&[2]);
    (0..N_RAYS)
        .map(|_| {
            let a = Vec3::new(2.0 * s.next_1d() - 1.0, 2.0 * s.next_1d() - 1.0, 0.15 + 0.1 * s.next_1d());
            let b = Vec3::new(2.0 * s.next_1d() - 1.0, 2.0 * s.next_1d() - 1.0, 0.15 + 0.3 * s.next_1d());
            Ray::segment(a, b - a, 1.0)
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let sphere = sphere(500); // 1 000 000 triangles
    let terrain = terrain(708); // 1 002 528 triangles
    let sphere_geo = [Geometry::Triangles { positions: &sphere.positions, indices: &sphere.indices }];
    let terrain_geo = [Geometry::Triangles { positions: &terrain.positions, indices: &terrain.indices }];
    let (cam, inc, sh) = (camera_rays(), incoherent_rays(), shadow_rays());

    let mut g = c.benchmark_group("build_1M_triangles");
    g.sample_size(10).measurement_time(Duration::from_secs(8));
    for (name, b, o) in backends() {
        g.bench_function(name, |bench| bench.iter(|| black_box(Accel::build(b, &sphere_geo, o.clone()).unwrap())));
    }
    g.finish();

    let mut g = c.benchmark_group("rays_1M_triangles");
    g.sample_size(10)
        .measurement_time(Duration::from_secs(3))
        .warm_up_time(Duration::from_secs(1))
        .throughput(Throughput::Elements(N_RAYS as u64));
    for (name, b, o) in backends() {
        let s = Accel::build(b, &sphere_geo, o.clone()).unwrap();
        let t = Accel::build(b, &terrain_geo, o).unwrap();
        g.bench_function(format!("{name}/camera"), |bench| bench.iter(|| black_box(trace_closest(&s, &cam))));
        if name == "embree" {
            g.bench_function(format!("{name}/camera_stream"), |bench| {
                bench.iter(|| black_box(trace_closest_batch(&s, &cam, true)))
            });
        }
        g.bench_function(format!("{name}/incoherent"), |bench| bench.iter(|| black_box(trace_closest(&s, &inc))));
        g.bench_function(format!("{name}/shadow"), |bench| bench.iter(|| black_box(trace_occluded(&t, &sh))));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
