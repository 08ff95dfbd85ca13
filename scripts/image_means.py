#!/usr/bin/env python3
"""The distribution of image means over seeds: renders a scene once per seed and method and
reports each render's image mean over the reference's, then per method their mean, median,
smallest and largest. A heavy-tailed estimator whose typical render is dark shows a median
below its mean.

    python3 scripts/image_means.py scenes/veach-ajar/scene.xml \
        --reference ../shared/references/veach-ajar_mitsuba3-path_8192spp_320x180_maxdepth-1_tent.exr \
        --seeds 1-9 --method "bdpt=--integrator bdpt" --method "pcbpt=--integrator pcbpt" \
        -- -D resx=320 -D resy=180 --max-depth -1 --time 15 --threads 2

Everything after `--` is passed to every render. Needs `cargo build --release` first.
"""

import argparse
import os
import re
import shlex
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from paired_means import BINARY, seeds, split_common  # noqa: E402


def main():
    argv, common = split_common(sys.argv[1:])
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene")
    p.add_argument("--reference", required=True)
    p.add_argument("--seeds", type=seeds, required=True, help="e.g. 1-9 or 1,2,5")
    p.add_argument("--method", action="append", required=True, help="NAME=OPTIONS (quoted)")
    args = p.parse_args(argv)
    if not os.path.exists(BINARY):
        sys.exit(f"{BINARY} not found: run `cargo build --release` first")
    methods = [m.split("=", 1) for m in args.method]
    ratios = {name: [] for name, _ in methods}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for name, opts in methods:
                out = os.path.join(tmp, "render.exr")
                cmd = [BINARY, "render", args.scene, "-o", out, "--seed", str(seed), "--quiet"]
                subprocess.run(cmd + common + shlex.split(opts), check=True)
                text = subprocess.run(
                    [BINARY, "compare", args.reference, out], check=True, capture_output=True, text=True
                ).stdout
                m = re.search(r"mean ratio\s+([0-9.eE+-]+)", text)
                if not m:
                    sys.exit(f"could not read the mean ratio from `pcbpt compare`:\n{text}")
                ratios[name].append(float(m.group(1)))
                print(f"seed {seed} {name}: mean ratio {ratios[name][-1]:.4f}", flush=True)
    print("method | renders | mean | median | min | max")
    for name, r in ratios.items():
        print(
            f"{name} | {len(r)} | {statistics.mean(r):.4f} | {statistics.median(r):.4f} | {min(r):.4f} | {max(r):.4f}"
        )


if __name__ == "__main__":
    main()
