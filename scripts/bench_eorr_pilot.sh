#!/usr/bin/env bash
# EORR's roulette thresholds from a 16-spp pilot against the running mean of every earlier
# pass: relMSE against the Mitsuba 3 references at equal samples per pixel, and the
# connections traced and skipped, four seeds each, on veach-ajar and cornell-box.
# Usage: scripts/bench_eorr_pilot.sh [PCBPT_BINARY]   (prints one line per render)
set -euo pipefail
cd "$(dirname "$0")/.."
P=${1:-target/release/pcbpt}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for scene in veach-ajar cornell-box; do
  case $scene in
    veach-ajar) defines=(-D resx=160 -D resy=90 -D max_depth=-1) ;;
    cornell-box) defines=(-D resx=128 -D resy=128) ;;
  esac
  for pilot in 16 0; do
    for seed in 1 2 3 4; do
      "$P" render "scenes/$scene/scene.xml" "${defines[@]}" --integrator eorr --eorr-pilot-spp $pilot \
        --spp 128 --seed $seed --threads 2 -q -o "$out/img.exr" --stats "$out/s.json"
      rel=$("$P" compare "tests/data/$scene.exr" "$out/img.exr" --metric relmse)
      python3 - "$out/s.json" "$scene" "$pilot" "$seed" "$rel" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))["render"]
c = s["counters"]
print(f"{sys.argv[2]} pilot={sys.argv[3]} seed={sys.argv[4]} relmse={sys.argv[5]} "
      f"seconds={s['seconds']:.2f} connections={c['connections']} skipped={c['connections_skipped']}")
PY
    done
  done
done
