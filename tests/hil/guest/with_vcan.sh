#!/bin/sh
# Inside the VM: creates and brings up vcan interfaces, then runs a command (its exit code is
# returned). Used for the SocketCAN driver's own tests.
#   with_vcan.sh "vcan0 vcan1" COMMAND [ARGS...]
set -u
. "$(dirname "$0")/lib.sh"
for i in $1; do hil_vcan_up "$i"; done
shift
"$@"
rc=$?
hil_log "$1 exited with $rc"
exit $rc
