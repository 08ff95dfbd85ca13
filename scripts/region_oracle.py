#!/usr/bin/env python3
"""How much a renderer could gain by choosing its estimator region by region.

From renders at equal time of several methods over several seeds (experiment results
directories, one per seed, holding SCENE_METHOD.exr), each method's per-pixel relative
variance is the seeds' sample variance over `r^2 + 0.01` (the relMSE's weighting, free of the
reference's own noise). Averaged over blocks of N x N pixels, the least of the methods' block
variances, block by block, is what an estimator would reach that used, in every block, the
method that is best there, at that method's cost: an oracle's bound on per-region choices
(of connections per camera vertex, or of path tracing against connections).

Printed per scene: each method's mean relative variance and relMSE against the reference,
then for each set of methods the oracle's mean over the best single method's, twice: chosen
and scored on the same seeds (optimistic: the least of noisy estimates is biased low) and
chosen on the first half of the seeds and scored on the second (cross-validated).

    pip install mitsuba numpy
    python3 scripts/region_oracle.py --scene staircase2 --reference tests/data/staircase2.exr \
        --methods path,bdpt,pcbpt,spcbpt --blocks 8 experiments/results/real-oracle-seed-{1..9}
"""
import argparse
import itertools
import os

import numpy as np

from error_bands import load


def block_means(v, n):
    h, w = v.shape[0] // n * n, v.shape[1] // n * n
    return v[:h, :w].reshape(h // n, n, w // n, n).mean(axis=(1, 3))


def variances(stack, den):
    """Per-pixel relative variance of one render (channels averaged)."""
    return (stack.var(axis=0, ddof=1) / den).mean(axis=-1)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", required=True)
    p.add_argument("--reference", required=True)
    p.add_argument("--methods", required=True, help="comma-separated method names")
    p.add_argument("--blocks", type=int, default=8, help="block side in pixels (1: per pixel)")
    p.add_argument("dirs", nargs="+", help="one results directory per seed")
    a = p.parse_args()
    if len(a.dirs) < 4:
        p.error("need at least four seeds (two per half for the cross-validated bound)")
    ref = load(a.reference)
    den = ref**2 + 0.01
    methods = a.methods.split(",")
    stacks = {}
    for m in methods:
        paths = [os.path.join(d, f"{a.scene}_{m}.exr") for d in a.dirs]
        for path in paths:
            if not os.path.exists(path):
                p.error(f"{path}: no such render")
        stacks[m] = np.stack([load(path) for path in paths])
    half = len(a.dirs) // 2
    full = {m: block_means(variances(s, den), a.blocks) for m, s in stacks.items()}
    first = {m: block_means(variances(s[:half], den), a.blocks) for m, s in stacks.items()}
    second = {m: block_means(variances(s[half:], den), a.blocks) for m, s in stacks.items()}
    print(f"{a.scene}: {len(a.dirs)} seeds, blocks of {a.blocks}x{a.blocks} pixels")
    for m, s in stacks.items():
        relmse = float(np.mean((s - ref) ** 2 / den))
        print(f"  {m:>10}: relative variance {full[m].mean():.5f}, relMSE {relmse:.5f}")
    for k in range(2, len(methods) + 1):
        for subset in itertools.combinations(methods, k):
            best = min(subset, key=lambda m: full[m].mean())
            optimistic = np.min([full[m] for m in subset], axis=0).mean()
            choice = np.argmin([first[m] for m in subset], axis=0)
            scored = np.choose(choice, [second[m] for m in subset]).mean()
            best_second = second[best].mean()
            shares = ", ".join(f"{m} {np.mean(choice == i):.0%}" for i, m in enumerate(subset))
            print(
                f"  best of {'+'.join(subset)} per block: {optimistic / full[best].mean():.3f}x {best} "
                f"(optimistic), {scored / best_second:.3f}x (cross-validated; blocks: {shares})"
            )


if __name__ == "__main__":
    main()
