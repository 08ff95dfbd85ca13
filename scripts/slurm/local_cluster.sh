#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, without systemd, for tests and benchmarks
# (tests/slurm.rs, scripts/bench_chunks.sh) or to try scripts/slurm/render.sh:
#
#   scripts/slurm/local_cluster.sh start DIR   # then: export SLURM_CONF=DIR/slurm.conf
#   scripts/slurm/local_cluster.sh stop DIR
#
# `start` generates a MUNGE key in DIR, runs munged as user munge on a socket in DIR, writes
# DIR/slurm.conf (state, spool, logs and pids under DIR, free ports, the node as
# `slurmd -C` sees it; process tracking and task launch that need no cgroups) and runs
# slurmctld and slurmd, each in the foreground of a background process whose PID goes to
# DIR/pids/NAME; it returns once the node is idle. `stop` cancels the cluster's jobs and
# stops the daemons by those PIDs. Needs root (munged runs as munge, slurmd launches jobs)
# and `scripts/setup.sh`. Nothing outside DIR is written.
set -euo pipefail
export PATH=$PATH:/usr/sbin:/sbin

usage() { echo "usage: $0 start|stop DIR" >&2; exit 2; }
[ $# -eq 2 ] || usage
cmd=$1
mkdir -p "$2"
dir=$(cd "$2" && pwd)
export SLURM_CONF=$dir/slurm.conf

# Whether PID is a live (not zombie) process named NAME (a PID of a process gone long ago
# may have been reused by another).
alive() {
  [ "$(cat "/proc/$1/comm" 2>/dev/null)" = "$2" ] && ! grep -q '^State:.*Z' "/proc/$1/status" 2>/dev/null
}

# Stops the daemon whose PID is in DIR/pids/NAME: SIGTERM, then SIGKILL after 10 s.
stop_daemon() {
  local name=$1 pidfile=$dir/pids/$1 pid
  [ -f "$pidfile" ] || return 0
  pid=$(cat "$pidfile")
  if alive "$pid" "$name"; then
    kill -TERM "$pid" 2>/dev/null || true
    for _ in $(seq 100); do
      alive "$pid" "$name" || break
      sleep 0.1
    done
    if alive "$pid" "$name"; then
      echo "local_cluster: $name ($pid) ignored SIGTERM; killing it" >&2
      kill -KILL "$pid" 2>/dev/null || true
    fi
  fi
  rm -f "$pidfile"
}

stop() {
  # Cancel what is still queued or running, so that slurmd ends the jobs' processes.
  if [ -f "$dir/pids/slurmctld" ] && jobs=$(timeout 10 squeue -h -o %A 2>/dev/null) && [ -n "$jobs" ]; then
    # shellcheck disable=SC2086
    timeout 10 scancel $jobs 2>/dev/null || true
    for _ in $(seq 50); do
      [ -z "$(timeout 10 squeue -h -o %A 2>/dev/null)" ] && break
      sleep 0.2
    done
  fi
  stop_daemon slurmd
  stop_daemon slurmctld
  stop_daemon munged
}

fail() {
  echo "local_cluster: $*" >&2
  for log in "$dir"/log/*; do
    [ -s "$log" ] && { echo "--- $log" >&2; tail -n 30 "$log" >&2; }
  done
  stop
  exit 1
}

# Waits up to 30 s for a command to succeed, checking that the daemon NAME still runs.
wait_for() {
  local name=$1
  shift
  for _ in $(seq 150); do
    "$@" >/dev/null 2>&1 && return 0
    alive "$(cat "$dir/pids/$name")" "$name" || fail "$name exited"
    sleep 0.2
  done
  fail "timed out waiting for: $*"
}

# A TCP port nothing listens on (bash's /dev/tcp connects or is refused).
free_port() {
  local p
  while :; do
    p=$((20000 + RANDOM % 20000))
    (echo >"/dev/tcp/127.0.0.1/$p") 2>/dev/null || { echo "$p"; return; }
  done
}

case "$cmd" in
  stop) stop; exit 0 ;;
  start) ;;
  *) usage ;;
esac

[ "$(id -u)" -eq 0 ] || { echo "local_cluster: needs root (munged runs as user munge, slurmd launches the jobs)" >&2; exit 1; }
for b in munged mungekey munge slurmctld slurmd sbatch sinfo squeue scancel setpriv; do
  command -v "$b" >/dev/null || { echo "local_cluster: $b not found; run scripts/setup.sh" >&2; exit 1; }
done
id munge >/dev/null 2>&1 || { echo "local_cluster: no user munge; run scripts/setup.sh" >&2; exit 1; }
[ ! -f "$dir/pids/slurmctld" ] || { echo "local_cluster: $dir holds a cluster already (stop it first)" >&2; exit 1; }

mkdir -p "$dir/munge" "$dir/state" "$dir/spool" "$dir/log" "$dir/pids"
# munged checks that the key and the folders on the way to its socket belong to it or to
# root and are not writable by others; clients (Slurm, as root) must reach the socket.
chmod 755 "$dir"
chown munge:munge "$dir/munge"
chmod 755 "$dir/munge"
rm -f "$dir/munge/munge.key"
mungekey --create --keyfile="$dir/munge/munge.key"
chown munge:munge "$dir/munge/munge.key"
chmod 600 "$dir/munge/munge.key"
setpriv --reuid=munge --regid=munge --clear-groups test -r "$dir/munge/munge.key" ||
  fail "user munge cannot reach $dir/munge: the folders above $dir must be searchable by others (chmod o+x)"

socket=$dir/munge/munge.socket
setpriv --reuid=munge --regid=munge --clear-groups munged --foreground \
  --key-file="$dir/munge/munge.key" --socket="$socket" --pid-file="$dir/munge/munged.pid" \
  --seed-file="$dir/munge/munged.seed" --log-file="$dir/munge/munged.log" \
  >"$dir/log/munged.log" 2>&1 </dev/null &
echo $! >"$dir/pids/munged"
wait_for munged munge --socket="$socket" --no-input

host=$(hostname -s)
node=$(slurmd -C | grep '^NodeName=')
cat >"$SLURM_CONF" <<CONF
# Written by scripts/slurm/local_cluster.sh: one node, everything under $dir.
ClusterName=pcbpt-local
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$(free_port)
SlurmdPort=$(free_port)
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$socket
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/state/slurmctld.pid
SlurmdPidFile=$dir/spool/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
MailProg=/bin/true
# No cgroups needed: processes tracked by parentage, tasks launched without binding.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
# Schedule every second (the defaults wait up to a minute for a dependent job).
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=1,bf_interval=1
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
$node NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=local Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF

slurmctld -D -i -f "$SLURM_CONF" >"$dir/log/slurmctld.stderr" 2>&1 </dev/null &
echo $! >"$dir/pids/slurmctld"
slurmd -D -N "$host" -f "$SLURM_CONF" >"$dir/log/slurmd.stderr" 2>&1 </dev/null &
echo $! >"$dir/pids/slurmd"
idle() { [ "$(sinfo -h -o %t)" = idle ]; }
wait_for slurmd idle
alive "$(cat "$dir/pids/slurmctld")" slurmctld || fail "slurmctld exited"
echo "local_cluster: $(sinfo -h -o '%D node (%c CPUs) %t') on $host; export SLURM_CONF=$SLURM_CONF" >&2
