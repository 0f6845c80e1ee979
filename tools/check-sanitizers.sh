#!/usr/bin/env bash
# Builds the default test suite with AddressSanitizer (+ LeakSanitizer) and
# UndefinedBehaviorSanitizer and runs it (`ctest -LE slow`). Any sanitizer report fails the run.
#   bash tools/check-sanitizers.sh                      clang++-14, build dir build-asan
#   SANITIZE_CXX=g++ SBPTT_BUILD_DIR=build-asan-gcc bash tools/check-sanitizers.sh
#
# Compiler: clang by default (installed if missing, with its sanitizer runtimes): it builds
# this instrumented code about 1.5x faster than GCC, which matters for CI's time budget, and it
# gives the suite a second compiler next to tools/test.sh's GCC. Both work.
# Build: -O1 with line tables and *without* NDEBUG, so Eigen's own bounds and size assertions
# are live too (a Release build compiles them out). UBSan is made fatal at compile time
# (-fno-sanitize-recover=all) and at run time (halt_on_error=1). Warnings are not errors here
# (tools/test.sh builds with -Werror already; GCC's -Wmaybe-uninitialized is unreliable on
# instrumented code, e.g. a false positive on std::visit over nn::Layer).
# Tests: one program per layer (SBPTT_GROUPED_TESTS; docs/testing.md gives the time it saves);
# tools/test.sh keeps one program per file, so every test file still compiles on its own there.
# The test programs whose cases run briefly even unoptimised are compiled at -O0, which builds
# them in about a third of the time (SBPTT_UNOPTIMIZED_TESTS; the measured choice is in
# docs/testing.md); the others and the examples, which the tests run at length, stay at -O1.
# The programs of [slow] cases alone are not built (SBPTT_SLOW_TESTS=OFF): only the default
# suite runs here. The network kernels are compiled once (SBPTT_SEPARATE_KERNELS), not once in
# each program (but the test files that #define a macro before the headers).
# The package tests (package_consumer, install_without_tests), which build projects of their own
# with the default compiler and flags, are left to tools/test.sh (tests/CMakeLists.txt).
set -euo pipefail
cd "$(dirname "$0")/.."
build=${SBPTT_BUILD_DIR:-build-asan}
jobs=${SBPTT_JOBS:-$(nproc)}
cxx=${SANITIZE_CXX:-clang++-14}
if [ -z "${SANITIZE_CXX:-}" ]; then bash tools/setup.sh clang-14 libclang-rt-14-dev; else bash tools/setup.sh; fi

unoptimized="tests_core;tests_sim;tests_bptt;tests_train;test_sim_mujoco;test_nn_no_malloc"
unoptimized+=";test_bptt_no_malloc"
cmake -S . -B "$build" -DCMAKE_CXX_COMPILER="$cxx" \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" \
  -DCMAKE_CXX_FLAGS="-fno-sanitize-recover=all" \
  -DSBPTT_SANITIZE="address;undefined" \
  -DSBPTT_WERROR=OFF \
  -DSBPTT_GROUPED_TESTS=ON \
  -DSBPTT_SLOW_TESTS=OFF \
  -DSBPTT_UNOPTIMIZED_TESTS="$unoptimized" \
  -DSBPTT_SEPARATE_KERNELS=ON \
  -DSBPTT_BUILD_EXAMPLES=ON >/dev/null
cmake --build "$build" -j "$jobs"

export ASAN_OPTIONS="detect_leaks=1:abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1:check_initialization_order=1:strict_init_order=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
ctest --test-dir "$build" -LE slow --output-on-failure -j "$jobs"
