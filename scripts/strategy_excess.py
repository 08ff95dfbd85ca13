#!/usr/bin/env python3
"""Which bidirectional strategies make a render's largest errors.

Takes the reference, a render and the folder of its per-strategy images
(`pcbpt render ... --strategy-images DIR`, which sum to the render). The render's largest
errors are its 0.1% of pixels with the highest relative squared error against the
reference; at each, a strategy's excess is its image's value above the median of its 5×5
neighbourhood (what the strategy adds there beyond its local level). Prints the share of
the squared error those pixels carry, each strategy's share of the summed excess at them
(largest first), and, with `--pixels K`, the K worst pixels with the two strategies that
stand out most.

    python3 scripts/strategy_excess.py REF.exr render.exr strategies/ [--pixels 15]

Needs numpy, scipy and the `mitsuba` Python package (EXR reading).
"""
import argparse
import glob
import os

import numpy as np
from scipy.ndimage import median_filter


def load(path):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    bmp = mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False)
    return np.array(bmp, dtype=np.float64).mean(axis=-1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("reference")
    ap.add_argument("render")
    ap.add_argument("strategies", help="folder of the render's per-strategy EXRs")
    ap.add_argument("--pixels", type=int, default=0, help="list this many of the worst pixels")
    ap.add_argument("--top", type=float, default=0.001, help="share of pixels counted as the largest errors")
    a = ap.parse_args()
    ref, img = load(a.reference), load(a.render)
    if ref.shape != img.shape:
        raise SystemExit(f"{a.render}: {img.shape} pixels, the reference has {ref.shape}")
    err = (img - ref) ** 2 / (ref**2 + 1e-2)
    k = max(1, int(err.size * a.top))
    worst = np.argsort(err.ravel())[::-1][:k]
    ys, xs = np.unravel_index(worst, err.shape)
    print(f"relMSE {err.mean():.5f}; the worst {k} pixels carry {err.ravel()[worst].sum() / err.sum():.3f} of it")
    files = sorted(glob.glob(os.path.join(a.strategies, "*.exr")))
    if not files:
        raise SystemExit(f"{a.strategies}: no strategy images")
    layers = {os.path.basename(f)[:-4]: load(f) for f in files}
    excess = {name: layer - median_filter(layer, size=5) for name, layer in layers.items()}
    at_worst = {name: e[ys, xs].clip(min=0).sum() for name, e in excess.items()}
    total = sum(at_worst.values()) or 1.0
    print("strategy        excess share  image mean")
    for name, v in sorted(at_worst.items(), key=lambda kv: -kv[1])[:10]:
        print(f"{name:<15} {v / total:12.3f}  {layers[name].mean():10.4f}")
    for y, x in list(zip(ys, xs))[: a.pixels]:
        top = sorted(((e[y, x], n) for n, e in excess.items()), reverse=True)[:2]
        parts = "  ".join(f"{n} {v:+.3f}" for v, n in top)
        print(f"({x:3d},{y:3d}) render {img[y, x]:.3f} reference {ref[y, x]:.3f}  {parts}")


if __name__ == "__main__":
    main()
