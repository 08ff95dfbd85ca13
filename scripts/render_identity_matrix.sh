#!/usr/bin/env bash
# Renders every integrator with a set of its options, on fixed seeds and thread counts, with
# two builds of pcbpt and checks that the images are the same bit for bit: what a change that
# should not change renders (a refactoring) is checked with, against the binary of the commit
# before it.
#
#   scripts/render_identity_matrix.sh OLD_PCBPT NEW_PCBPT [WORK_DIR]
#
# The options are written with the names both builds read (the --pc-* and --lvc-* names of
# the shared pool and budget options are kept as aliases). Prints one line per render and
# exits non-zero if any pair differs or fails.
set -uo pipefail
old=${1:?usage: render_identity_matrix.sh OLD_PCBPT NEW_PCBPT [WORK_DIR]}
new=${2:?usage: render_identity_matrix.sh OLD_PCBPT NEW_PCBPT [WORK_DIR]}
work=${3:-$(mktemp -d)}
mkdir -p "$work"
cd "$(dirname "$0")/.."

scenes=(
  "cornell-box|scenes/cornell-box/scene.xml|-D resx=64 -D resy=64 --spp 4"
  "veach-ajar|scenes/veach-ajar/scene.xml|-D resx=96 -D resy=54 --spp 4"
)
methods=(
  "path|--integrator path"
  "lighttrace|--integrator lighttrace"
  "bdpt|--integrator bdpt"
  "bdpt-balance|--integrator bdpt --heuristic balance"
  "eorr|--integrator eorr"
  "eorr-running-mean|--integrator eorr --eorr-pilot-spp 0 --eorr-fraction 0.2"
  "lvc|--integrator lvc"
  "lvc-3|--integrator lvc --lvc-connections 3 --lvc-light-paths 500"
  "pcbpt|--integrator pcbpt"
  "pcbpt-uniform|--integrator pcbpt --pc-mis uniform --pc-budget off"
  "pcbpt-resampling|--integrator pcbpt --pc-mis resampling --pc-connections 2"
  "pcbpt-cmf-printed|--integrator pcbpt --pc-sampling cmf --pc-distance-term printed --pc-cache-stride 16"
  "pcbpt-budget-moments|--integrator pcbpt --pc-budget-model moments --pc-budget-iterations 3 --pc-light-paths 300"
  "spcbpt|--integrator spcbpt"
  "spcbpt-harmonic|--integrator spcbpt --sp-mis harmonic --pc-budget off --sp-training-iterations 2"
  "pssmlt|--integrator pssmlt --bootstrap 2000"
  "pssmlt-path|--integrator pssmlt --bootstrap 2000 --mlt-path-integrator path"
  "pssmlt-two-stage|--integrator pssmlt --bootstrap 2000 --two-stage true"
  "memlt|--integrator memlt --bootstrap 2000"
  "memlt-one-stage|--integrator memlt --bootstrap 2000 --two-stage false --chains 16"
  "memlt-all-chains|--integrator memlt --bootstrap 2000 --direct-samples -1 --specular-samples 0 --independent-mutation true"
)
failed=0
for s in "${scenes[@]}"; do
  IFS='|' read -r sname sfile sargs <<<"$s"
  for m in "${methods[@]}"; do
    IFS='|' read -r mname margs <<<"$m"
    for threads in 1 2; do
      tag="$sname-$mname-t$threads"
      # shellcheck disable=SC2086
      if ! "$old" render "$sfile" $sargs $margs --threads "$threads" --seed 7 --quiet -o "$work/$tag-old.exr" 2>"$work/$tag-old.log"; then
        echo "FAIL (old build) $tag: $(tail -1 "$work/$tag-old.log")"; failed=1; continue
      fi
      # shellcheck disable=SC2086
      if ! "$new" render "$sfile" $sargs $margs --threads "$threads" --seed 7 --quiet -o "$work/$tag-new.exr" 2>"$work/$tag-new.log"; then
        echo "FAIL (new build) $tag: $(tail -1 "$work/$tag-new.log")"; failed=1; continue
      fi
      if cmp -s "$work/$tag-old.exr" "$work/$tag-new.exr"; then
        echo "same  $tag"
      else
        echo "DIFF  $tag"; failed=1
      fi
    done
  done
done
if [ "$failed" -ne 0 ]; then echo "render identity: some renders differ or failed"; exit 1; fi
echo "render identity: every render is the same bit for bit"
