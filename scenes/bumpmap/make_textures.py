#!/usr/bin/env python3
"""Writes the textures of the bump- and normal-mapping test scenes (needs numpy and mitsuba
for the image writers): textures/height.exr, a height field of two sine waves around 0.5 (linear
RGB, grey), and textures/normals.png, a tangent-space normal map of 4 × 4 domes
(8-bit RGB = (n + 1) / 2, read with raw="true"), and textures/flat.png, a flat one."""
import os

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "textures")
os.makedirs(here, exist_ok=True)

n = 128
u = (np.arange(n) + 0.5) / n
uu, vv = np.meshgrid(u, u)  # rows are v, columns u
h = 0.5 + 0.0075 * np.sin(2 * np.pi * 3 * uu) + 0.005 * np.sin(2 * np.pi * 5 * vv)
mi.Bitmap(np.repeat(h[:, :, None], 3, axis=2).astype(np.float32)).write(os.path.join(here, "height.exr"))

n = 128
u = (np.arange(n) + 0.5) / n
uu, vv = np.meshgrid(u, u)
x = (uu * 4) % 1.0 * 2 - 1  # position inside a tile, [-1, 1]
y = (vv * 4) % 1.0 * 2 - 1
r = np.sqrt(x * x + y * y)
c = np.tan(np.radians(25)) / (2 * 0.8)  # a paraboloid tilted by at most 25° at r = 0.8
inside = r < 0.8
nx = np.where(inside, 2 * c * x, 0.0)
ny = np.where(inside, 2 * c * y, 0.0)
nn = np.stack([nx, ny, np.ones_like(nx)], axis=2)
nn /= np.linalg.norm(nn, axis=2, keepdims=True)
rgb = np.clip(np.round((nn + 1) / 2 * 255), 0, 255).astype(np.uint8)
mi.Bitmap(rgb, pixel_format=mi.Bitmap.PixelFormat.RGB).write(os.path.join(here, "normals.png"))

# The unperturbed normal everywhere (the tests' negative control).
flat = np.zeros((4, 4, 3), dtype=np.uint8)
flat[:, :] = (128, 128, 255)
mi.Bitmap(flat, pixel_format=mi.Bitmap.PixelFormat.RGB).write(os.path.join(here, "flat.png"))
