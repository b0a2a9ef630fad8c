#!/usr/bin/env bash
# Prepares the arm64 cross environment on Debian bookworm (Debian multiarch). Idempotent; run as
# root (or with sudo). Used by tools/install-deps.sh --cross and tools/cross-test.sh.
#
# What it does:
#  1. `dpkg --add-architecture arm64`, installs crossbuild-essential-arm64, qemu-user and the
#     :arm64 libraries the build needs (co-installable with their amd64 twins).
#  2. Debian's arm64 libopencv-imgcodecs406 cannot be installed next to the amd64 one: it
#     depends on libgdal32 and a few GDAL libraries that are not "Multi-Arch: same" (installing
#     them would remove the host's OpenCV). Those few packages (EXTRACT below) are downloaded
#     with apt and unpacked into $AGV_AARCH64_EXTRA (default /opt/agvloc-aarch64); all their
#     dependencies are installed normally as :arm64 packages. The toolchain file links against
#     and runs with this directory (rpath-link / LD_LIBRARY_PATH under qemu).
#  3. Headers: the -dev packages that are "Multi-Arch: same" have byte-identical headers on every
#     architecture (dpkg enforces it), so the amd64 OpenCV/yaml-cpp headers installed by
#     tools/install-deps.sh serve the arm64 build; only the arm64 *libraries* are needed here.
#     toolchain/cmake/Find*.cmake find those libraries (OpenCVConfig.cmake lives in
#     libopencv-dev, which is not Multi-Arch and drags in every OpenCV module).
#
# Environment:
#   AGV_AARCH64_EXTRA=DIR         where the non-co-installable libraries are unpacked
#   AGV_CROSS_NO_LIBCAMERA=1      skip libcamera-dev:arm64 (the cross build is then replay-only)
set -euo pipefail

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
EXTRA="${AGV_AARCH64_EXTRA:-/opt/agvloc-aarch64}"
export DEBIAN_FRONTEND=noninteractive

HOST_PKGS=(crossbuild-essential-arm64 qemu-user file pkg-config cmake ninja-build
           libopencv-dev libyaml-cpp-dev libeigen3-dev libcli11-dev
           nlohmann-json3-dev)  # header-only, Architecture: all: serves the arm64 build
# Libraries for the arm64 build: OpenCV core/imgproc/calib3d (imgcodecs: see EXTRACT), zxing,
# yaml-cpp runtime (its -dev is not Multi-Arch), libpng, GoogleTest (static libs + CMake config),
# libapriltag3 (tag36h11 landmarks; libapriltag-dev:arm64 says Multi-Arch: same but its CMake
# targets file differs from the amd64 one, so dpkg refuses it: the amd64 headers serve and the
# build links the runtime library by its file name, CMakeLists.txt).
# A -dev package added to tools/install-deps.sh for the build needs its :arm64 twin here.
ARM_PKGS=(libc6-dev libstdc++-12-dev
          libopencv-core-dev libopencv-imgproc-dev libopencv-calib3d406
          libzxing-dev libapriltag3 libyaml-cpp0.7 libpng-dev libgtest-dev libgmock-dev)
if [ "${AGV_CROSS_NO_LIBCAMERA:-0}" != "1" ]; then ARM_PKGS+=(libcamera-dev); fi
# imu.source iio (drivers/iio; optional in CMake: without it the cross build has no IIO gyro).
ARM_PKGS+=(libiio-dev)
# VDA 5050 over MQTT (firmware/src/mqtt_publisher.cpp).
ARM_PKGS+=(libmosquitto-dev)
# The diagnostics page on the vehicle (firmware/src/diag_server.cpp; optional in CMake). Multi-Arch:
# same (libmicrohttpd-dev 0.9.75; pulls the arm64 libgnutls28-dev).
ARM_PKGS+=(libmicrohttpd-dev)
# Not co-installable with the amd64 versions (no Multi-Arch: same): unpacked into $EXTRA.
EXTRACT=(libopencv-imgcodecs406 libgdal32 gdal-plugins libarmadillo11 libhdf4-0-alt libogdi4.1)

installed() {  # $1 = package[:arch]
  dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"
}

