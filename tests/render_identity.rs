//! The render loop's images, bit for bit, for every integrator and option: the hashes of
//! small renders (obvhs backend, pure Rust, so they do not depend on the CPU's Embree
//! kernels) are kept in `tests/data/render_hashes.txt`. A change of the render loop that
//! only moves code must leave them all unchanged; a change that is meant to change images
//! re-records them with `PCBPT_BLESS_HASHES=1` and says why in its commit.
#![cfg(feature = "obvhs")]

mod common;

use common::*;
use pcbpt::accel::Backend;
use pcbpt::integrator::bidir::mis::Heuristic;
use pcbpt::integrator::metropolis::MltBase;
use pcbpt::integrator::pcbpt::{DistanceTerm, PcMis, PcSampling};
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions};

/// Every integrator with each of its options that changes what the loop does.
fn cases() -> Vec<(&'static str, RenderOptions)> {
    use IntegratorKind::*;
    let base = |kind| {
        let mut o = RenderOptions::new(kind, Budget::Spp(5));
        o.run.seed = 7;
        o.run.threads = 2;
        o.run.tile_size = 16;
        o
    };
    let with = |kind, f: &dyn Fn(&mut RenderOptions)| {
        let mut o = base(kind);
        f(&mut o);
        o
    };
    let pcbpt = |f: &dyn Fn(&mut RenderOptions)| {
        with(Pcbpt, &|o| {
            o.method.budget_mut().mode = pcbpt::integrator::budget::BudgetMode::Off;
            f(o)
        })
    };
    vec![
        ("path", base(Path)),
        ("guided", base(Guided)),
        // Training passes of 1, 2, 4 and 8 samples per pixel and the tree used wherever a
        // vertex is guided (no leaf learns to sample the BSDF alone): a change in what each
        // vertex records changes the tree, and so the image.
        (
            "guided_trained",
            with(Guided, &|o| {
                o.run.budget = Budget::Spp(32);
                o.method.guided_mut().learn_fraction = false;
            }),
        ),
        ("lighttrace", base(Lighttrace)),
        ("bdpt", base(Bdpt)),
        ("bdpt_balance", with(Bdpt, &|o| *o.method.heuristic_mut().unwrap() = Heuristic::Balance)),
        ("bdpt_layers", with(Bdpt, &|o| o.run.strategy_images = true)),
        ("eorr_running_mean", with(Eorr, &|o| o.method.eorr_mut().pilot_spp = 0)),
        ("eorr", base(Eorr)),
        ("lvc", base(Lvc)),
        ("lvc_3_connections", with(Lvc, &|o| o.method.lvc_mut().connections = 3)),
        // PCBPT's options with the fixed plan (`--pc-budget off`), then its defaults (the
        // budget, which changes the plan after iteration 2 of these 5).
        ("pcbpt", pcbpt(&|_| {})),
        ("pcbpt_uniform", pcbpt(&|o| o.method.pcbpt_mut().pc.mis = PcMis::Uniform)),
        ("pcbpt_resampling", pcbpt(&|o| o.method.pcbpt_mut().pc.mis = PcMis::Resampling)),
        (
            "pcbpt_cmf_printed",
            pcbpt(&|o| {
                o.method.pcbpt_mut().pc.sampling = PcSampling::Cmf;
                o.method.pcbpt_mut().pc.distance_term = DistanceTerm::Printed;
            }),
        ),
        ("pcbpt_layers", pcbpt(&|o| o.run.strategy_images = true)),
        ("pcbpt_budget", base(Pcbpt)),
        ("pssmlt", with(Pssmlt, &|o| o.method.chain_mut().bootstrap = 2000)),
        (
            "pssmlt_path",
            with(Pssmlt, &|o| {
                o.method.chain_mut().bootstrap = 2000;
                o.method.pssmlt_mut().base = MltBase::Path;
            }),
        ),
    ]
}

/// FNV-1a over the image's bits and those of its per-strategy images.
fn hash(out: &integrator::RenderOutput) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let images = std::iter::once(&out.image).chain(out.strategy_images.iter().map(|(_, i)| i));
    for bits in images.flat_map(|i| i.iter().flat_map(|p| p.to_array().map(f32::to_bits))) {
        for b in bits.to_le_bytes() {
            h = (h ^ b as u64).wrapping_mul(0x100_0000_01b3);
        }
    }
    h
}

#[test]
fn images_are_those_recorded() {
    let scene = load(&root().join("scenes/cornell-box/scene.xml"), &[("resx", "40"), ("resy", "30")], Backend::Obvhs);
    let file = root().join("tests/data/render_hashes.txt");
    let got: Vec<(String, u64)> = cases()
        .into_iter()
        .map(|(name, o)| (name.to_string(), hash(&integrator::render(&scene, &o).unwrap())))
        .collect();
    if std::env::var_os("PCBPT_BLESS_HASHES").is_some() {
        let text: String = got.iter().map(|(n, h)| format!("{n} {h:016x}\n")).collect();
        std::fs::write(&file, text).unwrap();
        return;
    }
    let recorded = std::fs::read_to_string(&file).unwrap();
    let mut mismatches = Vec::new();
    for (name, h) in &got {
        let want = recorded.lines().find_map(|l| l.strip_prefix(&format!("{name} "))).map(str::trim);
        if want != Some(format!("{h:016x}").as_str()) {
            mismatches.push(format!("{name}: {h:016x}, recorded {want:?}"));
        }
    }
    assert!(mismatches.is_empty(), "images changed:\n{}", mismatches.join("\n"));
}
