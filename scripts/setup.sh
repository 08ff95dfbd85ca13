#!/usr/bin/env bash
# Installs what pcbpt needs to build and to pass its tests on Debian/Ubuntu: the system
# Embree (headers and library), libclang for bindgen, pkg-config, g++ (the FLIP metric's C++
# core), Slurm's controller, node daemon and client commands with MUNGE (distributed renders
# through `scripts/slurm/`, and `tests/slurm.rs`, which starts its own single-node cluster:
# the packages' services are not started or needed) and Dask's distributed scheduler
# (`scripts/dask_render.py` and `tests/dask.rs`; python3 with pip from the system if there is
# no python3, then `dask[distributed]` from PyPI) and what the Python package's tests
# (`scripts/python_tests.sh`) need to make a virtual environment (python3 with venv and pip:
# Debian's python3-venv; the script installs maturin, NumPy and pytest into it from PyPI).
# Idempotent: installs only what is missing.
# `--build-only` installs only what building and rendering need (no Slurm, no Dask, no
# Python package tests).
# `--with-oiio` also installs OpenImageIO (headers, library, pkg-config file) for
# `cargo build --features oiio`; `--with-embree4` what `scripts/embree4.sh` needs to
# assemble an Embree 4 (python3 with pip, binutils' readelf; the C compiler comes with g++).
# `--with-oidn` also provides Intel Open Image Denoise for `cargo build --features oidn`
# (`--denoise`): python3 with pip and readelf, then `scripts/oidn.sh` assembles the library
# from PyPI's pyoidn wheel in $OIDN_DIR (default: target/oidn) and prints the OIDN_DIR
# to export for the build.
set -euo pipefail

packages=(libembree-dev libclang-dev pkg-config g++)
with_dask=1
with_slurm=1
with_python=1
with_oidn=0
for arg in "$@"; do
  case "$arg" in
    --build-only) with_dask=0; with_slurm=0; with_python=0 ;;
    --with-oiio) packages+=(libopenimageio-dev) ;;
    --with-embree4) packages+=(python3 python3-pip binutils) ;;
    --with-oidn) with_oidn=1; packages+=(binutils) ;;
    *) echo "setup: unknown option $arg (known: --build-only, --with-oiio, --with-embree4, --with-oidn)" >&2; exit 2 ;;
  esac
done
if [ "$with_slurm" -eq 1 ]; then
  packages+=(slurmctld slurmd slurm-client munge)
fi
# Dask needs a python3 with pip; a python3 already on PATH (a virtual environment, pyenv)
# is used as it is, otherwise the system's is installed.
if [ "$with_dask" -eq 1 ] && ! { command -v python3 >/dev/null 2>&1 && python3 -m pip --version >/dev/null 2>&1; }; then
  packages+=(python3 python3-pip)
fi
# scripts/python_tests.sh makes a virtual environment with pip in it: a python3 whose venv
# can (ensurepip, which Debian ships apart in python3-venv) is used as it is.
if [ "$with_python" -eq 1 ] && ! { command -v python3 >/dev/null 2>&1 && python3 -c 'import ensurepip, venv' >/dev/null 2>&1; }; then
  packages+=(python3 python3-venv python3-pip)
fi
# scripts/oidn.sh fetches a wheel with pip: a python3 with pip is used as it is.
if [ "$with_oidn" -eq 1 ] && ! { command -v python3 >/dev/null 2>&1 && python3 -m pip --version >/dev/null 2>&1; }; then
  packages+=(python3 python3-pip)
fi
missing=()
for p in "${packages[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done

sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}" >&2
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}" >/dev/null
else
  echo "setup: system packages present (${packages[*]})" >&2
fi

if [ "$with_dask" -eq 1 ]; then
  if python3 -c 'import dask.distributed' >/dev/null 2>&1; then
    echo "setup: dask.distributed present ($(python3 -c 'import dask; print(dask.__version__)'))" >&2
  else
    echo "setup: installing dask[distributed] for $(command -v python3)" >&2
    pip_args=(--quiet --disable-pip-version-check --root-user-action=ignore)
    # A system python3 (Debian 12's) refuses pip installs outside a virtual environment
    # unless told to (PEP 668); nothing of Debian's depends on Dask.
    if [ -e "$(python3 -c 'import sysconfig; print(sysconfig.get_path("stdlib"))')/EXTERNALLY-MANAGED" ]; then
      pip_args+=(--break-system-packages)
    fi
    pip_sudo=""
    if [ -n "$sudo" ] && [ ! -w "$(python3 -c 'import sysconfig; print(sysconfig.get_path("purelib"))')" ]; then
      pip_sudo="$sudo"
    fi
    $pip_sudo python3 -m pip install "${pip_args[@]}" 'dask[distributed]'
  fi
fi

if [ "$with_oidn" -eq 1 ]; then
  root="$(cd "$(dirname "$0")/.." && pwd)"
  oidn_dir="${OIDN_DIR:-$root/target/oidn}"
  "$root/scripts/oidn.sh" "$oidn_dir"
  echo "setup: for cargo build --features oidn: export OIDN_DIR=$oidn_dir" >&2
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install a Rust toolchain (rustup, Rust >= 1.88) and re-run" >&2
  exit 1
fi
