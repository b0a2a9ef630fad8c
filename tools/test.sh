#!/usr/bin/env bash
# Installs dependencies, builds and runs every test:
#   1. default preset (g++, warnings as errors): every test, VM tests included
#   2. asan preset (clang ASan + UBSan, -O1): the tests labelled unit, replay, golden, faults and
#      tsan (threaded live loop), then every libFuzzer harness from the same build (fuzz/run.sh)
#   3. tsan preset (clang TSan, -O1): the same tests
#   4. arm64 cross build, tests under qemu-aarch64, .deb package test
# Any sanitizer report fails its test. Prints the wall time of each step; about 33 min on an
# idle 2-core machine (docs/security.md, "Sanitizers in CI").
set -euo pipefail
cd "$(dirname "$0")/.."
jobs="$(nproc)"
t0=$(date +%s)
t_step=$t0
times=()
step() {
  local now
  now=$(date +%s)
  times+=("$(printf '%-28s %5d s' "$1" $(( now - t_step )))")
  echo "test.sh: $1 took $(( now - t_step )) s ($(( now - t0 )) s in all)"
  t_step=$now
}
trap 'printf "%s\n" "${times[@]}"' EXIT

bash tools/install-deps.sh
step "install-deps"
cmake --preset default
cmake --build --preset default -j "$jobs"
step "default: build"
ctest --preset default -j "$jobs"
step "default: ctest"

for preset in asan tsan; do
  cmake --preset "$preset"
  cmake --build --preset "$preset" -j "$jobs"
  step "$preset: build"
  # The test presets select the labels (unit, replay, golden, faults, tsan) and set the
  # sanitizer runtime options.
  ctest --preset "$preset" -j "$jobs"
  step "$preset: ctest"
  if [ "$preset" = asan ]; then
    # Fuzzing (docs/security.md): every harness, built above, on the committed corpus, 35 s each.
    bash fuzz/run.sh "${AGV_FUZZ_SECONDS:-35}"
    step "asan: fuzz/run.sh"
  fi
done

# arm64: cross build, tests under qemu-aarch64, .deb package test (docs/deployment.md)
bash tools/cross-test.sh
step "aarch64: cross-test.sh"
