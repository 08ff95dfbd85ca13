#!/usr/bin/env python3
"""Scene loading time of pcbpt binaries, alternated in one run on the same machine.

Loads each scene with each binary and each thread count (`render --spp 1` at 16×9, so the
render itself is negligible) `--repeats` times, alternating, and prints the median of the
`--stats` load times (reading and building the plugins; the BVH build) per binary and
thread count.

    cargo build --release
    python3 scripts/bench_loading.py --binary OLD/pcbpt --binary target/release/pcbpt \\
        --threads 1 2 --repeats 5 scenes/staircase2/scene.xml scenes/living-room/scene.xml

A scene a binary cannot load is reported as such and left out of that binary's rows.
"""
import argparse
import statistics
import subprocess

from pcbpt_stats import render_json


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--binary", action="append", required=True, help="pcbpt binary to measure; repeatable")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    times = {}
    failed = set()
    for _ in range(a.repeats):
        for scene in a.scenes:
            for b in a.binary:
                for t in a.threads:
                    if (scene, b) in failed:
                        continue
                    try:
                        load = render_json(b, scene, "--spp", 1, "--resolution", "16x9", "--threads", t)["load"]
                    except subprocess.CalledProcessError:
                        failed.add((scene, b))
                        continue
                    times.setdefault((scene, b, t), []).append((load["read_seconds"], load["bvh_seconds"]))
    print("| scene | binary | threads | reading s (median) | BVH s (median) | all runs, reading |")
    print("|---|---|---|---|---|---|")
    for scene in a.scenes:
        for b in a.binary:
            if (scene, b) in failed:
                print(f"| {scene} | {b} | | does not load | | |")
                continue
            for t in a.threads:
                runs = times[(scene, b, t)]
                read = statistics.median(r for r, _ in runs)
                bvh = statistics.median(v for _, v in runs)
                every = ", ".join(f"{r:.3f}" for r, _ in runs)
                print(f"| {scene} | {b} | {t} | {read:.3f} | {bvh:.3f} | {every} |")


if __name__ == "__main__":
    main()
