#!/usr/bin/env bash
# The runner's executors against the real engines (ctest label `cluster`, run by .ci/run, not
# by the default suite): one small grid of the real task programs (cart pole 1 pole and
# guidance rc 1, methods R and C, seeds 42 and 43, 3 epochs of 8 samples: 8 runs) run
#   (a) locally with --jobs 2,
#   (b) through GNU parallel (--emit parallel | parallel --jobs 2, then --merge),
#   (c) as a Slurm job array with its dependent merge job, on a single-node Slurm cluster
#       started by tools/slurm-local.sh (and stopped on any exit, failures included), in an
#       output folder whose name holds blanks and quotes,
#   (d) as 3 shards at once, then --merge;
# every summary.csv must have the same loss columns. Then (e) an array task cancelled with
# scancel while its run is under way, and the array resubmitted: the run resumes from its
# checkpoint (when the task programs have --checkpoint; else it is redone) and the losses are
# those of an uninterrupted run.
#   bash tests/reproduce_cluster.sh <build/examples> <scratch dir>
set -euo pipefail
# One cluster test at a time on a machine: the Slurm daemons listen on fixed ports.
exec 9> /tmp/sbptt-cluster-test.lock
flock 9
examples=$(cd "$1" && pwd)
work=$2
root=$(cd "$(dirname "$0")/.." && pwd)
R=$examples/reproduce
rm -rf "$work"
mkdir -p "$work"
grid=(--tasks cartpole,guidance --complexities 1 --methods R,C --clips norm --seeds 2 --epochs 3
      --samples 8 --no-plot)

fail() { echo "FAILED: $*" >&2; exit 1; }
ok() { echo "ok: $*"; }
# The loss columns (and labels, epochs, status) of a summary: everything but the two timings.
losses() { cut -d, -f1-9,12,13 "$1/summary.csv"; }

# (a) local
"$R" "${grid[@]}" --jobs 2 --out "$work/local" > "$work/local.log" 2>&1 || fail "local sweep"
[ "$(wc -l < "$work/local/summary.csv")" = 9 ] || fail "local summary has not 8 rows"
losses "$work/local" > "$work/reference"
ok "local sweep: 8 runs"

# (b) GNU parallel
command -v parallel >/dev/null || bash "$root/tools/setup.sh" parallel
"$R" "${grid[@]}" --out "$work/parallel" --emit parallel > "$work/parallel.commands"
[ "$(wc -l < "$work/parallel.commands")" = 8 ] || fail "--emit parallel printed not 8 lines"
parallel --will-cite --jobs 2 < "$work/parallel.commands" > "$work/parallel.log" 2>&1 \
  || fail "GNU parallel ran a command that failed (see $work/parallel.log)"
"$R" "${grid[@]}" --out "$work/parallel" --merge > "$work/parallel.merge" 2>&1 || fail "merge (b)"
losses "$work/parallel" | cmp -s - "$work/reference" || fail "GNU parallel: other losses"
ok "GNU parallel: the local losses"

# (c) Slurm: a job array and its merge job
export SBPTT_SLURM_DIR=$work/slurm-cluster
trap 'bash "$root/tools/slurm-local.sh" stop > /dev/null 2>&1 || true' EXIT
bash "$root/tools/slurm-local.sh" start
export SLURM_CONF=$SBPTT_SLURM_DIR/slurm.conf
wait_for_jobs() {  # until squeue lists none of the jobs, at most $1 s
  for _ in $(seq $(($1 * 4))); do
    [ -z "$(squeue -h -o %i)" ] && return 0
    sleep 0.25
  done
  squeue >&2
  fail "Slurm jobs still queued after $1 s"
}
# A folder whose name sbatch must read through its own quoting rules in #SBATCH lines.
slurm_out="$work/slurm runs, Bob's \"x\""
"$R" "${grid[@]}" --jobs 2 --out "$slurm_out" --emit slurm > "$work/slurm.emit"
submit=$(grep '^job=\$(sbatch' "$work/slurm.emit") || fail "--emit slurm printed no sbatch line"
(cd "$work" && bash -c "$submit") > /dev/null || fail "sbatch refused the emitted scripts"
wait_for_jobs 180
grep -q "8 of 8 planned runs done, 0 running (lock held), 0 missing" \
  "$slurm_out"/slurm/logs/merge_*.log || fail "the merge job did not find all 8 runs done"
[ "$(ls "$slurm_out/slurm/logs" | grep -c '^run_.*\.log$')" = 8 ] || fail "not a log per task"
losses "$slurm_out" | cmp -s - "$work/reference" || fail "Slurm: other losses"
ok "Slurm job array + merge job, a folder with blanks and quotes: the local losses, a log per task"

# (d) three shards at once
for k in 1 2 3; do
  "$R" "${grid[@]}" --jobs 1 --shard "$k/3" --out "$work/shards" > "$work/shard$k.log" 2>&1 &
done
wait
"$R" "${grid[@]}" --out "$work/shards" --merge > "$work/shards.merge" 2>&1 || fail "merge (d)"
losses "$work/shards" | cmp -s - "$work/reference" || fail "shards: other losses"
ok "3 shards: the local losses"

# (e) scancel mid-run, resubmit: a longer run (200 epochs), cancelled once its training log
# has rows, is redone by the resubmitted array and gives the same losses as run uninterrupted.
long=(--tasks cartpole --complexities 1 --methods C --clips norm --seeds 1 --epochs 200
      --samples 8 --no-plot)
"$R" "${long[@]}" --out "$work/long-local" > /dev/null 2>&1 || fail "long local run"
"$R" "${long[@]}" --jobs 1 --out "$work/long" --emit slurm > /dev/null
job=$(sbatch --parsable "$work/long/slurm/array.sh")
partial=$work/long/runs/cartpole_p1_C_norm_s42.partial.csv
checkpoint=$work/long/runs/cartpole_p1_C_norm_s42.checkpoint
logged() { [ -f "$partial" ] && [ "$(wc -l < "$partial")" -ge "$1" ]; }
# Cancelled after a few epochs: with checkpoints, after the first one is written.
for _ in $(seq 600); do
  logged 4 && { [ -f "$checkpoint" ] || ! "$examples/cartpole" --help | grep -q -- "--checkpoint "; } && break
  sleep 0.1
done
logged 4 || fail "the array task never logged 3 epochs"
scancel "${job%%;*}"
wait_for_jobs 60
[ ! -f "$work/long/runs/cartpole_p1_C_norm_s42.csv" ] || fail "the cancelled run counts as finished"
ok "scancel stopped the run after $(($(wc -l < "$partial") - 1)) epochs"
"$R" "${long[@]}" --jobs 1 --out "$work/long" --emit slurm > "$work/long.emit"
sbatch "$work/long/slurm/array.sh" > /dev/null
wait_for_jobs 180
"$R" "${long[@]}" --out "$work/long" --merge > /dev/null 2>&1 || fail "the resubmitted run did not finish"
cmp -s <(losses "$work/long") <(losses "$work/long-local") || fail "resubmitted: other losses"
ok "cancelled and resubmitted: the uninterrupted losses"
if "$examples/cartpole" --help | grep -q -- "--checkpoint "; then
  grep -q "resuming after epoch" "$work/long/runs/cartpole_p1_C_norm_s42.log" \
    || fail "the resubmitted run did not resume from its checkpoint"
  ok "the resubmitted run resumed from its checkpoint"
else
  echo "note: the task programs have no --checkpoint yet; the cancelled run was redone"
fi
echo "reproduce_cluster: all checks passed"
