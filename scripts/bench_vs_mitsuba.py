#!/usr/bin/env python3
"""Path-tracer speed against Mitsuba 3, measured in one run on the same machine.

Renders scenes/cornell-ply/cornell_mi.xml (256x256, max_depth 8, box filter, independent
sampler) with Mitsuba 3's `path` integrator (variant scalar_rgb by default) and with
`pcbpt render --integrator path`, the same number of samples per pixel and threads, and
prints samples per second of both and their ratio. Render time only: scene loading is
excluded for both. Each renderer runs `--repeats` times, alternating; the best time counts.

    pip install mitsuba numpy
    cargo build --release
    python3 scripts/bench_vs_mitsuba.py --spp 64 --threads 2
"""
import argparse
import os
import sys
import time

from pcbpt_stats import render_stats

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "cornell-ply", "cornell_mi.xml")


def mitsuba_seconds(spp, threads, variant):
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(variant)
    mi.set_log_level(mi.LogLevel.Warn)
    if threads:
        dr.set_thread_count(threads)
    scene = mi.load_file(SCENE)
    t0 = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=0)
    dr.eval(img)
    return time.perf_counter() - t0


def pcbpt_seconds(binary, spp, threads, rr_depth):
    return render_stats(binary, SCENE, "--integrator", "path", "--spp", spp, "--threads", threads,
                        "--rr-depth", rr_depth)["seconds"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--binary", default=os.path.join(ROOT, "target", "release", "pcbpt"))
    a = ap.parse_args()
    if not os.path.exists(a.binary):
        sys.exit(f"{a.binary} not found: run `cargo build --release` first")
    samples = 256 * 256 * a.spp
    mts, ours, ours5 = [], [], []
    for _ in range(a.repeats):
        mts.append(mitsuba_seconds(a.spp, a.threads, a.variant))
        ours.append(pcbpt_seconds(a.binary, a.spp, a.threads, 3))
        ours5.append(pcbpt_seconds(a.binary, a.spp, a.threads, 5))
    m, p, p5 = min(mts), min(ours), min(ours5)
    print(f"cornell-ply 256x256, {a.spp} spp, max_depth 8, {a.threads} threads, best of {a.repeats}")
    print(f"Mitsuba 3 ({a.variant}) path (rr_depth 5): {m:.3f} s, {samples / m / 1e6:.3f} M samples/s")
    print(f"pcbpt path (rr_depth 3, default):      {p:.3f} s, {samples / p / 1e6:.3f} M samples/s, ratio {m / p:.2f}x")
    print(f"pcbpt path (rr_depth 5, as Mitsuba):   {p5:.3f} s, {samples / p5 / 1e6:.3f} M samples/s, ratio {m / p5:.2f}x")


if __name__ == "__main__":
    main()
