#!/usr/bin/env bash
# ctest vda5050_interop_2.0.0 (labels mqtt, interop): run_interop.sh AGVLOC WORKDIR
# An independent VDA 5050 2.0.0 master control (npm vda-5050-lib, master_control.cjs) against
# agvloc over mosquitto. tools/install-deps.sh installs the pinned library (npm ci from
# package-lock.json); a checkout without it gets it here. Skipped (exit 77) only without node or
# npm; everything else missing (mosquitto, the registry for a first npm ci) fails.
set -euo pipefail
agvloc="$1"
work="$2"
case "$0" in */*) here="${0%/*}" ;; *) here=. ;; esac  # no dirname: PATH may be bare
here="$(cd "$here" && pwd)"
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  echo "SKIP: node and npm are needed for the vda-5050-lib master control (tools/install-deps.sh)"
  exit 77
fi
if [ ! -f "$here/node_modules/.package-lock.json" ] ||
   [ "$here/package-lock.json" -nt "$here/node_modules/.package-lock.json" ]; then
  (cd "$here" && npm ci --no-audit --no-fund --loglevel=error)
fi
exec node "$here/master_control.cjs" "$agvloc" "$(dirname "$agvloc")/agvloc-desk" "$work"
