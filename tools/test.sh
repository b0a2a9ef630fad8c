#!/usr/bin/env bash
# Installs dependencies, builds (default preset, warnings as errors) and runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/install-deps.sh
cmake --preset default
cmake --build --preset default -j "$(nproc)"
ctest --preset default -j "$(nproc)"
# arm64: cross build, tests under qemu-aarch64, .deb package test (docs/deployment.md)
bash tools/cross-test.sh
