//! PCBPT against the Mitsuba 3 path-tracer references on cornell-ply, veach-mis and
//! veach-ajar, for each MIS option and each distance term of the interpolation, with the
//! same verdict as the other bidirectional integrators (`tests/bidir_reference.rs`): two
//! seeds averaged, image mean within 0.5%, relMSE within 1.3× of what noise explains.

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::image_io::Image;
use pcbpt::integrator::bidir::pcbpt::{DistanceTerm, PcMis, PcOptions};
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};

struct Case {
    name: &'static str,
    scene: &'static str,
    defines: &'static [(&'static str, &'static str)],
    reference: &'static str,
    ref_noise: f64,
    mean_cutoff: Option<f32>,
    spp: u32,
}

const CORNELL_PLY: Case = Case {
    name: "cornell-ply",
    scene: "scenes/cornell-ply/cornell_mi.xml",
    defines: &[],
    reference: "cornell-ply_mitsuba3-path_4096spp_maxdepth8_box.exr",
    ref_noise: 8.0e-5,
    mean_cutoff: None,
    spp: 24,
};

const VEACH_MIS: Case = Case {
    name: "veach-mis",
    scene: "scenes/veach-mis/scene.xml",
    defines: &[("resx", "192"), ("resy", "108")],
    reference: "veach-mis.exr",
    ref_noise: 2.2e-5,
    mean_cutoff: Some(100.0),
    spp: 32,
};

const VEACH_AJAR: Case = Case {
    name: "veach-ajar",
    scene: "scenes/veach-ajar/scene.xml",
    defines: &[("resx", "160"), ("resy", "90"), ("max_depth", "-1")],
    reference: "veach-ajar.exr",
    ref_noise: 4.5e-3,
    mean_cutoff: None,
    spp: 128,
};

fn render(case: &Case, mis: PcMis, term: DistanceTerm, seed: u64) -> Image {
    let scene = load(&root().join(case.scene), case.defines, Backend::Embree);
    let mut o = RenderOptions::new(IntegratorKind::Pcbpt, Budget::Spp(case.spp));
    o.seed = seed;
    o.bidir.pc = PcOptions { mis, distance_term: term, ..PcOptions::default() };
    let out = integrator::render(&scene, &o).unwrap();
    Image::new(out.width, out.height, out.image)
}

fn check(case: &Case, mis: PcMis, term: DistanceTerm) {
    let reference = reference(case.reference);
    let a = render(case, mis, term, 1);
    let b = render(case, mis, term, 2);
    let (mut v, avg) = Verdict::averaged(&reference, &a, &b, case.ref_noise);
    if let Some(cutoff) = case.mean_cutoff {
        v = v.excluding_emitters(&reference, &avg, cutoff);
    }
    v.check(&format!("{}, PCBPT {mis:?} {term:?}, 2 × {} spp", case.name, case.spp), 0.005, 1.3).unwrap();
}

macro_rules! cases {
    ($($name:ident: $case:expr, $mis:ident, $term:ident;)*) => {
        $(
            #[test]
            fn $name() {
                check(&$case, PcMis::$mis, DistanceTerm::$term);
            }
        )*
    };
}

cases! {
    cornell_ply_uniform_falloff: CORNELL_PLY, Uniform, Falloff;
    cornell_ply_uniform_printed: CORNELL_PLY, Uniform, Printed;
    cornell_ply_resampling_falloff: CORNELL_PLY, Resampling, Falloff;
    cornell_ply_resampling_printed: CORNELL_PLY, Resampling, Printed;
    veach_mis_uniform_falloff: VEACH_MIS, Uniform, Falloff;
    veach_mis_uniform_printed: VEACH_MIS, Uniform, Printed;
    veach_mis_resampling_falloff: VEACH_MIS, Resampling, Falloff;
    veach_mis_resampling_printed: VEACH_MIS, Resampling, Printed;
    veach_ajar_uniform_falloff: VEACH_AJAR, Uniform, Falloff;
    veach_ajar_uniform_printed: VEACH_AJAR, Uniform, Printed;
    veach_ajar_resampling_falloff: VEACH_AJAR, Resampling, Falloff;
    veach_ajar_resampling_printed: VEACH_AJAR, Resampling, Printed;
}
