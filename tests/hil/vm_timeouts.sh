#!/usr/bin/env bash
# ctest hil_vm_timeouts: run-in-vm.sh's two limits. A loaded host stretches a TCG boot from ~6 s
# to over a minute; the command's --timeout must not be spent on that, and each limit must still
# stop what overruns it, saying which one it was.
#   vm_timeouts.sh RESULTS_DIR
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="$1"
rm -rf "$out"; mkdir -p "$out"
fail=0
vm() {  # vm NAME EXPECTED_RC OPTIONS... -- COMMAND...
  local name="$1" want="$2"; shift 2
  local t=$SECONDS rc
  "$here/vm/run-in-vm.sh" --quiet --share "$out/$name" "$@" 2>"$out/$name.stderr"
  rc=$?
  echo "$name: exit $rc (want $want) after $(( SECONDS - t )) s; $(tr '\n' ' ' <"$out/$name/.vm/timing" 2>/dev/null)"
  if [ "$rc" != "$want" ]; then
    echo "FAIL $name: run-in-vm.sh exited $rc, want $want"; sed 's/^/  | /' "$out/$name.stderr"
    fail=1
  fi
}
timed_out() { cat "$out/$1/.vm/timed_out" 2>/dev/null || echo none; }

# 1. A command shorter than its --timeout passes however long the boot took (before the split,
#    --timeout 3 covered the boot too, which takes longer than 3 s even on an idle host).
vm short_command 0 --timeout 3 -- true
# 2. A command that overruns its own limit is stopped by it, well before the boot's limit.
vm slow_command 124 --timeout 3 --boot-timeout 600 -- sleep 600
[ "$(timed_out slow_command)" = command ] || { echo "FAIL slow_command: timed_out=$(timed_out slow_command), want command"; fail=1; }
grep -q "command was still running" "$out/slow_command.stderr" ||
  { echo "FAIL slow_command: no 'command was still running' explanation"; fail=1; }
# 3. A boot that overruns its limit is stopped by it (no kernel boots to a command in 1 s of TCG).
vm slow_boot 124 --boot-timeout 1 --timeout 600 -- true
[ "$(timed_out slow_boot)" = boot ] || { echo "FAIL slow_boot: timed_out=$(timed_out slow_boot), want boot"; fail=1; }
grep -q "boot did not reach the command" "$out/slow_boot.stderr" ||
  { echo "FAIL slow_boot: no boot explanation"; fail=1; }
exit "$fail"
