"""pcbpt from Python: load Mitsuba XML scenes and render them into NumPy arrays.

The calls follow Mitsuba 3's (``mi.load_file``, ``mi.render``)::

    import pcbpt

    scene = pcbpt.load("scenes/cornell-box/scene.xml", resx=256, resy=256)
    image = pcbpt.render(scene, "bdpt", spp=64, seed=1)   # (256, 256, 3) float32
    reference = pcbpt.read_image("reference.exr")
    print(pcbpt.compare(reference, image))                  # relMSE

A render is the one ``pcbpt render`` makes: the same scene, integrator, options and seed
give the same image bit for bit, whatever the number of threads. Integrator options are
the command line's, by their names with ``_`` for ``-`` (``light_paths=1000`` for
``--light-paths 1000``); ``pcbpt render --integrator NAME --help`` and docs/cli.md list
them. Errors are exceptions: :class:`SceneError` (a :class:`ValueError`) for a scene
file's, naming file and line as the command line does; :class:`ValueError` for a bad
argument; :class:`FileNotFoundError` for a missing file. Ctrl-C interrupts a load, a
render or an experiment and raises :class:`KeyboardInterrupt`.
"""

from __future__ import annotations

import json
import os
import pathlib
from typing import Any, Optional, Union

import numpy as np

from . import _native
from ._native import Scene, SceneError

__all__ = [
    "Scene",
    "SceneError",
    "compare",
    "experiment",
    "integrators",
    "load",
    "read_image",
    "render",
    "write_image",
]

__version__: str = _native.__version__

PathLike = Union[str, "os.PathLike[str]"]


def load(
    path: PathLike,
    *,
    resolution: Union[None, str, tuple[int, int]] = None,
    backend: Optional[str] = None,
    threads: int = 0,
    override_integrator: bool = False,
    progress: bool = False,
    **defaults: Any,
) -> Scene:
    """Load a Mitsuba XML scene (version 3, or 0.x files upgraded) as ``pcbpt render`` does.

    The scene is read on a worker thread without the GIL; Ctrl-C (KeyboardInterrupt) is
    raised at once, and the loading, which cannot stop part-way, ends in the background
    and its scene is dropped.

    Args:
        path: the scene file.
        resolution: the film size instead of the scene's, ``(width, height)`` or ``"WxH"``
            (``--resolution``), for scenes that fix it in the XML.
        backend: the ray-tracing backend, ``"embree"`` (the default) or ``"obvhs"`` (in a
            build with the renderer's ``obvhs`` feature).
        threads: threads that read the files and build the tables (0: every core).
        override_integrator: read the file's ``<integrator>`` as ``--integrator`` does: only
            its ``max_depth``, ``rr_depth`` and ``hide_emitters`` apply, and a type this
            renderer lacks (or properties only it reads) is a warning instead of an error;
            then ``render`` needs an integrator if the file's is unknown.
        progress: draw the loading's progress on stderr (when it is a terminal).
        **defaults: the scene's ``<default>`` parameters (``-D name=value``), e.g.
            ``spp=16, resx=320, integrator="bdpt"``; values are passed as ``str(value)``,
            booleans as ``true``/``false``. Parameters named like the keywords above can
            only be set by the file.

    Returns:
        The loaded :class:`Scene`, which any number of renders share. The loader's
        warnings are issued as :class:`UserWarning` (and kept in ``scene.warnings``).

    Raises:
        FileNotFoundError: ``path`` does not exist.
        SceneError: the file, or one it reads, is wrong; the message names file and line.
        ValueError: a bad argument.
        KeyboardInterrupt: the load was interrupted.
    """
    defines = [(name, _parameter(value)) for name, value in defaults.items()]
    return _native.load(
        os.fspath(path),
        defines,
        _resolution(resolution),
        backend,
        threads,
        bool(override_integrator),
        bool(progress),
    )


