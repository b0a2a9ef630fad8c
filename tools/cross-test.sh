#!/usr/bin/env bash
# The arm64 cross build in one command (CI runs it from tools/test.sh):
#   1. prepares the cross environment (toolchain/prepare-aarch64.sh; idempotent, needs root/sudo),
#   2. configures and builds the preset `aarch64` (build/aarch64; no benchmarks, no VM tests; the
#      site tracker agvloc-overhead with its replay and bad-input tests only: AGV_OVERHEAD_SMOKE_ONLY),
#   3. runs the tests under qemu-aarch64 (CMAKE_CROSSCOMPILING_EMULATOR), except the labels
#      hil, vm (they boot an x86-64 VM), interop (needs npm tooling), and calib and sim: the desk
#      tool's commissioning and simulator tests (agvloc-desk is not shipped to the vehicle; they
#      run natively and under the sanitizers, and took ~240 s of the emulated run), and mqtt
#      (a mosquitto broker and python clients on the host: docs/guide/vda5050.md),
#   4. the package test (label package) builds the arm64 .deb and runs its binary emulated.
# Prints the time of each step. Environment: AGV_CROSS_JOBS (default nproc).
set -euo pipefail
cd "$(dirname "$0")/.."
jobs="${AGV_CROSS_JOBS:-$(nproc)}"
t0=$(date +%s)
step() { echo "cross-test: $1 done after $(( $(date +%s) - t0 )) s"; }

bash toolchain/prepare-aarch64.sh
step "prepare"
# AGV_HOST_DESK (a native agvloc-desk, e.g. build/default/firmware/agvloc-desk; tools/test.sh sets
# it) renders the test recordings natively instead of under qemu and skips building the desk tool
# for arm64 (CMakeLists.txt): a recording is the same on every architecture, and the desk tool is
# not shipped. Without it the desk tool is cross-built and runs emulated.
host_desk_arg=()
if [ -n "${AGV_HOST_DESK:-}" ]; then host_desk_arg=(-DAGV_HOST_DESK="$AGV_HOST_DESK"); fi
cmake --preset aarch64 -DAGV_BUILD_HIL=OFF -DAGV_BUILD_CAMERA_VM=OFF "${host_desk_arg[@]}"
cmake --build --preset aarch64 -j "$jobs"
step "build"
ctest --preset aarch64 -j "$jobs" -LE "^(hil|vm|interop|calib|sim|mqtt)$"
step "tests"
ls -l build/aarch64/packages/*.deb
