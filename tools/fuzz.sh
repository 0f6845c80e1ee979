#!/usr/bin/env bash
# Builds the libFuzzer targets of the file parsers (tests/fuzz/) with clang and fuzzes each
# for a fixed time, starting from the checked-in corpus. Exits non-zero on a crash, a
# sanitizer report or a broken invariant; the reproducer is left in <build>/fuzz/artifacts/.
# Installs clang and its runtime libraries (libFuzzer, sanitizers) if they are missing.
#   bash tools/fuzz.sh                 60 s per target, targets in parallel ($SBPTT_JOBS)
#   bash tools/fuzz.sh 300             300 s per target
#   SBPTT_FUZZ_SECONDS=10 bash tools/fuzz.sh
#   FUZZ_CXX=clang++-15 bash tools/fuzz.sh   another clang (its runtime must be installed)
# Reproduce a finding: <build>/tests/fuzz/fuzz_states <build>/fuzz/artifacts/crash-...
#
# New inputs libFuzzer finds go to <build>/fuzz/corpus/<target>/, never into the source
# tree; copy an interesting one into tests/fuzz/corpus/<target>/ by hand to keep it.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
seconds=${1:-${SBPTT_FUZZ_SECONDS:-60}}
jobs=${SBPTT_JOBS:-$(nproc)}
build=${SBPTT_BUILD_DIR:-build-fuzz}
cxx=${FUZZ_CXX:-clang++-14}
if [ -z "${FUZZ_CXX:-}" ]; then bash tools/setup.sh clang-14 libclang-rt-14-dev; else bash tools/setup.sh; fi

cmake -S . -B "$build" -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" \
  -DSBPTT_FUZZ=ON -DSBPTT_BUILD_TESTS=OFF -DSBPTT_BUILD_EXAMPLES=OFF >/dev/null
targets=(fuzz_parameters fuzz_states fuzz_checkpoint)
cmake --build "$build" -j "$jobs" --target "${targets[@]}"

export ASAN_OPTIONS="detect_leaks=1:abort_on_error=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
mkdir -p "$build/fuzz/artifacts"
run() {  # run <target>: fuzz one target for $seconds, log to <build>/fuzz/<target>.log
  local target=$1 name=${1#fuzz_}
  # A checkpoint holds the shuffling generator's 313 numbers (about 6.5 KB) before the rest.
  local max_len=4096
  [ "$name" = checkpoint ] && max_len=16384
  mkdir -p "$build/fuzz/corpus/$name"
  "$build/tests/fuzz/$target" "$build/fuzz/corpus/$name" "$root/tests/fuzz/corpus/$name" \
    -dict="$root/tests/fuzz/numbers.dict" -max_total_time="$seconds" -timeout=10 \
    -max_len="$max_len" -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$build/fuzz/artifacts/$target-" >"$build/fuzz/$target.log" 2>&1
}

status=0
failed=""
if [ "$jobs" -gt 1 ]; then
  pids=()
  for t in "${targets[@]}"; do run "$t" & pids+=($!); done
  for i in "${!targets[@]}"; do
    wait "${pids[$i]}" || { status=1; failed+=" ${targets[$i]}"; }
  done
else
  for t in "${targets[@]}"; do run "$t" || { status=1; failed+=" $t"; }; done
fi

for t in "${targets[@]}"; do
  summary=$(grep -E '^(stat::number_of_executed_units|stat::new_units_added|#[0-9]+ +DONE)' \
            "$build/fuzz/$t.log" | tr -s ' \n' ' ' || true)
  echo "fuzz: $t: ${summary:-no summary}"
done
if [ "$status" -ne 0 ]; then
  for t in $failed; do
    echo "===== $t: last lines of $build/fuzz/$t.log" >&2
    tail -n 60 "$build/fuzz/$t.log" >&2
  done
  echo "fuzz: FAILED:$failed (reproducers in $build/fuzz/artifacts/)" >&2
  exit 1
fi
echo "fuzz: no finding in ${seconds} s per target"
