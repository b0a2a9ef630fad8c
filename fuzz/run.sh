#!/usr/bin/env bash
# Builds the harnesses (build preset fuzz: target agv_fuzzers of the asan build in build/asan, a
# no-op after tools/test.sh built that preset) and runs every libFuzzer harness for a bounded
# time on a copy of the committed corpus (fuzz/corpus/<harness>/, so the tree stays clean) plus
# what it finds.
#   fuzz/run.sh [SECONDS_PER_HARNESS] [HARNESS...]      default 60 s, every harness
# Fails on any crash, property violation, leak, timeout (> 1 s for one input), sanitizer report
# or out-of-memory (> 2 GB RSS). The reproducer lands in $AGV_FUZZ_ARTIFACTS (default
# build/asan/fuzz/artifacts); rerun it with build/asan/fuzz/<harness> <file>.
# Environment: AGV_FUZZ_JOBS (build parallelism, default nproc); AGV_FUZZ_PARALLEL (harnesses run
# at once, default nproc); AGV_FUZZ_RUNS=N stops a harness
# after N executions (SECONDS stays the cap); AGV_FUZZ_KEEP_CORPUS=DIR keeps the grown corpus per
# harness under DIR (to continue a campaign or to minimise it into fuzz/corpus).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-60}"
shift || true
all=(fuzz_payload fuzz_map fuzz_recording_meta fuzz_recording_frames fuzz_recording_odom
     fuzz_recording_truth fuzz_config fuzz_candump fuzz_can_odometry fuzz_png fuzz_vision
     fuzz_vda_action fuzz_placements fuzz_config_apply fuzz_report_csv fuzz_site fuzz_http_request
     fuzz_detection_msg fuzz_order_intake)
if [ "$#" -gt 0 ]; then harnesses=("$@"); else harnesses=("${all[@]}"); fi

t0=$(date +%s)
cmake --preset asan >/dev/null
nice -n 10 cmake --build --preset fuzz -j "${AGV_FUZZ_JOBS:-$(nproc)}"
echo "fuzz: build took $(( $(date +%s) - t0 )) s"

dict_of() {
  case "$1" in
    fuzz_payload) echo fuzz/dict/payload.dict ;;
    fuzz_map) echo fuzz/dict/map.dict ;;
    fuzz_recording_meta) echo fuzz/dict/meta.dict ;;
    fuzz_recording_*) echo fuzz/dict/csv.dict ;;
    fuzz_config | fuzz_config_apply) echo fuzz/dict/config.dict ;;
    fuzz_site) echo fuzz/dict/site.dict ;;
    fuzz_placements | fuzz_report_csv) echo fuzz/dict/csv.dict ;;
    fuzz_candump) echo fuzz/dict/candump.dict ;;
    fuzz_vda_action) echo fuzz/dict/vda5050.dict ;;
    fuzz_detection_msg) echo fuzz/dict/detection_msg.dict ;;
    fuzz_order_intake) echo fuzz/dict/vda5050.dict ;;
  esac
}

artifacts="${AGV_FUZZ_ARTIFACTS:-build/asan/fuzz/artifacts}"
mkdir -p "$artifacts"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
export ASAN_OPTIONS="halt_on_error=1:abort_on_error=1:detect_leaks=1:allocator_may_return_null=1"
export UBSAN_OPTIONS="halt_on_error=1:abort_on_error=1:print_stacktrace=1"
# One harness: its summary line in $work/$h.row, and $work/$h.failed when it found something.
fuzz_one() {
  local h="$1" corpus="$work/corpus_$1" rc=0 execs rate secs files dict
  mkdir -p "$corpus"
  cp -r "fuzz/corpus/$h/." "$corpus/"
  local args=(-max_total_time="$seconds" -timeout=1 -rss_limit_mb=2048 -malloc_limit_mb=2048
              -print_final_stats=1 -artifact_prefix="$artifacts/$h-")
  [ -n "${AGV_FUZZ_RUNS:-}" ] && args+=(-runs="$AGV_FUZZ_RUNS")
  dict="$(dict_of "$h")"
  [ -n "$dict" ] && args+=(-dict="$dict")
  echo "fuzz: $h for $seconds s"
  nice -n 10 "build/asan/fuzz/$h" "${args[@]}" "$corpus" >"$work/$h.log" 2>&1 || rc=$?
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$work/$h.log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$work/$h.log" | tail -1)
  secs=$(sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$work/$h.log" | tail -1)
  files=$(find "$corpus" -type f | wc -l)
  local result=ok
  if [ "$rc" -ne 0 ]; then
    result=FAILED
    : >"$work/$h.failed"
    { echo "fuzz: $h FAILED (exit $rc); the end of its log:"; tail -40 "$work/$h.log"; } \
      >"$work/$h.failure"
  fi
  printf '%-24s %10s %8s %8s %8s %s\n' "$h" "${execs:-?}" "${secs:-?}" "${rate:-?}" "$files" \
    "$result" >"$work/$h.row"
  if [ -n "${AGV_FUZZ_KEEP_CORPUS:-}" ]; then
    mkdir -p "$AGV_FUZZ_KEEP_CORPUS/$h" && cp -r "$corpus/." "$AGV_FUZZ_KEEP_CORPUS/$h/"
  fi
}

# Harnesses run AGV_FUZZ_PARALLEL at a time (default nproc): each libFuzzer process uses one
# core, so one at a time left the second core idle for the whole step.
parallel="${AGV_FUZZ_PARALLEL:-$(nproc)}"
running=0
for h in "${harnesses[@]}"; do
  fuzz_one "$h" &
  running=$((running + 1))
  if [ "$running" -ge "$parallel" ]; then
    wait -n || true
    running=$((running - 1))
  fi
done
wait || true
failed=()
printf '%-24s %10s %8s %8s %8s %s\n' harness executions seconds exec/s corpus result \
  > "$work/summary"
for h in "${harnesses[@]}"; do
  cat "$work/$h.row" >> "$work/summary" 2>/dev/null ||
    printf '%-24s %s\n' "$h" "no result" >> "$work/summary"
  if [ -f "$work/$h.failed" ] || [ ! -f "$work/$h.row" ]; then
    failed+=("$h")
    cat "$work/$h.failure" 2>/dev/null || true
  fi
done
cat "$work/summary"
echo "fuzz: ${#harnesses[@]} harnesses, $(( $(date +%s) - t0 )) s in all (build included)"
if [ "${#failed[@]}" -gt 0 ]; then
  echo "fuzz: FAILED: ${failed[*]} (reproducers in $artifacts)"
  exit 1
fi
echo "fuzz: every harness ran without a finding"
