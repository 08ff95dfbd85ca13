#!/usr/bin/env python3
"""Per-sample variance and cost of methods against a baseline, and the cost of their rays alone.

Each method is renders at a fixed number of samples per pixel from several seeds, each with
the `--stats` JSON that `pcbpt render` wrote beside it (same path, `.json` for `.exr`). Printed
per method, relative to the first method given (the baseline):

- its per-sample relative variance `V` (the seeds' sample variance over `r^2 + 0.01`, times
  the samples per pixel: free of the reference's own noise);
- its time per sample, and `V` times it (relMSE x time at equal time);
- a floor on relMSE x time: `V` times the rays it traces per sample, extension rays (camera
  rays, walks and light paths) at full price and shadow rays at `a` of it, as if everything
  else it does were free: a method whose floor is above a target cannot reach it by being
  made faster, only by sampling better.

    pip install mitsuba numpy
    python3 scripts/sample_costs.py --reference tests/data/staircase2.exr \
        path=128=r/path_s1.exr,r/path_s2.exr spcbpt-n1=32=r/n1_s1.exr,r/n1_s2.exr
"""
import argparse
import json

import numpy as np

from error_bands import load

SHADOW_PRICES = (1.0, 0.5, 0.25)


def method(text):
    try:
        name, spp, paths = text.split("=")
        paths = paths.split(",")
        spp = int(spp)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text}: expected NAME=SPP=A.exr,B.exr[,...]")
    if len(paths) < 2:
        raise argparse.ArgumentTypeError(f"{text}: at least two seeds")
    return name, spp, paths


def measure(ref_den, spp, paths):
    stack = np.stack([load(p) for p in paths])
    v = float((stack.var(axis=0, ddof=1) / ref_den).mean()) * spp
    stats = [json.load(open(p[: -len(".exr")] + ".json"))["render"] for p in paths]
    seconds = float(np.mean([s["seconds"] for s in stats])) / spp
    c = [s["counters"] for s in stats]
    extension = np.mean([x["camera_rays"] + x["extension_rays"] for x in c]) / spp
    shadow = np.mean([x["shadow_rays"] for x in c]) / spp
    return v, seconds, extension, shadow


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reference", required=True)
    p.add_argument("methods", nargs="+", type=method, help="NAME=SPP=A.exr,B.exr[,...]; the first is the baseline")
    a = p.parse_args()
    ref = load(a.reference)
    den = ref**2 + 0.01
    rows = [(name, measure(den, spp, paths)) for name, spp, paths in a.methods]
    base_name, (bv, bs, be, bsh) = rows[0]
    print(f"baseline {base_name}: V {bv:.3f} per sample, {be:.0f} extension and {bsh:.0f} shadow rays a pass")
    for name, (v, s, e, sh) in rows:
        floors = " ".join(f"a={al:g}: {v * (e + al * sh) / (bv * (be + al * bsh)):.2f}" for al in SHADOW_PRICES)
        print(
            f"  {name:>12}: V {v / bv:.2f}x, time a sample {s / bs:.2f}x, relMSE x time {v * s / (bv * bs):.2f}x; "
            f"rays {e / be:.2f}x extension, {sh / bsh:.2f}x shadow; rays' floor {floors}"
        )


if __name__ == "__main__":
    main()
