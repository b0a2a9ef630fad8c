#!/usr/bin/env bash
# Runs inside the VM (see run_imu_vm.sh):  guest_imu.sh IMU_VM_CHECK
# A Bosch BMI160 on i2c-stub: the stub answers the chip id (0xD1 at register 0x00), so Debian's
# bmi160_i2c probes; the gyro data registers hold known values; a sysfs trigger (built by
# build-iio-trig-sysfs.sh, loaded by run-in-vm.sh) is pulsed from a shell loop, since a device on
# the stub has no interrupt line. imu_vm_check then reads the device through drivers/iio.
set -uo pipefail
bin="$1"
addr=0x68
bb=busybox  # Debian's busybox-static has i2cset; i2c-tools is not needed
# Raw gyro register values (s16, little-endian at 0x0C x, 0x0E y, 0x10 z) and the scale the
# kernel reports at the reset range (register 0x43 = 0: +-2000 deg/s -> 0.001065 rad/s per LSB).
raw_x=200; raw_y=-300; raw_z=1000; raw_z2=-2000; scale=0.001065

modprobe i2c-dev || { echo "FAIL: modprobe i2c-dev"; exit 1; }
modprobe i2c-stub chip_addr=$addr || { echo "FAIL: modprobe i2c-stub"; exit 1; }
bus=""
for d in /sys/bus/i2c/devices/i2c-*; do
  [ "$(cat "$d/name" 2>/dev/null)" = "SMBus stub driver" ] && bus="${d##*/i2c-}"
done
[ -n "$bus" ] || { echo "FAIL: no i2c-stub adapter"; ls /sys/bus/i2c/devices/; exit 1; }
echo "guest: i2c-stub is bus $bus"
# Registers and values in hex: busybox i2cset reads bare numbers as hex.
set_reg() { $bb i2cset -y -f "$bus" "$addr" "$(printf 0x%02x "$1")" "$(printf 0x%02x "$2")" b; }
set_s16() {  # register value: little-endian, low byte at the register
  local v=$(( $2 & 0xffff ))
  set_reg "$1" $(( v & 0xff )) && set_reg $(( $1 + 1 )) $(( v >> 8 ))
}
set_reg 0x00 0xd1 || { echo "FAIL: i2cset chip id"; exit 1; }
set_s16 0x0c $raw_x && set_s16 0x0e $raw_y && set_s16 0x10 $raw_z || { echo "FAIL: i2cset data"; exit 1; }

modprobe bmi160_i2c || { echo "FAIL: modprobe bmi160_i2c"; exit 1; }
echo "bmi160 $addr" >"/sys/bus/i2c/devices/i2c-$bus/new_device"
iio=""
for i in $(seq 50); do
  for d in /sys/bus/iio/devices/iio:device*; do
    [ "$(cat "$d/name" 2>/dev/null)" = bmi160 ] && iio="$d"
  done
  [ -n "$iio" ] && break
  sleep 0.2
done
[ -n "$iio" ] || { echo "FAIL: bmi160 did not probe"; dmesg | tail -n 20; exit 1; }
echo "guest: bmi160 is ${iio##*/}: $(ls "$iio/scan_elements" | tr '\n' ' ')"
echo "guest: in_anglvel_z_raw $(cat "$iio/in_anglvel_z_raw") (register read by the kernel driver)"
echo "guest: in_anglvel_z_type $(cat "$iio/scan_elements/in_anglvel_z_type"), in_anglvel_scale $(cat "$iio/in_anglvel_scale")"

echo 0 >/sys/bus/iio/devices/iio_sysfs_trigger/add_trigger || { echo "FAIL: add_trigger"; exit 1; }
trig=""
for d in /sys/bus/iio/devices/trigger*; do
  [ "$(cat "$d/name" 2>/dev/null)" = sysfstrig0 ] && trig="$d"
done
[ -n "$trig" ] || { echo "FAIL: no sysfstrig0"; exit 1; }
# A pulse every 20 ms at most; TCG makes it fewer. No fork per pulse (an exec over the 9p root
# costs ~0.2 s under TCG): the wait is bash's own `read -t` on a fifo nobody writes. Stops when
# the trigger goes away.
mkfifo /tmp/imu_pulse_wait
(
  exec 9<>/tmp/imu_pulse_wait
  while [ -e "$trig/trigger_now" ]; do
    echo 1 >"$trig/trigger_now" 2>/dev/null
    read -r -t 0.02 -u 9
  done
) &
pulse=$!

"$bin" --device bmi160 --trigger sysfstrig0 --rate-hz 100 --samples "${AGV_IMU_VM_SAMPLES:-30}" \
  --raw-x $raw_x --raw-y $raw_y --raw-z $raw_z --scale $scale \
  --set-cmd "$(printf 'busybox i2cset -y -f %s %s 0x10 0x%02x b && busybox i2cset -y -f %s %s 0x11 0x%02x b' \
    "$bus" $addr $(( raw_z2 & 0xff )) "$bus" $addr $(( (raw_z2 & 0xffff) >> 8 )))" \
  --raw-z2 $raw_z2 --remove "/sys/bus/i2c/devices/i2c-$bus/delete_device=$addr" \
  ${AGV_IMU_VM_ARGS:-}
rc=$?
[ -e "$iio" ] && echo "guest: bmi160 still present after the run (expected removed)"
kill "$pulse" 2>/dev/null
exit "$rc"
