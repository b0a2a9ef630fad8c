#!/usr/bin/env bash
# Builds the IIO sysfs trigger (iio-trig-sysfs.ko) out of tree for the VM kernel, as
# tests/camera_vm/build-vimc.sh builds vimc: Debian's kernel has IIO and the IMU drivers but no
# software trigger (CONFIG_IIO_SYSFS_TRIGGER and CONFIG_IIO_HRTIMER_TRIGGER are off), and an IMU
# instantiated on i2c-stub has no interrupt line, hence no data-ready trigger of its own. The
# source is one file in linux-source-6.1; it builds in seconds against linux-headers-<KVER>.
#
#   tests/imu_vm/build-iio-trig-sysfs.sh   prints the path of iio-trig-sysfs.ko (last line)
#   AGV_VM_CACHE=/dir                      cache root (default /var/cache/agvloc-vm)
#
# Installs linux-source-6.1 and linux-headers-<KVER> with apt when missing (root needed then).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
log() { echo "build-iio-trig-sysfs: $*" >&2; }
die() { echo "build-iio-trig-sysfs: ERROR: $*" >&2; exit 1; }

kdir="$("$root/tests/hil/vm/fetch-kernel.sh" | tail -n1)" || die "fetch-kernel.sh failed"
# shellcheck disable=SC1091
. "$kdir/kernel.env"
[ -n "${KVER:-}" ] || die "no KVER in $kdir/kernel.env"

cache="${AGV_VM_CACHE:-/var/cache/agvloc-vm}/iio-trig-sysfs-$KVER"
if [ -f "$cache/iio-trig-sysfs.ko" ]; then
  log "using cached $cache/iio-trig-sysfs.ko"
  echo "$cache/iio-trig-sysfs.ko"
  exit 0
fi

headers="/usr/src/linux-headers-$KVER"
series="$(echo "$KVER" | cut -d. -f1,2)"
tarball="/usr/src/linux-source-$series.tar.xz"
need=()
[ -d "$headers" ] || need+=("linux-headers-$KVER")
[ -f "$tarball" ] || need+=("linux-source-$series")
if [ "${#need[@]}" -gt 0 ]; then
  log "installing ${need[*]}"
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get install -y -q --no-install-recommends "${need[@]}" >&2 ||
    { $SUDO apt-get update -q >&2 && $SUDO apt-get install -y -q --no-install-recommends "${need[@]}" >&2; } ||
    die "cannot install ${need[*]}"
fi
[ -d "$headers" ] && [ -f "$tarball" ] || die "missing $headers or $tarball"

work="$(mktemp -d /tmp/agvloc-iiotrig.XXXXXX)"
trap 'rm -rf "$work"' EXIT
rel="linux-source-$series/drivers/iio/trigger/iio-trig-sysfs.c"
tar -C "$work" -xJf "$tarball" "$rel" || die "cannot extract $rel from $tarball"
src="$work/src"
mkdir -p "$src"
mv "$work/$rel" "$src/"
echo "obj-m := iio-trig-sysfs.o" >"$src/Kbuild"
log "building against $headers"
make -s -C "$headers" M="$src" modules >&2 || die "iio-trig-sysfs build failed"
[ -f "$src/iio-trig-sysfs.ko" ] || die "build produced no iio-trig-sysfs.ko"
mkdir -p "$cache"
cp "$src/iio-trig-sysfs.ko" "$cache/iio-trig-sysfs.ko.tmp" &&
  mv "$cache/iio-trig-sysfs.ko.tmp" "$cache/iio-trig-sysfs.ko"
log "built $cache/iio-trig-sysfs.ko ($(modinfo -F vermagic "$cache/iio-trig-sysfs.ko"))"
echo "$cache/iio-trig-sysfs.ko"
