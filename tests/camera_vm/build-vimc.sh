#!/usr/bin/env bash
# Builds the vimc (virtual media controller camera) kernel module out of tree for the VM kernel.
# Debian's kernel does not ship vimc, but its source is in linux-source-6.1 and it builds in
# seconds against linux-headers-<same version>. The .ko is cached outside the source tree.
#
#   tests/camera_vm/build-vimc.sh      prints the path of vimc.ko (last line)
#   AGV_VM_CACHE=/dir                  cache root (default /var/cache/agvloc-vm, as fetch-kernel.sh)
#
# Installs linux-source-6.1 and linux-headers-<KVER> with apt when missing (root needed then).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
MODULE=vimc
# shellcheck source=../hil/vm/module-build.sh
. "$here/../hil/vm/module-build.sh"
module_cached_or_prepare

log "extracting vimc from $tarball"
tar -C "$work" -xJf "$tarball" --wildcards "linux-source-$series/drivers/media/test-drivers/vimc/*"
src="$work/linux-source-$series/drivers/media/test-drivers/vimc"
[ -f "$src/Makefile" ] || die "vimc sources not found in $tarball"
log "building against $headers"
make -s -C "$headers" M="$src" CONFIG_VIDEO_VIMC=m modules >&2 || die "vimc build failed"
module_install "$src"
