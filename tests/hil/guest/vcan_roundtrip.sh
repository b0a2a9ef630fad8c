#!/bin/sh
# Inside the VM: a real kernel vcan bus; cansend -> candump round trip of classic, extended,
# remote, empty and CAN FD frames. The host checks the capture (check_vcan_roundtrip.py).
#   vcan_roundtrip.sh OUTDIR
set -u
. "$(dirname "$0")/lib.sh"
out="$1"
hil_vcan_up vcan0 72
ip -d link show vcan0
hil_capture_start vcan0 "$out/capture.log"
# Keep this list in sync with EXPECTED in check_vcan_roundtrip.py.
for f in 123#DEADBEEF 1ABCDEF0#0011223344556677 7FF# 100#R 000#01 \
         456##1000102030405060708090A0B0C0D0E0F10111213; do
  cansend vcan0 "$f" || hil_die "cansend vcan0 $f"
done
sleep 0.5
hil_capture_stop
hil_log "captured $(wc -l <"$out/capture.log") frame(s) into $out/capture.log"
