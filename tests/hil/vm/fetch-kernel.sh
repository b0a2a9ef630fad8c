#!/usr/bin/env bash
# Fetches Debian's stock kernel (vmlinuz + modules) for the HIL virtual machine and unpacks it
# into a cache outside the source tree. No installation, no bootloader: `apt-get download` +
# `dpkg -x`. The concrete version is discovered at run time from the `linux-image-amd64`
# meta-package, never hard-coded.
#
#   tests/hil/vm/fetch-kernel.sh            prints the unpacked kernel directory (last line)
#   AGV_VM_CACHE=/some/dir fetch-kernel.sh  cache location (default /var/cache/agvloc-vm)
#   AGV_VM_KERNEL_PKG=linux-image-6.1.0-N-amd64   pin a concrete package (skips discovery)
#
# Layout: $CACHE/<package>/ (dpkg -x tree: boot/vmlinuz-*, lib/modules/<kver>/) and
# $CACHE/<package>/kernel.env with KVER, VMLINUZ, MODDIR. $CACHE/current -> newest package.
# Idempotent: an already unpacked package is reused; with no network an existing cache is used.
set -euo pipefail

CACHE="${AGV_VM_CACHE:-/var/cache/agvloc-vm}"
META_PKG="linux-image-amd64"

log() { echo "fetch-kernel: $*" >&2; }
die() { echo "fetch-kernel: ERROR: $*" >&2; exit 1; }

mkdir -p "$CACHE" || die "cannot create cache dir $CACHE (set AGV_VM_CACHE)"
# Several test runners may start at once (HIL, camera VM): serialise on a lock.
exec 9>"$CACHE/.lock"
flock 9

use_cached() {
  if [ -e "$CACHE/current/kernel.env" ]; then
    log "using cached kernel $(readlink -f "$CACHE/current")"
    readlink -f "$CACHE/current"
    exit 0
  fi
  die "$1 and no cached kernel in $CACHE"
}

# 1. Which concrete package does the meta-package point at?
pkg="${AGV_VM_KERNEL_PKG:-}"
if [ -z "$pkg" ]; then
  pkg="$(apt-cache depends "$META_PKG" 2>/dev/null |
    awk '$1 == "Depends:" && $2 ~ /^linux-image-[0-9]/ { print $2; exit }')" || true
fi
if [ -z "$pkg" ]; then
  use_cached "apt-cache knows no $META_PKG (run apt-get update?)"
fi

dest="$CACHE/$pkg"
if [ -e "$dest/kernel.env" ]; then
  if [ ! -e "$(. "$dest/kernel.env"; echo "$MODDIR")/modules.dep" ]; then
    (. "$dest/kernel.env"; depmod -b "$dest" -F "$dest/boot/System.map-$KVER" "$KVER") || true
  fi
  ln -sfn "$pkg" "$CACHE/current"
  log "reusing $dest"
  echo "$dest"
  exit 0
fi

# 2. Download the meta-package and the concrete image it depends on.
work="$(mktemp -d "$CACHE/.dl.XXXXXX")"
trap 'rm -rf "$work"' EXIT
chmod 755 "$work"
# apt drops privileges to _apt for the download when it can write there.
if [ "$(id -u)" -eq 0 ] && id _apt >/dev/null 2>&1; then chown _apt "$work"; fi
if ! (cd "$work" && apt-get download -q "$META_PKG" >&2); then
  use_cached "apt-get download $META_PKG failed"
fi
# Prefer the exact dependency recorded in the downloaded meta-package.
dep="$(dpkg-deb -f "$work"/${META_PKG}_*.deb Depends |
  tr ',' '\n' | awk '{ print $1 }' | grep -E '^linux-image-[0-9]' | head -n1)" || true
if [ -n "$dep" ] && [ -z "${AGV_VM_KERNEL_PKG:-}" ] && [ "$dep" != "$pkg" ]; then
  log "meta-package depends on $dep (apt-cache said $pkg); using $dep"
  pkg="$dep"
  dest="$CACHE/$pkg"
fi
log "downloading $pkg"
if ! (cd "$work" && apt-get download -q "$pkg" >&2); then
  use_cached "apt-get download $pkg failed"
fi

# 3. Unpack (into a temporary dir, renamed atomically when complete).
tmp_dest="$work/unpacked"
dpkg -x "$work"/"${pkg}"_*.deb "$tmp_dest"
vmlinuz="$(ls "$tmp_dest"/boot/vmlinuz-* 2>/dev/null | head -n1)"
[ -n "$vmlinuz" ] || die "no boot/vmlinuz-* in $pkg"
kver="${vmlinuz##*/vmlinuz-}"
moddir=""
for d in "$tmp_dest/lib/modules/$kver" "$tmp_dest/usr/lib/modules/$kver"; do
  [ -d "$d" ] && moddir="$d"
done
[ -n "$moddir" ] || die "no lib/modules/$kver in $pkg"
# The package ships no modules.dep (depmod runs at install time): generate it so that the
# guest's modprobe and our dependency resolution work.
depmod -b "$tmp_dest" -F "$tmp_dest/boot/System.map-$kver" "$kver" ||
  log "depmod failed (modprobe inside the guest will not work; insmod still does)"
rm -rf "$dest"
mv "$tmp_dest" "$dest"
cat >"$dest/kernel.env" <<ENV
# written by tests/hil/vm/fetch-kernel.sh
PKG=$pkg
KVER=$kver
VMLINUZ=$dest/boot/vmlinuz-$kver
MODDIR=$dest${moddir#"$tmp_dest"}
ENV
ln -sfn "$pkg" "$CACHE/current"
log "unpacked $pkg (kernel $kver) into $dest"
echo "$dest"
