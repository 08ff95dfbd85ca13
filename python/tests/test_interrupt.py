"""Ctrl-C during a load or an experiment: KeyboardInterrupt comes at once (a load) or after
the pass under way (an experiment's render), never after the whole call."""

import pathlib
import time

import numpy as np
import pytest

import pcbpt
from conftest import CORNELL, interrupted_after


def _threads_named(name: str) -> set[int]:
    """The ids of this process's threads of that name (and of the threads they started,
    which inherit it: Embree's workers stay)."""
    tasks = pathlib.Path("/proc/self/task").iterdir()
    return {int(t.name) for t in tasks if (t / "comm").read_text().strip() == name}


def _grid_scene(folder: pathlib.Path, n: int) -> pathlib.Path:
    """A scene of one binary PLY grid of n × n vertices (2 (n-1)² triangles)."""
    u = np.linspace(-1, 1, n, dtype="<f4")
    x, y = np.meshgrid(u, u)
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(n * n, "<f4")], axis=1)
    i = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    quads = np.stack([i, i + 1, i + n + 1, i + n], axis=1)
    faces = np.zeros(2 * len(quads), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"] = 3
    faces["v"][0::2] = quads[:, [0, 1, 2]]
    faces["v"][1::2] = quads[:, [0, 2, 3]]
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {n * n}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    with open(folder / "grid.ply", "wb") as f:
        f.write(header.encode())
        f.write(vertices.tobytes())
        f.write(faces.tobytes())
    scene = folder / "grid.xml"
    scene.write_text(
        """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/><transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
  <emitter type="constant"/>
  <shape type="ply"><string name="filename" value="grid.ply"/></shape>
</scene>"""
    )
    return scene


def test_keyboard_interrupt_is_raised_while_a_load_goes_on(tmp_path):
    # Two million triangles, read and built on one thread: seconds of loading.
    scene = _grid_scene(tmp_path, 1000)
    before = _threads_named("pcbpt-load")
    with interrupted_after(0.2):
        with pytest.raises(KeyboardInterrupt):
            pcbpt.load(scene, threads=1)
    # Raised while the loading still ran: its thread (the first of the new ones of its
    # name) was left to finish on its own, and does.
    started = _threads_named("pcbpt-load") - before
    assert started, "the load ended before KeyboardInterrupt was raised"
    loader = min(started)
    deadline = time.monotonic() + 300
    while loader in _threads_named("pcbpt-load") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert loader not in _threads_named("pcbpt-load")
    # Loading again works.
    assert pcbpt.load(scene, threads=2).triangles == 2 * 999 * 999


EXPERIMENT = """
time = 30
threads = 2

[[scene]]
name = "cornell"
file = "{scene}"
defines = {{ resx = "16", resy = "12" }}
reference = "reference.exr"

[[method]]
name = "path"
integrator = "path"

[[method]]
name = "bdpt"
integrator = "bdpt"
"""


def test_keyboard_interrupt_stops_an_experiment_and_is_raised(tmp_path):
    scene = pcbpt.load(CORNELL, resx=16, resy=12)
    pcbpt.write_image(tmp_path / "reference.exr", pcbpt.render(scene, spp=4, threads=2))
    (tmp_path / "suite.toml").write_text(EXPERIMENT.format(scene=CORNELL))
    start = time.monotonic()
    with interrupted_after(0.5):
        with pytest.raises(KeyboardInterrupt):
            pcbpt.experiment(tmp_path / "suite.toml")
    # Two methods of 30 s each: stopped in the first, after its pass under way, whose
    # image is not written, and the scene left unfinished has no table.
    assert time.monotonic() - start < 10
    assert not (tmp_path / "suite" / "cornell_path.exr").exists()
    assert not (tmp_path / "suite" / "results.md").exists()
