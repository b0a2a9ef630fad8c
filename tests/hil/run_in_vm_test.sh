#!/usr/bin/env bash
# ctest wrapper: runs a command in the VM with vcan interfaces up, keeps the results dir and
# explains failures.   run_in_vm_test.sh RESULTS_DIR TIMEOUT_S "vcan0 ..." COMMAND [ARGS...]
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="$1"; timeout_s="$2"; ifaces="$3"; shift 3
rm -rf "$out"; mkdir -p "$out"
"$here/vm/run-in-vm.sh" --share "$out" --timeout "$timeout_s" --quiet -- \
  "$here/guest/with_vcan.sh" "$ifaces" "$@"
rc=$?
# The command's own output is in the guest console; show it (ctest keeps it on failure).
sed -n '/AGV-VM: COMMAND-START/,/AGV-VM: COMMAND-EXIT/p' "$out/.vm/console.log"
if [ "$rc" -ne 0 ]; then
  echo "FAIL: '$*' in the VM exited with $rc; guest console: $out/.vm/console.log"
fi
exit "$rc"
