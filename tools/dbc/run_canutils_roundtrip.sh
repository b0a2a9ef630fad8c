#!/usr/bin/env bash
# can-utils interop (ctest "can_interop_canutils", label interop):
#   run_canutils_roundtrip.sh <agv_can_tool> <workdir>
# Our candump -l log -> log2asc (can-utils reads our format) -> asc2log (can-utils writes its
# format) -> our parser; the frames must come back identical.
set -euo pipefail
tool="$1"
work="$2"
mkdir -p "$work"
"$tool" interop "$work/ours.log" "$work/ours.expected"
log2asc -I "$work/ours.log" -O "$work/ours.asc" can0
asc2log -I "$work/ours.asc" -O "$work/back.log" 2>/dev/null
"$tool" same-frames "$work/ours.log" "$work/back.log"
