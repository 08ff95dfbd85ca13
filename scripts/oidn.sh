#!/usr/bin/env bash
# Assembles Intel Open Image Denoise for `cargo build --features oidn` (`--denoise`) from
# PyPI's pyoidn wheel (Debian 12 has no OIDN package). The wheel ships OIDN 2.5.1's
# libraries in pyoidn/oidn/lib/ (the API library, its core, its device modules and TBB)
# but no headers and no pkg-config file; the `oidn` crate needs neither: its bindings are
# pre-generated, and its build script links -lOpenImageDenoise from $OIDN_DIR/lib.
#
# Layout of DEST (what OIDN_DIR points at):
#   lib/libOpenImageDenoise.so.2.5.1, lib/libOpenImageDenoise_core.so.2.5.1,
#   lib/libOpenImageDenoise_device_cpu.so.2.5.1, lib/libtbb.so.12   the wheel's files
#   lib/libOpenImageDenoise.so.2 -> libOpenImageDenoise.so.2.5.1 (its SONAME),
#   lib/libOpenImageDenoise.so -> libOpenImageDenoise.so.2 (what -l finds)
# Only the CPU device is kept (the wheel's CUDA, HIP and SYCL modules are not needed;
# OIDN looks for device modules beside its core and skips absent ones). The libraries
# carry RPATH $ORIGIN/../lib, so they find each other and TBB here; pcbpt's build.rs gives
# its binaries an rpath to $OIDN_DIR/lib.
#
# Usage: scripts/oidn.sh DEST
# Idempotent: DEST is rebuilt in DEST.new and swapped in; a DEST that exists must have
# been made by this script (it holds .oidn-dist). Needs python3 with pip and readelf.
set -euo pipefail

WHEEL=pyoidn
WHEEL_VERSION=2.5.1.0
WHEEL_SHA256=32ad13368f8de1ef63001942ad05b02a00cd732d1206d97f352d3a3f606d823e
WHEEL_PLATFORM=manylinux2014_x86_64
OIDN_VERSION=2.5.1
STAMP=".oidn-dist"

die() {
  echo "oidn.sh: $*" >&2
  exit 1
}

[ $# -eq 1 ] || die "usage: $0 DEST"
command -v python3 >/dev/null 2>&1 || die "python3 not found (needed to fetch the $WHEEL wheel)"
python3 -m pip --version >/dev/null 2>&1 || die "python3 has no pip (install python3-pip)"
command -v readelf >/dev/null 2>&1 || die "readelf not found (install binutils)"
[ "$(uname -m)" = x86_64 ] || die "the $WHEEL wheel used here is for x86-64 Linux only"

dest="$(realpath -m "$1")"
if [ -f "$dest/$STAMP" ] && grep -q "$WHEEL_SHA256" "$dest/$STAMP"; then
  echo "oidn.sh: Open Image Denoise $OIDN_VERSION present in $dest" >&2
  exit 0
fi
if [ -e "$dest" ] && [ ! -f "$dest/$STAMP" ]; then
  die "$dest exists and was not made by this script (no $STAMP); choose another DEST"
fi

work="$(mktemp -d)"
new="$dest.new"
trap 'rm -rf "$work" "$new"' EXIT
rm -rf "$new"
mkdir -p "$new/lib"

echo "oidn.sh: fetching $WHEEL $WHEEL_VERSION (Open Image Denoise $OIDN_VERSION)" >&2
python3 -m pip download -q --no-deps --only-binary=:all: --platform "$WHEEL_PLATFORM" \
  -d "$work/wheel" "$WHEEL==$WHEEL_VERSION" || die "pip download of $WHEEL $WHEEL_VERSION failed"
wheel_file="$(ls "$work"/wheel/"$WHEEL"-"$WHEEL_VERSION"-*.whl)"
echo "$WHEEL_SHA256  $wheel_file" | sha256sum -c --quiet - || die "$wheel_file: unexpected SHA-256"
python3 - "$wheel_file" "$new/lib" "$OIDN_VERSION" <<'EOF'
import sys, zipfile
from pathlib import Path

wheel, lib, version = sys.argv[1], Path(sys.argv[2]), sys.argv[3]
wanted = [f"libOpenImageDenoise.so.{version}", f"libOpenImageDenoise_core.so.{version}",
          f"libOpenImageDenoise_device_cpu.so.{version}", "libtbb.so.12"]
with zipfile.ZipFile(wheel) as whl:
    names = set(whl.namelist())
    for name in wanted:
        member = f"pyoidn/oidn/lib/{name}"
        if member not in names:
            sys.exit(f"oidn.sh: the wheel has no {member}")
        target = lib / name
        target.write_bytes(whl.read(member))
        target.chmod(0o755)
EOF
api="libOpenImageDenoise.so.$OIDN_VERSION"
dynamic="$(LC_ALL=C readelf -d "$new/lib/$api")"
grep -q "Library soname: \[libOpenImageDenoise.so.2\]" <<<"$dynamic" || die "$api: SONAME is not libOpenImageDenoise.so.2"
grep -q "Shared library: \[libOpenImageDenoise_core.so.$OIDN_VERSION\]" <<<"$dynamic" ||
  die "$api does not NEED libOpenImageDenoise_core.so.$OIDN_VERSION"
grep -Eq 'R(UN)?PATH.*\[\$ORIGIN/\.\./lib\]' <<<"$dynamic" || die "$api lacks RPATH \$ORIGIN/../lib"
ln -s "$api" "$new/lib/libOpenImageDenoise.so.2"
ln -s libOpenImageDenoise.so.2 "$new/lib/libOpenImageDenoise.so"

printf '%s %s %s (Open Image Denoise %s)\n' "$WHEEL" "$WHEEL_VERSION" "$WHEEL_SHA256" "$OIDN_VERSION" >"$new/$STAMP"
rm -rf "$dest"
mv "$new" "$dest"
echo "oidn.sh: Open Image Denoise $OIDN_VERSION assembled in $dest" >&2
