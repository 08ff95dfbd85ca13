"""Loading and rendering: the images, their statistics, and that they are the command line's."""

import json
import subprocess
import time

import numpy as np
import pytest

import pcbpt
from conftest import CORNELL, SMALL, interrupted_after


def test_integrators_are_the_command_lines():
    assert pcbpt.integrators() == [
        "path", "guided", "lighttrace", "bdpt", "eorr", "lvc", "pssmlt", "pcbpt", "spcbpt", "memlt", "vcm", "bpm"
    ]


def test_scene_attributes_are_the_files_after_the_defaults(cornell):
    assert (cornell.width, cornell.height) == (SMALL["resx"], SMALL["resy"])
    assert (cornell.integrator, cornell.plugin, cornell.sampler) == ("path", "path", "independent")
    assert (cornell.spp, cornell.seed, cornell.max_depth, cornell.rr_depth) == (4, 0, 30, 3)
    assert cornell.triangles > 0 and cornell.warnings == [] and cornell.backend == "embree"
    assert "24x20" in repr(cornell)


def test_defaults_keywords_set_scene_parameters():
    scene = pcbpt.load(CORNELL, resx=8, resy=6, spp=3, max_depth=5, integrator="bdpt")
    assert (scene.width, scene.height, scene.spp, scene.max_depth, scene.integrator) == (8, 6, 3, 5, "bdpt")
    resized = pcbpt.load(CORNELL, resolution=(10, 7), spp=1)
    assert (resized.width, resized.height) == (10, 7)
    assert pcbpt.load(CORNELL, resolution="9x5", spp=1).width == 9


@pytest.mark.parametrize("integrator", ["path", "bdpt"])
def test_render_gives_a_float_image_of_the_film_size(cornell, integrator):
    image = pcbpt.render(cornell, integrator, seed=1, threads=2)
    assert image.shape == (cornell.height, cornell.width, 3)
    assert image.dtype == np.float32
    assert np.isfinite(image).all()
    assert 0.01 < image.mean() < 10


def test_the_seed_decides_the_image_and_threads_do_not(cornell):
    a = pcbpt.render(cornell, seed=3, threads=1)
    b = pcbpt.render(cornell, seed=3, threads=2)
    c = pcbpt.render(cornell, seed=4, threads=2)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.array_equal(pcbpt.render(cornell), pcbpt.render(cornell, seed=cornell.seed))


# Renders compared with the command line's: (integrator, keywords, the same as arguments).
SAME_AS_CLI = [
    (None, {}, []),
    ("path", {"wavefront": False}, ["--integrator", "path", "--wavefront", "false"]),
    ("bdpt", {}, ["--integrator", "bdpt"]),
    ("bdpt", {"wavefront": False}, ["--integrator", "bdpt", "--wavefront", "false"]),
    ("bdpt", {"heuristic": "balance", "max_depth": 4}, ["--integrator", "bdpt", "--heuristic", "balance", "--max-depth", "4"]),
    ("lvc", {"light_paths": 300}, ["--integrator", "lvc", "--light-paths", "300"]),
    ("pssmlt", {"two_stage": False}, ["--integrator", "pssmlt", "--two-stage", "false"]),
    ("vcm", {"vcm_radius": 0.01}, ["--integrator", "vcm", "--vcm-radius", "0.01"]),
    ("bpm", {"vcm_alpha": 0.9}, ["--integrator", "bpm", "--vcm-alpha", "0.9"]),
    ("guided", {"guided_bsdf_fraction": 0.3}, ["--integrator", "guided", "--guided-bsdf-fraction", "0.3"]),
    ("lighttrace", {}, ["--integrator", "lighttrace"]),
    ("eorr", {}, ["--integrator", "eorr"]),
    ("pcbpt", {}, ["--integrator", "pcbpt"]),
    ("spcbpt", {}, ["--integrator", "spcbpt"]),
    ("memlt", {"bootstrap": 5000}, ["--integrator", "memlt", "--bootstrap", "5000"]),
]


def test_every_integrator_is_compared_with_the_command_line():
    assert {i for i, _, _ in SAME_AS_CLI if i} == set(pcbpt.integrators())


@pytest.mark.parametrize("integrator,options,args", SAME_AS_CLI)
def test_the_image_and_statistics_are_the_command_lines(cornell, cli, tmp_path, integrator, options, args):
    exr, stats_file = tmp_path / "cli.exr", tmp_path / "cli.json"
    defines = [a for k, v in SMALL.items() for a in ("-D", f"{k}={v}")]
    subprocess.run(
        [cli, "render", CORNELL, *defines, *args, "--seed", "11", "--threads", "2", "-q", "-o", exr, "--stats", stats_file],
        check=True,
    )
    image, stats = pcbpt.render(cornell, integrator, seed=11, threads=2, stats=True, **options)
    assert np.array_equal(image, pcbpt.read_image(exr))
    theirs = json.loads(stats_file.read_text())
    for key in ["integrator", "options", "spp", "width", "height", "threads", "counters", "invalid_samples"]:
        assert stats["render"][key] == theirs["render"][key], key
    assert stats["triangles"] == theirs["triangles"]


