#!/usr/bin/env python3
"""Write scenes/smoke/smoke.vol: a 32^3 one-channel density grid of a smoke-like plume
(Gaussian puffs rising and spreading along y, modulated by a smooth pseudo-noise), in
Mitsuba's binary volume format (version 3, float32), values in [0, 1]. Deterministic:
running it again gives the same bytes. The output is CC0, like the script.

    python3 scripts/make_smoke_vol.py [OUT]
"""
import math
import os
import struct
import sys

N = 32
# (centre x, y, z in the unit cube, radius, weight)
PUFFS = [
    (0.50, 0.18, 0.50, 0.14, 1.0),
    (0.46, 0.38, 0.53, 0.17, 0.9),
    (0.55, 0.58, 0.47, 0.20, 0.75),
    (0.62, 0.78, 0.52, 0.18, 0.55),
    (0.38, 0.70, 0.42, 0.13, 0.45),
]


def noise(x, y, z):
    """A smooth pseudo-noise in [0.5, 1]: a few incommensurate sines."""
    s = math.sin(9.1 * x + 2.3 * y) * math.sin(7.3 * z - 4.1 * y) + 0.5 * math.sin(13.7 * (x + z) + 11.9 * y)
    return 0.75 + 0.25 * max(-1.0, min(1.0, s / 1.5))


def density(x, y, z):
    d = sum(w * math.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / (r * r)) for cx, cy, cz, r, w in PUFFS)
    return min(1.0, d) * noise(x, y, z)


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "scenes", "smoke", "smoke.vol")
    values = []
    for k in range(N):
        for j in range(N):
            for i in range(N):
                values.append(density((i + 0.5) / N, (j + 0.5) / N, (k + 0.5) / N))
    top = max(values)
    data = b"VOL" + bytes([3]) + struct.pack("<5i", 1, N, N, N, 1) + struct.pack("<6f", 0, 0, 0, 1, 1, 1)
    data += struct.pack(f"<{len(values)}f", *(v / top for v in values))
    tmp = out + ".tmp"
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, out)
    print(f"{out}: {N}^3 cells, mean density {sum(values) / top / len(values):.4f}")


if __name__ == "__main__":
    main()
