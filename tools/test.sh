#!/usr/bin/env bash
# Installs dependencies, builds and runs every test:
#   1. default preset (g++, warnings as errors): every test. The VM tests (labels hil and vm: one
#      emulated machine at a time, one core, ~430 s in all) run in the background from here on,
#      beside the sanitizer jobs, instead of alone at the end of the default ctest with the second
#      core idle; they are built to pass on a loaded machine (docs/design/hil.md). Their log is printed
#      when they end; a test that failed there runs again alone, and a failure alone fails the
#      script.
#   2. asan preset (clang ASan + UBSan, -O1): the tests labelled unit, replay, golden, faults and
#      tsan (threaded live loop), then every libFuzzer harness from the same build (fuzz/run.sh)
#   3. tsan preset (clang TSan, -O1): the code that starts threads: test programs linking
#      firmware/ or drivers/posix (or labelled tsan); single-threaded test programs are not even
#      built there (tests/CMakeLists.txt), and the replay, golden and fault tests are not run
#      there: they replay with --fast, on one thread, where TSan has nothing to find
#   4. arm64 cross build (gold, -g1, no desk tool: the default build's renders the recordings),
#      tests under qemu-aarch64, .deb package test (the cross environment's apt work runs in the
#      background from the start)
# The sanitizer fault suites replay the base recordings the default build rendered
# (AGV_FAULTS_BASE_FROM, tests/faults/run_faults.py --base-from) instead of rendering them again
# under the sanitizers. Any sanitizer report fails its test. Prints the wall time of each step
# (docs/guide/testing.md, "Time budget").
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
# The arm64 cross environment (toolchain/prepare-aarch64.sh) is apt work, downloading and unpacking
# (~3 min on a fresh machine), not compiling: it runs beside the default build and is waited for
# before the cross build, where cross-test.sh runs it again (a no-op once prepared).
mkdir -p build
prep_log=build/prepare-aarch64.log
( bash toolchain/prepare-aarch64.sh >"$prep_log" 2>&1; echo $? >"$prep_log.rc" ) &
prep_pid=$!
# Each test program runs as a few tests of its cases (AGV_TESTS_PER_PROGRAM, tests/CMakeLists.txt:
# shards of up to 16 cases) rather than one process per case: the default ctest's test CPU
# halved (docs/guide/testing.md). A developer's own `cmake --preset default` keeps one test per case.
cmake --preset default -DAGV_TESTS_PER_PROGRAM=ON
cmake --build --preset default -j "$jobs"
step "default: build"
ctest --preset default -j "$jobs" -LE '^(hil|vm)$'
step "default: ctest (no VM)"

vm_log=build/default/vm-tests.log
( ctest --preset default -L '^(hil|vm)$' >"$vm_log" 2>&1; echo $? >"$vm_log.rc" ) &
vm_pid=$!
trap 'printf "%s\n" "${times[@]}"; pkill -TERM -P "$vm_pid" 2>/dev/null || true' EXIT
export AGV_FAULTS_BASE_FROM="$PWD/build/default/tests/faults/work"

# The TSan build tests no desk tool (it starts no threads): it renders its test recordings with the
# default build's (AGV_HOST_DESK, CMakeLists.txt) instead of building its own.
host_desk="$PWD/build/default/firmware/agvloc-desk"
for preset in asan tsan; do
  if [ "$preset" = tsan ]; then
    cmake --preset "$preset" -DAGV_HOST_DESK="$host_desk"
  else
    cmake --preset "$preset"
  fi
  cmake --build --preset "$preset" -j "$jobs"
  step "$preset: build"
  # The test presets select the labels (asan: unit, replay, golden, faults, tsan; tsan: unit,
  # tsan) and set the sanitizer runtime options.
  ctest --preset "$preset" -j "$jobs"
  step "$preset: ctest"
  if [ "$preset" = asan ]; then
    # Fuzzing (docs/design/security.md): every harness, built above, on the committed corpus, 5 s
    # each: a regression check of the corpus and a short search; campaigns are run by hand (60 s+).
    bash fuzz/run.sh "${AGV_FUZZ_SECONDS:-5}"
    step "asan: fuzz/run.sh"
  fi
done

# arm64: cross build, tests under qemu-aarch64, .deb package test (docs/guide/deployment.md)
wait "$prep_pid" || true
cat "$prep_log"
if [ "$(cat "$prep_log.rc" 2>/dev/null || echo 1)" != 0 ]; then
  echo "test.sh: preparing the arm64 cross environment failed (log above)" >&2
  exit 1
fi
step "aarch64: prepare (in the background), waited for"
# The default build's desk tool renders the arm64 tests' recordings natively (as for TSan above).
AGV_HOST_DESK="$host_desk" bash tools/cross-test.sh
step "aarch64: cross-test.sh"

wait "$vm_pid" || true
step "default: VM tests (waited for)"
cat "$vm_log"
vm_rc="$(cat "$vm_log.rc" 2>/dev/null || echo 1)"
if [ "$vm_rc" != 0 ]; then
  # Beside the sanitizer builds the emulated guest can fall seconds behind real time (3.9 s
  # odometry lag, a 554 ms pose gap, a 96 s boot in two runs); the overlap is a time saving, not
  # the condition the tests judge. A VM test that failed there runs again alone (ctest
  # --rerun-failed: the background run was the last ctest of this build); both logs are printed
  # and only a failure alone fails the script.
  echo "test.sh: VM tests failed beside the sanitizer jobs (exit $vm_rc); running the failed ones again alone" >&2
  # The re-run writes the same results directories: keep the failing run's for diagnosis.
  rm -rf build/default/hil-results-beside-load
  cp -a build/default/hil-results build/default/hil-results-beside-load
  echo "test.sh: the failing run's results are kept in build/default/hil-results-beside-load" >&2
  vm_rc=0
  ctest --preset default -L '^(hil|vm)$' --rerun-failed --output-on-failure || vm_rc=$?
  step "default: failed VM tests again, alone"
fi
if [ "$vm_rc" != 0 ]; then
  echo "test.sh: the VM tests failed (exit $vm_rc, log above: $vm_log)" >&2
  exit 1
fi
