//! `pcbpt experiment` end to end on a tiny suite: outputs exist, the numbers are consistent;
//! a stopped experiment returns what it has done.

mod common;

use common::root;
use pcbpt::experiment;

fn write(dir: &std::path::Path, name: &str, body: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    let scene = root().join("scenes/cornell-box/scene.xml");
    let text = format!(
        r#"name = "tiny"
threads = 2
baseline = "path"
{body}

[[method]]
name = "path"
integrator = "path"

[[method]]
name = "bdpt"
integrator = "bdpt"
heuristic = "balance"
"#
    )
    .replace("SCENE", scene.to_str().unwrap());
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn tiny_experiment_writes_table_csv_plot_and_figure_with_consistent_numbers() {
    let d = tempfile::tempdir().unwrap();
    // Equal time, reference rendered by BDPT, convergence checkpoints.
    let f = write(
        d.path(),
        "timed.toml",
        r#"time = 1.2
checkpoints = 5

[[scene]]
name = "cornell"
file = "SCENE"
defines = { resx = "40", resy = "40" }
reference_method = "bdpt"
reference_time = 3
crops = [[8, 8, 10, 10], [25, 4, 8, 8]]"#,
    );
    let results = experiment::run(&f, None, true).unwrap();
    let out = d.path().join("timed");
    for name in [
        "results.md",
        "convergence.csv",
        "convergence_cornell.svg",
        "figure_cornell.png",
        "cornell_reference.exr",
        "cornell_path.exr",
        "cornell_bdpt.exr",
    ] {
        assert!(out.join(name).exists(), "{name} missing");
    }
    assert_eq!(results.len(), 2);
    for r in &results {
        assert!(r.curve.len() >= 3, "{}: {:?}", r.method, r.curve);
        // relMSE falls as the render converges: the first checkpoint is worse than the end.
        assert!(r.curve[0].2 > r.curve.last().unwrap().2, "{}: {:?}", r.method, r.curve);
        assert!(r.curve.windows(2).all(|w| w[0].0 <= w[1].0 && w[0].1 <= w[1].1));
        assert!((r.mean_ratio - 1.0).abs() < 0.05, "{}: {}", r.method, r.mean_ratio);
    }
    let table = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(table.contains("| cornell | path |") && table.contains("1.00×"), "{table}");
    let csv = std::fs::read_to_string(out.join("convergence.csv")).unwrap();
    let rows = results.iter().map(|r| r.curve.len()).sum::<usize>();
    assert_eq!(csv.lines().count(), rows + 1);

    // A fixed sample count is deterministic: against its own earlier image as the
    // reference, the same method scores a relMSE of exactly 0.
    let first = write(
        d.path(),
        "fixed.toml",
        r#"spp = 4

[[scene]]
name = "cornell"
file = "SCENE"
defines = { resx = "24", resy = "24" }
reference_method = "path"
reference_time = 0.5"#,
    );
    let a = experiment::run(&first, None, true).unwrap();
    let image = d.path().join("fixed").join("cornell_bdpt.exr");
    let again = write(
        d.path(),
        "again.toml",
        &format!(
            r#"spp = 4

[[scene]]
name = "cornell"
file = "SCENE"
defines = {{ resx = "24", resy = "24" }}
reference = "{}""#,
            image.display()
        ),
    );
    let b = experiment::run(&again, None, true).unwrap();
    assert_eq!(b[1].method, "bdpt");
    assert_eq!(b[1].relmse, 0.0, "{:?}", b[1]);
    assert!(b[0].relmse > 0.0);
    assert_eq!(a[1].spp, 4);
}

#[test]
fn experiment_file_errors_name_the_file_and_line() {
    let d = tempfile::tempdir().unwrap();
    let f = write(
        d.path(),
        "bad.toml",
        "time = 1\nsppp = 3\n[[scene]]\nname = \"x\"\nfile = \"SCENE\"\nreference = \"r.exr\"",
    );
    let e = experiment::run(&f, None, true).unwrap_err().to_string();
    assert!(e.contains("bad.toml:5") && e.contains("sppp"), "{e}");
    let f = write(
        d.path(),
        "both.toml",
        "time = 1\nspp = 3\n[[scene]]\nname = \"x\"\nfile = \"SCENE\"\nreference = \"r.exr\"",
    );
    let e = experiment::run(&f, None, true).unwrap_err().to_string();
    assert!(e.contains("both.toml") && e.contains("exactly one"), "{e}");
    let f = write(d.path(), "noref.toml", "time = 1\n[[scene]]\nname = \"x\"\nfile = \"SCENE\"");
    let e = experiment::run(&f, None, true).unwrap_err().to_string();
    assert!(e.contains("noref.toml") && e.contains("reference"), "{e}");
}

#[test]
fn a_scene_with_a_fixed_film_runs_at_the_suite_resolution() {
    let d = tempfile::tempdir().unwrap();
    let scene = root().join("scenes/staircase2/scene.xml");
    let f = d.path().join("fixed-film.toml");
    std::fs::write(
        &f,
        format!(
            r#"spp = 1

[[scene]]
name = "staircase2"
file = "{}"
resolution = "40x24"
reference_method = "path"
reference_time = 0.3

[[method]]
name = "path"
integrator = "path"

[[method]]
name = "bdpt"
integrator = "bdpt"
"#,
            scene.display()
        ),
    )
    .unwrap();
    let results = experiment::run(&f, None, true).unwrap();
    assert_eq!(results.len(), 2);
    for name in ["staircase2_reference.exr", "staircase2_path.exr", "staircase2_bdpt.exr"] {
        let img = pcbpt::image_io::read_exr(&d.path().join("fixed-film").join(name)).unwrap();
        assert_eq!((img.width, img.height), (40, 24), "{name}");
    }
    // A malformed resolution names the file and line.
    let text = std::fs::read_to_string(&f).unwrap().replace("\"40x24\"", "\"40 by 24\"");
    std::fs::write(&f, text).unwrap();
    let e = experiment::run(&f, None, true).unwrap_err().to_string();
    assert!(e.contains("fixed-film.toml:6") && e.contains("40 by 24"), "{e}");
}

#[test]
fn method_options_are_the_integrators_and_seed_lists_are_checked() {
    let d = tempfile::tempdir().unwrap();
    let scene = "[[scene]]\nname = \"x\"\nfile = \"SCENE\"\nreference = \"r.exr\"";
    // An option another integrator reads, one no integrator reads, a value that does not parse.
    for (file, option, says) in [
        (
            "other.toml",
            "pc_cache_stride = 8",
            "`pc_cache_stride`: --pc-cache-stride is an option of pcbpt, not of path",
        ),
        (
            "none.toml",
            "pc_cache_strides = 8",
            "`pc_cache_strides`: --pc-cache-strides is not an option of any integrator",
        ),
        ("value.toml", "pc_mis = \"sideways\"", "sideways"),
    ] {
        let body = format!(
            "time = 1\n{scene}\n[[method]]\nname = \"m\"\nintegrator = \"{}\"\n{option}",
            if file == "value.toml" { "pcbpt" } else { "path" }
        );
        let f = write(d.path(), file, &body);
        let e = experiment::run(&f, None, true).unwrap_err().to_string();
        assert!(e.contains(file) && e.contains("method m") && e.contains(says), "{e}");
    }
    // Malformed seed lists name the key and the line; `seed` with `seeds` is refused.
    for (file, seeds, says) in [
        ("empty.toml", "seeds = []", "no seed"),
        ("twice.toml", "seeds = [1, 2, 1]", "seed 1 twice"),
        ("range.toml", "seeds = \"1-9\"", "not a range"),
        ("kind.toml", "seeds = 9", "a list of seeds"),
    ] {
        let f = write(d.path(), file, &format!("time = 1\n{seeds}\n{scene}"));
        let e = experiment::run(&f, None, true).unwrap_err().to_string();
        assert!(e.contains(&format!("{file}:5")) && e.contains(says), "{e}");
    }
    let f = write(d.path(), "both-seeds.toml", &format!("time = 1\nseed = 1\nseeds = [1, 2]\n{scene}"));
    let e = experiment::run(&f, None, true).unwrap_err().to_string();
    assert!(e.contains("both-seeds.toml") && e.contains("not both"), "{e}");
}

#[test]
fn a_suite_over_seeds_writes_each_seed_and_a_summary() {
    let d = tempfile::tempdir().unwrap();
    let reference = d.path().join("ref.exr");
    let scene = root().join("scenes/cornell-box/scene.xml");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_pcbpt"))
        .args(["render", scene.to_str().unwrap(), "-D", "resx=24", "-D", "resy=24", "--integrator", "bdpt"])
        .args(["--spp", "64", "--quiet", "-o", reference.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let f = write(
        d.path(),
        "seeds.toml",
        &format!(
            "spp = 2\nseeds = \"3..=5\"\n[[scene]]\nname = \"cornell\"\nfile = \"SCENE\"\ndefines = {{ resx = \"24\", resy = \"24\" }}\nreference = \"{}\"",
            reference.display()
        ),
    );
    let results = experiment::run(&f, None, true).unwrap();
    assert_eq!(results.len(), 6);
    let out = d.path().join("seeds");
    for seed in [3, 4, 5] {
        assert!(out.join(format!("seed-{seed}/results.md")).exists());
        assert!(out.join(format!("seed-{seed}/cornell_bdpt.exr")).exists());
    }
    // Different seeds, different images; the summary's relMSE means are the runs' own.
    let a = std::fs::read(out.join("seed-3/cornell_path.exr")).unwrap();
    let b = std::fs::read(out.join("seed-4/cornell_path.exr")).unwrap();
    assert_ne!(a, b);
    let summary = std::fs::read_to_string(out.join("summary.md")).unwrap();
    let path: Vec<f64> = results.iter().filter(|r| r.method == "path").map(|r| r.relmse).collect();
    let mean = path.iter().sum::<f64>() / 3.0;
    assert!(summary.contains("summary over 3 seeds (3, 4, 5)"), "{summary}");
    assert!(summary.contains(&format!("| cornell | path | 3 | {mean:.5} |")), "{summary}");
    assert!(summary.contains("| cornell | path | 3 |") && summary.contains("| 1.000 | 1.000 | 0 of 3 |"), "{summary}");
}

/// Every suite in experiments/ reads: its keys, its seeds and every method's options (an
/// option renamed or moved to another integrator would fail here, not at the end of a run).
#[test]
fn every_suite_in_experiments_loads() {
    let mut n = 0;
    for entry in std::fs::read_dir(root().join("experiments")).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            experiment::ExperimentFile::load(&p).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 30, "{n} suites");
}

/// A stopped experiment returns the runs done: with its flag set before it starts, none,
/// and no image is rendered (the flag reaches every render, which ends after its pass under
/// way; `python/tests/test_interrupt.py` interrupts one running).
#[test]
fn a_stopped_experiment_returns_the_runs_done() {
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;
    let d = tempfile::tempdir().unwrap();
    let body = r#"time = 30

[[scene]]
name = "cornell"
file = "SCENE"
defines = { resx = "16", resy = "12" }
reference_method = "bdpt"
reference_time = 30"#;
    let f = write(d.path(), "stopped.toml", body);
    let results = experiment::run_stoppable(&f, None, true, &Arc::new(AtomicBool::new(true))).unwrap();
    assert!(results.is_empty());
    let out = d.path().join("stopped");
    for name in ["cornell_reference.exr", "cornell_path.exr", "results.md"] {
        assert!(!out.join(name).exists(), "{name} written");
    }
}

/// `--scenes`, `--methods`, `--seeds` and `--time` run a part of a file: only the runs named,
/// with the seeds and budget given; a name the file lacks, or a selection without the
/// baseline, is an error naming the file.
#[test]
fn the_command_line_selects_scenes_methods_seeds_and_time() {
    let d = tempfile::tempdir().unwrap();
    let scene = "[[scene]]\nname = \"NAME\"\nfile = \"SCENE\"\ndefines = { resx = \"16\", resy = \"16\" }\nreference_method = \"bdpt\"\nreference_time = 0.2\n";
    let f =
        write(d.path(), "part.toml", &format!("spp = 2\n{}{}", scene.replace("NAME", "a"), scene.replace("NAME", "b")));
    let out = d.path().join("out");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_pcbpt"))
        .args(["experiment", f.to_str().unwrap(), "--quiet", "--scenes", "b", "--methods", "path,bdpt"])
        .args(["--seeds", "7,9", "--time", "0.1", "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for seed in [7, 9] {
        let table = std::fs::read_to_string(out.join(format!("seed-{seed}/results.md"))).unwrap();
        assert!(table.contains("| b |") && !table.contains("| a |"), "{table}");
        assert!(out.join(format!("seed-{seed}/b_path.exr")).exists());
        assert!(!out.join(format!("seed-{seed}/a_path.exr")).exists());
    }
    assert!(!out.join("seed-1").exists());
    let summary = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(summary.contains("summary over 2 seeds (7, 9)"), "{summary}");
    // The tables say which budget ran, whatever the file's name says.
    assert!(summary.contains("run at 0.1 s per render"), "{summary}");
    // The library takes the same selection: a time budget instead of the file's 2 spp.
    let selection =
        experiment::Selection { scenes: vec!["a".into()], methods: vec!["path".into()], seeds: None, time: Some(0.1) };
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let err = experiment::run_selected(&f, &selection, Some(&d.path().join("lib")), true, &stop).unwrap_err();
    assert!(err.to_string().contains("reference method \"bdpt\" is not a method"), "{err}");
    let selection = experiment::Selection { methods: vec!["path".into(), "bdpt".into()], ..selection };
    let runs = experiment::run_selected(&f, &selection, Some(&d.path().join("lib")), true, &stop).unwrap();
    assert_eq!(runs.len(), 2);
    assert!(runs.iter().all(|r| r.scene == "a" && r.spp > 2), "{runs:?}");
    for (args, wanted) in [
        (&["--scenes", "c"][..], "no scene \"c\" here (its scenes: a, b)"),
        (&["--methods", "bdpt"][..], "the baseline method \"path\" is not among the selected methods"),
        (&["--seeds", "3,3"][..], "names seed 3 twice"),
    ] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_pcbpt"))
            .args(["experiment", f.to_str().unwrap(), "--quiet"])
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(wanted), "{args:?}: {err}");
        assert!(args[0] == "--seeds" || err.contains("part.toml"), "{args:?}: {err}");
    }
}