def render(
    scene: Scene,
    integrator: Optional[str] = None,
    *,
    spp: Optional[int] = None,
    time: Optional[float] = None,
    seed: Optional[int] = None,
    threads: int = 0,
    stats: bool = False,
    max_depth: Optional[int] = None,
    rr_depth: Optional[int] = None,
    sampler: Optional[str] = None,
    progress: bool = False,
    aov: Optional[Any] = None,
    noise_threshold: Optional[float] = None,
    display_server: Optional[str] = None,
    **options: Any,
):
    """Render a scene; the image is the one ``pcbpt render`` writes for the same arguments.

    The render runs on worker threads without the GIL; Ctrl-C (KeyboardInterrupt) stops it
    after the pass under way and is raised again.

    Args:
        scene: a scene from :func:`load`.
        integrator: one of :func:`integrators` (default: the one the scene file names).
            Naming it drops the file's ``strict_normals``, as ``--integrator`` does.
        spp: samples per pixel (mutations per pixel for ``pssmlt`` and ``memlt``); default:
            the scene's sample count.
        time: render for this many seconds instead (whole passes of one sample per pixel).
        seed: seed of the random numbers (default: the scene sampler's).
        threads: worker threads (0: every core); the image does not depend on it.
        stats: also return the render's statistics.
        max_depth: longest path in segments from the camera (-1: unlimited) instead of the
            file's (``--max-depth``).
        rr_depth: depth from which Russian roulette may end paths (``--rr-depth``).
        sampler: ``"independent"`` or ``"sobol"`` (the path tracer's) instead of the
            file's sampler (``--sampler``).
        progress: draw a progress bar on stderr (when it is a terminal).
        aov: AOVs to return beside the image (``--aov``): a list of names, or one
            comma-separated string, of ``"albedo"``, ``"normal"``, ``"depth"``,
            ``"position"`` and ``"variance"`` (docs/usage.md says what each holds).
        noise_threshold: stop once the render's own relMSE estimate falls below this
            (``--noise-threshold``), or at ``spp``/``time``, whichever comes first.
        display_server: ``"HOST:PORT"`` of a tev viewer to stream the image to while it
            renders (``--display-server``); a viewer that is absent or goes away costs a
            warning on stderr, never the render.
        **options: the integrator's options by their command-line names with ``_`` for
            ``-`` (``light_paths=1000``, ``pc_mis="harmonic"``, ``two_stage=False``);
            values are passed as ``str(value)``, booleans as ``true``/``false``; None
            leaves an option at its default.

    Returns:
        The image, a float32 array of shape ``(height, width, 3)`` (linear RGB, rows from
        the top); with ``stats=True``, a tuple ``(image, stats)`` whose dict is the JSON
        that ``pcbpt render --stats`` writes (``stats["render"]["integrator"]``,
        ``["spp"]``, ``["seconds"]``, ``["options"]``, ``["relmse_estimate"]`` with a noise
        threshold or the variance, …; ``stats["output"]`` is None). With ``aov``, a dict of
        the AOVs' channels by their EXR names (``"Albedo.R"``, ``"Ns.X"``, ``"Z"``,
        ``"Variance.G"``, …; float32 arrays of shape ``(height, width)``) comes last:
        ``(image, aovs)`` or ``(image, stats, aovs)``.

    Raises:
        ValueError: a bad argument, or an option the integrator does not read (the
            message names the integrators that read it).
        KeyboardInterrupt: the render was interrupted.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a pcbpt.Scene (from pcbpt.load), got {type(scene).__name__}")
    if isinstance(aov, str):
        aov = [aov]
    image, text, aovs = _native.render(
        scene,
        integrator,
        spp,
        None if time is None else float(time),
        seed,
        threads,
        max_depth,
        rr_depth,
        sampler,
        bool(progress),
        None if aov is None else [str(a) for a in aov],
        None if noise_threshold is None else float(noise_threshold),
        None if display_server is None else str(display_server),
        options,
    )
    out = (image,)
    if stats:
        out += (json.loads(text),)
    if aov is not None:
        out += (aovs,)
    return out if len(out) > 1 else image


def compare(reference: Any, image: Any, metric: Optional[str] = "relmse") -> Any:
    """Compare an image with a reference as ``pcbpt compare`` does.

    Args:
        reference: the reference, an array of shape ``(height, width, 3)``.
        image: the image to test, of the same shape.
        metric: ``"relmse"`` (per channel ``(t - r)² / (r² + 0.01)``, averaged),
            ``"mse"``, ``"mean_ratio"`` (``mean(image) / mean(reference)``) or ``"flip"``;
            None for a dict of every metric but FLIP (with the two means and the count of
            non-finite pixels of ``image``, which the sums leave out).

    Returns:
        The metric's value (a float), or the dict.
    """
    return _native.compare(_image(reference, "reference"), _image(image, "image"), metric)


def read_image(path: PathLike) -> np.ndarray:
    """Read an image as linear RGB, a float32 array of shape ``(height, width, 3)``.

    EXR and Radiance HDR are read as they are; PNG, JPEG, TGA and BMP are decoded from
    sRGB, as ``pcbpt compare`` reads them.
    """
    return _native.read_image(os.fspath(path))


def write_image(path: PathLike, image: Any) -> None:
    """Write an image of shape ``(height, width, 3)``: ``.exr`` (linear float RGB) or
    ``.png`` (sRGB), as ``pcbpt render -o`` writes them."""
    _native.write_image(os.fspath(path), _image(image, "image"))


def integrators() -> list[str]:
    """The integrators' names, as ``render`` and ``--integrator`` take them."""
    return _native.integrators()


