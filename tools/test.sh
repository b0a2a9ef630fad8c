#!/usr/bin/env bash
# Installs dependencies, builds (default preset, warnings as errors) and runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/install-deps.sh
cmake --preset default
cmake --build --preset default -j "$(nproc)"
ctest --preset default -j "$(nproc)"
# Fuzzing (docs/security.md): every libFuzzer harness under ASan + UBSan on the committed corpus,
# 35 s each (9-10 min with the build on 2 cores, docs/security.md); fails on any finding.
bash fuzz/run.sh "${AGV_FUZZ_SECONDS:-35}"
# arm64: cross build, tests under qemu-aarch64, .deb package test (docs/deployment.md)
bash tools/cross-test.sh
