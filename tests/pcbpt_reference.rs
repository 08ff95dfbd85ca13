//! PCBPT against the Mitsuba 3 path-tracer references on cornell-ply, veach-mis and
//! veach-ajar, for each MIS option and each distance term of the interpolation, with the
//! same verdict as the other bidirectional integrators (`tests/bidir_reference.rs`): two
//! seeds averaged, image mean within 0.5%, relMSE within 1.3× of what noise explains.

mod common;

use common::*;
use pcbpt::image_io::Image;
use pcbpt::integrator::bidir::pcbpt::{DistanceTerm, PcMis, PcOptions};
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};

fn render(case: &Case, spp: u32, mis: PcMis, term: DistanceTerm, seed: u64) -> Image {
    let scene = case.scene();
    let mut o = RenderOptions::new(IntegratorKind::Pcbpt, Budget::Spp(spp));
    o.seed = seed;
    o.bidir.pc = PcOptions { mis, distance_term: term, ..PcOptions::default() };
    let out = integrator::render(&scene, &o).unwrap();
    Image::new(out.width, out.height, out.image)
}

fn check(case: &Case, spp: u32, mis: PcMis, term: DistanceTerm) {
    let a = render(case, spp, mis, term, 1);
    let b = render(case, spp, mis, term, 2);
    case.check(&a, &b, &format!("PCBPT {mis:?} {term:?}, 2 × {spp} spp"));
}

macro_rules! cases {
    ($($name:ident: $case:expr, $spp:expr, $mis:ident, $term:ident;)*) => {
        $(
            #[test]
            fn $name() {
                check(&$case, $spp, PcMis::$mis, DistanceTerm::$term);
            }
        )*
    };
}

cases! {
    cornell_ply_uniform_falloff: CORNELL_PLY, 24, Uniform, Falloff;
    cornell_ply_uniform_printed: CORNELL_PLY, 24, Uniform, Printed;
    cornell_ply_resampling_falloff: CORNELL_PLY, 24, Resampling, Falloff;
    cornell_ply_resampling_printed: CORNELL_PLY, 24, Resampling, Printed;
    veach_mis_uniform_falloff: VEACH_MIS, 32, Uniform, Falloff;
    veach_mis_uniform_printed: VEACH_MIS, 32, Uniform, Printed;
    veach_mis_resampling_falloff: VEACH_MIS, 32, Resampling, Falloff;
    veach_mis_resampling_printed: VEACH_MIS, 32, Resampling, Printed;
    veach_ajar_uniform_falloff: VEACH_AJAR, 128, Uniform, Falloff;
    veach_ajar_uniform_printed: VEACH_AJAR, 128, Uniform, Printed;
    veach_ajar_resampling_falloff: VEACH_AJAR, 128, Resampling, Falloff;
    veach_ajar_resampling_printed: VEACH_AJAR, 128, Resampling, Printed;
}
