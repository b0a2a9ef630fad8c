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
root="$(cd "$here/../.." && pwd)"
log() { echo "build-vimc: $*" >&2; }
die() { echo "build-vimc: ERROR: $*" >&2; exit 1; }

kdir="$("$root/tests/hil/vm/fetch-kernel.sh" | tail -n1)" || die "fetch-kernel.sh failed"
# shellcheck disable=SC1091
. "$kdir/kernel.env"
[ -n "${KVER:-}" ] || die "no KVER in $kdir/kernel.env"

cache="${AGV_VM_CACHE:-/var/cache/agvloc-vm}/vimc-$KVER"
if [ -f "$cache/vimc.ko" ]; then
  log "using cached $cache/vimc.ko"
  echo "$cache/vimc.ko"
  exit 0
fi

headers="/usr/src/linux-headers-$KVER"
# The source package is versioned by the upstream series (6.1), the headers by the ABI (KVER).
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

work="$(mktemp -d /tmp/agvloc-vimc.XXXXXX)"
trap 'rm -rf "$work"' EXIT
log "extracting vimc from $tarball"
tar -C "$work" -xJf "$tarball" --wildcards "linux-source-$series/drivers/media/test-drivers/vimc/*"
src="$work/linux-source-$series/drivers/media/test-drivers/vimc"
[ -f "$src/Makefile" ] || die "vimc sources not found in $tarball"
log "building against $headers"
make -s -C "$headers" M="$src" CONFIG_VIDEO_VIMC=m modules >&2 || die "vimc build failed"
[ -f "$src/vimc.ko" ] || die "build produced no vimc.ko"
mkdir -p "$cache"
cp "$src/vimc.ko" "$cache/vimc.ko.tmp" && mv "$cache/vimc.ko.tmp" "$cache/vimc.ko"
log "built $cache/vimc.ko ($(modinfo -F vermagic "$cache/vimc.ko"))"
echo "$cache/vimc.ko"
