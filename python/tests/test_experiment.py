"""Experiment files run as `pcbpt experiment` runs them."""

import numpy as np
import pytest

import pcbpt
from conftest import CORNELL

EXPERIMENT = """
name = "two integrators"
spp = 2
threads = 2
seeds = [1, 2]

[[scene]]
name = "cornell"
file = "{scene}"
defines = {{ resx = "16", resy = "12" }}
reference = "reference.exr"

[[method]]
name = "path"
integrator = "path"

[[method]]
name = "bdpt-balance"
integrator = "bdpt"
heuristic = "balance"
"""


def test_an_experiment_writes_its_outputs_and_returns_its_runs(tmp_path):
    scene = pcbpt.load(CORNELL, resx=16, resy=12)
    reference = pcbpt.render(scene, spp=16, seed=99, threads=2)
    pcbpt.write_image(tmp_path / "reference.exr", reference)
    (tmp_path / "suite.toml").write_text(EXPERIMENT.format(scene=CORNELL))

    result = pcbpt.experiment(tmp_path / "suite.toml")

    assert result["output"] == tmp_path / "suite"
    assert (result["output"] / "summary.md").is_file()
    runs = result["runs"]
    assert [(r["seed"], r["method"]) for r in runs] == [
        (1, "path"), (1, "bdpt-balance"), (2, "path"), (2, "bdpt-balance")
    ]
    for r in runs:
        folder = result["output"] / f"seed-{r['seed']}"
        assert (folder / "results.md").is_file()
        image = pcbpt.read_image(folder / f"cornell_{r['method']}.exr")
        # The run's image is the one render() gives for its integrator, options and seed,
        # and its relMSE the one compare() gives.
        options = {"heuristic": "balance"} if r["method"] == "bdpt-balance" else {}
        integrator = "bdpt" if options else "path"
        same = pcbpt.render(scene, integrator, spp=2, seed=r["seed"], threads=2, **options)
        assert np.array_equal(image, same)
        assert r["relmse"] == pcbpt.compare(reference, image) > 0
        assert r["spp"] == 2 and r["curve"][-1][1] == 2


def test_an_experiment_writes_where_it_is_told(tmp_path):
    scene = pcbpt.load(CORNELL, resx=16, resy=12)
    pcbpt.write_image(tmp_path / "reference.exr", pcbpt.render(scene, spp=2, threads=2))
    (tmp_path / "suite.toml").write_text(EXPERIMENT.format(scene=CORNELL).replace("seeds = [1, 2]", "seed = 3"))
    result = pcbpt.experiment(tmp_path / "suite.toml", output=tmp_path / "elsewhere")
    assert result["output"] == tmp_path / "elsewhere"
    assert (tmp_path / "elsewhere" / "results.md").is_file()
    assert {r["seed"] for r in result["runs"]} == {3}


def test_a_bad_experiment_file_is_a_value_error(tmp_path):
    (tmp_path / "bad.toml").write_text(EXPERIMENT.format(scene=CORNELL).replace("spp = 2", ""))
    with pytest.raises(ValueError, match="give exactly one of `time`"):
        pcbpt.experiment(tmp_path / "bad.toml")
    (tmp_path / "other.toml").write_text(EXPERIMENT.format(scene=CORNELL) + 'pc_mis = "harmonic"\n')
    with pytest.raises(ValueError, match="--pc-mis is an option of pcbpt, not of bdpt"):
        pcbpt.experiment(tmp_path / "other.toml")
