#!/usr/bin/env bash
# Installs what is missing, builds with warnings as errors, and runs the test suite.
#   bash tools/test.sh          default suite (everything not tagged [slow])
#   bash tools/test.sh --slow   only the slow checks
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
label=(-LE slow)
[ "${1:-}" = "--slow" ] && label=(-L slow)
build=${SBPTT_BUILD_DIR:-build}
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DSBPTT_WERROR=ON -DSBPTT_BUILD_TESTS=ON \
  -DSBPTT_BUILD_EXAMPLES=ON ${SBPTT_CMAKE_ARGS:-} >/dev/null
cmake --build "$build" -j "$(nproc)"
ctest --test-dir "$build" "${label[@]}" --output-on-failure -j "$(nproc)"
