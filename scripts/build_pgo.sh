#!/usr/bin/env bash
# Builds a profile-guided release binary of pcbpt: an instrumented build renders a training
# suite, LLVM merges the counts, and a second build optimises with them (branch layout,
# inlining and code placement from measured frequencies). The same source as
# `cargo build --release` and the same images, bit for bit (the compiler's choices of
# layout change, not the floating-point arithmetic; BENCHMARKS.md shows the check), only
# faster: BENCHMARKS.md, "Path tracer against Mitsuba 3 on the real scenes".
#
#   scripts/build_pgo.sh            # writes target/pgo/release/pcbpt
#
# The training suite is every shipped scene except the two real ones the speed figures of
# BENCHMARKS.md are measured on (`staircase2`, `living-room`), rendered by the path tracer
# and the bidirectional integrators at small sizes, so the profile is not fitted to the
# scenes it is judged on. Needs LLVM's `llvm-profdata` of the compiler's own LLVM version:
# `rustup component add llvm-tools` (the script runs it when rustup is there).
# Environment: PCBPT_PGO_TARGET (the binary's target folder, default target/pgo),
# EMBREE_DIR as for any build.
set -euo pipefail
cd "$(dirname "$0")/.."

target="${PCBPT_PGO_TARGET:-$PWD/target/pgo}"
gen_target="$PWD/target/pgo-gen"
data="$gen_target/profiles"

sysroot="$(rustc --print sysroot)"
host="$(rustc -vV | sed -n 's/^host: //p')"
profdata="$sysroot/lib/rustlib/$host/bin/llvm-profdata"
if [ ! -x "$profdata" ] && command -v rustup >/dev/null 2>&1; then
  rustup component add llvm-tools >&2
fi
if [ ! -x "$profdata" ]; then
  echo "build_pgo: $profdata not found: install the llvm-tools component of this toolchain" >&2
  exit 1
fi

echo "build_pgo: instrumented build ($gen_target)" >&2
rm -rf "$data"
mkdir -p "$data"
RUSTFLAGS="${RUSTFLAGS:-} -Cprofile-generate=$data" \
  cargo build --release --target-dir "$gen_target" --bin pcbpt
gen="$gen_target/release/pcbpt"

out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
train() { # scene, integrator, spp, extra arguments
  local scene="$1" integrator="$2" spp="$3"
  shift 3
  echo "build_pgo: training on $scene ($integrator, $spp spp)" >&2
  "$gen" render "$scene" --integrator "$integrator" --spp "$spp" --threads 2 \
    -o "$out/image.exr" "$@" >/dev/null
}
for scene in scenes/cornell-box/scene.xml scenes/veach-mis/scene.xml scenes/veach-ajar/scene.xml \
  scenes/sunlit-room/scene.xml scenes/cutout/scene.xml scenes/bumpmap/scene.xml \
  scenes/materials/scene.xml scenes/glass-caustic/scene.xml scenes/sunsky/scene.xml; do
  train "$scene" path 16 --resolution 320x180
  train "$scene" bdpt 2 --resolution 160x90
  train "$scene" pcbpt 2 --resolution 160x90
done

rm -f "$gen_target"/merged-*.profdata
"$profdata" merge -o "$gen_target/merged.profdata" "$data"
# Cargo does not see a profile's contents change, only the flags: the file is named by its
# hash, so a new profile (new sources, new training) always rebuilds.
profile="$gen_target/merged-$(sha256sum "$gen_target/merged.profdata" | cut -c1-16).profdata"
mv "$gen_target/merged.profdata" "$profile"

echo "build_pgo: optimised build ($target)" >&2
RUSTFLAGS="${RUSTFLAGS:-} -Cprofile-use=$profile" \
  cargo build --release --target-dir "$target" --bin pcbpt
echo "build_pgo: $target/release/pcbpt" >&2
