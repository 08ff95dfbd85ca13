//! Distributed renders through Slurm (`scripts/slurm/`). The test starts a single-node
//! cluster of its own, without systemd (`scripts/slurm/local_cluster.sh`: a MUNGE key and
//! munged running as user munge, slurmctld and slurmd, all under a temporary folder, on free
//! ports), checks it with a trivial job, then renders the Cornell box as 4 array tasks and a
//! merge job through `scripts/slurm/render.sh --wait`: the merged image must equal the
//! single-process render bit for bit. A chunk that fails must make `render.sh --wait` fail,
//! naming the chunk, with no image. The daemons are stopped by their PIDs when the test
//! ends, passed or failed.
//!
//! Needs root and the Slurm packages (`scripts/setup.sh` installs them); without them the test
//! fails saying so, unless `PCBPT_SKIP_SLURM=1`.
#![cfg(unix)]

mod common;

use common::distributed::{
    assert_same_bits, describe, missing_programs, pcbpt, render_options, scene, single_render, tools_or_skip,
};
use common::root;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Instant;

/// A running single-node cluster; dropping it stops every daemon by its PID.
struct Cluster {
    dir: PathBuf,
}

impl Cluster {
    /// Starts the cluster in `dir`. The guard exists before the daemons do, so that a start
    /// that fails half-way stops what it started.
    fn start(dir: PathBuf) -> Cluster {
        let cluster = Cluster { dir };
        let o = cluster.script("start");
        assert!(o.status.success(), "the cluster did not start: {}", describe(&o));
        cluster
    }

    fn script(&self, verb: &str) -> Output {
        Command::new(root().join("scripts/slurm/local_cluster.sh"))
            .arg(verb)
            .arg(&self.dir)
            .output()
            .expect("runs scripts/slurm/local_cluster.sh")
    }

    /// A command talking to this cluster.
    fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", self.dir.join("slurm.conf"));
        c
    }

    /// The daemons' logs, for a failure's message.
    fn logs(&self) -> String {
        let mut s = String::new();
        for name in ["slurmctld.log", "slurmd.log", "munged.log"] {
            let text = std::fs::read_to_string(self.dir.join("log").join(name)).unwrap_or_default();
            let tail: Vec<&str> = text.lines().rev().take(25).collect();
            s += &format!("--- {name}\n");
            for line in tail.iter().rev() {
                s += line;
                s.push('\n');
            }
        }
        s
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("Slurm logs:\n{}", self.logs());
        }
        // Cancels the jobs, then SIGTERM (SIGKILL after 10 s) to each daemon by its PID.
        let o = self.script("stop");
        if !o.status.success() {
            eprintln!("stopping the cluster: {}", describe(&o));
        }
        // Whatever the script left (it removes a PID file once its daemon is gone).
        for name in ["slurmd", "slurmctld", "munged"] {
            let Ok(pid) = std::fs::read_to_string(self.dir.join("pids").join(name)) else { continue };
            let pid = pid.trim();
            let comm = std::fs::read_to_string(format!("/proc/{pid}/comm")).unwrap_or_default();
            if comm.trim() == name {
                eprintln!("killing {name} ({pid})");
                let _ = Command::new("kill").args(["-KILL", pid]).status();
            }
        }
    }
}

/// Whether the test can run here; panics with what to do when it cannot and is not skipped.
fn slurm_available() -> bool {
    let missing =
        missing_programs(&["munged", "mungekey", "slurmctld", "slurmd", "sbatch", "sinfo", "scontrol", "setpriv"]);
    let ok = tools_or_skip("Slurm", "PCBPT_SKIP_SLURM", &missing).unwrap_or_else(|e| panic!("{e}"));
    if ok {
        let uid = Command::new("id").arg("-u").output().expect("runs id");
        assert_eq!(
            String::from_utf8_lossy(&uid.stdout).trim(),
            "0",
            "the Slurm test starts munged as user munge and slurmd, which needs root; run it as root or set PCBPT_SKIP_SLURM=1"
        );
    }
    ok
}

fn render_sh(cluster: &Cluster, n: usize, outdir: &Path, options: &[String]) -> Output {
    cluster
        .command(root().join("scripts/slurm/render.sh"))
        .env("PCBPT", pcbpt())
        .arg("--wait")
        .arg(scene())
        .arg(outdir)
        .arg(n.to_string())
        .args(options)
        .output()
        .expect("runs scripts/slurm/render.sh")
}

#[test]
fn chunks_rendered_by_slurm_merge_into_the_single_render() {
    if !slurm_available() {
        return;
    }
    let tmp = tempfile::Builder::new().prefix("pcbpt-slurm-").tempdir().unwrap();
    let t = Instant::now();
    let cluster = Cluster::start(tmp.path().join("cluster"));
    eprintln!("cluster up in {:.1} s", t.elapsed().as_secs_f64());

    // The cluster runs a job.
    let out = tmp.path().join("hostname.out");
    let o = cluster
        .command("sbatch")
        .args(["--wait", "--quiet", "--output"])
        .arg(&out)
        .args(["--wrap", "hostname"])
        .output()
        .unwrap();
    assert!(o.status.success(), "sbatch --wrap hostname: {}", describe(&o));
    let host = std::fs::read_to_string(&out).unwrap();
    assert!(!host.trim().is_empty(), "the job printed nothing");
    eprintln!("trivial job ran on {} ({:.1} s)", host.trim(), t.elapsed().as_secs_f64());

    // Four chunks and the merge give the single-process image.
    for integrator in ["path", "pcbpt"] {
        let options = render_options(integrator);
        let full = tmp.path().join(format!("full_{integrator}.exr"));
        single_render(&options, &full);
        let outdir = tmp.path().join(format!("chunks_{integrator}"));
        let o = render_sh(&cluster, 4, &outdir, &options);
        assert!(o.status.success(), "render.sh ({integrator}): {}", describe(&o));
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(
            stdout.lines().any(|l| l.starts_with("chunks ")) && stdout.lines().any(|l| l.starts_with("merge ")),
            "render.sh printed no job ids: {stdout}"
        );
        for i in 0..4 {
            assert!(outdir.join(format!("part_{i}.exr")).is_file(), "no part {i}");
        }
        assert_same_bits(&outdir.join("image.exr"), &full);
        eprintln!("{integrator}: 4 chunks merged equal the single render ({:.1} s)", t.elapsed().as_secs_f64());
    }

    // A chunk that fails (here every chunk: an option pcbpt refuses) cancels the merge, and
    // render.sh --wait says which chunk failed and where its log is.
    let outdir = tmp.path().join("failing");
    let mut options = render_options("path");
    options.push("--no-such-option".into());
    let o = render_sh(&cluster, 2, &outdir, &options);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "render.sh succeeded with a failing chunk: {}", describe(&o));
    assert!(stderr.contains("chunk 0: FAILED") && stderr.contains("no-such-option"), "{}", describe(&o));
    assert!(!outdir.join("image.exr").exists(), "an image was written");
    eprintln!("failed chunks reported ({:.1} s)", t.elapsed().as_secs_f64());
}
