#!/usr/bin/env bash
# Installs what is missing, builds with warnings as errors, and runs the test suite.
#   bash tools/test.sh          default suite (everything not tagged [slow])
#   bash tools/test.sh --slow   only the slow checks (not the cluster tests)
#   bash tools/test.sh --cluster  only the tests against GNU parallel and a local Slurm cluster
#                                (tests/reproduce_cluster.sh; as root)
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
label=(-LE slow)
[ "${1:-}" = "--slow" ] && label=(-L slow -LE cluster)
[ "${1:-}" = "--cluster" ] && label=(-L cluster)
build=${SBPTT_BUILD_DIR:-build}
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DSBPTT_WERROR=ON -DSBPTT_BUILD_TESTS=ON \
  -DSBPTT_BUILD_EXAMPLES=ON ${SBPTT_CMAKE_ARGS:-} >/dev/null
cmake --build "$build" -j "$(nproc)"
ctest --test-dir "$build" "${label[@]}" --output-on-failure -j "$(nproc)"
