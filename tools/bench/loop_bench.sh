#!/usr/bin/env bash
# Loop benchmark (docs/performance.md): a 60 s simulated run replayed at real-time pace through
# the threaded loop; prints end-to-end latency, output period jitter, CPU use and peak RSS, and
# the jitter of a bare periodic timer measured at the same time (the machine's own baseline).
#   tools/bench/loop_bench.sh [BUILD_DIR] [WORK_DIR]
set -euo pipefail
cd "$(dirname "$0")/../.."
BUILD="${1:-build/default}"
WORK="${2:-/tmp/agvloc-loop-bench}"
BIN="$BUILD/firmware/agvloc"
mkdir -p "$WORK"
if [ ! -f "$WORK/rec60/frames.csv" ]; then
  "$BIN" sim --out "$WORK/rec60" --trajectory lawnmower --duration-s 60 --fps 30 \
    --speed-mps 1.0 --exposure-ms 0.5 --seed 3 --force
fi
"$BUILD/tests/bench/timer_baseline" 100 60 > "$WORK/baseline.txt" &
BASE_PID=$!
/usr/bin/time -v "$BIN" replay "$WORK/rec60" --out "$WORK/out" --realtime --quiet ${AGV_BENCH_CONFIG:+--config "$AGV_BENCH_CONFIG"} \
  > "$WORK/replay.txt" 2> "$WORK/time.txt"
wait "$BASE_PID"
echo "== machine: $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg)"
grep -E "end to end|output period jitter|vision \(total\)|exposure -> vision|missed periods|dropped" "$WORK/replay.txt"
cat "$WORK/baseline.txt"
grep -E "Percent of CPU|Maximum resident|Elapsed" "$WORK/time.txt"
