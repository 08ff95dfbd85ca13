"""Errors are Python exceptions with the command line's messages; bad input never crashes."""

import subprocess

import pytest

import pcbpt
from conftest import CORNELL


def cli_error(cli, scene) -> str:
    """The command line's error message for rendering `scene` (without "error: ")."""
    run = subprocess.run([cli, "render", scene, "-q"], stderr=subprocess.PIPE, text=True)
    assert run.returncode != 0
    return run.stderr.strip().removeprefix("error: ")


def test_a_missing_file_is_file_not_found(tmp_path):
    missing = tmp_path / "nothing.xml"
    with pytest.raises(FileNotFoundError) as e:
        pcbpt.load(missing)
    assert e.value.filename == str(missing)
    with pytest.raises(FileNotFoundError):
        pcbpt.read_image(tmp_path / "nothing.exr")
    with pytest.raises(FileNotFoundError):
        pcbpt.experiment(tmp_path / "nothing.toml")


SCENE_ERRORS = [
    # Malformed XML: a closing tag that does not match.
    ('<scene version="3.0.0">\n  <integrator type="path">\n  </integrtor>\n</scene>\n', 3),
    # A property that is no number.
    ('<scene version="3.0.0">\n  <integrator type="path">\n    <integer name="max_depth" value="oops"/>\n'
     "  </integrator>\n</scene>\n", 3),
    # A property nothing reads.
    ('<scene version="3.0.0">\n\n  <integrator type="path">\n    <float name="nonsense" value="1"/>\n'
     "  </integrator>\n</scene>\n", 4),
]


@pytest.mark.parametrize("text,line", SCENE_ERRORS)
def test_a_scene_error_names_file_and_line_as_the_command_line_does(cli, tmp_path, text, line):
    scene = tmp_path / "broken.xml"
    scene.write_text(text)
    with pytest.raises(pcbpt.SceneError) as e:
        pcbpt.load(scene)
    assert isinstance(e.value, ValueError)
    assert str(e.value).startswith(f"{scene}:{line}:")
    assert (e.value.file, e.value.line) == (str(scene), line)
    assert str(e.value) == cli_error(cli, scene)


def test_an_option_of_another_integrator_names_those_that_read_it(cornell):
    with pytest.raises(ValueError, match=r"light_paths: --light-paths is an option of lvc, pcbpt, spcbpt, not of path"):
        pcbpt.render(cornell, "path", light_paths=1000)
    with pytest.raises(ValueError, match="--pc-mis is an option of pcbpt, not of bdpt"):
        pcbpt.render(cornell, "bdpt", pc_mis="harmonic")
    with pytest.raises(ValueError, match="--no-such-thing is not an option of any integrator"):
        pcbpt.render(cornell, "bdpt", no_such_thing=1)


def test_bad_option_values_are_value_errors(cornell):
    with pytest.raises(ValueError, match="invalid value 'nope'"):
        pcbpt.render(cornell, "bdpt", heuristic="nope")
    with pytest.raises(ValueError, match="invalid value"):
        pcbpt.render(cornell, "lvc", light_paths=-5)
    with pytest.raises(ValueError, match="invalid value"):
        pcbpt.render(cornell, "pssmlt", two_stage="perhaps")


BAD_RENDERS = [
    ({"integrator": "nope"}, "unknown integrator \"nope\""),
    ({"spp": 0}, "spp must be at least 1"),
    ({"spp": -1}, "spp must be"),
    ({"spp": 2**40}, "spp must be"),
    ({"time": -1.0}, "time must be a positive number"),
    ({"time": float("nan")}, "time must be a positive number"),
    ({"spp": 4, "time": 1.0}, "give spp or time, not both"),
    ({"seed": -3}, "seed must be"),
    ({"threads": -1}, "threads must be"),
    ({"max_depth": -2}, "max_depth must be -1"),
    ({"rr_depth": -1}, "rr_depth must be"),
    ({"sampler": "halton"}, "unknown sampler"),
    ({"integrator": "bdpt", "sampler": "sobol"}, "sampler sobol is the path tracer's"),
]


@pytest.mark.parametrize("keywords,says", BAD_RENDERS)
def test_bad_render_arguments_are_value_errors(cornell, keywords, says):
    with pytest.raises(ValueError, match=says):
        pcbpt.render(cornell, **keywords)


def test_arguments_of_the_wrong_type_are_type_errors(cornell):
    with pytest.raises(TypeError):
        pcbpt.render("scene.xml")
    with pytest.raises(TypeError):
        pcbpt.render(cornell, spp="many")


@pytest.mark.parametrize(
    "keywords,says",
    [
        ({"resolution": "big"}, "is not a resolution"),
        ({"resolution": (0, 10)}, "between 1 and 65536"),
        ({"resolution": (1, 2, 3)}, "resolution must be"),
        ({"backend": "optix"}, "unknown backend"),
        ({"threads": -2}, "threads must be"),
    ],
)
def test_bad_load_arguments_are_value_errors(keywords, says):
    with pytest.raises(ValueError, match=says):
        pcbpt.load(CORNELL, **keywords)


def test_a_bad_scene_parameter_is_a_scene_error():
    with pytest.raises(pcbpt.SceneError, match="is not"):
        pcbpt.load(CORNELL, resx="wide")
