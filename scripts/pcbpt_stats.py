"""Runs `pcbpt render` and returns its `--stats` JSON (shared by the benchmark scripts)."""
import json
import os
import subprocess
import tempfile


def render_json(binary, scene, *args):
    """Renders `scene` with the extra command-line `args`; returns the whole `--stats` JSON."""
    with tempfile.TemporaryDirectory() as d:
        stats = os.path.join(d, "stats.json")
        subprocess.run([binary, "render", scene, *map(str, args), "-o", os.path.join(d, "out.exr"), "--stats", stats,
                        "--quiet"], check=True)
        with open(stats) as f:
            return json.load(f)


def render_stats(binary, scene, *args):
    """Renders `scene` with the extra command-line `args`; returns the "render" statistics."""
    return render_json(binary, scene, *args)["render"]
