#!/usr/bin/env python3
"""Render Mitsuba 3 `path` references for the project's scenes and record their settings.

Each reference is the average of chunks of 256 spp with seeds 0, 1, 2, ... (Mitsuba's own
advice for large sample counts), written as tests/data/<name>.exr with a JSON file beside it
holding every setting that made it. Needs `pip install mitsuba`.

Scenes whose film size is fixed in the XML (Bitterli's Mitsuba 0.5 exports) are resized in
memory, and the properties Mitsuba 3 refuses (`high_quality_edges`) are stripped there too;
a `mask` whose opacity bitmap has an alpha channel gets that alpha as a single-channel EXR
written to a scratch folder (pcbpt's opacity is the alpha; Mitsuba 3 would read the colour);
the scene file is never changed (scripts/mitsuba_scene.py).

    python3 scripts/make_references.py cornell-box            # one reference
    python3 scripts/make_references.py staircase2 --out-dir /tmp/refs   # elsewhere
    python3 scripts/make_references.py --list                 # what can be made
    python3 scripts/make_references.py sunlit-room --chunks-dir /tmp/chunks   # keep each chunk

With two chunks or more, the JSON also holds the reference's own noise: the relMSE between
the averages of the first and the second half of the chunks, and a quarter of it (the
noise the average of both halves carries).
"""
import argparse
import json
import os
import sys
import time

import mitsuba_scene

# name -> (scene file relative to the repository root, parameter overrides, total spp,
#          film size (width, height) replacing the file's, or None)
REFERENCES = {
    "cornell-box": ("scenes/cornell-box/scene.xml", {"resx": 128, "resy": 128, "max_depth": 30}, 8192, None),
    "veach-mis": ("scenes/veach-mis/scene.xml", {"resx": 192, "resy": 108}, 8192, None),
    "veach-ajar": ("scenes/veach-ajar/scene.xml", {"resx": 160, "resy": 90, "max_depth": -1}, 16384, None),
    "materials": ("scenes/materials/scene.xml", {"resx": 160, "resy": 120}, 4096, None),
    # A diffuse ground and block under `sunsky` (Hosek-Wilkie sky and sun).
    "sunsky": ("scenes/sunsky/scene.xml", {"resx": 80, "resy": 60}, 4096, None),
    # Bitterli's Mitsuba 0.5 export as published: its own maxDepth (65) and tent filter.
    "staircase2": ("scenes/staircase2/scene.xml", {}, 1024, (320, 180)),
    # The room lit by `sunsky` through a window: the file's own 320x180, max_depth (16)
    # and tent filter.
    "sunlit-room": ("scenes/sunlit-room/scene.xml", {}, 1024, None),
    # A quad cut out by the alpha of an RGBA texture (opaque, clear and half-clear texels).
    "cutout": ("scenes/cutout/scene.xml", {"resx": 96, "resy": 72}, 4096, None),
    # "The Grey & White Room", as published: maxDepth 65, tent filter, the envmap; the
    # leaves' mask reads leaf.png's alpha (handed to Mitsuba as a single-channel EXR).
    "living-room": ("scenes/living-room/scene.xml", {}, 1024, (320, 180)),
    # Shading normals perturbed by a bump map and by a normal map, under a grazing light.
    "bumpmap": ("scenes/bumpmap/scene.xml", {"resx": 160, "resy": 120}, 2048, None),
    "normalmap": ("scenes/bumpmap/normalmap.xml", {"resx": 160, "resy": 120}, 2048, None),
    # A glass ball on a floor under a small spherical light: its caustic seen directly and
    # through the ball (MEMLT's scene).
    "glass-caustic": ("scenes/glass-caustic/scene.xml", {"resx": 160, "resy": 90}, 32768, None),
    # An open box under a point light and a spot light, both out of the camera's view
    # (MEMLT's lights with a Dirac position).
    "spot-point": ("scenes/spot-point/scene.xml", {"resx": 128, "resy": 96}, 4096, None),
    # Fog through the open front of a box, a glass sphere, a small light: Mitsuba 3's
    # volpath (the scene's own integrator).
    "fog-caustic": ("scenes/fog-caustic/scene.xml", {"resx": 64, "resy": 64}, 16384, None),
    # A plume of smoke (a heterogeneous medium over scenes/smoke/smoke.vol) on a floor under
    # a square light: Mitsuba 3's volpath (the scene's own integrator).
    "smoke": ("scenes/smoke/scene.xml", {"resx": 64, "resy": 64}, 16384, None),
}

