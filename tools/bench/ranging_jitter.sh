#!/usr/bin/env bash
# The second camera's cost in the threaded loop, side by side (docs/design/ranging.md, "Cost in
# the threaded loop"): one simulated drive with a rendered rack stream (rack_drive_eval.sh's
# scene), replayed with --realtime (the threads of `agvloc run`) without and with the second
# camera, alternating, RUNS times each. Prints per run the output period jitter, end-to-end
# latency, the process's CPU time and, with the second camera, its worker's CPU per frame.
#   tools/bench/ranging_jitter.sh [BUILD_DIR] [WORK_DIR] [RUNS]
# Environment: AGV_BENCH_LOOP=FILE, a configuration with the loop's real-time keys (e.g. the
# shipped configuration's `loop:` section) used by both runs; the second camera's run adds the
# recording's ranging.yaml to it.
set -euo pipefail
cd "$(dirname "$0")/../.."
BUILD="${1:-build/default}"
WORK="${2:-/tmp/agvloc-ranging-jitter}"
RUNS="${3:-3}"
BIN="$(realpath "$BUILD/firmware/agvloc")"
DESK="$(realpath "$BUILD/firmware/agvloc-desk")"
RENDER="$(realpath "$BUILD/tools/eval/ranging/render_ranging_stream")"
mkdir -p "$WORK"
# The drive and its rack stream: rack_drive_eval.sh makes them (seed 1, no slips) and keeps them.
if [ ! -f "$WORK/rack_1/ranging/frames.csv" ]; then
  SLIP_RATE_PER_S=0 tools/eval/ranging/rack_drive_eval.sh "$WORK" "$BIN" "$DESK" "$RENDER" 1 \
    > "$WORK/eval.log"
fi
REC="$WORK/rack_1"
floor_cfg=()
cat "${AGV_BENCH_LOOP:-/dev/null}" > "$WORK/floor.yaml"
# Beside ranging.yaml: its site file is named relative to the configuration.
cat "$WORK/floor.yaml" "$REC/ranging.yaml" > "$REC/rack_bench.yaml"
[ -s "$WORK/floor.yaml" ] && floor_cfg=(--config "$WORK/floor.yaml")
echo "== commit $(git rev-parse --short HEAD 2>/dev/null || echo '?'), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)"
for ((i = 1; i <= RUNS; i++)); do
  for mode in floor rack; do
    cfg=("${floor_cfg[@]}")
    [ "$mode" = rack ] && cfg=(--config "$REC/rack_bench.yaml")
    /usr/bin/time -f "cpu user %U s, system %S s, wall %e s" "$BIN" replay "$REC" --realtime \
      --quiet --out "$WORK/out_rt_$mode" "${cfg[@]}" > "$WORK/rt_$mode.txt" 2> "$WORK/rt_$mode.err"
    echo "-- run $i, $mode (load $(cut -d' ' -f1 /proc/loadavg))"
    grep -E "end to end|output period jitter|missed periods" "$WORK/rt_$mode.txt" || true
    grep -E "^ranging camera" "$WORK/rt_$mode.txt" || true
    tail -1 "$WORK/rt_$mode.err"
  done
done
