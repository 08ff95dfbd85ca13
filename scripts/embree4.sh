#!/usr/bin/env bash
# Assembles an Embree 4 installation for building pcbpt with EMBREE_DIR, from two registry
# packages (Debian 12 has no Embree 4 package):
#
#   headers  the crate embree4-sys 0.0.12 (crates.io) vendors the Embree 4.2 headers
#            (lib/embree4/ in the crate); fetched with cargo.
#   library  the PyPI wheel embreex 4.4.0.post1 (manylinux_2_28 x86-64) ships Embree 4.4.0
#            as embreex.libs/libembree4-<hash>.so.4 with its TBB, libtbb-<hash>.so.12;
#            fetched with pip. Any Python version can fetch it: only the two libraries
#            are used.
#
# Layout of DEST:
#   include/embree4/*.h      the 4.2 headers, patched to the library's build options (below)
#   lib/libembree4-<hash>.so.4, lib/libtbb-<hash>.so.12   the wheel's files, names kept
#   lib/libembree4.so.4 -> libembree4-<hash>.so.4, lib/libembree4.so -> libembree4.so.4
#
# Linking: the library's SONAME is libembree4-<hash>.so.4, so a program linked with
# -lembree4 records that name as NEEDED and finds it through its own rpath to DEST/lib
# (pcbpt's build.rs adds one when EMBREE_DIR is set). The library itself carries
# RPATH $ORIGIN and NEEDs libtbb-<hash>.so.12, found beside it.
#
# Header patch. The wheel's 4.4 library is built with instance arrays (Embree's CMake
# default since 4.3, EMBREE_GEOMETRY_INSTANCE_ARRAY): its RTCHit, RTCHit4/8/16,
# RTCRayQueryContext and RTCPointQueryContext carry an `instPrimID` stack after `instID`,
# which the 4.2 headers do not have. Unpatched, sizeof(RTCRayHit) is 80 bytes in the
# headers and 96 in the library, and every rtcIntersect1 writes instPrimID (4 bytes) past
# the caller's RTCRayHit: into the next ray of an array. The script therefore defines
# RTC_GEOMETRY_INSTANCE_ARRAY in rtcore_config.h and adds the instPrimID fields and their
# initialisation/copy lines exactly where Embree 4.3's headers have them. The other
# layout options match unpatched: RTC_MAX_INSTANCE_LEVEL_COUNT 1 and RTC_MIN_WIDTH 0.
# RTC_VERSION stays 40200: the headers declare the 4.2 API, which the 4.4 library serves.
#
# Check. scripts/embree4_check.c is compiled against DEST and run before DEST is put in
# place: it compares the library's instance-array and min-width support with the
# headers, intersects known geometry (two meshes and an instance) and checks distances,
# ids, barycentrics and instance ids, and that nothing is written after the headers'
# structs. Without the patch it fails.
#
# Usage: scripts/embree4.sh DEST
# Idempotent: DEST is rebuilt in DEST.new and swapped in; a DEST that exists must have
# been made by this script (it holds .embree4-dist). Needs cargo, python3 with pip, and a
# C compiler (cc) and readelf (binutils).
set -euo pipefail

CRATE=embree4-sys
CRATE_VERSION=0.0.12
WHEEL=embreex
WHEEL_VERSION=4.4.0.post1
WHEEL_SHA256=2cd0f7d5c6342e6247e31f700761689cae7829454d8c6de0c41e62124a023e1f
WHEEL_PLATFORM=manylinux_2_28_x86_64
STAMP=".embree4-dist"

die() {
  echo "embree4.sh: $*" >&2
  exit 1
}

