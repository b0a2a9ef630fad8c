# Sourced by the out-of-tree kernel module builders (tests/camera_vm/build-vimc.sh,
# tests/imu_vm/build-iio-trig-sysfs.sh): the VM kernel's version, the module cache, the Debian
# linux-source and linux-headers packages, a scratch folder. Set MODULE (the .ko's base name)
# before sourcing. Defines log, die, module_cached_or_prepare and module_install.
log() { echo "build-$MODULE: $*" >&2; }
die() { echo "build-$MODULE: ERROR: $*" >&2; exit 1; }

# Prints the cached .ko's path and exits when it is there; otherwise sets KVER, series, tarball,
# headers, cache and work (removed on exit), installing the packages first when missing.
module_cached_or_prepare() {
  local vm_dir kdir
  vm_dir="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
  kdir="$("$vm_dir/fetch-kernel.sh" | tail -n1)" || die "fetch-kernel.sh failed"
  # shellcheck disable=SC1091
  . "$kdir/kernel.env"
  [ -n "${KVER:-}" ] || die "no KVER in $kdir/kernel.env"
  cache="${AGV_VM_CACHE:-/var/cache/agvloc-vm}/$MODULE-$KVER"
  if [ -f "$cache/$MODULE.ko" ]; then
    log "using cached $cache/$MODULE.ko"
    echo "$cache/$MODULE.ko"
    exit 0
  fi
  headers="/usr/src/linux-headers-$KVER"
  # The source package is versioned by the upstream series (6.1), the headers by the ABI (KVER).
  series="$(echo "$KVER" | cut -d. -f1,2)"
  tarball="/usr/src/linux-source-$series.tar.xz"
  local need=()
  [ -d "$headers" ] || need+=("linux-headers-$KVER")
  [ -f "$tarball" ] || need+=("linux-source-$series")
  if [ "${#need[@]}" -gt 0 ]; then
    log "installing ${need[*]}"
    local SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get install -y -q --no-install-recommends "${need[@]}" >&2 ||
      { $SUDO apt-get update -q >&2 &&
        $SUDO apt-get install -y -q --no-install-recommends "${need[@]}" >&2; } ||
      die "cannot install ${need[*]}"
  fi
  [ -d "$headers" ] && [ -f "$tarball" ] || die "missing $headers or $tarball"
  work="$(mktemp -d "/tmp/agvloc-$MODULE.XXXXXX")"
  trap 'rm -rf "$work"' EXIT
}

# Copies the built SRC_DIR/$MODULE.ko into the cache atomically and prints its path.
module_install() {
  local src="$1"
  [ -f "$src/$MODULE.ko" ] || die "build produced no $MODULE.ko"
  mkdir -p "$cache"
  cp "$src/$MODULE.ko" "$cache/$MODULE.ko.tmp" && mv "$cache/$MODULE.ko.tmp" "$cache/$MODULE.ko"
  log "built $cache/$MODULE.ko ($(modinfo -F vermagic "$cache/$MODULE.ko"))"
  echo "$cache/$MODULE.ko"
}
