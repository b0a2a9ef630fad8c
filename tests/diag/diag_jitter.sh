#!/usr/bin/env bash
# The output loop with the diagnostics page (docs/guide/diagnostics.md): period jitter and end to end of
# `agvloc replay --realtime` with the page off, served with no client, with 50 clients polling at
# the page's own rate, and with 50 clients requesting as fast as answered (stress);
# AGV_BENCH_RUNS (3) runs per mode, interleaved; one line per run. The same measurement as
# tools/bench/mqtt_jitter.sh (same recording, the same summary lines).
#   tests/diag/diag_jitter.sh AGVLOC RECORDING WORKDIR [LOOP_EXTRA]
# LOOP_EXTRA: YAML lines added to every mode's loop section, e.g. the shipped real-time settings
# "  realtime_priority: 50\n  vision_priority: 40\n  lock_memory: true\n".
set -u
HERE="$(cd "$(dirname "$0")" && pwd)"
BIN="$(realpath "$1")"
REC="$(realpath "$2")"
mkdir -p "$3" && cd "$3"
EXTRA="$(printf "${4:-}")"
[ -n "$EXTRA" ] && EXTRA="$EXTRA
"
printf 'loop:\n  output_rate_hz: 100\n%s' "$EXTRA" > off.yaml
printf 'loop:\n  output_rate_hz: 100\n%sdiag:\n  port: 0\n' "$EXTRA" > on.yaml
run() {  # mode i
  local mode=$1 i=$2 log=log_$1$2.txt lp= port= pid=
  if [ "$mode" = off ]; then
    "$BIN" replay "$REC" --out out_$mode$i --config off.yaml --realtime --quiet > $log 2>&1
  else
    "$BIN" replay "$REC" --out out_$mode$i --config on.yaml --realtime --quiet --serve > $log 2>&1 &
    pid=$!
    for _ in $(seq 400); do
      port=$(sed -n 's/^diag: serving http:[^ ]*:\([0-9]*\)\/.*/\1/p' $log)
      [ -n "$port" ] && break
      sleep 0.05
    done
    case $mode in
      page50) python3 "$HERE/diag_load.py" "$port" 50 page > load_$mode$i.txt & lp=$! ;;
      flood50) python3 "$HERE/diag_load.py" "$port" 50 flood > load_$mode$i.txt & lp=$! ;;
    esac
    for _ in $(seq 1200); do grep -q '^diag: replay finished' $log && break; sleep 0.1; done
    if [ -n "$lp" ]; then kill $lp; wait $lp; fi
    kill $pid
    wait $pid
  fi
  echo "$mode $i $(grep 'output period jitter' $log | sed 's/  */ /g') | $(grep 'end to end' $log | sed 's/  */ /g') | $(grep '^diag: [0-9]' $log) $(cat load_$mode$i.txt 2>/dev/null)"
}
# AGV_BENCH_RUNS (default 3) runs per mode; tools/bench/jitter_compare.py compares the modes.
for i in $(seq 1 "${AGV_BENCH_RUNS:-3}"); do for m in off idle page50 flood50; do run $m $i; done; done
