#!/usr/bin/env bash
# The path tracer's error with the independent and the sobol sampler on the shipped scenes
# with references: per scene and sample count, the relMSE against the reference (tests/data,
# which carries its own noise: the sampler's gain is understated by it) averaged over seeds
# 1–4, and the samples per second of each sampler, from which the equal-time ratio follows.
#
#   scripts/sampler_relmse.sh [PCBPT] [OUT_DIR]
#
# Prints one line per scene, sample count and sampler: relMSE (mean of the seeds), samples/s.
set -euo pipefail
cd "$(dirname "$0")/.."
pcbpt=${1:-target/release/pcbpt}
out=${2:-$(mktemp -d)}
mkdir -p "$out"
scenes=(
  "cornell-box|scenes/cornell-box/scene.xml|-D resx=128 -D resy=128 -D max_depth=30|cornell-box.exr"
  "veach-ajar|scenes/veach-ajar/scene.xml|-D resx=160 -D resy=90 -D max_depth=-1|veach-ajar.exr"
  "materials|scenes/materials/scene.xml|-D resx=160 -D resy=120|materials.exr"
  "staircase2|scenes/staircase2/scene.xml|--resolution 320x180|staircase2.exr"
  "living-room|scenes/living-room/scene.xml|--resolution 320x180|living-room.exr"
)
for entry in "${scenes[@]}"; do
  IFS='|' read -r name file args ref <<<"$entry"
  for spp in 4 16 64; do
    for sampler in independent sobol; do
      sum=0; rate=0
      for seed in 1 2 3 4; do
        img="$out/$name-$spp-$sampler-$seed.exr"
        # shellcheck disable=SC2086
        line=$("$pcbpt" render "$file" $args --integrator path --spp "$spp" --sampler "$sampler" --seed "$seed" \
          --threads 2 -o "$img" 2>&1 | grep '^rendered:')
        r=$(sed -E 's/.*: ([0-9.]+) M samples\/s.*/\1/' <<<"$line")
        e=$("$pcbpt" compare --json "tests/data/$ref" "$img" | sed -nE 's/.*"relmse": ([0-9.eE+-]+).*/\1/p')
        sum=$(python3 -c "print($sum + $e)"); rate=$(python3 -c "print($rate + $r)")
      done
      python3 -c "import sys; n, spp, s, e, r = sys.argv[1:]; print(f'{n:<12} {int(spp):>3} spp  {s:<11} relMSE {float(e) / 4:.4e}  {float(r) / 4:.3f} M samples/s')" \
        "$name" "$spp" "$sampler" "$sum" "$rate"
    done
  done
done
