#!/bin/sh
# Inside the VM: one HIL scenario on a real kernel vcan bus. Written by hil.py on the host:
# $OUT/scenario.env (variables below) and the canplayer logs. Everything this script produces
# stays in $OUT (the writable share) for the host checks:
#   capture.log     candump -L of the whole bus (same format as candump -l)
#   localizer.log   the localizer's stdout+stderr;  localizer.rc  its exit code
#   events.log      what this script did when (wall-clock seconds, as candump), for the host checks
#   cangen.log      the random frames cangen sent (garbage scenario)
#
# scenario.env: SCENARIO, AGVLOC, RECORDING, CONFIG, SPEED, IFACE, ODOM_LOG_1, ODOM_LOG_2 (may be
# empty), GARBAGE_LOG (may be empty), CANGEN_COUNT, CANGEN_GAP_MS, CANGEN_START_S,
# LINK_DOWN_S, LOCALIZER_LIMIT_S, EXTRA_ARGS.
#   scenario.sh OUT
set -u
. "$(dirname "$0")/lib.sh"
OUT="$1"
. "$OUT/scenario.env"

now() { date +%s.%N; }  # CLOCK_REALTIME, as candump's timestamps
event() { echo "$(now) $*" >>"$OUT/events.log"; hil_log "$*"; }
: >"$OUT/events.log"

# The inputs read while the bus runs (the recording's frames, the canplayer logs) are copied to
# the guest's tmpfs first: the 9p share is served by the emulator's I/O thread, and on a loaded
# host a read there took seconds (beside two busy processes frames reached vision 3.3 s late,
# median, and the pose was never valid; from tmpfs 16-33 ms).
in_dir=/tmp/hil-inputs
rm -rf "$in_dir"; mkdir -p "$in_dir"
cp -rL "$RECORDING" "$in_dir/recording" || hil_die "copying $RECORDING to $in_dir failed"
RECORDING="$in_dir/recording"
for v in ODOM_LOG_1 ODOM_LOG_2 GARBAGE_LOG; do
  eval "f=\${$v:-}"
  [ -n "$f" ] || continue
  cp "$f" "$in_dir/" || hil_die "copying $f to $in_dir failed"
  eval "$v=\$in_dir/\$(basename \"\$f\")"
done
event "inputs copied to $in_dir ($(du -sm "$in_dir" | cut -f1) MB)"

hil_vcan_up "$IFACE"
# Keep the interface's tx queue as the real CAN drivers have it.
ip link set "$IFACE" txqueuelen 10 2>/dev/null || true

# -D: keep capturing when the interface goes down (link-flap scenario). -r: a 4 MB socket
# buffer and a tmpfs file, so that the capture does not drop frames when the emulated guest is
# starved (it did with the default buffer while writing over 9p).
before=$(hil_receivers "$IFACE")
candump -L -D -r 4194304 "$IFACE" >/tmp/capture.log 2>"$OUT/candump.err" &
capture_pid=$!
hil_wait_receivers "$IFACE" $((before + 1)) 30
event "capture started"

# The localizer. Its replay clock starts with the first odometry frame it receives.
before=$(hil_receivers "$IFACE")
# shellcheck disable=SC2086
"$AGVLOC" replay "$RECORDING" --out "$OUT/run" --config "$CONFIG" --can "$IFACE" \
  --odom-from-can --realtime --speed "$SPEED" $EXTRA_ARGS >"$OUT/localizer.log" 2>&1 &
loc_pid=$!
event "localizer started pid $loc_pid"
# Wait until it listens on the bus (or died).
i=0
while [ "$(hil_receivers "$IFACE")" -le "$before" ]; do
  if ! kill -0 "$loc_pid" 2>/dev/null; then
    wait "$loc_pid"; echo "$?" >"$OUT/localizer.rc"
    event "localizer exited before opening $IFACE"
    kill -TERM "$capture_pid"; wait "$capture_pid"
    cp /tmp/capture.log "$OUT/capture.log"
    exit 0
  fi
  i=$((i + 1))
  [ "$i" -gt 600 ] && { event "localizer did not open $IFACE within 60 s"; break; }
  sleep 0.1
done
event "localizer listening"

garbage_pids=""
if [ -n "${GARBAGE_LOG:-}" ]; then
  (
    sleep "$CANGEN_START_S"
    event "garbage start"
    canplayer -I "$GARBAGE_LOG" "$IFACE=$IFACE" &
    p1=$!
    # Random IDs (11- and 29-bit), lengths and data, including RTR frames. -v -v: log what
    # was sent so the host can tell injected frames from the localizer's.
    cangen "$IFACE" -g "$CANGEN_GAP_MS" -I r -L r -D r -n "$CANGEN_COUNT" -v -v \
      >"$OUT/cangen.log" 2>&1 &
    p2=$!
    cangen "$IFACE" -g "$CANGEN_GAP_MS" -e -I r -L r -D r -n "$CANGEN_COUNT" -v -v \
      >"$OUT/cangen_eff.log" 2>&1 &
    p3=$!
    cangen "$IFACE" -g $((CANGEN_GAP_MS * 4)) -R -I r -n $((CANGEN_COUNT / 4)) -v -v \
      >"$OUT/cangen_rtr.log" 2>&1 &
    wait $p1 $p2 $p3 $!
    event "garbage end"
  ) &
  garbage_pids=$!
fi

event "odometry part 1 start"
canplayer -I "$ODOM_LOG_1" "$IFACE=$IFACE" || event "canplayer part 1 failed ($?)"
event "odometry part 1 end"
if [ -n "${ODOM_LOG_2:-}" ]; then
  if [ "$SCENARIO" = link_flap ]; then
    event "link down requested"
    ip link set "$IFACE" down && event "link down"
    sleep "$LINK_DOWN_S"
    event "link up requested"
    ip link set "$IFACE" up && event "link up"
  fi
  event "odometry part 2 start"
  canplayer -I "$ODOM_LOG_2" "$IFACE=$IFACE" || event "canplayer part 2 failed ($?)"
  event "odometry part 2 end"
fi
[ -n "$garbage_pids" ] && wait $garbage_pids

# The localizer should end by itself when the recording is over.
i=0
while kill -0 "$loc_pid" 2>/dev/null; do
  i=$((i + 1))
  if [ "$i" -gt $((LOCALIZER_LIMIT_S * 10)) ]; then
    event "localizer still running ${LOCALIZER_LIMIT_S}s after the odometry ended: SIGTERM"
    kill -TERM "$loc_pid"
    sleep 2
    kill -KILL "$loc_pid" 2>/dev/null
    break
  fi
  sleep 0.1
done
wait "$loc_pid"
rc=$?
echo "$rc" >"$OUT/localizer.rc"
event "localizer exited with $rc"
sleep 0.2
kill -TERM "$capture_pid"
wait "$capture_pid"
cp /tmp/capture.log "$OUT/capture.log"
event "capture stopped ($(wc -l <"$OUT/capture.log") frames)"
exit 0
