#!/usr/bin/env bash
# The VM tests' common end: boots the VM sharing RESULTS_DIR with MODULES loaded, runs the guest
# command, prints the guest's command section of the console and the boot timing, and exits with
# the guest command's status (naming WHAT and the console on a failure).
#   run-check-in-vm.sh WHAT RESULTS_DIR TIMEOUT_S MODULES GUEST_COMMAND...
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
what="$1"; out="$2"; timeout_s="$3"; modules="$4"; shift 4
"$here/run-in-vm.sh" --share "$out" --timeout "$timeout_s" --quiet --modules "$modules" -- "$@"
rc=$?
sed -n '/AGV-VM: COMMAND-START/,/AGV-VM: COMMAND-EXIT/p' "$out/.vm/console.log"
[ -f "$out/.vm/timing" ] && cat "$out/.vm/timing"
if [ "$rc" -ne 0 ]; then
  echo "FAIL: $what in the VM exited with $rc; console: $out/.vm/console.log"
fi
exit "$rc"
