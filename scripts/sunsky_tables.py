#!/usr/bin/env python3
"""Regenerate src/light/sunsky_data.bin, the RGB tables of the Hosek-Wilkie sky and sun model
that `src/light/sunsky.rs` reads (Mitsuba 3's `sunsky` emitter in its RGB variants).

Reads Mitsuba 3's data files (`pip install mitsuba`; mitsuba/data/sunsky/) and writes, as
little-endian float32 arrays one after the other, with no header:

  sky_params  [10 turbidity][2 albedo][6 control points][3 RGB][9 parameters]   (sky_params_rgb)
  sky_rad     [10 turbidity][2 albedo][6 control points][3 RGB]                 (sky_rad_rgb)
  sun_irrad   [10 turbidity][30 elevations 2°, 5°, .. 89°][3 RGB]
              the spectral sun irradiance (sampling_data.bin, 11 wavelengths 320..720 nm)
              projected on the linear sRGB matching functions: mean_i(rgb(λ_i) · E(λ_i)),
              which Mitsuba 3 computes when the emitter is built
  sun_rad     [10 turbidity][45 segments][3 RGB][4 powers of elevation][6 powers of cos ψ]
              (sun_rad_rgb, the limb-darkened sun of `complex_sun`)

The data are Lukas Hosek's and Alexander Wilkie's (3-clause BSD, src/light/SUNSKY_LICENSE).

    python3 scripts/sunsky_tables.py            # rewrites src/light/sunsky_data.bin
"""
import os

import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(os.path.dirname(mi.__file__), "data", "sunsky")


def field(f, name):
    """A field of a Mitsuba tensor file as a float64 numpy array of its shape."""
    fld = f[name]
    t = fld.to(mi.TensorXd) if "64" in str(fld.dtype) else fld.to(mi.TensorXf)
    return np.array(t, dtype=np.float64)


def main():
    datasets = mi.TensorFile(os.path.join(DATA, "sunsky_datasets.bin"))
    sampling = mi.TensorFile(os.path.join(DATA, "sampling_data.bin"))
    sky_params = field(datasets, "sky_params_rgb")
    sky_rad = field(datasets, "sky_rad_rgb")
    sun_rad = field(datasets, "sun_rad_rgb")
    sun_irr = field(sampling, "sun_irradiance")
    assert sky_params.shape == (10, 2, 6, 3, 9), sky_params.shape
    assert sky_rad.shape == (10, 2, 6, 3), sky_rad.shape
    assert sun_rad.shape == (10, 45, 3, 4, 6), sun_rad.shape
    assert sun_irr.shape == (10, 30, 11), sun_irr.shape
    # Linear sRGB matching functions at the model's wavelengths (zero outside 360..830 nm).
    rgb = np.zeros((11, 3))
    for i in range(11):
        w = 320.0 + 40.0 * i
        if mi.MI_CIE_MIN <= w <= mi.MI_CIE_MAX:
            rgb[i] = np.array(mi.xyz_to_srgb(mi.cie1931_xyz(w)))
    sun_irr_rgb = np.einsum("tek,kc->tec", sun_irr, rgb) / 11.0
    out = os.path.join(ROOT, "src", "light", "sunsky_data.bin")
    blob = b"".join(a.astype("<f4").tobytes() for a in (sky_params, sky_rad, sun_irr_rgb, sun_rad))
    with open(out + ".tmp", "wb") as f:
        f.write(blob)
    os.replace(out + ".tmp", out)
    print(f"{out}: {len(blob)} bytes")


if __name__ == "__main__":
    main()
