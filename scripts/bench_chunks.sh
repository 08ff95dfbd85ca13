#!/usr/bin/env bash
# What cutting a render into chunks costs, through Slurm (BENCHMARKS.md, "Distributed
# renders (Slurm)"):
#
#   cargo build --release
#   scripts/bench_chunks.sh [--chunks "1 2 4"] [--merge-parts "4 16"] [SCENE [render options...]]
#
# Renders SCENE (default: veach-ajar, 480×270, 96 spp, seed 1: about 30 s on 2 threads)
# once in a single process, then as N chunks (each given every CPU of the node, so they run
# one after another) through scripts/slurm/render.sh --wait, and reports for each N: the wall time from
# submission to the merged image; the chunks' CPU time (user + system: what a chunk costs,
# less sensitive than wall time to other work on the machine) against the single process's;
# their loading; the merge; and Slurm's overhead: submission to the merge's end, less the
# chunks' and the merge's wall times. Every merged image is checked against the single
# render (MSE 0). Then `pcbpt merge` alone, on the parts of a 1920×1080 render cut into 4
# and 16 chunks (best of 3): its cost per megapixel and part.
#
# Uses the cluster of $SLURM_CONF if `sinfo` answers, else starts a single-node cluster
# of its own (scripts/slurm/local_cluster.sh; needs root and scripts/setup.sh)
# and stops it at the end. The binary is $PCBPT, else target/release/pcbpt.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
pcbpt=${PCBPT:-$root/target/release/pcbpt}
chunks="1 2 4"
merge_parts="4 16"
while [ $# -gt 0 ]; do
  case "$1" in
    --chunks) chunks=$2; shift 2 ;;
    --merge-parts) merge_parts=$2; shift 2 ;;
    *) break ;;
  esac
