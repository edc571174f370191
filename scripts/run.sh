#!/usr/bin/env bash
# Installs the dependencies, builds the twin and runs the default scenario
# (the FADAL 2216 pocket corner) into the folder given (default: out).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=RelWithDebInfo
cmake --build build -j"$(nproc)" --target twin
build/bin/twin run -o "${1:-out}"
