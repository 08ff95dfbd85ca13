#!/usr/bin/env python3
"""Radiance of Mitsuba 3's `sunsky` emitter (scalar_rgb) in given directions, for the values
`src/light/sunsky.rs`'s tests compare against. Prints one line per query: the case, the
world direction the radiance arrives from (unit, towards the sky), and the RGB radiance.

    python3 scripts/sunsky_values.py
"""
import math

import drjit as dr
import mitsuba as mi

mi.set_variant("scalar_rgb")

# name -> the emitter's properties (Mitsuba 3 names).
CASES = {
    "direction": {"sun_direction": [0.3, 0.4, 0.5]},
    "tokyo": {},
    "dusk": {"latitude": 48.85, "longitude": 2.35, "timezone": 1, "year": 2021, "month": 3,
             "day": 21, "hour": 17, "minute": 40, "second": 12, "turbidity": 7.5,
             "albedo": {"type": "rgb", "value": [0.1, 0.5, 0.9]}},
    "complex": {"sun_direction": [-0.2, 0.1, 0.35], "complex_sun": True, "turbidity": 2.2,
                "albedo": 0.8, "sun_aperture": 3.0, "sun_scale": 2.0, "sky_scale": 0.5,
                "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90)},
}


def sun_dir(emitter):
    return mi.traverse(emitter)["sun_direction"]


def directions(sun):
    """Sky directions (world), then the sun's centre and a point near its rim."""
    out = [mi.ScalarVector3f(0, 0, 1), mi.ScalarVector3f(0.6, -0.3, 0.2), mi.ScalarVector3f(-0.5, 0.7, 0.05),
           mi.ScalarVector3f(0, 1, 0.5), mi.ScalarVector3f(0.2, 0.9, -0.3)]
    s = mi.ScalarVector3f(sun)
    f = mi.Frame3f(s)
    out.append(s)
    out.append(f.to_world(mi.ScalarVector3f(math.sin(0.0021), 0, math.cos(0.0021))))
    out.append(f.to_world(mi.ScalarVector3f(0, math.sin(0.02), math.cos(0.02))))
    return [dr.normalize(d) for d in out]


def main():
    for name, props in CASES.items():
        e = mi.load_dict({"type": "sunsky", **props})
        s = sun_dir(e)
        print(f"{name} sun {s[0]:.9f} {s[1]:.9f} {s[2]:.9f}")
        for d in directions(s):
            si = mi.SurfaceInteraction3f()
            si.wi = -d
            v = e.eval(si)
            print(f"{name} {d[0]:.9g} {d[1]:.9g} {d[2]:.9g} -> {v[0]:.9g} {v[1]:.9g} {v[2]:.9g}")


if __name__ == "__main__":
    main()
