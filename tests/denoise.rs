//! `--denoise`: with `--features oidn`, Open Image Denoise's image of a noisy render lies
//! closer to a converged reference than the render itself, and is written beside the raw
//! image, which stays as a render without `--denoise` makes it. Without the feature the
//! option is refused by name before rendering.

mod common;

use common::root;
use std::path::Path;
use std::process::{Command, Output};

/// A path-traced render of the Cornell box at 64×64 (its film's box filter keeps the noise
/// of neighbouring pixels independent, as the denoiser expects).
fn render(out: &Path, spp: &str, seed: &str, extra: &[&str]) -> Output {
    let scene = root().join("scenes/cornell-ply/cornell_mi.xml");
    let mut args = vec!["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "--quiet"];
    args.extend(["--resolution", "64x64", "--integrator", "path", "--spp", spp, "--seed", seed]);
    args.extend(extra);
    Command::new(env!("CARGO_BIN_EXE_pcbpt")).args(&args).output().expect("runs the binary")
}

#[cfg(feature = "oidn")]
#[test]
fn the_denoised_image_is_closer_to_the_reference_and_the_raw_one_unchanged() {
    use pcbpt::compare::metrics;
    use pcbpt::image_io::read_exr;
    let d = tempfile::tempdir().unwrap();
    let (raw, plain, reference) = (d.path().join("raw.exr"), d.path().join("plain.exr"), d.path().join("ref.exr"));
    // The reference's noise is independent of the render's (another seed).
    for (out, spp, seed, extra) in
        [(&raw, "4", "7", &["--denoise"][..]), (&plain, "4", "7", &[]), (&reference, "256", "8", &[])]
    {
        let o = render(out, spp, seed, extra);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let denoised = d.path().join("raw.denoised.exr");
    common::distributed::assert_same_bits(&raw, &plain);
    let r = read_exr(&reference).unwrap();
    let noisy = metrics(&r, &read_exr(&raw).unwrap()).unwrap().relmse;
    let clean = metrics(&r, &read_exr(&denoised).unwrap()).unwrap().relmse;
    eprintln!("relMSE against 256 spp: raw {noisy:.4}, denoised {clean:.4}");
    assert!(clean < 0.5 * noisy, "denoised relMSE {clean} against raw {noisy}");
}

#[cfg(not(feature = "oidn"))]
#[test]
fn without_the_feature_denoise_is_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("raw.exr");
    let o = render(&out, "1", "7", &["--denoise"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("--denoise") && err.contains("--features oidn") && !err.contains("panicked"), "{err}");
    assert!(!out.exists(), "rendered before refusing");
}
