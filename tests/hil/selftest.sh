#!/usr/bin/env bash
# ctest hil_harness_selftest: proves the HIL checks can fail. Runs the nominal scenario against
# fake_agvloc.py (a Python double of the localizer, written from the DBC) told to corrupt some
# pose CRCs, skip an alive counter and send at half the configured rate; the harness must fail
# exactly those checks and still pass the ones the faults do not touch.
#   selftest.sh RESULTS_DIR PYTHON
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="$1"; py="${2:-/usr/bin/python3}"
AGV_FAKE_FAULT=bad-crc,skip-counter,half-rate "$py" "$here/hil.py" nominal \
  --agvloc "$here/fake_agvloc.py" --results "$out" --recording synthetic:8 \
  --set loop.output_rate_hz=20 >"$out.log" 2>&1
rc=$?
report="$out/report.txt"
fail=0
if [ "$rc" -ne 1 ]; then echo "FAIL: the harness exited $rc on a broken localizer, expected 1"; fail=1; fi
for must_fail in "AGV_PoseXY length and CRC" "AGV_PoseXY alive counter continuous" \
                 "AGV_PoseXY period"; do
  if ! grep -q "^FAIL $must_fail" "$report" 2>/dev/null; then
    echo "FAIL: the harness did not catch the injected fault: '$must_fail' did not fail"; fail=1
  fi
done
for must_pass in "AGV_Status length and CRC" "AGV_Status alive counter continuous" \
                 "AGV_Heartbeat.ProtocolVersion" "all odometry frames on the bus" \
                 "decoded poses agree with the offline replay of the odometry the localizer received" \
                 "the odometry the localizer received is the odometry sent" "FaultOdomE2E clear"; do
  if ! grep -q "^PASS $must_pass" "$report" 2>/dev/null; then
    echo "FAIL: '$must_pass' should pass against the fake (a check that fails for the wrong reason)"
    fail=1
  fi
done
if [ "$fail" -ne 0 ]; then
  echo "harness output: $out.log; report: $report"
  cat "$out.log"
  exit 1
fi
echo "PASS: the harness caught the injected faults and passed the rest:"
grep -E "^(PASS|FAIL)" "$report"
