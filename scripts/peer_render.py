#!/usr/bin/env python3
"""Renders a scene with a peer renderer for a fixed wall time; used by `pcbpt experiment`.

    peer_render.py --renderer mitsuba --scene scene.xml --time 20 --threads 2 --out out.pfm
                   [--define resx=320 ...] [--max-depth -1] [--seed 0] [--width W --height H --resize-film]
    peer_render.py --renderer luxcore-bidir --scene cornell.scn --width 256 --height 256 ...

Mitsuba 3 (`pip install mitsuba`): the `path` integrator of the XML scene (variant
scalar_rgb), rendered in chunks of spp with different seeds until the time is spent; the
chunks are averaged. The scene text is handed to Mitsuba without the properties it refuses
(`high_quality_edges`) and, with `--resize-film`, with the film resized to --width x --height
(scripts/mitsuba_scene.py); the file is never changed. The image is written as PFM (float RGB). LuxCore (`pip install pyluxcore`): a LuxCore scene (.scn) rendered with
PATHCPU or BIDIRCPU, with the RANDOM or the METROPOLIS sampler, for the wall time. Prints one JSON line: spp, seconds, samples per second.
Exit status 3 when the renderer is not installed.
"""
import argparse
import json
import os
import sys
import time


def write_pfm(path, img):
    """Writes float RGB (rows top first) as a little-endian PFM (rows bottom first)."""
    import numpy as np

    img = np.ascontiguousarray(np.asarray(img, dtype="<f4")[::-1])
    h, w = img.shape[0], img.shape[1]
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode())
        f.write(img.tobytes())
    os.replace(tmp, path)


def mitsuba(a):
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError:
        print("Mitsuba 3 is not installed (pip install mitsuba numpy)", file=sys.stderr)
        sys.exit(3)
    import numpy as np

    mi.set_variant("scalar_rgb")
    mi.set_log_level(mi.LogLevel.Warn)
    dr.set_thread_count(a.threads)
    params = dict(d.split("=", 1) for d in a.define)
    if a.max_depth is not None:
        params["max_depth"] = str(a.max_depth)
    import mitsuba_scene

    resolution = (a.width, a.height) if a.resize_film else None
    scene = mitsuba_scene.load(mi, a.scene, resolution, **params)
    acc, n, chunk, spp = None, 0, 1, 0
    t0 = time.perf_counter()
    while True:
        img = np.array(mi.render(scene, spp=chunk, seed=a.seed * 100003 + n))
        acc = img * chunk if acc is None else acc + img * chunk
        spp += chunk
        n += 1
        elapsed = time.perf_counter() - t0
        if elapsed >= a.time:
            break
        # Chunks of about a tenth of the budget.
        per = elapsed / spp
        chunk = max(1, min(int(0.1 * a.time / per), int((a.time - elapsed) / per) + 1))
    img = acc / spp
    h, w = img.shape[0], img.shape[1]
    write_pfm(a.out, img[:, :, :3])
    return spp, elapsed, spp * w * h / elapsed


def luxcore(a, engine, sampler):
    import numpy as np  # before pyluxcore: the other order crashes in its TBB start-up

    try:
        import pyluxcore
    except ImportError:
        print("LuxCore is not installed (pip install pyluxcore)", file=sys.stderr)
        sys.exit(3)

    pyluxcore.Init(lambda msg: None)
    scene = os.path.abspath(a.scene)
    cwd = os.getcwd()
    os.chdir(os.path.dirname(scene))
    try:
        props = pyluxcore.Properties()
        depth = a.max_depth if a.max_depth and a.max_depth > 0 else 1024
        props.SetFromString(f"""
renderengine.type = "{engine}"
sampler.type = "{sampler}"
native.threads.count = {a.threads}
film.width = {a.width}
film.height = {a.height}
film.filter.type = "NONE"
film.outputs.0.type = "RGB"
film.outputs.0.filename = "out.exr"
path.maxdepth = {depth}
light.maxdepth = {depth}
eye.maxdepth = {depth}
batch.halttime = {a.time}
""")
        props.Set(pyluxcore.Property("scene.file", scene))
        session = pyluxcore.RenderSession(pyluxcore.RenderConfig(props))
        t0 = time.perf_counter()
        session.Start()
        while not session.HasDone():
            time.sleep(0.2)
            session.UpdateStats()
        elapsed = time.perf_counter() - t0
        stats = session.GetStats()
        spp = stats.Get("stats.renderengine.pass").GetFloat()
        buf = np.zeros(a.width * a.height * 3, dtype=np.float32)
        session.GetFilm().GetOutputFloat(pyluxcore.FilmOutputType.RGB, buf)
        session.Stop()
    finally:
        os.chdir(cwd)
    # LuxCore's film rows run bottom to top.
    img = buf.reshape(a.height, a.width, 3)[::-1]
    write_pfm(a.out, img)
    return int(spp), elapsed, spp * a.width * a.height / elapsed


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--renderer", required=True, choices=["mitsuba", "luxcore-path", "luxcore-bidir",
                                                          "luxcore-path-metropolis", "luxcore-bidir-metropolis"])
    ap.add_argument("--scene", required=True)
    ap.add_argument("--time", type=float, required=True)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--out", required=True)
    ap.add_argument("--define", action="append", default=[])
    ap.add_argument("--max-depth", type=int)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--height", type=int, default=256)
    ap.add_argument("--resize-film", action="store_true",
                    help="mitsuba: render at --width x --height instead of the scene's film size")
    a = ap.parse_args()
    if a.renderer == "mitsuba":
        spp, secs, rate = mitsuba(a)
    else:
        engine = "PATHCPU" if a.renderer.startswith("luxcore-path") else "BIDIRCPU"
        sampler = "METROPOLIS" if a.renderer.endswith("metropolis") else "RANDOM"
        spp, secs, rate = luxcore(a, engine, sampler)
    print(json.dumps({"spp": spp, "seconds": secs, "samples_per_second": rate}), flush=True)
    # pyluxcore's log callback crashes the interpreter's shutdown; everything is written.
    os._exit(0)


if __name__ == "__main__":
    main()
