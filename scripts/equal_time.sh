#!/bin/sh
# Equal-time comparison of integrators on one scene against a reference EXR.
#
#   scripts/equal_time.sh SCENE.xml REFERENCE.exr SECONDS "INTEGRATORS" [render options...]
#
# Renders SCENE with each integrator for SECONDS of wall time (same threads and options),
# then prints spp reached, samples/s and relMSE / mean ratio against REFERENCE. Outputs go
# to ${OUT:-equal-time}/.
set -eu
scene=$1 ref=$2 secs=$3 integrators=$4
shift 4
out=${OUT:-equal-time}
bin=${PCBPT:-target/release/pcbpt}
mkdir -p "$out"
printf '| integrator | spp | samples/s | relMSE | mean ratio | notes |\n|---|---|---|---|---|---|\n'
for i in $integrators; do
    "$bin" render "$scene" --integrator "$i" --time "$secs" -o "$out/$i.exr" --stats "$out/$i.json" --quiet "$@"
    python3 - "$out/$i.json" "$ref" "$out/$i.exr" "$bin" "$i" <<'PY'
import json, subprocess, sys
stats, ref, img, binary, name = sys.argv[1:]
r = json.load(open(stats))["render"]
m = json.loads(subprocess.run([binary, "compare", ref, img, "--json"], check=True, capture_output=True, text=True).stdout)
notes = ""
if r.get("mlt"):
    t = r["mlt"]
    notes = f"acceptance small {t['small_acceptance'] * 100:.1f}%, large {t['large_acceptance'] * 100:.1f}%; {t['mutations_per_second'] / 1e6:.3f} M mutations/s"
print(f"| {name} | {r['spp']} | {r['samples_per_second'] / 1e6:.3f} M | {m['relmse']:.4f} | {m['mean_ratio']:.4f} | {notes} |")
PY
done