def experiment(path: PathLike, *, output: Optional[PathLike] = None, quiet: bool = True) -> dict:
    """Run an experiment file (TOML; see experiments/) as ``pcbpt experiment FILE`` does.

    Every method renders every scene for the same time or sample count, over the file's
    seeds; the outputs (each run's EXR, ``results.md``, ``convergence.csv``, plots, and
    ``summary.md`` over several seeds) are written into the output folder. It runs on
    worker threads without the GIL; Ctrl-C (KeyboardInterrupt) stops the render under way
    after its current pass, ends the experiment there (the outputs of the runs finished
    are kept, without the tables of the scene and seed left unfinished) and is raised
    again.

    Args:
        path: the experiment file.
        output: the output folder (default: the file's ``output``, or its name beside it).
        quiet: print nothing but errors (``False``: the command line's progress lines).

    Raises:
        KeyboardInterrupt: the experiment was interrupted.

    Returns:
        ``{"output": folder, "runs": [...]}``: the folder (a :class:`pathlib.Path`) and one
        dict per run, with ``scene``, ``method``, ``seed``, ``spp``, ``seconds``,
        ``samples_per_second``, ``relmse``, ``flip``, ``mean_ratio`` and ``curve`` (the
        ``(seconds, spp, relmse)`` checkpoints, the last at the end).
    """
    folder, runs = _native.experiment(
        os.fspath(path), None if output is None else os.fspath(output), bool(quiet)
    )
    return {"output": pathlib.Path(folder), "runs": runs}


def _parameter(value: Any) -> str:
    """A scene parameter's text: booleans as the XML writes them."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _resolution(resolution: Union[None, str, tuple[int, int]]) -> Optional[str]:
    """``(width, height)`` as ``WxH``."""
    if resolution is None or isinstance(resolution, str):
        return resolution
    try:
        width, height = resolution
    except (TypeError, ValueError):
        raise ValueError(f"resolution must be (width, height) or 'WxH', got {resolution!r}") from None
    return f"{width}x{height}"


def _image(array: Any, what: str) -> np.ndarray:
    """An image argument as a C-contiguous float32 array of shape (height, width, 3)."""
    image = np.ascontiguousarray(array, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"{what} must have shape (height, width, 3), got {image.shape}")
    return image
