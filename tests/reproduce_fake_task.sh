#!/bin/sh
# A fake task program for the runner's tests (reproduce_*.cmake): it keeps the task-program
# contract (the flags, the training log rewritten atomically after every epoch, exit 0 or 3).
# Deterministic losses from the flags; the seconds column depends on the process id, so the
# timing columns differ between sweeps (and must be left out of comparisons). Method R with
# seed 43 "diverges": two epochs, exit 3. It notes every start and its pid in the out dir.
# When a file `checkpoints` sits beside it, its --help lists --checkpoint FILE, which it then
# keeps like the real programs: after every epoch, the epoch and the log's length; a restart
# cuts the log (which must still be there, at least that long; else exit 1 like the real
# programs) back to that length and resumes after that epoch (noted in fake_resumes). A file
# `stop_<run name>` in the out dir holding an exit code makes the run end with it after its
# epoch (the file removed): a task program stopped by a signal it answers exits 128 + it. Its
# mask of ignored signals (SigIgn of /proc) goes to fake_ignored_signals.
task=$(basename "$0")
csv= epochs=1 seed=0 method= clip= complexity= threads=1 checkpoint=
if [ "${1:-}" = --help ]; then
  flags="--csv FILE, --threads N, --epochs N, --seed N, --method M, --clip C, --samples N"
  [ -f "$(dirname "$0")/checkpoints" ] && flags="$flags, --checkpoint FILE"
  echo "usage: $task [flags]"
  echo "flags: $flags"
  exit 0
fi
while [ $# -gt 0 ]; do
  case "$1" in
    --csv) csv=$2; shift 2 ;;
    --checkpoint) checkpoint=$2; shift 2 ;;
    --threads) threads=$2; shift 2 ;;
    --epochs) epochs=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --method) method=$2; shift 2 ;;
    --clip) clip=$2; shift 2 ;;
    --model) shift 2 ;;
    --poles|--rc|--target|--samples) [ "$1" = --samples ] || complexity=$2; shift 2 ;;
    *) echo "$task: unknown flag '$1'" >&2; exit 2 ;;
  esac
done
[ -n "$csv" ] || { echo "$task: no --csv" >&2; exit 2; }
out=$(dirname "$(dirname "$csv")")
name=$(basename "$csv" .partial.csv)
echo "$$" >> "$out/fake_pids"
echo "$name" >> "$out/fake_invocations"
echo "$name $threads" >> "$out/fake_threads"
while read -r key value; do
  [ "$key" = SigIgn: ] && echo "$name $value" >> "$out/fake_ignored_signals"
done < "/proc/$$/status"
stop=$epochs
[ "$method" = R ] && [ "$seed" = 43 ] && stop=2
e=1
if [ -n "$checkpoint" ] && [ -f "$checkpoint" ]; then
  read -r resumed lines < "$checkpoint"
  if [ ! -f "$csv" ] || [ "$(wc -l < "$csv")" -lt "$lines" ]; then
    echo "$task: training log '$csv' is shorter than checkpoint '$checkpoint' expects" >&2
    exit 1
  fi
  head -n "$lines" "$csv" > "$csv.rows"
  cp "$csv.rows" "$csv.tmp.$$" && mv "$csv.tmp.$$" "$csv"
  echo "$task: resuming after epoch $resumed from checkpoint '$checkpoint'"
  echo "$name $resumed" >> "$out/fake_resumes"
  e=$((resumed + 1))
else
  echo "epoch,batch_loss,train_loss,test_loss,update_norm2,cos_m_r,agree_fraction,seconds" > "$csv.rows"
fi
while [ "$e" -le "$stop" ]; do
  awk -v e="$e" -v s="$seed" -v m="$method" -v c="$complexity" -v p="$$" 'BEGIN {
    f = (m == "R") ? 1.0 : (m == "M") ? 0.8 : (m == "C") ? 0.5 : 1.5
    loss = f * (1 + c) / (e + s - 41)
    cosine = (m == "C") ? "0.25" : ""
    agree = (m == "C") ? "0.75" : ""
    printf "%d,%.17g,%.17g,%.17g,%.9g,%s,%s,%.6f\n", e, 1.1 * loss, 1.05 * loss, loss,
           loss * loss, cosine, agree, 0.01 + (p % 97) / 1000.0 }' >> "$csv.rows"
  cp "$csv.rows" "$csv.tmp.$$" && mv "$csv.tmp.$$" "$csv"
  if [ -n "$checkpoint" ]; then
    echo "$e $((e + 1))" > "$checkpoint.tmp.$$" && mv "$checkpoint.tmp.$$" "$checkpoint"
  fi
  echo "$task: epoch $e"
  if [ -f "$out/stop_$name" ]; then
    code=$(cat "$out/stop_$name"); rm -f "$out/stop_$name"; exit "$code"
  fi
  sleep 0.12
  e=$((e + 1))
done
rm -f "$csv.rows"
[ "$stop" -lt "$epochs" ] && exit 3
exit 0
