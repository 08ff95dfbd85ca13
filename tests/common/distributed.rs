//! Helpers of the distributed-render tests (`tests/slurm.rs`, `tests/dask.rs`): the render
//! they cut into chunks, the single-process render it must equal, the bit-for-bit check, and
//! the rule for missing tools (fail with what to install, unless the test is skipped by its
//! environment variable).

use super::root;
use pcbpt::image_io;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Whether the test may run: `Ok(true)` when every tool is there, `Ok(false)` when they are
/// not and `skip_var=1` says to skip the test (printed, so a skip is never silent), `Err`
/// (the test must fail) otherwise.
pub fn tools_or_skip(what: &str, skip_var: &str, missing: &[String]) -> Result<bool, String> {
    if missing.is_empty() {
        return Ok(true);
    }
    let msg = format!("{what} not found ({}): run `scripts/setup.sh` (README.md's first command)", missing.join(", "));
    if std::env::var(skip_var).is_ok_and(|v| v == "1") {
        eprintln!("SKIPPED: {msg} ({skip_var}=1)");
        return Ok(false);
    }
    Err(format!("{msg}, or set {skip_var}=1 to skip this test"))
}

/// The executables among `names` found neither on PATH nor in /usr/sbin or /sbin.
pub fn missing_programs(names: &[&str]) -> Vec<String> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    let mut dirs: Vec<PathBuf> = std::env::split_paths(&path).collect();
    dirs.extend(["/usr/sbin", "/sbin"].map(PathBuf::from));
    names.iter().filter(|n| !dirs.iter().any(|d| d.join(n).is_file())).map(|n| n.to_string()).collect()
}

pub fn scene() -> PathBuf {
    root().join("scenes/cornell-box/scene.xml")
}

/// The render options every chunk and the single-process render share: a small Cornell box
/// (a few hundred milliseconds on one thread), a fixed seed.
pub fn render_options(integrator: &str) -> Vec<String> {
    ["-D", "resx=64", "-D", "resy=48", "--spp", "16", "--seed", "7", "--threads", "1", "--integrator", integrator]
        .map(String::from)
        .to_vec()
}

pub fn pcbpt() -> &'static str {
    env!("CARGO_BIN_EXE_pcbpt")
}

/// Renders `scene()` with `options` in one process into `out`.
pub fn single_render(options: &[String], out: &Path) {
    let o = Command::new(pcbpt())
        .arg("render")
        .arg(scene())
        .args(options)
        .arg("-o")
        .arg(out)
        .arg("--quiet")
        .output()
        .expect("runs pcbpt");
    assert!(o.status.success(), "single-process render failed: {}", String::from_utf8_lossy(&o.stderr));
}

/// The number of pixels of `a` and `b` that differ in any bit of any channel, with the
/// first such pixel's message; panics if the two differ in size.
pub fn differing_pixels(a: &Path, b: &Path) -> (usize, String) {
    let read = |p: &Path| image_io::read_exr(p).unwrap_or_else(|e| panic!("reading {}: {e}", p.display()));
    let (x, y) = (read(a), read(b));
    assert_eq!((x.width, x.height), (y.width, y.height), "{} and {} differ in size", a.display(), b.display());
    assert!(x.mean() > 0.0 && y.mean() > 0.0, "{} or {} is black", a.display(), b.display());
    let bits = |p: pcbpt::math::Rgb| p.to_array().map(f32::to_bits);
    let differ: Vec<usize> = (0..x.pixels.len()).filter(|&i| bits(x.pixels[i]) != bits(y.pixels[i])).collect();
    let first = differ.first().map_or(String::new(), |&i| {
        format!(
            "first at ({}, {}): {:?} against {:?}",
            i as u32 % x.width,
            i as u32 / x.width,
            x.pixels[i],
            y.pixels[i]
        )
    });
    (differ.len(), first)
}

/// Panics unless `a` and `b` hold the same pixels, every channel the same bits.
pub fn assert_same_bits(a: &Path, b: &Path) {
    let (n, first) = differing_pixels(a, b);
    assert!(n == 0, "{} and {} differ in {n} pixels; {first}", a.display(), b.display());
}

/// The text of a command's output, for messages.
pub fn describe(o: &Output) -> String {
    format!(
        "status {}\n--- stdout\n{}--- stderr\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}
