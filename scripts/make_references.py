#!/usr/bin/env python3
"""Render Mitsuba 3 `path` references for the project's scenes and record their settings.

Each reference is the average of chunks of 256 spp with seeds 0, 1, 2, ... (Mitsuba's own
advice for large sample counts), written as tests/data/<name>.exr with a JSON file beside it
holding every setting that made it. Needs `pip install mitsuba`.

    python3 scripts/make_references.py cornell-box            # one reference
    python3 scripts/make_references.py --list                 # what can be made
"""
import argparse
import json
import os
import sys
import time

# name -> (scene file relative to the repository root, parameter overrides, total spp)
REFERENCES = {
    "cornell-box": ("scenes/cornell-box/scene.xml", {"resx": 128, "resy": 128, "max_depth": 30}, 8192),
    "veach-mis": ("scenes/veach-mis/scene.xml", {"resx": 192, "resy": 108}, 8192),
    "veach-ajar": ("scenes/veach-ajar/scene.xml", {"resx": 160, "resy": 90, "max_depth": -1}, 16384),
    "materials": ("scenes/materials/scene.xml", {"resx": 160, "resy": 120}, 4096),
}

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def render(name, variant, chunk):
    import mitsuba as mi
    import numpy as np

    mi.set_variant(variant)
    scene_rel, params, spp = REFERENCES[name]
    scene_path = os.path.join(ROOT, scene_rel)
    chunks = max(1, spp // chunk)
    acc = None
    t0 = time.time()
    for seed in range(chunks):
        scene = mi.load_file(scene_path, spp=chunk, **params)
        img = np.array(mi.render(scene, seed=seed, spp=chunk), dtype=np.float64)
        acc = img if acc is None else acc + img
        print(f"{name}: chunk {seed + 1}/{chunks} ({time.time() - t0:.0f} s)", file=sys.stderr)
    img = (acc / chunks).astype(np.float32)[:, :, :3]
    out = os.path.join(ROOT, "tests", "data", f"{name}.exr")
    tmp = out + ".tmp.exr"
    mi.Bitmap(img).write(tmp)
    os.replace(tmp, out)
    settings = {
        "renderer": f"Mitsuba {mi.__version__}",
        "variant": variant,
        "integrator": "path",
        "scene": scene_rel,
        "parameters": params,
        "spp": chunks * chunk,
        "chunks": {"count": chunks, "spp": chunk, "seeds": f"0..{chunks - 1}"},
        "image_mean": float(img.mean()),
        "seconds": round(time.time() - t0, 1),
    }
    with open(out[:-4] + ".json", "w") as f:
        json.dump(settings, f, indent=2)
        f.write("\n")
    print(f"{out}: mean {img.mean():.6f}", file=sys.stderr)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("names", nargs="*", help="references to render (default: all)")
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--chunk", type=int, default=256, help="spp per chunk")
    ap.add_argument("--list", action="store_true")
    a = ap.parse_args()
    if a.list:
        for k, (scene, params, spp) in REFERENCES.items():
            print(f"{k}: {scene} {params} {spp} spp")
        return
    for name in a.names or REFERENCES:
        if name not in REFERENCES:
            sys.exit(f"unknown reference {name!r}; --list shows them")
        render(name, a.variant, a.chunk)


if __name__ == "__main__":
    main()