def test_statistics_are_the_stats_files(cornell):
    _, stats = pcbpt.render(cornell, "bdpt", spp=2, threads=2, stats=True, heuristic="balance")
    render = stats["render"]
    assert render["integrator"] == "bdpt"
    assert render["options"] == {"heuristic": "balance", "wavefront": True}
    assert (render["spp"], render["width"], render["height"], render["threads"]) == (2, 24, 20, 2)
    assert render["seconds"] > 0 and not render["interrupted"]
    assert stats["output"] is None and stats["embree_version"]
    assert set(stats) >= {"scene", "load_seconds", "triangles", "load", "degenerate_triangles"}


def test_a_time_budget_renders_whole_passes(cornell):
    image, stats = pcbpt.render(cornell, time=0.2, threads=2, stats=True)
    assert stats["render"]["spp"] >= 1 and np.isfinite(image).all()


def test_keyboard_interrupt_stops_a_render_and_is_raised():
    scene = pcbpt.load(CORNELL, resx=64, resy=64)
    start = time.monotonic()
    with interrupted_after(0.5):
        with pytest.raises(KeyboardInterrupt):
            pcbpt.render(scene, "bdpt", time=60, threads=2)
    assert time.monotonic() - start < 10
    # The scene is free again.
    assert pcbpt.render(scene, spp=1, threads=2).shape == (64, 64, 3)


def test_an_unknown_integrator_in_the_file_needs_one_named():
    with pytest.raises(pcbpt.SceneError, match="unknown integrator plugin \"sppm\""):
        pcbpt.load(CORNELL, integrator="sppm", **{k: v for k, v in SMALL.items()})
    with pytest.warns(UserWarning, match="replaced"):
        scene = pcbpt.load(CORNELL, integrator="sppm", override_integrator=True, **SMALL)
    assert scene.integrator is None and scene.plugin == "sppm"
    with pytest.raises(ValueError, match="pick one with integrator="):
        pcbpt.render(scene)
    assert pcbpt.render(scene, "path", seed=2, threads=2).shape == (20, 24, 3)


def test_aovs_and_the_noise_threshold_come_back_beside_the_image(cornell, cli, tmp_path):
    exr = tmp_path / "cli.exr"
    defines = [a for k, v in SMALL.items() for a in ("-D", f"{k}={v}")]
    subprocess.run(
        [cli, "render", CORNELL, *defines, "--seed", "5", "--threads", "2", "-q", "-o", exr, "--aov", "albedo,depth,variance", "--noise-threshold", "100"],
        check=True,
    )
    image, stats, aovs = pcbpt.render(
        cornell, seed=5, threads=2, stats=True, aov=["albedo", "depth", "variance"], noise_threshold=100
    )
    assert np.array_equal(image, pcbpt.read_image(exr))
    names = {"Albedo.R", "Albedo.G", "Albedo.B", "Z", "Variance.R", "Variance.G", "Variance.B"}
    assert set(aovs) == names
    for name, channel in aovs.items():
        assert channel.shape == (cornell.height, cornell.width) and channel.dtype == np.float32, name
        assert np.isfinite(channel).all() and (channel >= 0).all(), name
    assert 0 < aovs["Albedo.R"].max() <= 1 and aovs["Z"].max() > 0
    # A threshold this high stops at the first estimate, after 2 spp.
    render = stats["render"]
    assert render["spp"] == 2 and render["noise_threshold_reached"] and render["relmse_estimate"] < 100
    image, depth = pcbpt.render(cornell, seed=5, threads=2, aov="depth")
    assert set(depth) == {"Z"}


@pytest.mark.parametrize(
    "keywords,says",
    [
        ({"aov": ["albedo", "colour"]}, "colour"),
        ({"aov": "depth,"}, "aov"),
        ({"noise_threshold": -1}, "noise_threshold"),
        ({"noise_threshold": float("nan")}, "noise_threshold"),
        ({"noise_threshold": 0}, "noise_threshold"),
        ({"aov": "variance", "spp": 1}, "at least 2"),
    ],
)
def test_bad_aovs_and_thresholds_are_value_errors(cornell, keywords, says):
    with pytest.raises(ValueError, match=says):
        pcbpt.render(cornell, threads=2, **keywords)
