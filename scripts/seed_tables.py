#!/usr/bin/env python3
"""Tables over the seeds of an equal-time experiment (`pcbpt experiment`, one file per seed).

Reads each seed's `results.md` and prints, per scene, the mean over the seeds of relMSE x
seconds / T (T, the experiments' time, 10 by default) and of the samples per pixel for each
method; the ratios of the means of the pool integrators with and without budgets, against
BDPT and against the better of the path tracer and BDPT; each seed's ratio of a budget to
the same integrator without one; each pool integrator as the experiment ran it (its
defaults, or without a budget) against BDPT and the better of the two; and the image
means (mean and median over the seeds).

    python3 scripts/seed_tables.py experiments/results/budget-margin-seed-{1..9} [--time 10]
"""
import statistics as st
import sys
from collections import defaultdict

SCENES = ["cornell-ply", "veach-mis", "veach-ajar", "living-room", "staircase2", "sunlit-room"]
METHODS = ["path", "bdpt", "pcbpt", "spcbpt", "pcbpt-budget", "spcbpt-budget", "spcbpt-after-training"]


def read(folders):
    """relMSE x s, spp and image mean per (scene, method), each a dict over the folders."""
    rel, spp, mean = defaultdict(dict), defaultdict(dict), defaultdict(dict)
    for k, folder in enumerate(folders):
        with open(f"{folder}/results.md") as f:
            for line in f:
                c = [x.strip() for x in line.split("|")]
                if len(c) < 12 or c[1] in ("scene", "---"):
                    continue
                try:
                    n, secs, err, ratio = int(c[3]), float(c[5]), float(c[6]), float(c[8])
                except ValueError:
                    continue
                rel[(c[1], c[2])][k] = err * secs
                spp[(c[1], c[2])][k] = n
                mean[(c[1], c[2])][k] = ratio
    return rel, spp, mean


def main():
    args = sys.argv[1:]
    time = 10.0
    if "--time" in args:
        i = args.index("--time")
        time = float(args[i + 1])
        del args[i : i + 2]
    if not args:
        sys.exit(__doc__)
    rel, spp, mean = read(args)
    scenes = [s for s in SCENES if any(k[0] == s for k in rel)]
    methods = [me for me in METHODS if any(k[1] == me for k in rel)]
    m = lambda sc, me: st.mean(rel[(sc, me)].values()) / time
    print(f"{len(args)} seeds; relMSE x s / {time:g}, mean over the seeds (mean samples per pixel)\n")
    print("| scene | " + " | ".join(methods) + " |")
    print("|---" * (len(methods) + 1) + "|")
    for sc in scenes:
        cells = [f"{m(sc, me):.3g} ({st.mean(spp[(sc, me)].values()):.0f})" for me in methods]
        print(f"| `{sc}` | " + " | ".join(cells) + " |")
    # The ratios whose methods the experiment ran.
    ratios = [
        ("PCBPT budget / PCBPT", "pcbpt-budget", "pcbpt"),
        ("PCBPT budget / BDPT", "pcbpt-budget", "bdpt"),
        ("PCBPT budget / best", "pcbpt-budget", "best"),
        ("SPCBPT budget / SPCBPT", "spcbpt-budget", "spcbpt"),
        ("SPCBPT budget / BDPT", "spcbpt-budget", "bdpt"),
        ("SPCBPT budget / best", "spcbpt-budget", "best"),
        ("PCBPT / BDPT", "pcbpt", "bdpt"),
        ("PCBPT / best", "pcbpt", "best"),
        ("SPCBPT / BDPT", "spcbpt", "bdpt"),
        ("SPCBPT / best", "spcbpt", "best"),
        ("SPCBPT / PCBPT", "spcbpt", "pcbpt"),
        ("SPCBPT budget / PCBPT budget", "spcbpt-budget", "pcbpt-budget"),
        ("SPCBPT / SPCBPT measured after training", "spcbpt", "spcbpt-after-training"),
        ("SPCBPT measured after training / best", "spcbpt-after-training", "best"),
    ]
    have = set(methods) | ({"best"} if {"path", "bdpt"} <= set(methods) else set())
    ratios = [r for r in ratios if r[1] in have and r[2] in have]
    print("\n| scene | " + " | ".join(r[0] for r in ratios) + " |")
    print("|---" * (len(ratios) + 1) + "|")
    for sc in scenes:
        value = lambda me: min(m(sc, "path"), m(sc, "bdpt")) if me == "best" else m(sc, me)
        print(f"| `{sc}` | " + " | ".join(f"{value(a) / value(b):.2f}" for _, a, b in ratios) + " |")
    print("\nPer seed, a budget over the same integrator without one (relMSE x s):")
    for sc in scenes:
        for a, b in [("pcbpt-budget", "pcbpt"), ("spcbpt-budget", "spcbpt")]:
            if a not in methods or b not in methods:
                continue
            r = [rel[(sc, a)][k] / rel[(sc, b)][k] for k in sorted(rel[(sc, a)])]
            print(f"  {sc} {a}: " + " / ".join(f"{x:.2f}" for x in r) + f" (median {st.median(r):.2f})")
    print("\nImage means over the reference's, mean / median over the seeds:\n")
    print("| scene | " + " | ".join(methods) + " |")
    print("|---" * (len(methods) + 1) + "|")
    for sc in scenes:
        cells = [f"{st.mean(mean[(sc, me)].values()):.4f} / {st.median(mean[(sc, me)].values()):.4f}" for me in methods]
        print(f"| `{sc}` | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
