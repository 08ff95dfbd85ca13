#!/usr/bin/env python3
"""Per scene and method of an equal-time experiment run once per seed (`pcbpt experiment`, one
results folder per seed): relMSE seed by seed, its mean and median over the seeds, FLIP's
mean, and the image means' mean and median; then each method's mean and median relMSE
against every other's.

    python3 scripts/seed_summary.py experiments/results/memlt-glass-nine-seed-{1..9}
"""
import statistics as st
import sys
from collections import defaultdict


def main():
    folders = sys.argv[1:]
    if not folders:
        sys.exit(__doc__)
    rel, flip, mean = defaultdict(list), defaultdict(list), defaultdict(list)
    order = []
    for folder in folders:
        with open(f"{folder}/results.md") as f:
            for line in f:
                c = [x.strip() for x in line.split("|")]
                if len(c) < 10 or c[1] in ("scene", "---"):
                    continue
                try:
                    err, fl, ratio = float(c[6]), float(c[7]), float(c[8])
                except ValueError:
                    continue
                key = (c[1], c[2])
                if key not in order:
                    order.append(key)
                rel[key].append(err)
                flip[key].append(fl)
                mean[key].append(ratio)
    print("| scene | method | relMSE seed by seed | mean | median | FLIP (mean) | image mean: mean, median |")
    print("|---|---|---|---|---|---|---|")
    for key in order:
        r = rel[key]
        print(
            f"| `{key[0]}` | {key[1]} | {' / '.join(f'{x:.5f}' for x in r)} | {st.mean(r):.5f} | "
            f"{st.median(r):.5f} | {st.mean(flip[key]):.4f} | {st.mean(mean[key]):.4f}, {st.median(mean[key]):.4f} |"
        )
    print()
    print("| scene | method | against | mean relMSE ratio | median relMSE ratio | seeds with less relMSE |")
    print("|---|---|---|---|---|---|")
    for a in order:
        for b in order:
            if a[0] != b[0] or a == b or len(rel[a]) != len(rel[b]):
                continue
            wins = sum(x < y for x, y in zip(rel[a], rel[b]))
            print(
                f"| `{a[0]}` | {a[1]} | {b[1]} | {st.mean(rel[a]) / st.mean(rel[b]):.3f} | "
                f"{st.median(rel[a]) / st.median(rel[b]):.3f} | {wins} of {len(rel[a])} |"
            )


if __name__ == "__main__":
    main()
