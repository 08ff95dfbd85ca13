//! Path-tracer samples per second on `cornell-ply` (256×256, max_depth 8, box filter).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use pcbpt::accel::{Backend, BuildOptions, BvhLayout};
use pcbpt::integrator::{Budget, IntegratorKind, RenderOptions, render};
use pcbpt::scene::{LoadOptions, Scene};
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-ply/cornell_mi.xml");
    let flat = BuildOptions { layout: BvhLayout::Flat, ..BuildOptions::default() };
    let mut backends =
        vec![("embree", Backend::Embree, BuildOptions::default()), ("embree-flat", Backend::Embree, flat)];
    if cfg!(feature = "obvhs") {
        backends.push(("obvhs", Backend::Obvhs, BuildOptions::default()));
    }
    let spp = 4;
    let mut g = c.benchmark_group("path_cornell_ply_256x256");
    g.sample_size(10).measurement_time(Duration::from_secs(6)).throughput(Throughput::Elements(256 * 256 * spp as u64));
    for (name, backend, build) in backends {
        let scene = Scene::load(&path, &LoadOptions { backend, build, ..Default::default() }).expect("scene loads");
        let opts = RenderOptions::new(IntegratorKind::Path, Budget::Spp(spp));
        g.bench_function(name, |bench| bench.iter(|| black_box(render(&scene, &opts).expect("renders"))));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
