"""Shared fixtures: the repository's scenes, a small Cornell box, and the command line.

The command-line binary is `$PCBPT_CLI` when set, otherwise the one `cargo build --profile ci`
builds from this checkout (the profile the test script builds the wheel with).
"""

import _thread
import contextlib
import json
import os
import pathlib
import signal
import subprocess
import threading

import pytest

import pcbpt

REPO = pathlib.Path(__file__).resolve().parents[2]
CORNELL = REPO / "scenes" / "cornell-box" / "scene.xml"
# Small enough that a render takes milliseconds.
SMALL = {"resx": 24, "resy": 20, "spp": 4}


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The `pcbpt` command-line binary."""
    if os.environ.get("PCBPT_CLI"):
        return pathlib.Path(os.environ["PCBPT_CLI"])
    out = subprocess.run(
        ["cargo", "build", "--profile", "ci", "--bin", "pcbpt", "--message-format=json-render-diagnostics"],
        cwd=REPO,
        check=True,
        stdout=subprocess.PIPE,
        text=True,
    ).stdout
    for line in out.splitlines():
        message = json.loads(line)
        if message.get("reason") == "compiler-artifact" and message.get("executable"):
            return pathlib.Path(message["executable"])
    raise RuntimeError("cargo built no pcbpt binary")


@pytest.fixture(scope="session")
def cornell() -> pcbpt.Scene:
    """Bitterli's Cornell box at 24x20 pixels and 4 samples per pixel."""
    return pcbpt.load(CORNELL, **SMALL)


@contextlib.contextmanager
def interrupted_after(seconds: float):
    """Ctrl-C (SIGINT's KeyboardInterrupt) on the main thread `seconds` after entering."""
    # A process started in the background by a shell inherits SIGINT ignored, and then
    # interrupt_main() does nothing: Python's own handler is installed for the duration.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(seconds, _thread.interrupt_main)
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
