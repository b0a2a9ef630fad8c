#!/usr/bin/env bash
# ctest wrapper: boots the VM with the IIO sysfs trigger loaded and runs imu_vm_check on a BMI160
# instantiated on i2c-stub (guest_imu.sh).
#   run_imu_vm.sh RESULTS_DIR IMU_VM_CHECK_BINARY
# The guest console is kept in RESULTS_DIR/.vm/.
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
out="$1"; bin="$2"
rm -rf "$out"; mkdir -p "$out"
trig="$("$here/build-iio-trig-sysfs.sh" | tail -n1)" ||
  { echo "FAIL: build-iio-trig-sysfs.sh failed"; exit 1; }
exec "$root/tests/hil/vm/run-check-in-vm.sh" imu_vm_check "$out" "${AGV_IMU_VM_TIMEOUT:-240}" \
  "$trig" bash "$here/guest_imu.sh" "$bin"
