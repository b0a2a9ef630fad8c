#!/usr/bin/env bash
# The output loop with VDA 5050 on (docs/guide/vda5050.md): period jitter and end to end of
# `agvloc replay --realtime` with MQTT off, broker up, broker down (nothing listening), broker up
# with instantActions flooded by garbage; AGV_BENCH_RUNS (3) runs per mode, interleaved; one line
# per run.
#   tools/bench/mqtt_jitter.sh AGVLOC RECORDING WORKDIR [LOOP_EXTRA]
# LOOP_EXTRA: YAML lines added to every mode's loop section, e.g. the shipped real-time settings
# "  realtime_priority: 50\n  vision_priority: 40\n  lock_memory: true\n" (as tests/diag/diag_jitter.sh).
# Needs mosquitto and mosquitto_pub (tools/install-deps.sh). Port 18877 must be free.
# AGV_LOAD_CPUS: a CPU list the broker and the flooding client are pinned to (taskset -c): they
# stand for the fleet's machines, so with loop.service_cpus set this keeps off the loop's cores
# only what a vehicle's own cores would do.
set -u
BIN="$(realpath "$1")"
REC="$(realpath "$2")"
mkdir -p "$3" && cd "$3"
PORT=18877
PIN=
[ -n "${AGV_LOAD_CPUS:-}" ] && PIN="taskset -c $AGV_LOAD_CPUS"
printf 'listener %d 127.0.0.1\nallow_anonymous true\npersistence false\n' $PORT > m.conf
EXTRA="$(printf "${4:-}")"
[ -n "$EXTRA" ] && EXTRA="$EXTRA
"
printf 'loop:\n  output_rate_hz: 100\n%svda5050:\n  enabled: true\n  broker_port: %d\n  manufacturer: acme\n  serial_number: agv-7\n' "$EXTRA" $PORT > on.yaml
printf 'loop:\n  output_rate_hz: 100\n%s' "$EXTRA" > off.yaml
run() {  # mode i
  local mode=$1 i=$2 cfg=on.yaml bp= fp=
  # foreign: the control: broker up and flooded as in `flood`, agvloc with MQTT off. What it adds
  # over `off` is the machine's share of the flood; what `flood` adds over it is agvloc's.
  case $mode in off | foreign) cfg=off.yaml ;; esac
  if [ "$mode" = up ] || [ "$mode" = flood ] || [ "$mode" = foreign ]; then $PIN mosquitto -c m.conf >/dev/null 2>&1 & bp=$!; sleep 0.3; fi
  if [ "$mode" = flood ] || [ "$mode" = foreign ]; then $PIN mosquitto_pub -p $PORT -l -t uagv/v2/acme/agv-7/instantActions < <($PIN yes '{"headerId": [[[ not json') >/dev/null 2>&1 & fp=$!; sleep 0.3; fi
  $BIN replay $REC --out out_$mode$i --config $cfg --realtime --quiet > log_$mode$i.txt 2>&1
  [ -n "$fp" ] && kill $fp
  [ -n "$bp" ] && kill $bp
  wait 2>/dev/null
  echo "$mode $i $(grep 'output period jitter' log_$mode$i.txt | sed 's/  */ /g') | $(grep 'end to end' log_$mode$i.txt | sed 's/  */ /g') | $(grep '^vda5050' log_$mode$i.txt | cut -c1-160)"
}
# AGV_BENCH_RUNS (default 3) runs per mode; tools/bench/jitter_compare.py compares the modes.
# AGV_BENCH_MODES: the modes, in order (default "off up down flood"; foreign is the control).
for i in $(seq 1 "${AGV_BENCH_RUNS:-3}"); do
  for m in ${AGV_BENCH_MODES:-off up down flood}; do run $m $i; done
done
