#!/usr/bin/env python3
"""Per-sample relative variance of a method from two renders that differ only in the seed.

Half the mean over pixels and channels of `(a - b)^2 / (r^2 + 0.01)` (the relMSE of
`pcbpt compare`, with the reference `r` only in the denominator) estimates the relative
variance of one render, free of the reference's own noise; times the samples per pixel it is
the variance of one sample, comparable between methods at any sample count.

    pip install mitsuba numpy
    python3 scripts/seed_variance.py REFERENCE.exr SPP A1.exr A2.exr [B1.exr B2.exr ...]
"""
import sys

from error_bands import load


def main():
    if len(sys.argv) < 5 or len(sys.argv) % 2 == 0:
        sys.exit(__doc__)
    ref = load(sys.argv[1])
    spp = float(sys.argv[2])
    den = ref**2 + 0.01
    for a, b in zip(sys.argv[3::2], sys.argv[4::2]):
        x, y = load(a), load(b)
        v = ((x - y) ** 2 / 2 / den).mean()
        print(f"{a} {b}: relative variance {v:.5f}, per sample {v * spp:.4f}")


if __name__ == "__main__":
    main()
