#!/usr/bin/env bash
# Loop benchmark (docs/design/performance.md): a 60 s simulated run replayed at real-time pace through
# the threaded loop; prints end-to-end latency, output period jitter, CPU use and peak RSS, and
# the jitter of a bare periodic timer measured at the same time (the machine's own baseline).
#   tools/bench/loop_bench.sh [BUILD_DIR] [WORK_DIR]
# Environment:
#   AGV_BENCH_CONFIG=FILE        localizer configuration (loop.realtime_priority, pose_on_fix, ...)
#   AGV_BENCH_BASELINE_FIFO=N    run the bare timer at SCHED_FIFO priority N (compare like with
#                                like when the config sets loop.realtime_priority); 0 = normal
#   AGV_BENCH_BASELINE_SPIN_US=N the bare timer also waits like loop.spin_before_deadline_us N
set -euo pipefail
cd "$(dirname "$0")/../.."
BUILD="${1:-build/default}"
WORK="${2:-/tmp/agvloc-loop-bench}"
BIN="$BUILD/firmware/agvloc"
DESK="$BUILD/firmware/agvloc-desk"
mkdir -p "$WORK"
if [ ! -f "$WORK/rec60/frames.csv" ]; then
  "$DESK" sim --out "$WORK/rec60" --trajectory lawnmower --duration-s 60 --fps 30 \
    --speed-mps 1.0 --exposure-ms 0.5 --seed 3 --force
fi
"$BUILD/tests/bench/timer_baseline" 100 60 "${AGV_BENCH_BASELINE_FIFO:-0}" "${AGV_BENCH_BASELINE_SPIN_US:-0}" > "$WORK/baseline.txt" &
BASE_PID=$!
LOAD_START="$(cut -d' ' -f1-3 /proc/loadavg)"
/usr/bin/time -v "$BIN" replay "$WORK/rec60" --out "$WORK/out" --realtime --quiet ${AGV_BENCH_CONFIG:+--config "$AGV_BENCH_CONFIG"} \
  > "$WORK/replay.txt" 2> "$WORK/time.txt"
wait "$BASE_PID"
echo "== commit $(git rev-parse --short HEAD 2>/dev/null || echo '?'), config ${AGV_BENCH_CONFIG:-(defaults)}"
echo "== machine: $(nproc) cores, load average at start $LOAD_START, at end $(cut -d' ' -f1-3 /proc/loadavg)"
grep -E "end to end|output period jitter|vision \(total\)|exposure -> vision|missed periods|dropped" "$WORK/replay.txt"
grep -E "^agvloc:" "$WORK/time.txt" || true
cat "$WORK/baseline.txt"
grep -E "User time|System time|Percent of CPU|Maximum resident|Elapsed" "$WORK/time.txt"
