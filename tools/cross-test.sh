#!/usr/bin/env bash
# The arm64 cross build in one command (CI runs it from tools/test.sh):
#   1. prepares the cross environment (toolchain/prepare-aarch64.sh; idempotent, needs root/sudo),
#   2. configures and builds the preset `aarch64` (build/aarch64; no benchmarks, no VM tests),
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
# The test recordings are rendered by a native agvloc-desk when there is one (AGV_HOST_DESK,
# default: the default build's): a recording is the same on every architecture, the desk tool is not
# shipped, and rendering under qemu cost minutes. Without one the desk tool is built for arm64 and
# runs emulated, as before.
host_desk="${AGV_HOST_DESK:-$PWD/build/default/firmware/agvloc-desk}"
host_desk_arg=()
if [ -x "$host_desk" ]; then host_desk_arg=(-DAGV_HOST_DESK="$host_desk"); fi
cmake --preset aarch64 -DAGV_BUILD_HIL=OFF -DAGV_BUILD_CAMERA_VM=OFF "${host_desk_arg[@]}"
cmake --build --preset aarch64 -j "$jobs"
step "build"
ctest --preset aarch64 -j "$jobs" -LE "^(hil|vm|interop|calib|sim|mqtt)$"
step "tests"
ls -l build/aarch64/packages/*.deb
