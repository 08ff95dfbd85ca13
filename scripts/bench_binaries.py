#!/usr/bin/env python3
"""Render speed of two pcbpt binaries (e.g. built against two Embree versions), alternating.

    python3 scripts/bench_binaries.py A/pcbpt B/pcbpt --integrators path bdpt \
        --seconds 10 --threads 2 --repeats 5

For each repeat and integrator, renders cornell-ply (256×256) for `--seconds` with A and
with B (A first in odd repeats, B first in even ones), and prints samples/s and the Embree version each binary reports. The summary gives
each binary's median and the median, minimum and maximum of the per-repeat ratios B / A:
pairing neighbouring runs keeps the ratio fair on a machine whose load changes.

With `--spp N` each run renders N samples per pixel instead, and the figure is samples per
CPU second (user + system time of the render process, loading included): on a machine that
other jobs keep busy, CPU time waits for no one, so it varies far less than wall time.
"""

import argparse
import os
import resource
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pcbpt_stats import render_json  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "cornell-ply", "cornell_mi.xml")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a", help="first pcbpt binary")
    ap.add_argument("b", help="second pcbpt binary")
    ap.add_argument("--integrators", nargs="+", default=["path", "bdpt"])
    ap.add_argument("--scene", default=SCENE)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--spp", type=int, help="render this many spp and report samples per CPU second")
    a = ap.parse_args()
    for b in (a.a, a.b):
        if not os.path.exists(b):
            sys.exit(f"{b} not found")
    rates = {(i, k): [] for i in a.integrators for k in "ab"}
    versions = {}
    for r in range(a.repeats):
        for i in a.integrators:
            order = (("a", a.a), ("b", a.b))
            for k, binary in order if r % 2 == 0 else order[::-1]:
                budget = ("--spp", a.spp) if a.spp else ("--time", a.seconds)
                before = resource.getrusage(resource.RUSAGE_CHILDREN)
                j = render_json(binary, a.scene, "--integrator", i, *budget, "--threads", a.threads)
                after = resource.getrusage(resource.RUSAGE_CHILDREN)
                versions[k] = j.get("embree_version")
                s = j["render"]
                if a.spp:
                    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
                    rates[(i, k)].append(s["width"] * s["height"] * s["spp"] / cpu)
                else:
                    rates[(i, k)].append(s["samples_per_second"])
                print(f"repeat {r + 1} {i} {k} (Embree {versions[k]}): {rates[(i, k)][-1] / 1e6:.4f} M samples/s"
                      f"{' of CPU time' if a.spp else ''}", flush=True)
    budget = f"{a.spp} spp per run, samples per CPU second" if a.spp else f"{a.seconds:g} s per run"
    print(f"{os.path.relpath(a.scene, ROOT)}, {a.threads} threads, {budget}, {a.repeats} repeats; "
          f"A = Embree {versions['a']}, B = Embree {versions['b']}")
    print("| integrator | A M samples/s (median) | B M samples/s (median) | B / A median | B / A min–max |")
    print("|---|---|---|---|---|")
    for i in a.integrators:
        ra, rb = rates[(i, "a")], rates[(i, "b")]
        ratios = [y / x for x, y in zip(ra, rb)]
        print(f"| {i} | {statistics.median(ra) / 1e6:.4f} | {statistics.median(rb) / 1e6:.4f} | "
              f"{statistics.median(ratios):.3f} | {min(ratios):.3f}–{max(ratios):.3f} |")


if __name__ == "__main__":
    main()
