#!/usr/bin/env bash
# Independent-decoder check (ctest "can_interop_candied", label interop):
#   run_interop.sh <agv_can_tool> <workdir>
# Installs the pinned candied (package-lock.json) with `npm ci` when missing, lets the codec
# write a candump -l log, and decodes it with candied against can/agvloc.dbc.
set -euo pipefail
tool="$1"
work="$2"
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
if [ ! -f "$here/node_modules/candied/package.json" ]; then
  (cd "$here" && npm ci --no-audit --no-fund --loglevel=error)
fi
mkdir -p "$work"
"$tool" interop "$work/interop.log" "$work/interop.expected"
node "$here/check_candied.cjs" "$root/can/agvloc.dbc" "$work/interop.log" "$work/interop.expected"
