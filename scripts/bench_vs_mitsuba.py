#!/usr/bin/env python3
"""Path-tracer speed against Mitsuba 3, measured in one run on the same machine.

Renders a scene with Mitsuba 3's `path` integrator (variant scalar_rgb by default; `--variant`
may be given more than once, e.g. `--variant llvm_ad_rgb --variant scalar_rgb`) and with
`pcbpt render --integrator path`, the same number of samples per pixel and threads, and
prints samples per second of both and their ratio. Render time only: scene loading is
excluded for both. Each renderer runs `--repeats` times, alternating; the best time counts,
and the ratios are to the first variant's best time.

Mitsuba 3's LLVM variants JIT-compile their kernels (the first render of a scene compiles,
later ones reuse them: one render is run untimed first) and run asynchronously: a render is
timed until its image is a NumPy array. Their JIT needs a libLLVM it can drive: Debian 12's
`libllvm19` works (its path is set as DRJIT_LIBLLVM_PATH when that is unset and the library
is there); LLVM 14 and 15 fail on AVX-512 CPUs.

Scenes (`--scene`): `cornell-ply` (scenes/cornell-ply/cornell_mi.xml, 256x256, max_depth 8,
box filter), and Bitterli's published `staircase2` and `living-room` at 320x180 with their own
max_depth and filter (loaded in Mitsuba 3 through scripts/mitsuba_scene.py: the film resized
and `high_quality_edges` stripped in memory; pcbpt reads the file as it is, with
`--resolution`).

    pip install mitsuba numpy
    cargo build --release
    python3 scripts/bench_vs_mitsuba.py --spp 64 --threads 2
    python3 scripts/bench_vs_mitsuba.py --scene staircase2 --spp 16 --threads 2

`--binary` may be given more than once (e.g. the plain release build and the profile-guided
one of scripts/build_pgo.sh): every binary then runs in the same alternation, and each gets
its own rows. `--rr5 false` leaves out the runs at Mitsuba's rr_depth 5. `--wavefront both`
runs pcbpt's path tracer as a wavefront and one path at a time in the same alternation
(default: `true`, the wavefront alone).
"""
import argparse
import os
import sys
import time

import mitsuba_scene
import numpy as np
from pcbpt_stats import render_stats

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LIBLLVM = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"

# name -> (scene file relative to the repository root, film size replacing the file's or None,
#          the film size rendered, description)
SCENES = {
    "cornell-ply": ("scenes/cornell-ply/cornell_mi.xml", None, (256, 256), "max_depth 8, box filter"),
    "staircase2": ("scenes/staircase2/scene.xml", (320, 180), (320, 180), "its max_depth 65, tent filter"),
    "living-room": ("scenes/living-room/scene.xml", (320, 180), (320, 180), "its max_depth 65, tent filter"),
}


def mitsuba_seconds(scene_path, resolution, spp, threads, variant):
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(variant)
    mi.set_log_level(mi.LogLevel.Warn)
    if threads:
        dr.set_thread_count(threads)
    scene = mitsuba_scene.load(mi, scene_path, resolution)
    jit = not variant.startswith("scalar")
    if jit and (variant, scene_path) not in COMPILED:
        np.array(mi.render(scene, spp=spp, seed=0))
        COMPILED.add((variant, scene_path))
    t0 = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=0)
    np.array(img) if jit else dr.eval(img)
    return time.perf_counter() - t0


# The (variant, scene) pairs whose kernels a first, untimed render has compiled.
COMPILED = set()


def pcbpt_seconds(binary, scene_path, resolution, spp, threads, rr_depth, wavefront):
    extra = ["--resolution", f"{resolution[0]}x{resolution[1]}"] if resolution else []
    return render_stats(binary, scene_path, "--integrator", "path", "--spp", spp, "--threads", threads,
                        "--rr-depth", rr_depth, "--wavefront", wavefront, *extra)["seconds"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", choices=sorted(SCENES), default="cornell-ply")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variant", action="append",
                    help="Mitsuba 3 variant; repeatable (default: scalar_rgb)")
    ap.add_argument("--wavefront", choices=["true", "false", "both"], default="true",
                    help="pcbpt's path tracer as a wavefront, one path at a time, or both")
    ap.add_argument("--binary", action="append",
                    help="pcbpt binary to measure; repeatable (default: target/release/pcbpt)")
    ap.add_argument("--rr5", choices=["true", "false"], default="true",
                    help="also run pcbpt at Mitsuba's rr_depth 5")
    a = ap.parse_args()
    binaries = a.binary or [os.path.join(ROOT, "target", "release", "pcbpt")]
    for b in binaries:
        if not os.path.exists(b):
            sys.exit(f"{b} not found: run `cargo build --release` (or scripts/build_pgo.sh) first")
    variants = a.variant or ["scalar_rgb"]
    if any(not v.startswith("scalar") for v in variants) and os.path.exists(LIBLLVM):
        os.environ.setdefault("DRJIT_LIBLLVM_PATH", LIBLLVM)
    rr_depths = [3, 5] if a.rr5 == "true" else [3]
    wavefronts = ["true", "false"] if a.wavefront == "both" else [a.wavefront]
    rel, resolution, (w, h), what = SCENES[a.scene]
    scene_path = os.path.join(ROOT, rel)
    samples = w * h * a.spp
    mts = {v: [] for v in variants}
    configs = [(b, rr, wf) for b in binaries for rr in rr_depths for wf in wavefronts]
    ours = {c: [] for c in configs}
    for _ in range(a.repeats):
        for v in variants:
            mts[v].append(mitsuba_seconds(scene_path, resolution, a.spp, a.threads, v))
        for c in configs:
            ours[c].append(pcbpt_seconds(c[0], scene_path, resolution, a.spp, a.threads, c[1], c[2]))
    m = min(mts[variants[0]])
    print(f"{a.scene} {w}x{h}, {a.spp} spp, {what}, {a.threads} threads, best of {a.repeats}")
    for v in variants:
        t = min(mts[v])
        print(f"Mitsuba 3 ({v}) path (rr_depth 5): {t:.3f} s, {samples / t / 1e6:.3f} M samples/s, "
              f"ratio {m / t:.2f}x (all runs: {', '.join(f'{x:.3f}' for x in mts[v])})")
    for b, rr, wf in configs:
        name = os.path.relpath(b, ROOT) if len(binaries) > 1 else "pcbpt"
        p = min(ours[(b, rr, wf)])
        which = "rr_depth 3, default" if rr == 3 else "rr_depth 5, as Mitsuba"
        how = "wavefront" if wf == "true" else "one path at a time"
        print(f"{name} path ({how}, {which}): {p:.3f} s, {samples / p / 1e6:.3f} M samples/s, ratio {m / p:.2f}x "
              f"(all runs: {', '.join(f'{t:.3f}' for t in ours[(b, rr, wf)])})")


if __name__ == "__main__":
    main()
