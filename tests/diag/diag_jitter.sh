#!/usr/bin/env bash
# The output loop with the diagnostics page (docs/guide/diagnostics.md): period jitter and end to end of
# `agvloc replay --realtime` with the page off, served with no client, with 50 clients polling at
# the page's own rate, and with 50 clients requesting as fast as answered (stress);
# AGV_BENCH_RUNS (3) runs per mode, interleaved; one line per run. The same measurement as
# tools/bench/mqtt_jitter.sh (same recording, the same summary lines).
#   tests/diag/diag_jitter.sh AGVLOC RECORDING WORKDIR [LOOP_EXTRA]
# LOOP_EXTRA: YAML lines added to every mode's loop section, e.g. the shipped real-time settings
# "  realtime_priority: 50\n  vision_priority: 40\n  lock_memory: true\n".
# AGV_LOAD_CPUS: a CPU list the load generator is pinned to (taskset -c). Its 50 clients stand
# for browsers on other machines, so with loop.service_cpus set, pinning them to those CPUs keeps
# on the loop's cores only what a vehicle's own cores would do.
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
PIN=
[ -n "${AGV_LOAD_CPUS:-}" ] && PIN="taskset -c $AGV_LOAD_CPUS"
run() {  # mode i
  local mode=$1 i=$2 log=log_$1$2.txt lp= port= pid=
  # Every mode runs the same way (in the background, the shell polling its log every 0.1 s), so
  # that the harness's own work (a grep and a sleep ten times a second) is in the reference too:
  # with the page off run in the foreground instead, an idle server scored 2.9x off's jitter p99.
  local cfg=on.yaml serve=--serve fpid= flog=foreign_$1$2.txt
  case $mode in off | foreign50) cfg=off.yaml serve= ;; esac
  if [ "$mode" = foreign50 ]; then
    # The control: the same page, flooded the same way, served by a second agvloc process (a fast
    # replay of the same recording, then serving until killed) while the measured one runs with
    # the page off. What foreign50 adds over off is the machine's share of the load, not the page.
    $PIN "$BIN" replay "$REC" --out out_f$mode$i --config on.yaml --fast --quiet --serve > $flog 2>&1 &
    fpid=$!
    for _ in $(seq 1200); do grep -q '^diag: replay finished' $flog && break; sleep 0.05; done
    port=$(sed -n 's/^diag: serving http:[^ ]*:\([0-9]*\)\/.*/\1/p' $flog)
    $PIN python3 "$HERE/diag_load.py" "$port" 50 flood > load_$mode$i.txt & lp=$!
    sleep 0.5
  fi
  "$BIN" replay "$REC" --out out_$mode$i --config $cfg --realtime --quiet $serve > $log 2>&1 &
  pid=$!
  if [ -n "$serve" ]; then
    for _ in $(seq 400); do
      port=$(sed -n 's/^diag: serving http:[^ ]*:\([0-9]*\)\/.*/\1/p' $log)
      [ -n "$port" ] && break
      sleep 0.05
    done
  fi
  case $mode in
    page50) $PIN python3 "$HERE/diag_load.py" "$port" 50 page > load_$mode$i.txt & lp=$! ;;
    flood50) $PIN python3 "$HERE/diag_load.py" "$port" 50 flood > load_$mode$i.txt & lp=$! ;;
  esac
  for _ in $(seq 1200); do
    grep -q '^diag: replay finished' $log && break
    kill -0 $pid 2> /dev/null || break
    sleep 0.1
  done
  if [ -n "$lp" ]; then kill $lp; wait $lp; fi
  kill $pid 2> /dev/null
  wait $pid
  if [ -n "$fpid" ]; then kill $fpid; wait $fpid; fi
  echo "$mode $i $(grep 'output period jitter' $log | sed 's/  */ /g') | $(grep 'end to end' $log | sed 's/  */ /g') | $(grep '^diag: [0-9]' $log) $(cat load_$mode$i.txt 2>/dev/null)"
}
# AGV_BENCH_RUNS (default 3) runs per mode; tools/bench/jitter_compare.py compares the modes.
# AGV_BENCH_MODES: the modes, in order (default "off idle page50 flood50"; foreign50 is the
# control above).
for i in $(seq 1 "${AGV_BENCH_RUNS:-3}"); do
  for m in ${AGV_BENCH_MODES:-off idle page50 flood50}; do run $m $i; done
done
