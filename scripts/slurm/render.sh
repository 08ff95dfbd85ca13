#!/usr/bin/env bash
# Renders SCENE across a Slurm cluster: a job array of N tasks, task I rendering chunk I of
# N of the render's iterations (chunk.sbatch), then a merge job that waits for the whole
# array to succeed (--dependency=afterok) and writes the image (merge.sbatch). The image is
# the one `pcbpt render SCENE [render options...]` would write, bit for bit (PSSMLT's
# converges to it).
#
#   scripts/slurm/render.sh [--wait] [--cpus C] [--max-running K] [--output FILE]
#                           SCENE OUTDIR N [render options...]
#
# OUTDIR (created) must be on a filesystem every node sees: it receives the parts
# part_I.exr, the logs logs/chunk_<job>_<I>.log and logs/merge_<job>.log, and the image
# (OUTDIR/image.exr unless --output; .png works too). Render options are the same as a
# single render's, with a sample budget (--spp; --time cannot be cut into chunks).
#   --cpus C         CPUs per chunk task (default 1); the render uses them all (--threads C)
#   --max-running K  at most K chunk tasks at a time (the array's %K)
#   --wait           wait for the merge; exit non-zero (with the failed tasks' logs) if a
#                    chunk or the merge failed
# The pcbpt binary is $PCBPT, else the one on PATH; it must be at the same path on the
# nodes. Other sbatch settings come from sbatch's own environment variables
# (SBATCH_PARTITION, SBATCH_TIMELIMIT, SBATCH_ACCOUNT, ...).
#
# Prints the job ids on stdout, one per line: `chunks ARRAY_JOB_ID` and `merge MERGE_JOB_ID`.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
usage() {
  echo "usage: $0 [--wait] [--cpus C] [--max-running K] [--output FILE] SCENE OUTDIR N [render options...]" >&2
  exit 2
}

wait=0 cpus=1 max_running="" output=""
while [ $# -gt 0 ]; do
  case "$1" in
    --wait) wait=1; shift ;;
    --cpus) cpus=${2:?}; shift 2 ;;
    --max-running) max_running=${2:?}; shift 2 ;;
    --output) output=${2:?}; shift 2 ;;
    -h | --help) usage ;;
    --*) echo "render.sh: unknown option $1" >&2; usage ;;
    *) break ;;
  esac
done
[ $# -ge 3 ] || usage
scene=$1 outdir=$2 n=$3
shift 3
[[ "$n" =~ ^[1-9][0-9]*$ ]] || { echo "render.sh: N must be a positive integer, not '$n'" >&2; exit 2; }
[ -f "$scene" ] || { echo "render.sh: no scene file $scene" >&2; exit 2; }

pcbpt=${PCBPT:-$(command -v pcbpt || true)}
if [ -z "$pcbpt" ] || [ ! -x "$pcbpt" ]; then echo "render.sh: no pcbpt binary (set PCBPT or put pcbpt on PATH)" >&2; exit 2; fi

# Jobs run elsewhere: hand them absolute paths.
mkdir -p "$outdir/logs"
outdir=$(cd "$outdir" && pwd)
scene=$(cd "$(dirname "$scene")" && pwd)/$(basename "$scene")
pcbpt=$(cd "$(dirname "$pcbpt")" && pwd)/$(basename "$pcbpt")
output=${output:-$outdir/image.exr}
case "$output" in /*) ;; *) output=$PWD/$output ;; esac
# Parts of an earlier render in the same folder must not be merged into this one.
rm -f "$outdir"/part_*.exr

array=0-$((n - 1))${max_running:+%$max_running}
chunks=$(sbatch --parsable --array="$array" --cpus-per-task="$cpus" \
  --output="$outdir/logs/chunk_%A_%a.log" \
  "$here/chunk.sbatch" "$pcbpt" "$scene" "$outdir" "$n" "$@")
chunks=${chunks%%;*} # --parsable prints "id" or "id;cluster"
# The merge runs only if every chunk succeeded; otherwise Slurm cancels it.
merge=$(sbatch --parsable --dependency="afterok:$chunks" --kill-on-invalid-dep=yes \
  --output="$outdir/logs/merge_%j.log" \
  "$here/merge.sbatch" "$pcbpt" "$outdir" "$n" "$output")
merge=${merge%%;*}
echo "chunks $chunks"
echo "merge $merge"
[ "$wait" -eq 1 ] || exit 0

# Poll the merge job (sbatch --wait polls at growing intervals of up to 32 s).
state=""
while :; do
  state=$(scontrol -o show job "$merge" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | cut -d= -f2 || true)
  case "$state" in
    PENDING | RUNNING | CONFIGURING | COMPLETING | REQUEUED | RESIZING | SUSPENDED) sleep 1 ;;
    *) break ;;
  esac
done
if [ "$state" = COMPLETED ]; then
  echo "render.sh: wrote $output" >&2
  exit 0
fi
echo "render.sh: merge job $merge ended ${state:-(no longer known to slurmctld)}" >&2
# Name the chunks that did not complete, in order, with the end of the first three logs.
shown=0
while read -r task line; do
  st=$(grep -o 'JobState=[^ ]*' <<<"$line" | cut -d= -f2)
  [ "$st" = COMPLETED ] && continue
  log=$(grep -o 'StdOut=[^ ]*' <<<"$line" | cut -d= -f2)
  echo "render.sh: chunk $task: $st ($(grep -o 'ExitCode=[^ ]*' <<<"$line")), log $log" >&2
  if [ "$shown" -lt 3 ] && [ -s "$log" ]; then
    tail -n 20 "$log" >&2
    shown=$((shown + 1))
  fi
done < <(scontrol -o show job "$chunks" 2>/dev/null | sed -E 's/.*ArrayTaskId=([^ ]*).*/\1 &/' | sort -n)
log="$outdir/logs/merge_$merge.log"
if [ -s "$log" ]; then
  echo "render.sh: merge log $log:" >&2
  tail -n 20 "$log" >&2
fi
exit 1
