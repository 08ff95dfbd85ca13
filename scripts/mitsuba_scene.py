"""Loading a project scene in Mitsuba 3 the way pcbpt reads it, without changing the file.

Bitterli's Mitsuba 0.5 exports (`scenes/staircase2/`) carry `high_quality_edges` in the film,
which Mitsuba 3 refuses (pcbpt ignores it with a warning), and fix their film size in the
XML (no `<default>`s), so `-D resx=...` cannot shrink them (pcbpt's `--resolution` can).
`load()` edits the scene text in memory (the properties stripped, the film resized) and hands
it to `mi.load_string` with the scene's folder first in Mitsuba's file resolver, so relative
paths (meshes, textures, includes) resolve as they do for the file itself.

The opacity of a `mask` is a bitmap's alpha channel in pcbpt where the bitmap has one (the
leaves of `scenes/living-room/`, cut out by `leaf.png`'s alpha); Mitsuba 3 reads an RGBA
bitmap's colour there instead (the luminance). With `alpha_opacity` (the default), `load()`
writes the alpha of each such bitmap to a single-channel EXR in a scratch folder and points
the mask's texture at it in the text handed to Mitsuba, so Mitsuba renders what pcbpt does;
the scratch folder is removed once Mitsuba has loaded the scene.
"""
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET

# Properties Mitsuba 3 refuses that pcbpt ignores: removed from the text handed to Mitsuba.
STRIP = ("high_quality_edges", "highQualityEdges")


def mask_alpha_bitmaps(root):
    """The `filename` elements of the bitmaps that are a mask's `opacity`."""
    found = []
    for bsdf in root.iter("bsdf"):
        if bsdf.get("type") != "mask":
            continue
        for tex in bsdf:
            if tex.tag == "texture" and tex.get("name") == "opacity" and tex.get("type") == "bitmap":
                found += [c for c in tex if c.get("name") == "filename"]
    return found


def alpha_to_exr(mi, src, dst):
    """Writes the alpha channel of image `src` (linear: 8-bit values divided by 255) to the
    single-channel EXR `dst`. Returns False, writing nothing, when `src` has no alpha."""
    import numpy as np

    bmp = mi.Bitmap(src)
    if not bmp.has_alpha():
        return False
    rgba = bmp.convert(mi.Bitmap.PixelFormat.RGBA, mi.Struct.Type.Float32, srgb_gamma=False)
    alpha = np.array(rgba, dtype=np.float32)[:, :, 3:4].copy()
    mi.Bitmap(alpha, mi.Bitmap.PixelFormat.Y).write(dst)
    return True


def scene_text(path, resolution=None, strip=STRIP, alpha_dir=None, mi=None):
    """The scene file's XML with every property named in `strip` removed and, with a
    `resolution` (width, height), the film of the sensor resized (its `width` and `height`
    replaced or added). With `alpha_dir` (and the `mi` module), each mask's opacity bitmap
    that has an alpha channel is replaced by that alpha as a single-channel EXR written
    there. The file itself is only read."""
    tree = ET.parse(path)
    root = tree.getroot()
    if alpha_dir is not None:
        base = os.path.dirname(os.path.abspath(path))
        for i, elem in enumerate(mask_alpha_bitmaps(root)):
            src = os.path.join(base, elem.get("value"))
            dst = os.path.join(alpha_dir, f"opacity{i}.exr")
            if alpha_to_exr(mi, src, dst):
                elem.set("value", dst)
    for parent in list(root.iter()):
        for child in list(parent):
            if child.get("name") in strip:
                parent.remove(child)
    if resolution is not None:
        films = [f for s in root.iter("sensor") for f in s.iter("film")]
        if not films:
            raise ValueError(f"{path}: no <film> in a <sensor> to resize")
        for film in films:
            for name, value in zip(("width", "height"), resolution):
                props = [c for c in film if c.get("name") == name]
                if not props:
                    props = [ET.SubElement(film, "integer", {"name": name})]
                for p in props:
                    p.tag = "integer"
                    p.set("value", str(int(value)))
    return ET.tostring(root, encoding="unicode")


def _resolver(mi):
    return mi.file_resolver() if hasattr(mi, "file_resolver") else mi.Thread.thread().file_resolver()


def load(mi, path, resolution=None, strip=STRIP, alpha_opacity=True, **params):
    """Loads `path` in Mitsuba 3 (variant already set) as `scene_text` gives it, with
    `params` replacing its `<default>`s; with `alpha_opacity`, masks read their bitmap's
    alpha (above). The file resolver is restored afterwards."""
    scratch = tempfile.mkdtemp(prefix="pcbpt-opacity-") if alpha_opacity else None
    fr = _resolver(mi)
    saved = [str(fr[i]) for i in range(len(fr))]
    try:
        text = scene_text(path, resolution, strip, scratch, mi)
        fr.prepend(os.path.dirname(os.path.abspath(path)))
        return mi.load_string(text, **params)
    finally:
        fr.clear()
        for p in saved:
            fr.append(p)
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
