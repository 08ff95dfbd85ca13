#!/usr/bin/env python3
"""relMSE of test images against a reference, per luminance band of the reference's pixels.

The relMSE is `pcbpt compare`'s (per channel `(t - r)^2 / (r^2 + 0.01)`, averaged over all
channels of the pixels counted); the bands are the quarters of the reference's pixels by
luminance (darkest first), so that one sees where in the image a method's error sits:
Metropolis methods spread their samples by brightness, and their error by band differs from
a path tracer's. Also printed: the relMSE of the images box-filtered to 2x2 and 4x4 blocks
(noise that survives averaging neighbouring pixels is the chains' low-frequency error) and
the ratio of image means.

With `--region NAME=X0:X1,Y0:Y1` (pixel ranges, end excluded; repeatable) it also prints
each region's share of the relMSE: the sum of its pixels' terms over the whole image's pixel
count, so that the shares and the rest add up to the relMSE.

With `--blocks N` it also prints, per block of N x N pixels, the ratio of the test image's
luminance to the reference's (where a Metropolis image lacks light in a region, the rest of
the image is brighter by as much: its total is fixed), and the relMSE over the image
downsampled to 8x8 and 16x16 blocks.

    pip install mitsuba numpy
    python3 scripts/error_bands.py REFERENCE.exr TEST.exr [TEST.exr ...] [--region NAME=X0:X1,Y0:Y1 ...]
"""
import argparse
import sys

import numpy as np

# Rec. 709 luminance weights of linear RGB.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def load(path):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    bmp = mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False)
    return np.array(bmp, dtype=np.float64)


def relmse(t, r):
    return float(np.mean((t - r) ** 2 / (r * r + 0.01)))


def boxed(a, f):
    h, w = a.shape[0] // f * f, a.shape[1] // f * f
    return a[:h, :w].reshape(h // f, f, w // f, f, 3).mean(axis=(1, 3))


def parse_region(text):
    try:
        name, ranges = text.split("=")
        xs, ys = ranges.split(",")
        x0, x1 = (int(v) for v in xs.split(":"))
        y0, y1 = (int(v) for v in ys.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text}: expected NAME=X0:X1,Y0:Y1")
    return name, (slice(y0, y1), slice(x0, x1))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("reference")
    ap.add_argument("tests", nargs="+")
    ap.add_argument("--region", type=parse_region, action="append", default=[], metavar="NAME=X0:X1,Y0:Y1")
    ap.add_argument("--blocks", type=int, default=0, metavar="N")
    a = ap.parse_args()
    ref = load(a.reference)
    lum = ref @ LUMINANCE
    band = np.digitize(lum, np.quantile(lum, [0.25, 0.5, 0.75]))
    print("image: relMSE, 2x2, 4x4, quarters by luminance (darkest first), mean ratio")
    for path in a.tests:
        t = load(path)
        if t.shape != ref.shape:
            sys.exit(f"{path}: {t.shape[1]}x{t.shape[0]} against the reference's {ref.shape[1]}x{ref.shape[0]}")
        terms = (t - ref) ** 2 / (ref * ref + 0.01)
        quarters = " ".join(f"{terms[band == i].mean():.4f}" for i in range(4))
        print(
            f"{path}: {relmse(t, ref):.5f}, {relmse(boxed(t, 2), boxed(ref, 2)):.5f}, "
            f"{relmse(boxed(t, 4), boxed(ref, 4)):.5f}, {quarters}, {t.mean() / ref.mean():.4f}"
        )
        if a.region:
            per_pixel = terms.mean(axis=2)
            shares = [(name, per_pixel[r].sum() / per_pixel.size) for name, r in a.region]
            rest = per_pixel.mean() - sum(v for _, v in shares)
            print("  " + ", ".join(f"{name} {v:.5f}" for name, v in shares) + f", rest {rest:.5f}")
        if a.blocks > 0:
            ratio = (boxed(t, a.blocks) @ LUMINANCE) / (boxed(ref, a.blocks) @ LUMINANCE)
            print(f"  8x8 {relmse(boxed(t, 8), boxed(ref, 8)):.5f}, 16x16 {relmse(boxed(t, 16), boxed(ref, 16)):.5f}")
            print(f"  luminance against the reference per {a.blocks}x{a.blocks} block:")
            for row in ratio:
                print("   " + " ".join(f"{v:.2f}" for v in row))


if __name__ == "__main__":
    main()
