#!/usr/bin/env python3
"""BDPT speed against LuxCore's bidirectional engine (BIDIRCPU), measured in one run.

LuxCore renders ../shared/scenes/cornell-ply/cornell.scn (the geometry of
scenes/cornell-ply/cornell_mi.xml) with BIDIRCPU and the RANDOM sampler; pcbpt renders
cornell_mi.xml with `--integrator bdpt`. Same resolution (256x256), same longest path (8
segments: LuxCore's eye and light depths 8), same thread count, same wall time. A sample is
one camera subpath plus one light subpath with all their connections in both renderers.
Samples per second are taken from each renderer's own statistics after the warm-up
(scene parsing and BVH build excluded for both). Runs alternate, `--repeats` times; the
median rate counts.

    pip install pyluxcore
    cargo build --release
    python3 scripts/bench_vs_luxcore.py --seconds 20 --threads 2
"""
import argparse
import os
import statistics
import sys
import time

from pcbpt_stats import render_stats

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "cornell-ply", "cornell_mi.xml")
SHARED = os.path.join(os.path.dirname(ROOT), "shared", "scenes", "cornell-ply")


def luxcore_rate(seconds, threads, size, depth, engine):
    import pyluxcore

    pyluxcore.Init(lambda msg: None)
    cwd = os.getcwd()
    os.chdir(SHARED)
    try:
        props = pyluxcore.Properties()
        props.SetFromString(f"""
renderengine.type = "{engine}"
sampler.type = "RANDOM"
native.threads.count = {threads}
film.width = {size}
film.height = {size}
film.filter.type = "NONE"
path.maxdepth = {depth}
light.maxdepth = {depth}
eye.maxdepth = {depth}
path.russianroulette.depth = 3
light.russianroulette.depth = 3
batch.haltspp = 0
batch.halttime = 0
""")
        props.Set(pyluxcore.Property("scene.file", os.path.join(SHARED, "cornell.scn")))
        config = pyluxcore.RenderConfig(props)
        session = pyluxcore.RenderSession(config)
        session.Start()
        # Warm-up: the first second includes thread start-up.
        time.sleep(1.0)
        session.UpdateStats()
        s0 = session.GetStats()
        n0 = s0.Get("stats.renderengine.pass").GetFloat() * size * size
        t0 = time.perf_counter()
        time.sleep(seconds)
        session.UpdateStats()
        s1 = session.GetStats()
        n1 = s1.Get("stats.renderengine.pass").GetFloat() * size * size
        t1 = time.perf_counter()
        # LuxCore's own rate, as a cross-check of the pass count.
        own = s1.Get("stats.renderengine.total.samplesec").GetFloat()
        session.Stop()
        return (n1 - n0) / (t1 - t0), own
    finally:
        os.chdir(cwd)


def pcbpt_rate(binary, seconds, threads, depth, integrator):
    return render_stats(binary, SCENE, "--integrator", integrator, "--time", seconds, "--threads", threads,
                        "--max-depth", depth)["samples_per_second"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--depth", type=int, default=8)
    ap.add_argument("--binary", default=os.path.join(ROOT, "target", "release", "pcbpt"))
    a = ap.parse_args()
    if not os.path.exists(a.binary):
        sys.exit(f"{a.binary} not found: run `cargo build --release` first")
    try:
        import pyluxcore  # noqa: F401
    except ImportError:
        sys.exit("LuxCore is not installed: pip install pyluxcore")
    lux, ours = [], []
    for _ in range(a.repeats):
        rate, own = luxcore_rate(a.seconds, a.threads, 256, a.depth, "BIDIRCPU")
        print(f"LuxCore run: {rate / 1e6:.4f} M samples/s from passes, {own / 1e6:.4f} M/s as LuxCore reports it")
        lux.append(rate)
        ours.append(pcbpt_rate(a.binary, a.seconds, a.threads, a.depth, "bdpt"))
    l, o = statistics.median(lux), statistics.median(ours)
    print(f"cornell-ply 256x256, max depth {a.depth}, {a.threads} threads, {a.seconds:g} s per run, median of {a.repeats}")
    print(f"LuxCore BIDIRCPU: {l / 1e6:.4f} M samples/s  (runs: {', '.join(f'{x / 1e6:.4f}' for x in lux)})")
    print(f"pcbpt bdpt:       {o / 1e6:.4f} M samples/s  (runs: {', '.join(f'{x / 1e6:.4f}' for x in ours)})")
    print(f"ratio: {o / l:.2f}x")


if __name__ == "__main__":
    main()
