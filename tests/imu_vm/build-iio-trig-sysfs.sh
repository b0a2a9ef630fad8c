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
MODULE=iio-trig-sysfs
# shellcheck source=../hil/vm/module-build.sh
. "$here/../hil/vm/module-build.sh"
module_cached_or_prepare

rel="linux-source-$series/drivers/iio/trigger/iio-trig-sysfs.c"
tar -C "$work" -xJf "$tarball" "$rel" || die "cannot extract $rel from $tarball"
src="$work/src"
mkdir -p "$src"
mv "$work/$rel" "$src/"
echo "obj-m := iio-trig-sysfs.o" >"$src/Kbuild"
log "building against $headers"
make -s -C "$headers" M="$src" modules >&2 || die "iio-trig-sysfs build failed"
module_install "$src"
