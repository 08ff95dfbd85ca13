#!/usr/bin/env bash
# Installs what pcbpt needs to build on Debian/Ubuntu: the system Embree (headers and
# library), libclang for bindgen, pkg-config, g++ (the FLIP metric's C++ core). Idempotent: installs only what is missing.
# `--with-oiio` also installs OpenImageIO (headers, library, pkg-config file) for
# `cargo build --features oiio`; `--with-embree4` what `scripts/embree4.sh` needs to
# assemble an Embree 4 (python3 with pip, binutils' readelf; the C compiler comes with g++).
set -euo pipefail

packages=(libembree-dev libclang-dev pkg-config g++)
for arg in "$@"; do
  case "$arg" in
    --with-oiio) packages+=(libopenimageio-dev) ;;
    --with-embree4) packages+=(python3 python3-pip binutils) ;;
    *) echo "setup: unknown option $arg (known: --with-oiio, --with-embree4)" >&2; exit 2 ;;
  esac
done
missing=()
for p in "${packages[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done

if [ ${#missing[@]} -gt 0 ]; then
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  echo "setup: installing ${missing[*]}" >&2
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}" >/dev/null
else
  echo "setup: system packages present (${packages[*]})" >&2
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install a Rust toolchain (rustup, Rust >= 1.88) and re-run" >&2
  exit 1
fi
