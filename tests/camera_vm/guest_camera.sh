#!/usr/bin/env bash
# Runs inside the VM (see run_camera_vm.sh):  guest_camera.sh v4l2|libcamera CAMERA_VM_CHECK
# Extra arguments for camera_vm_check can be given in AGV_CAMERA_VM_ARGS.
set -uo pipefail
driver="$1"; bin="$2"
common=(--fps 30 --exposure-us 1000 --frames "${AGV_CAMERA_VM_FRAMES:-300}" --restart-frames 30)
case "$driver" in
  v4l2)
    dev=""
    for d in /sys/class/video4linux/video*; do
      case "$(cat "$d/name" 2>/dev/null)" in *vid-cap*) dev="/dev/${d##*/}"; break ;; esac
    done
    [ -n "$dev" ] || { echo "FAIL: no vivid capture node"; ls -l /sys/class/video4linux/; exit 1; }
    echo "guest: vivid capture node $dev"
    # vivid's end-of-frame stamps are synthetic (in the future); use its real start-of-exposure.
    tsrc=(--v4l2-ctrl "Timestamp Source=1")
    # 1) NV12 (Y plane in place) and 2) YUYV (copied to gray), short runs; 3) GREY (in place),
    # full run, restart, then device removal.
    "$bin" --driver v4l2 --id "$dev" --width 640 --height 480 --format yuv "${tsrc[@]}" \
      --fps 30 --exposure-us 1000 --frames 100 --restart-frames 0 || exit 1
    "$bin" --driver v4l2 --id "$dev" --width 640 --height 480 --v4l2-fourcc YUYV "${tsrc[@]}" \
      --fps 30 --exposure-us 1000 --frames 100 --restart-frames 0 || exit 1
    exec "$bin" --driver v4l2 --id "$dev" --width 640 --height 480 --format gray "${tsrc[@]}" \
      "${common[@]}" --unbind /sys/bus/platform/drivers/vivid/unbind=vivid.0 \
      ${AGV_CAMERA_VM_ARGS:-}
    ;;
  libcamera)
    # libcamera enumerates media devices through udev; the guest runs in a chroot.
    export SYSTEMD_IGNORE_CHROOT=1  # udevd and udevadm refuse to work in a chroot otherwise
    /lib/systemd/systemd-udevd --daemon || { echo "FAIL: udevd"; exit 1; }
    udevadm trigger --action=add
    udevadm settle --timeout=60
    ls /dev/media* /dev/video* 2>&1 | tr '\n' ' '; echo
    # vimc's scaler output must be a multiple of 6 in both directions for libcamera 0.0.3.
    exec "$bin" --driver libcamera --width 648 --height 480 "${common[@]}" \
      --unbind /sys/bus/platform/drivers/vimc/unbind=vimc.0 ${AGV_CAMERA_VM_ARGS:-}
    ;;
esac
echo "usage: guest_camera.sh v4l2|libcamera BINARY" >&2
exit 2
