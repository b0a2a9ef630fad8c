#!/usr/bin/env bash
# ctest wrapper: boots the VM with the camera test driver loaded and runs camera_vm_check in it.
#   run_camera_vm.sh v4l2|libcamera RESULTS_DIR CAMERA_VM_CHECK_BINARY
# v4l2: Debian's own vivid module. libcamera: vimc.ko built by build-vimc.sh (cached) plus the
# media modules it needs from the VM kernel. The guest console is kept in RESULTS_DIR/.vm/.
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
driver="$1"; out="$2"; bin="$3"
rm -rf "$out"; mkdir -p "$out"
case "$driver" in
  v4l2) modules="vivid" ;;
  libcamera)
    vimc="$("$here/build-vimc.sh" | tail -n1)" || { echo "FAIL: build-vimc.sh failed"; exit 1; }
    modules="mc videodev v4l2-tpg videobuf2-common videobuf2-memops videobuf2-v4l2"
    modules="$modules videobuf2-vmalloc videobuf2-dma-contig $vimc" ;;
  *) echo "usage: run_camera_vm.sh v4l2|libcamera RESULTS_DIR BINARY" >&2; exit 2 ;;
esac
exec "$root/tests/hil/vm/run-check-in-vm.sh" "camera_vm_check ($driver)" "$out" \
  "${AGV_CAMERA_VM_TIMEOUT:-270}" "$modules" bash "$here/guest_camera.sh" "$driver" "$bin"