done
if [ $# -gt 0 ]; then
  scene=$1
  shift
  opts=("$@")
else
  scene=$root/scenes/veach-ajar/scene.xml
  opts=(-D resx=480 -D resy=270 --spp 96 --seed 1)
fi
[ -x "$pcbpt" ] || { echo "bench_chunks: no $pcbpt (cargo build --release, or set PCBPT)" >&2; exit 1; }
export PCBPT=$pcbpt # for render.sh

work=$(mktemp -d /tmp/pcbpt-bench-chunks.XXXXXX)
chmod 755 "$work" # munged runs as user munge, under it
own_cluster=0
cleanup() {
  if [ "$own_cluster" -eq 1 ]; then "$root/scripts/slurm/local_cluster.sh" stop "$work/cluster" || true; fi
  rm -rf "$work"
}
trap cleanup EXIT
if [ -n "${SLURM_CONF:-}" ] && sinfo -h >/dev/null 2>&1; then
  echo "bench_chunks: using the cluster of $SLURM_CONF" >&2
else
  own_cluster=1
  "$root/scripts/slurm/local_cluster.sh" start "$work/cluster"
  export SLURM_CONF=$work/cluster/slurm.conf
fi
cpus=$(sinfo -h -o %c | head -n 1)

now() { date +%s.%N; }
# awk for the arithmetic (no bc on a minimal system).
calc() { awk "BEGIN { printf \"%.2f\", $* }"; }
# The render's loading time from its summary line: "... in R s (+L s loading) ...".
load_s() { sed -nE 's/.* in [0-9.]+ s \(\+([0-9.]+) s loading\).*/\1/p' "$1" | tail -n 1; }
# The start and end times the job scripts log, and the CPU time (user + system) of their
# `time` line ("...: R s wall, U s user, S s system").
stamp() { sed -nE "s/.*: $2 ([0-9.]+)\$/\\1/p" "$1" | tail -n 1; }
cpu_s() { sed -nE 's/.* s wall, ([0-9.]+) s user, ([0-9.]+) s system$/\1 \2/p' "$1" | tail -n 1 | awk '{ printf "%.2f", $1 + $2 }'; }
same() {
  local mse
  mse=$("$pcbpt" compare "$1" "$2" | sed -nE 's/^MSE +([^ ]+)/\1/p')
  if awk "BEGIN { exit !($mse == 0) }"; then echo yes; else echo "NO (MSE $mse)"; fi
}
TIMEFORMAT="%R s wall, %U s user, %S s system"

echo "# scripts/bench_chunks.sh on $(hostname): $(nproc) CPUs, node of $cpus CPUs, load average $(cut -d' ' -f1-3 /proc/loadavg)"
echo "# scene $scene ${opts[*]}"
echo
{ time "$pcbpt" render "$scene" "${opts[@]}" --threads "$cpus" -o "$work/single.exr" 2>"$work/single.log"; } 2>>"$work/single.log"
single=$(sed -nE 's/^([0-9.]+) s wall.*/\1/p' "$work/single.log")
single_cpu=$(cpu_s "$work/single.log")
echo "single process ($cpus threads): $single s wall, $single_cpu s CPU, loading $(load_s "$work/single.log") s"
echo
echo "| chunks | submit → image (s) | wall vs single | chunks' CPU (s) | CPU vs single | chunks' loading (s) | longest chunk (s) | merge (s) | Slurm's overhead (s) | identical |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for n in $chunks; do
  out=$work/n$n
  t0=$(now)
  "$root/scripts/slurm/render.sh" --wait --cpus "$cpus" "$scene" "$out" "$n" "${opts[@]}" --threads "$cpus" >"$work/ids_$n" 2>"$work/render_$n.log" ||
    { cat "$work/render_$n.log" >&2; exit 1; }
  t1=$(now)
  sum_task=0 sum_cpu=0 sum_load=0 max_task=0
  for log in "$out"/logs/chunk_*.log; do
    task=$(calc "$(stamp "$log" end) - $(stamp "$log" start)")
    sum_task=$(calc "$sum_task + $task")
    sum_cpu=$(calc "$sum_cpu + $(cpu_s "$log")")
    sum_load=$(calc "$sum_load + $(load_s "$log")")
    max_task=$(awk "BEGIN { print ($task > $max_task) ? $task : $max_task }")
  done
  mlog=$(echo "$out"/logs/merge_*.log)
  merge_end=$(stamp "$mlog" end)
  merge=$(calc "$merge_end - $(stamp "$mlog" start)")
  # The node runs one chunk at a time (each has every CPU): what is neither a chunk nor the
  # merge between submission and the merge's end is Slurm's (scheduling, dependency, launch).
  overhead=$(calc "$merge_end - $t0 - $sum_task - $merge")
  echo "| $n | $(calc "$t1 - $t0") | $(calc "($t1 - $t0) / $single")× | $sum_cpu | $(calc "$sum_cpu / $single_cpu")× | $sum_load | $max_task | $merge | $overhead | $(same "$work/single.exr" "$out/image.exr") |"
done

# The merge alone: parts of a 1920×1080 render (cheap: two bounces, one sample per pixel
# and chunk), rendered here without Slurm, merged three times each (the best CPU time).
[ -n "$merge_parts" ] || exit 0
echo
echo "| parts of 1920×1080 | part file (MiB) | merge wall (s) | merge CPU (s) | of which reading (wall, s) | CPU s per megapixel and part |"
echo "|---|---|---|---|---|---|"
big=(-D resx=1920 -D resy=1080 -D max_depth=2 --seed 1)
mp=$(calc "1920 * 1080 / 1e6")
for k in $merge_parts; do
  parts=()
  for ((i = 0; i < k; i++)); do
    "$pcbpt" render "$root/scenes/cornell-box/scene.xml" "${big[@]}" --spp "$k" --chunk "$i/$k" \
      --threads "$(nproc)" --quiet -o "$work/big_${k}_$i.exr"
    parts+=("$work/big_${k}_$i.exr")
  done
  best_cpu=1e9
  for _ in 1 2 3; do
    { time "$pcbpt" merge "${parts[@]}" -o "$work/big_$k.exr" 2>"$work/merge_$k.log"; } 2>>"$work/merge_$k.log"
    c=$(cpu_s "$work/merge_$k.log")
    if awk "BEGIN { exit !($c < $best_cpu) }"; then
      best_cpu=$c
      best_wall=$(sed -nE 's/^([0-9.]+) s wall.*/\1/p' "$work/merge_$k.log")
      reading=$(sed -nE 's/.*\(([0-9.]+) s reading\).*/\1/p' "$work/merge_$k.log")
    fi
  done
  size=$(calc "$(stat -c %s "${parts[0]}") / 1048576")
  echo "| $k | $size | $best_wall | $best_cpu | $reading | $(awk "BEGIN { printf \"%.3f\", $best_cpu / $mp / $k }") |"
  rm -f "${parts[@]}"
done
