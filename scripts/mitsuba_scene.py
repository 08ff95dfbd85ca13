"""Loading a project scene in Mitsuba 3 the way pcbpt reads it, without changing the file.

Bitterli's Mitsuba 0.5 exports (`scenes/staircase2/`) carry `high_quality_edges` in the film,
which Mitsuba 3 refuses (pcbpt ignores it with a warning), and fix their film size in the
XML (no `<default>`s), so `-D resx=...` cannot shrink them (pcbpt's `--resolution` can).
`load()` edits the scene text in memory (the properties stripped, the film resized) and hands
it to `mi.load_string` with the scene's folder first in Mitsuba's file resolver, so relative
paths (meshes, textures, includes) resolve as they do for the file itself.
"""
import os
import xml.etree.ElementTree as ET

# Properties Mitsuba 3 refuses that pcbpt ignores: removed from the text handed to Mitsuba.
STRIP = ("high_quality_edges", "highQualityEdges")


def scene_text(path, resolution=None, strip=STRIP):
    """The scene file's XML with every property named in `strip` removed and, with a
    `resolution` (width, height), the film of the sensor resized (its `width` and `height`
    replaced or added). The file itself is only read."""
    tree = ET.parse(path)
    root = tree.getroot()
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


def load(mi, path, resolution=None, strip=STRIP, **params):
    """Loads `path` in Mitsuba 3 (variant already set) as `scene_text` gives it, with
    `params` replacing its `<default>`s. The file resolver is restored afterwards."""
    text = scene_text(path, resolution, strip)
    fr = _resolver(mi)
    saved = [str(fr[i]) for i in range(len(fr))]
    fr.prepend(os.path.dirname(os.path.abspath(path)))
    try:
        return mi.load_string(text, **params)
    finally:
        fr.clear()
        for p in saved:
            fr.append(p)
