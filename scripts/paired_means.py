#!/usr/bin/env python3
"""Same-seed pairs: renders a scene twice per seed, once with option set A and once with B,
and reports the ratio of the image means (B / A) per seed, their mean and its standard error.

With the same seed, PCBPT's `--pc-mis uniform` and `--pc-mis resampling` trace the same paths
and differ only in their MIS weights, so the ratio isolates what the weights do to the image
mean: unbiased weights give ratios that average to one.

    python3 scripts/paired_means.py scenes/veach-ajar/scene.xml --seeds 100-159 \
        --a "--pc-mis uniform" --b "--pc-mis resampling" \
        -- --integrator pcbpt -D resx=80 -D resy=45 --spp 64 --max-depth -1

Everything after `--` is passed to both renders. Needs `cargo build --release` first.
"""

import argparse
import math
import os
import re
import shlex
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BINARY = os.path.join(ROOT, "target", "release", "pcbpt")


def seeds(text):
    out = []
    for part in text.split(","):
        if "-" in part:
            lo, hi = part.split("-")
            out.extend(range(int(lo), int(hi) + 1))
        else:
            out.append(int(part))
    return out


def split_common(argv):
    """The script's own arguments and those after `--`, passed to every render."""
    if "--" in argv:
        i = argv.index("--")
        return argv[:i], argv[i + 1 :]
    return argv, []


def main():
    argv, common = split_common(sys.argv[1:])
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene")
    p.add_argument("--seeds", type=seeds, required=True, help="e.g. 1-60 or 1,2,5")
    p.add_argument("--a", default="", help="options of render A (quoted)")
    p.add_argument("--b", default="", help="options of render B (quoted)")
    args = p.parse_args(argv)
    if not os.path.exists(BINARY):
        sys.exit(f"{BINARY} not found: run `cargo build --release` first")
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            files = []
            for name, opts in (("a", args.a), ("b", args.b)):
                out = os.path.join(tmp, f"{name}.exr")
                cmd = [BINARY, "render", args.scene, "-o", out, "--seed", str(seed), "--quiet"]
                subprocess.run(cmd + common + shlex.split(opts), check=True)
                files.append(out)
            text = subprocess.run(
                [BINARY, "compare", files[0], files[1]], check=True, capture_output=True, text=True
            ).stdout
            m = re.search(r"mean ratio\s+([0-9.eE+-]+)", text)
            if not m:
                sys.exit(f"could not read the mean ratio from `pcbpt compare`:\n{text}")
            ratios.append(float(m.group(1)))
            print(f"seed {seed}: B/A {ratios[-1]:.4f}", flush=True)
    n = len(ratios)
    mean = sum(ratios) / n
    se = math.sqrt(sum((r - mean) ** 2 for r in ratios) / (n - 1) / n) if n > 1 else float("nan")
    print(f"{n} pairs: mean B/A {mean:.4f} ± {se:.4f} (standard error)")


if __name__ == "__main__":
    main()
