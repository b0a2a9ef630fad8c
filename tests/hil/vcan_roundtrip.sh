#!/usr/bin/env bash
# ctest hil_vcan_roundtrip: boots the VM, runs guest/vcan_roundtrip.sh on a real kernel vcan0,
# then checks the capture on the host with python-can.
#   vcan_roundtrip.sh RESULTS_DIR [PYTHON]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="$1"; py="${2:-/usr/bin/python3}"
rm -rf "$out"; mkdir -p "$out"
"$here/vm/run-in-vm.sh" --quiet --share "$out" --timeout 180 -- "$here/guest/vcan_roundtrip.sh" "$out"
if ! "$py" "$here/check_vcan_roundtrip.py" "$out/capture.log"; then
  echo "capture: $out/capture.log; guest console: $out/.vm/console.log"
  exit 1
fi
echo "timing: $(tr '\n' ' ' <"$out/.vm/timing")"