[ $# -eq 1 ] || die "usage: $0 DEST"
for tool in cargo python3 cc readelf; do
  command -v "$tool" >/dev/null 2>&1 || die "$tool not found (needed to fetch and check Embree 4)"
done
python3 -m pip --version >/dev/null 2>&1 || die "python3 has no pip (install python3-pip)"
[ "$(uname -m)" = x86_64 ] || die "the $WHEEL wheel used here is for x86-64 Linux only"

here="$(cd "$(dirname "$0")" && pwd)"
dest="$(realpath -m "$1")"
if [ -e "$dest" ] && [ ! -f "$dest/$STAMP" ]; then
  die "$dest exists and was not made by this script (no $STAMP); choose another DEST"
fi

work="$(mktemp -d)"
trap 'rm -rf "$work" "$dest.new"' EXIT
new="$dest.new"
rm -rf "$new"
mkdir -p "$new/include" "$new/lib"

# Headers: let cargo fetch the crate (checksum verified against the index), then copy
# them from the unpacked source.
echo "embree4.sh: fetching $CRATE $CRATE_VERSION (headers)" >&2
mkdir -p "$work/crate/src"
cat >"$work/crate/Cargo.toml" <<EOF
[package]
name = "embree4-headers"
version = "0.0.0"
edition = "2021"

[dependencies]
$CRATE = "=$CRATE_VERSION"
EOF
: >"$work/crate/src/lib.rs"
(cd "$work/crate" && cargo fetch -q) || die "cargo fetch of $CRATE $CRATE_VERSION failed"
crate_dir="$(cd "$work/crate" && cargo metadata -q --format-version 1 |
  python3 -c 'import json, os, sys
m = json.load(sys.stdin)
print(next(os.path.dirname(p["manifest_path"]) for p in m["packages"] if p["name"] == sys.argv[1]))' "$CRATE")" ||
  die "could not locate the $CRATE source"
[ -f "$crate_dir/lib/embree4/rtcore.h" ] || die "$crate_dir/lib/embree4/rtcore.h missing"
mkdir -p "$new/include/embree4"
cp "$crate_dir"/lib/embree4/*.h "$new/include/embree4/"
grep -q '^#define RTC_VERSION 40200$' "$new/include/embree4/rtcore_config.h" ||
  die "$CRATE $CRATE_VERSION does not carry the Embree 4.2.0 headers this script patches"

# The header patch (see the top of this file). Each edit must apply exactly as often as
# expected, so a different header version fails here instead of being half-patched.
python3 - "$new/include/embree4" <<'EOF'
import re, sys
from pathlib import Path

inc = Path(sys.argv[1])
GUARD = "#if defined(RTC_GEOMETRY_INSTANCE_ARRAY)\n{}\n#endif\n"

def edit(name, pattern, repl, count):
    path = inc / name
    text, n = re.subn(pattern, repl, path.read_text(), flags=re.M)
    if n != count:
        sys.exit(f"embree4.sh: header patch: {name}: {n} matches of {pattern!r}, expected {count}")
    path.write_text(text)

# The library's build option.
edit("rtcore_config.h", r"^(#define RTC_MAX_INSTANCE_LEVEL_COUNT 1\n)",
     r"\1\n/* The library is built with instance arrays (Embree's EMBREE_GEOMETRY_INSTANCE_ARRAY). */\n"
     r"#define RTC_GEOMETRY_INSTANCE_ARRAY\n", 1)

# Struct fields: an instPrimID stack after each instID stack (RTCHit, RTCHit4/8/16,
# RTCHitNt, RTCRayQueryContext, RTCPointQueryContext).
def field(m):
    indent, dims = m.group(1), m.group(2)
    return m.group(0) + "\n" + GUARD.format(f"{indent}unsigned int instPrimID[RTC_MAX_INSTANCE_LEVEL_COUNT]{dims};").rstrip("\n")
for name, count in (("rtcore_ray.h", 5), ("rtcore_common.h", 2)):
    edit(name, r"^([ \t]*)unsigned int instID\[RTC_MAX_INSTANCE_LEVEL_COUNT\]((?:\[\w+\])?);[^\n]*$", field, count)

# Loops over the instance levels that set or copy instID also set or copy instPrimID.
def loop(m):
    head, indent, stmt = m.group(1), m.group(2), m.group(3)
    outer = re.match(r"[ \t]*", head).group(0)
    twin = stmt.replace("instID", "instPrimID")
    return f"{head} {{\n{indent}{stmt}\n" + GUARD.format(f"{indent}{twin}") + f"{outer}}}\n"
edit("rtcore_ray.h", r"^([ \t]*for \(unsigned int l = 0; l < RTC_MAX_INSTANCE_LEVEL_COUNT; l\+\+\))\n([ \t]+)([^\n]*instID[^\n]*)\n", loop, 3)
edit("rtcore_common.h", r"^([ \t]*for \(; l < RTC_MAX_INSTANCE_LEVEL_COUNT; \+\+l\))\n([ \t]+)([^\n]*instID[^\n]*)\n", loop, 1)
edit("rtcore_common.h", r"^([ \t]*)context->instID\[0\] = RTC_INVALID_GEOMETRY_ID;\n",
     lambda m: m.group(0) + GUARD.format(m.group(1) + "context->instPrimID[0] = RTC_INVALID_GEOMETRY_ID;"), 1)

