#!/usr/bin/env python3
"""Renders a scene across Dask workers: chunk I of N of the render's iterations
(`pcbpt render ... --chunk I/N`) runs as a task on some worker, writing OUTDIR/part_I.exr;
once every chunk has succeeded, `pcbpt merge` adds the parts into the image, which equals
the single-process render with the same options bit for bit.

    scripts/dask_render.py [--workers K | --scheduler tcp://HOST:8786] [--pcbpt PATH]
                           [--output FILE] SCENE OUTDIR N [render options...]

Without --scheduler the chunks run on a local cluster of K workers (default: one per chunk,
at most one per CPU; give the render a `--threads` so that they do not all use every
CPU). With --scheduler they run on the workers of a running `dask scheduler`: OUTDIR, SCENE
and the pcbpt binary must then be at the same paths on every worker (a shared filesystem);
when a chunk fails, chunks already running on other machines are left to finish.
The render options must include what fixes the image, --spp and --seed. The merge runs
here. Exits non-zero if a chunk or the merge fails, printing its command and stderr.
Needs `dask[distributed]` (`scripts/setup.sh` installs it).
"""

import argparse
import logging
import os
import shutil
import socket
import subprocess
import sys
import time


def render_chunk(cmd):
    """Runs one chunk's command on a worker; returns what the client reports."""
    start = time.time()
    p = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    return {
        "cmd": cmd,
        "returncode": p.returncode,
        "stderr": p.stderr,
        "host": socket.gethostname(),
        "seconds": time.time() - start,
    }


def fail(what, cmd, returncode, stderr):
    print(f"dask_render: {what} failed (exit status {returncode}): {' '.join(cmd)}", file=sys.stderr)
    sys.stderr.write(stderr)
    # The render cannot be merged any more: end the chunks still rendering here (the local
    # cluster's workers are threads of this process, the chunks its child processes).
    import psutil  # a dependency of distributed

    for child in psutil.Process().children(recursive=True):
        child.kill()
    sys.exit(1)


def main():
    ap = argparse.ArgumentParser(
        description="Render a scene as N chunks on Dask workers and merge them.",
        usage="%(prog)s [--workers K | --scheduler ADDRESS] [--pcbpt PATH] [--output FILE] "
        "SCENE OUTDIR N [render options...]",
    )
    where = ap.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="workers of the local cluster (default: min(N, CPUs))")
    where.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://10.0.0.1:8786")
    ap.add_argument("--pcbpt", default=os.environ.get("PCBPT") or shutil.which("pcbpt"), help="the pcbpt binary ($PCBPT, else on PATH)")
    ap.add_argument("--output", help="the merged image, .exr or .png (default OUTDIR/image.exr)")
    ap.add_argument("scene")
    ap.add_argument("outdir")
    ap.add_argument("n", type=int)
    ap.add_argument("render_options", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    if a.n < 1:
        ap.error("N must be at least 1")
    if not a.pcbpt or not os.access(a.pcbpt, os.X_OK):
        ap.error("no pcbpt binary: pass --pcbpt, set PCBPT or put pcbpt on PATH")
    if not os.path.isfile(a.scene):
        ap.error(f"no scene file {a.scene}")
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        print("dask_render: dask.distributed is not installed: run scripts/setup.sh", file=sys.stderr)
        sys.exit(2)

    # Workers elsewhere get absolute paths.
    pcbpt = os.path.abspath(a.pcbpt)
    scene = os.path.abspath(a.scene)
    outdir = os.path.abspath(a.outdir)
    output = os.path.abspath(a.output or os.path.join(outdir, "image.exr"))
    os.makedirs(outdir, exist_ok=True)
    parts = [os.path.join(outdir, f"part_{i}.exr") for i in range(a.n)]
    for p in parts:  # parts of an earlier render must not be mistaken for this one's
        if os.path.exists(p):
            os.remove(p)
    cmds = [[pcbpt, "render", scene, *a.render_options, "--chunk", f"{i}/{a.n}", "-o", parts[i]] for i in range(a.n)]

    if a.scheduler:
        cluster = None
        client = Client(a.scheduler)
    else:
        # The tasks only wait for a child process: worker threads in this process suffice.
        k = a.workers or min(a.n, os.cpu_count() or 1)
        cluster = LocalCluster(
            n_workers=k, threads_per_worker=1, processes=False, dashboard_address=None, silence_logs=logging.ERROR
        )
        client = Client(cluster)
    start = time.time()
    try:
        futures = [client.submit(render_chunk, cmd, key=f"pcbpt-chunk-{i}-of-{a.n}-{start}", pure=False) for i, cmd in enumerate(cmds)]
        for future in as_completed(futures):
            try:
                r = future.result()
            except Exception as e:  # the worker died or the task could not run
                fail("a chunk's task", ["(on a Dask worker)"], "none", f"{e!r}\n")
            chunk = r["cmd"][r["cmd"].index("--chunk") + 1]
            if r["returncode"] != 0:
                fail(f"chunk {chunk} on {r['host']}", r["cmd"], r["returncode"], r["stderr"])
            print(f"dask_render: chunk {chunk} rendered on {r['host']} in {r['seconds']:.2f} s", file=sys.stderr)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    rendered = time.time()

    cmd = [pcbpt, "merge", *parts, "-o", output]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        fail("merge", cmd, p.returncode, p.stderr)
    print(
        f"dask_render: wrote {output} ({a.n} chunks in {rendered - start:.2f} s, merged in {time.time() - rendered:.2f} s)",
        file=sys.stderr,
    )


if __name__ == "__main__":
    main()
