#!/usr/bin/env bash
# Installs what is missing, builds the examples and runs the main demo.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DSBPTT_BUILD_TESTS=OFF >/dev/null
cmake --build build -j "$(nproc)" --target rotation
mkdir -p out
./build/examples/rotation --csv out/rotation.csv
echo "trajectories written to out/rotation.csv"