# Settings the scene file gives, recorded in the JSON beside the reference.
NOTES = {
    "sunlit-room": {
        "film": "the scene's default 320x180",
        "max_depth": "the scene's default, 16",
        "filter": "the scene's tent",
        "emitter": "sunsky: Mitsuba 3's Hosek-Wilkie sun and sky, sun 30 degrees up, default turbidity and albedo, sun_scale = sky_scale = 20",
    },
}

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def render(name, variant, chunk, out_dir, chunks_dir=None):
    import xml.etree.ElementTree as ET

    import mitsuba as mi
    import numpy as np

    mi.set_variant(variant)
    scene_rel, params, spp, resolution = REFERENCES[name]
    scene_path = os.path.join(ROOT, scene_rel)
    chunks = max(1, spp // chunk)
    t0 = time.time()
    # The film resized and `high_quality_edges` stripped in memory; the file stays as it is.
    scene = mitsuba_scene.load(mi, scene_path, resolution, **params)
    images = []
    for seed in range(chunks):
        images.append(np.array(mi.render(scene, seed=seed, spp=chunk), dtype=np.float64)[:, :, :3])
        if chunks_dir:
            os.makedirs(chunks_dir, exist_ok=True)
            mi.Bitmap(images[-1].astype(np.float32)).write(os.path.join(chunks_dir, f"{name}_seed{seed}.exr"))
        print(f"{name}: chunk {seed + 1}/{chunks} ({time.time() - t0:.0f} s)", file=sys.stderr)
    acc = sum(images)
    img = (acc / chunks).astype(np.float32)
    os.makedirs(out_dir, exist_ok=True)
    out = os.path.join(out_dir, f"{name}.exr")
    tmp = out + ".tmp.exr"
    mi.Bitmap(img).write(tmp)
    os.replace(tmp, out)
    settings = {
        "renderer": f"Mitsuba {mi.__version__}",
        "variant": variant,
        "integrator": ET.parse(scene_path).getroot().find("integrator").get("type"),
        "scene": scene_rel,
        "parameters": params,
    }
    if resolution is not None:
        settings["film"] = {"width": resolution[0], "height": resolution[1]}
        settings["stripped"] = list(mitsuba_scene.STRIP[:1])
    settings.update(NOTES.get(name, {}))
    masked = [e.get("value") for e in mitsuba_scene.mask_alpha_bitmaps(ET.parse(scene_path).getroot())]
    if masked:
        settings["mask_opacity"] = (
            f"the alpha channel of {', '.join(masked)} where it has one, handed to Mitsuba 3 as a "
            "single-channel EXR (Mitsuba 3 would read the colour of the RGBA file)"
        )
    settings.update({
        "spp": chunks * chunk,
        "chunks": {"count": chunks, "spp": chunk, "seeds": f"0..{chunks - 1}"},
        "image_mean": float(img.mean()),
        "seconds": round(time.time() - t0, 1),
    })
    if chunks >= 2:
        # The reference's own noise: relMSE (as src/compare.rs defines it, relative to the
        # reference) between the averages of the first and the second half of the chunks.
        # Each half carries relMSE(A, B) / 2 of noise, their average a quarter.
        half = chunks // 2
        a = sum(images[:half]) / half
        b = sum(images[half:2 * half]) / half
        r = img.astype(np.float64)
        rel = float(np.mean((a - b) ** 2 / (r * r + 0.01)))
        settings["noise"] = {
            "halves": f"chunks 0..{half - 1} against {half}..{2 * half - 1}",
            "relmse_halves": rel,
            "relmse_reference": rel / 4,
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
    ap.add_argument("--out-dir", default=os.path.join(ROOT, "tests", "data"), help="where to write (default tests/data)")
    ap.add_argument("--chunks-dir", help="also write each chunk's image there")
    ap.add_argument("--list", action="store_true")
    a = ap.parse_args()
    if a.list:
        for k, (scene, params, spp, resolution) in REFERENCES.items():
            film = f" film {resolution[0]}x{resolution[1]}" if resolution else ""
            print(f"{k}: {scene} {params}{film} {spp} spp")
        return
    for name in a.names or REFERENCES:
        if name not in REFERENCES:
            sys.exit(f"unknown reference {name!r}; --list shows them")
        render(name, a.variant, a.chunk, a.out_dir, a.chunks_dir)


if __name__ == "__main__":
    main()