if ! dpkg --print-foreign-architectures | grep -qx arm64; then
  echo "prepare-aarch64: adding architecture arm64"
  $SUDO dpkg --add-architecture arm64
  $SUDO apt-get update -q
fi
if ! apt-cache show libopencv-core406:arm64 >/dev/null 2>&1; then
  $SUDO apt-get update -q
fi

# Direct run-time dependencies of the extracted packages (first alternative of each group, no
# virtual packages), minus the extracted packages themselves: installed as normal :arm64 packages.
extract_deps() {
  apt-cache depends "${EXTRACT[@]/%/:arm64}" |
    awk '/^[^ ]/ {alt = 0; next}
         /Depends:/ { if (!alt && $2 !~ /^</) print $2; alt = ($1 ~ /^\|/) }' |
    sed 's/:arm64$//' | sort -u | grep -vxF -f <(printf '%s\n' "${EXTRACT[@]}")
}
mapfile -t DEPS < <(extract_deps)

missing=()
for p in "${HOST_PKGS[@]}"; do installed "$p" || missing+=("$p"); done
for p in "${ARM_PKGS[@]}" "${DEPS[@]}"; do installed "$p:arm64" || missing+=("$p:arm64"); done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "prepare-aarch64: installing ${#missing[@]} package(s)"
  # Refuse anything that would remove a host package (a co-installability regression).
  if $SUDO apt-get install -s -q --no-install-recommends "${missing[@]}" | grep '^Remv'; then
    echo "prepare-aarch64: installing would remove the packages above; aborting" >&2
    exit 1
  fi
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "prepare-aarch64: all $(( ${#HOST_PKGS[@]} + ${#ARM_PKGS[@]} + ${#DEPS[@]} )) packages present"
fi

# Unpack the non-co-installable libraries. A stamp holds the exact versions so a Debian point
# release that updates them (and their installed dependencies) triggers a re-extract.
want=""
for p in "${EXTRACT[@]}"; do
  want+="$p=$(apt-cache policy "$p:arm64" | awk '/Candidate:/ {print $2}')"$'\n'
done
if [ ! -f "$EXTRA/.stamp" ] || [ "$(cat "$EXTRA/.stamp")" != "$(printf '%s' "$want")" ]; then
  echo "prepare-aarch64: unpacking ${EXTRACT[*]} (arm64) into $EXTRA"
  tmp="$(mktemp -d)"
  trap 'rm -rf "$tmp"' EXIT
  # apt-get download runs as the unprivileged _apt user when root: give it a writable directory.
  chmod 777 "$tmp"
  (cd "$tmp" && $SUDO apt-get download -q "${EXTRACT[@]/%/:arm64}")
  $SUDO rm -rf "$EXTRA"
  $SUDO mkdir -p "$EXTRA"
  # .filemap ("file package version" per line) lets packaging/deb-depends.cmake name the Debian
  # package behind each of these libraries for the arm64 .deb's Depends (they are not in dpkg's
  # database here).
  filemap="$tmp/filemap"
  : >"$filemap"
  for deb in "$tmp"/*.deb; do
    $SUDO dpkg-deb -x "$deb" "$EXTRA"
    pkg="$(dpkg-deb -f "$deb" Package)"
    ver="$(dpkg-deb -f "$deb" Version)"
    dpkg-deb -c "$deb" | awk -v p="$pkg" -v v="$ver" '$1 !~ /^d/ {n = split($6, a, "/"); print a[n], p, v}' >>"$filemap"
  done
  $SUDO cp "$filemap" "$EXTRA/.filemap"
  # Development symlink for the one library we link directly (libopencv-imgcodecs-dev:arm64
  # cannot be installed either).
  lib="$EXTRA/usr/lib/aarch64-linux-gnu"
  $SUDO ln -sf "$(basename "$(ls "$lib"/libopencv_imgcodecs.so.4.*.*)")" "$lib/libopencv_imgcodecs.so"
  printf '%s' "$want" | $SUDO tee "$EXTRA/.stamp" >/dev/null
fi

aarch64-linux-gnu-g++ --version | head -n 1
qemu-aarch64 --version | head -n 1
echo "prepare-aarch64: ready (extra libraries in $EXTRA)"
