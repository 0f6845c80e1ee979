#!/usr/bin/env bash
# Installs what is missing, builds, and runs the main demo: the quick profile of the paper's
# three experiments (about 10 minutes on 2 cores), then prints the results table and where the
# plots are. A second call resumes: finished runs are not redone.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
# Only the programs are built; the test options stay as a previous tools/test.sh left them.
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j "$(nproc)" --target reproduce toy cartpole guidance quantum rotation
./build/examples/reproduce --profile quick --jobs "$(nproc)" --out out/quick "$@"
