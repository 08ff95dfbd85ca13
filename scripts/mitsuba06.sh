#!/usr/bin/env bash
# Mitsuba 0.6, the PCBPT paper's peer (its `mlt` with the manifold perturbation is MEMLT),
# for comparisons only: never a dependency of pcbpt.
#
#   scripts/mitsuba06.sh build DEST
#       Installs the build's Debian packages, clones the public repository's `scons-python3`
#       branch (Python 3 SConscripts; `master` has none) into DEST/mitsuba and builds it
#       with the stock configuration (`-march=nocona`, `-DMTS_DEBUG`, as its users get it)
#       and the fixes Debian 12 needs: `-std=gnu++11` (hex-float literals), OpenEXR 3's
#       include folders and libraries, no Python bindings, `Imf::Int64` -> `uint64_t` and an
#       `ImfFrameBuffer.h` include in bitmap.cpp, boost::placeholders in volcache.cpp.
#       About 17 minutes on 2 cores.
#   scripts/mitsuba06.sh memlt DEST SPP OUT.exr [SCENE_DIR] [SWITCH=true|false ...]
#       Renders veach-ajar (SCENE_DIR, default ../shared/scenes/veach-ajar, its
#       `scene_v0.6.xml`) at 320x180 with unlimited depth and Mitsuba 0.6's MEMLT (`mlt`,
#       `manifoldPerturbation` true, every other setting its default: direct light separate
#       at 16 samples, 100 000 luminance samples) at SPP mutations per pixel on 2 threads,
#       and prints its render time and acceptance statistics. The scene file is copied with
#       only its integrator block replaced; its models and textures are linked. SWITCHes
#       set the integrator's booleans (`lensPerturbation=false`, ...) to compare single
#       mutations: give SCENE_DIR to give them.
set -euo pipefail

cmd=${1:?usage: mitsuba06.sh build DEST | memlt DEST SPP OUT.exr [SCENE_DIR] [SWITCH=BOOL ...]}
dest=${2:?DEST missing}
mkdir -p "$dest"
dest=$(cd "$dest" && pwd)
root=$(cd "$(dirname "$0")/.." && pwd)

case "$cmd" in
build)
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then sudo=sudo; fi
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -q scons libboost-dev libboost-system-dev \
        libboost-filesystem-dev libboost-thread-dev libopenexr-dev libimath-dev libxerces-c-dev libeigen3-dev \
        libglewmx-dev libpng-dev libjpeg-dev libfftw3-dev zlib1g-dev libgl1-mesa-dev libxxf86vm-dev git python3
    if [ ! -d "$dest/mitsuba" ]; then
        git clone --branch scons-python3 https://github.com/mitsuba-renderer/mitsuba "$dest/mitsuba"
    fi
    cd "$dest/mitsuba"
    cp build/config-linux-gcc.py config.py
    python3 - <<'PY'
import re
s = open('config.py').read()
s = s.replace("CXXFLAGS       = [", "CXXFLAGS       = ['-std=gnu++11', ", 1)
s = re.sub(r"OEXRINCLUDE\s*=.*", "OEXRINCLUDE    = ['/usr/include/OpenEXR', '/usr/include/Imath']", s)
s = re.sub(r"OEXRLIB\s*=.*", "OEXRLIB        = ['OpenEXR', 'Imath', 'Iex', 'IlmThread', 'z']", s)
i = s.find('# The following runs a helper script')
if i >= 0:
    s = s[:i]
open('config.py', 'w').write(s)
p = 'src/libcore/bitmap.cpp'
s = open(p).read().replace('Imf::Int64', 'uint64_t')
if '#include <ImfFrameBuffer.h>' not in s:
    s = s.replace('#include <ImfOutputFile.h>', '#include <ImfOutputFile.h>\n#include <ImfFrameBuffer.h>', 1)
open(p, 'w').write(s)
p = 'src/volume/volcache.cpp'
s = open(p).read()
if 'boost/bind/bind.hpp' not in s:
    s = s.replace('#include <mitsuba/render/volume.h>',
                  '#include <mitsuba/render/volume.h>\n#include <boost/bind/bind.hpp>\nusing namespace boost::placeholders;', 1)
open(p, 'w').write(s)
PY
    nice -n 19 scons -j"$(nproc)"
    echo "Mitsuba 0.6 built in $dest/mitsuba/dist"
    ;;
memlt)
    spp=${3:?SPP missing}
    out=${4:?OUT.exr missing}
    scene_dir=${5:-$root/../shared/scenes/veach-ajar}
    work=$(mktemp -d)
    trap 'rm -rf "$work"' EXIT
    ln -s "$(cd "$scene_dir" && pwd)/models" "$work/models"
    ln -s "$(cd "$scene_dir" && pwd)/textures" "$work/textures"
    python3 - "$scene_dir/scene_v0.6.xml" "$work/memlt.xml" "${@:6}" <<'PY'
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
    export PATH="$dest/mitsuba/dist:$PATH" LD_LIBRARY_PATH="$dest/mitsuba/dist"
    out_abs=$(cd "$(dirname "$out")" && pwd)/$(basename "$out")
    (cd "$work" && mitsuba -p 2 -o "$out_abs" memlt.xml -Dresx=320 -Dresy=180 -Dspp="$spp") 2>&1 |
        grep -E "Render time|Acceptance rate|Accepted mutations|mutation :|perturbation :"
    ;;
*)
    echo "unknown command $cmd: build or memlt" >&2
    exit 2
    ;;
esac
