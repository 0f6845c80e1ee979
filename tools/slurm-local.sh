#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for the cluster tests (docs/reproduce.md):
# munged, slurmctld and slurmd with the configuration tools/slurm-local.conf, all state,
# spool, pid and log files under one folder (default /tmp/sbptt-slurm; $SBPTT_SLURM_DIR).
#
#   bash tools/slurm-local.sh start    # waits until sinfo shows the node idle (at most 60 s)
#   export SLURM_CONF=/tmp/sbptt-slurm/slurm.conf   # for sbatch, squeue, sinfo, scancel
#   bash tools/slurm-local.sh stop     # stops the three daemons it started (by their pid files)
#
# Runs as root (Debian's Slurm 22.05 without cgroups: proctrack/linuxproc, task/none). Installs
# slurmctld, slurmd, slurm-client and munge when missing (through tools/setup.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${SBPTT_SLURM_DIR:-/tmp/sbptt-slurm}
conf=$dir/slurm.conf

stop() {
  if [ -f "$conf" ]; then
    SLURM_CONF=$conf scancel --full --quiet --user root 2>/dev/null || true
  fi
  for daemon in slurmd slurmctld munged; do
    local pidfile=$dir/$daemon.pid
    [ -f "$pidfile" ] || continue
    local pid
    pid=$(cat "$pidfile")
    if [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; then
      kill "$pid"
      for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
      kill -0 "$pid" 2>/dev/null && kill -9 "$pid"
    fi
    rm -f "$pidfile"
  done
  echo "slurm-local: stopped (logs in $dir)"
}

start() {
  if [ "$(id -u)" != 0 ]; then
    echo "slurm-local: run as root (Slurm's slurmd here runs jobs as any user)" >&2
    exit 1
  fi
  for program in munged slurmctld slurmd sinfo sbatch; do
    command -v "$program" >/dev/null || { bash tools/setup.sh slurmctld slurmd slurm-client munge; break; }
  done
  [ -f "$dir/slurmctld.pid" ] && stop >/dev/null
  rm -rf "$dir"
  mkdir -p "$dir/state" "$dir/spool"
  chmod 700 "$dir"
  # munge: a fresh key and a private socket, so the machine's own munged (if any) is untouched.
  dd if=/dev/urandom of="$dir/munge.key" bs=1024 count=1 status=none
  chmod 400 "$dir/munge.key"
  munged --force --key-file="$dir/munge.key" --socket="$dir/munge.socket" \
    --pid-file="$dir/munged.pid" --log-file="$dir/munged.log" --seed-file="$dir/munged.seed"
  local host cpus memory
  host=$(hostname -s)
  cpus=$(nproc)
  memory=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 / 2 ))
  sed -e "s|@DIR@|$dir|g" -e "s|@HOST@|$host|g" -e "s|@CPUS@|$cpus|g" \
      -e "s|@MEMORY@|$memory|g" -e "s|@CTLD_PORT@|${SBPTT_SLURMCTLD_PORT:-6817}|g" \
      -e "s|@SLURMD_PORT@|${SBPTT_SLURMD_PORT:-6818}|g" tools/slurm-local.conf > "$conf"
  slurmctld -c -f "$conf"
  slurmd -f "$conf"
  for _ in $(seq 600); do
    if [ "$(SLURM_CONF=$conf sinfo -h -o %t 2>/dev/null)" = idle ]; then
      echo "slurm-local: node $host idle ($cpus CPUs); export SLURM_CONF=$conf"
      return 0
    fi
    sleep 0.1
  done
  echo "slurm-local: the node did not become idle within 60 s; sinfo says:" >&2
  SLURM_CONF=$conf sinfo >&2 || true
  tail -n 5 "$dir/slurmctld.log" "$dir/slurmd.log" "$dir/munged.log" >&2 || true
  stop >&2
  exit 1
}

case "${1:-}" in
  start) start ;;
  stop) stop ;;
  *) echo "usage: bash tools/slurm-local.sh start|stop" >&2; exit 2 ;;
esac
