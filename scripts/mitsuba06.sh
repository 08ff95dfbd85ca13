#!/usr/bin/env bash
# Mitsuba 0.6, the PCBPT paper's peer (its `mlt` with the manifold perturbation is MEMLT),
# for comparisons only: never a dependency of pcbpt. The script runs an installation of
# Mitsuba 0.6 that you provide and builds nothing. Name the installation with
# `--mitsuba PATH` or the environment variable MITSUBA06 (the option wins): the `mitsuba`
# executable itself, or a folder holding it (the executable's folder, e.g. a build's
# `dist/`, or a folder with it in `dist/` or `bin/`). Its shared libraries are looked
# for beside the executable (prepended to LD_LIBRARY_PATH). Without either, or where no
# executable that reports Mitsuba 0.x is found, the script stops with status 2.
#
#   scripts/mitsuba06.sh [--mitsuba PATH] memlt SPP OUT.exr [SCENE_DIR] [SWITCH=true|false ...]
#       Renders veach-ajar (SCENE_DIR, default ../shared/scenes/veach-ajar, its
#       `scene_v0.6.xml`) at 320x180 with unlimited depth and Mitsuba 0.6's MEMLT (`mlt`,
#       `manifoldPerturbation` true, every other setting its default: direct light separate
#       at 16 samples, 100 000 luminance samples) at SPP mutations per pixel on 2 threads,
#       and prints its render time and acceptance statistics. The scene file is copied with
#       only its integrator block replaced; its models and textures are linked. SWITCHes
#       set the integrator's booleans (`lensPerturbation=false`, ...) to compare single
#       mutations: give SCENE_DIR to give them.
#
#   MITSUBA06=/opt/mitsuba-0.6/dist scripts/mitsuba06.sh memlt 820 m06.exr
#   scripts/mitsuba06.sh --mitsuba /opt/mitsuba-0.6/dist/mitsuba memlt 256 m.exr \
#       ../shared/scenes/veach-ajar lensPerturbation=false
set -euo pipefail

usage="usage: scripts/mitsuba06.sh [--mitsuba PATH] memlt SPP OUT.exr [SCENE_DIR] [SWITCH=true|false ...]
  PATH (or \$MITSUBA06): the Mitsuba 0.6 \`mitsuba\` executable or the folder that holds it"

die() {
    echo "mitsuba06.sh: $*" >&2
    exit 2
}

# The installation: --mitsuba PATH (anywhere among the arguments) or $MITSUBA06.
given=${MITSUBA06:-}
given_by=MITSUBA06
args=()
while [ $# -gt 0 ]; do
    case $1 in
    --mitsuba)
        [ $# -ge 2 ] || die "--mitsuba needs a PATH"$'\n'"$usage"
        given=$2 given_by=--mitsuba
        shift 2
        ;;
    --mitsuba=*)
        given=${1#--mitsuba=} given_by=--mitsuba
        shift
        ;;
    -h | --help)
        echo "$usage"
        exit 0
        ;;
    *)
        args+=("$1")
        shift
        ;;
    esac
done
set -- ${args[@]+"${args[@]}"}

cmd=${1:-}
case "$cmd" in
memlt) ;;
"") die "no command"$'\n'"$usage" ;;
*) die "unknown command '$cmd' (the command is memlt)"$'\n'"$usage" ;;
esac

spp=${2:-}
out=${3:-}
[ -n "$spp" ] || die "SPP missing"$'\n'"$usage"
[[ $spp =~ ^[0-9]+$ ]] && [ "$spp" -gt 0 ] || die "SPP '$spp': expected a positive number of mutations per pixel"
[ -n "$out" ] || die "OUT.exr missing"$'\n'"$usage"

if [ -z "$given" ]; then
    die "no Mitsuba 0.6 installation given: set MITSUBA06 or pass --mitsuba PATH, naming its \`mitsuba\` executable or the folder that holds it (a build's dist/)"
fi

# The executable: PATH itself, a command name on $PATH, or `mitsuba` in the folder PATH
# (directly, or in its dist/ or bin/, or in mitsuba/dist/ below it).
mts=""
if [ -d "$given" ]; then
    for c in "$given/mitsuba" "$given/dist/mitsuba" "$given/bin/mitsuba" "$given/mitsuba/dist/mitsuba"; do
        if [ -f "$c" ] && [ -x "$c" ]; then
            mts=$c
            break
        fi
    done
    [ -n "$mts" ] || die "$given_by names the folder $given, which holds no \`mitsuba\` executable (looked in it and in its dist/ and bin/)"
elif [ -f "$given" ]; then
    [ -x "$given" ] || die "$given_by names $given, which is not executable"
    mts=$given
elif [[ $given != */* ]] && command -v "$given" >/dev/null; then
    mts=$(command -v "$given")
else
    die "$given_by names $given, which does not exist"
fi
mts_dir=$(cd "$(dirname "$mts")" && pwd)
mts=$mts_dir/$(basename "$mts")
export LD_LIBRARY_PATH="$mts_dir${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"

# Mitsuba 0.x prints "Mitsuba version 0.6.0 ..." first in its help; Mitsuba 3's `mitsuba`
# (pip's) is another renderer with other scene files.
banner=$("$mts" -h 2>&1 | head -n 1 || true)
case "$banner" in
*"Mitsuba version 0."*) ;;
*) die "$mts does not report Mitsuba 0.x (its -h printed: ${banner:-nothing}); $given_by must name a Mitsuba 0.6 installation" ;;
esac

root=$(cd "$(dirname "$0")/.." && pwd)
scene_dir=${4:-$root/../shared/scenes/veach-ajar}
[ -f "$scene_dir/scene_v0.6.xml" ] || die "$scene_dir/scene_v0.6.xml not found (SCENE_DIR: a scene folder with a Mitsuba 0.6 scene_v0.6.xml)"
scene_dir=$(cd "$scene_dir" && pwd)
out_dir=$(dirname "$out")
[ -d "$out_dir" ] || die "the folder of $out does not exist"
out_abs=$(cd "$out_dir" && pwd)/$(basename "$out")

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
ln -s "$scene_dir/models" "$work/models"
ln -s "$scene_dir/textures" "$work/textures"
python3 - "$scene_dir/scene_v0.6.xml" "$work/memlt.xml" "${@:5}" <<'PY'
import re, sys
s = open(sys.argv[1]).read()
block = re.search(r'<integrator type="\$integrator">.*?</integrator>', s, re.S)
if not block:
    sys.exit(f"{sys.argv[1]}: no integrator block to replace")
switches = {"manifoldPerturbation": "true"}
for arg in sys.argv[3:]:
    name, _, value = arg.partition("=")
    if value not in ("true", "false"):
        sys.exit(f"switch {arg!r}: expected NAME=true or NAME=false")
    switches[name] = value
flags = "".join(f'\t\t<boolean name="{n}" value="{v}" />\n' for n, v in switches.items())
s = s.replace(block.group(0), '<integrator type="mlt">\n\t\t<integer name="maxDepth" value="-1" />\n'
              + flags + '\t</integrator>')
open(sys.argv[2], 'w').write(s)
PY
(cd "$work" && "$mts" -p 2 -o "$out_abs" memlt.xml -Dresx=320 -Dresy=180 -Dspp="$spp") 2>&1 |
    grep -E "Render time|Acceptance rate|Accepted mutations|mutation :|perturbation :"