# The SoA accessor for packets: instPrimID follows the instID levels.
edit("rtcore_ray.h", r"^(RTC_FORCEINLINE unsigned int& RTCHitN_instID\([^\n]*\n)",
     lambda m: m.group(1) + GUARD.format(
         "RTC_FORCEINLINE unsigned int& RTCHitN_instPrimID(RTCHitN* hit, unsigned int N, unsigned int i, unsigned int l) "
         "{ return ((unsigned*)hit)[7*N + N*RTC_MAX_INSTANCE_LEVEL_COUNT + N*l + i]; }"), 1)
EOF

# Library: the wheel (pinned by hash), unpacked with Python's zipfile.
echo "embree4.sh: fetching $WHEEL $WHEEL_VERSION (library)" >&2
python3 -m pip download -q --no-deps --only-binary=:all: --platform "$WHEEL_PLATFORM" \
  --implementation cp --python-version 3.11 --abi cp311 -d "$work/wheel" "$WHEEL==$WHEEL_VERSION" ||
  die "pip download of $WHEEL $WHEEL_VERSION failed"
wheel_file="$(ls "$work"/wheel/"$WHEEL"-"$WHEEL_VERSION"-*.whl)"
echo "$WHEEL_SHA256  $wheel_file" | sha256sum -c --quiet - || die "$wheel_file: unexpected SHA-256"
python3 - "$wheel_file" "$new/lib" <<'EOF'
import re, sys, zipfile
from pathlib import Path

wanted = re.compile(r"embreex\.libs/(libembree4-[0-9a-f]+\.so\.4|libtbb-[0-9a-f]+\.so\.12)$")
found = []
with zipfile.ZipFile(sys.argv[1]) as whl:
    for name in whl.namelist():
        m = wanted.match(name)
        if m:
            target = Path(sys.argv[2]) / m.group(1)
            target.write_bytes(whl.read(name))
            target.chmod(0o755)
            found.append(m.group(1))
if sorted(n.split("-")[0] for n in found) != ["libembree4", "libtbb"]:
    sys.exit(f"embree4.sh: the wheel holds {found}, expected one libembree4 and one libtbb")
EOF
embree_lib="$(cd "$new/lib" && ls libembree4-*.so.4)"
tbb_lib="$(cd "$new/lib" && ls libtbb-*.so.12)"
# What the dynamic linker will look for: the library's SONAME and its TBB.
dynamic="$(LC_ALL=C readelf -d "$new/lib/$embree_lib")"
grep -q "Library soname: \[$embree_lib\]" <<<"$dynamic" || die "$embree_lib: SONAME is not its file name"
grep -q "Shared library: \[$tbb_lib\]" <<<"$dynamic" || die "$embree_lib does not NEED $tbb_lib"
grep -Eq 'R(UN)?PATH.*\[\$ORIGIN\]' <<<"$dynamic" || die "$embree_lib lacks RPATH \$ORIGIN (TBB would not be found)"
ln -s "$embree_lib" "$new/lib/libembree4.so.4"
ln -s libembree4.so.4 "$new/lib/libembree4.so"

# Check the assembled headers against the library before putting them in place.
cc -O1 -I"$new/include" "$here/embree4_check.c" -L"$new/lib" -lembree4 -lm -Wl,-rpath,"$new/lib" \
  -o "$work/embree4_check" || die "could not compile scripts/embree4_check.c against $new"
"$work/embree4_check" >"$work/check.log" 2>&1 || {
  cat "$work/check.log" >&2
  die "the assembled headers do not match the library (see the checks above)"
}

printf '%s %s (headers, patched)\n%s %s %s (library: %s, %s)\n' "$CRATE" "$CRATE_VERSION" \
  "$WHEEL" "$WHEEL_VERSION" "$WHEEL_SHA256" "$embree_lib" "$tbb_lib" >"$new/$STAMP"
rm -rf "$dest"
mv "$new" "$dest"
echo "embree4.sh: $(head -n1 "$work/check.log"); all checks passed" >&2
echo "embree4.sh: Embree 4 assembled in $dest (build with EMBREE_DIR=$dest)" >&2
