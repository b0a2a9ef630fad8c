#!/usr/bin/env bash
# Installs every Debian package the build, the tests and the tools need.
# Idempotent; run as root (or with sudo) on Debian bookworm.
#   tools/install-deps.sh            host build + tests (incl. HIL VM tooling)
#   tools/install-deps.sh --cross    also the arm64 cross environment (see toolchain/)
#   tools/install-deps.sh --train    also PyTorch and ONNX for retraining the learned tray detector
#                                    (tools/train/tray_obb; never needed to build, test or run)
set -euo pipefail

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

PKGS=(
  build-essential cmake ninja-build pkg-config git ca-certificates
  # algo / drivers / firmware
  libopencv-dev
  # agvloc-desk calibrate intrinsics: ChArUco boards (OpenCV aruco, contrib)
  libopencv-contrib-dev
  libeigen3-dev libpng-dev libzxing-dev libyaml-cpp-dev libcli11-dev
  libcamera-dev libcamera-ipa udev
  # GigE Vision / USB3 Vision cameras (drivers/aravis) and the simulated GigE camera its tests run
  # (arv-fake-gv-camera-0.8). aravis-0.8.pc names libusb-1.0 and zlib, which libaravis-dev does not
  # pull in: without their -dev packages pkg-config does not find aravis at all.
  libaravis-dev aravis-tools libusb-1.0-0-dev zlib1g-dev
  # imu.source iio: gyro from a Linux IIO device (drivers/iio)
  libiio-dev
  # VDA 5050 position over MQTT (docs/guide/vda5050.md): client library, JSON; broker, independent
  # client and the official schemas' validator for the mqtt tests
  libmosquitto-dev nlohmann-json3-dev mosquitto mosquitto-clients python3-paho-mqtt
  python3-jsonschema
  # a second MQTT broker (RabbitMQ's MQTT plugin) for agvloc-overhead's broker-independence test;
  # its service is never started: the test runs a node of its own
  rabbitmq-server
  # diagnostics page and /metrics (docs/guide/diagnostics.md): HTTP server; the page test's browser
  libmicrohttpd-dev chromium
  # agvloc-desk calibrate vehicle: nonlinear least squares
  libceres-dev
  # site model and route planner (algo/site): Boost.Geometry predicates, Boost.Graph Dijkstra
  libboost-dev
  # tests, benchmarks, comparison baseline
  libgtest-dev libgmock-dev libbenchmark-dev libapriltag-dev valgrind
  clang-format clang-tidy
  # sanitizer presets asan (with the fuzz/ harnesses) and tsan: clang, libFuzzer, ASan/UBSan/TSan
  clang libclang-rt-14-dev
  # lld: the faster linker (cmake/Linker.cmake; gold, in binutils, where lld cannot be used)
  lld
  # CAN tools and independent decoders
  can-utils python3-can iproute2
  # hardware-in-the-loop virtual machine
  qemu-system-x86 qemu-user busybox-static kmod cpio gzip xz-utils
)

missing=()
for p in "${PKGS[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ "${#missing[@]}" -gt 0 ]; then
  echo "install-deps: installing ${#missing[@]} package(s): ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "install-deps: all ${#PKGS[@]} packages present"
fi

# npm (for the independent DBC decoder `candied`): Debian's nodejs+npm only when
# no node toolchain is present; some images ship their own node, which conflicts.
if ! command -v npm >/dev/null 2>&1; then
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get install -y -q --no-install-recommends nodejs npm
fi

# The VDA 5050 2.0.0 interop test's master control (tests/vda5050/interop): vda-5050-lib as pinned
# in its package-lock.json, into its ignored node_modules; as the invoking user under sudo, so that
# the test can refresh it.
interop="$(cd "$(dirname "$0")/../tests/vda5050/interop" && pwd)"
if [ ! -f "$interop/node_modules/.package-lock.json" ] ||
   [ "$interop/package-lock.json" -nt "$interop/node_modules/.package-lock.json" ]; then
  as_user=()
  if [ "$(id -u)" -eq 0 ] && [ -n "${SUDO_USER:-}" ]; then as_user=(sudo -u "$SUDO_USER"); fi
  (cd "$interop" && "${as_user[@]}" npm ci --no-audit --no-fund --loglevel=error)
fi

if [ "${1:-}" = "--cross" ]; then
  "$(dirname "$0")/../toolchain/prepare-aarch64.sh"
fi

# Debian's interpreter (/usr/bin/python3) gets these; a python3 of pyenv or a venv does not see them.
if [ "${1:-}" = "--train" ]; then
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get install -y -q --no-install-recommends python3-torch python3-onnx python3-pil
fi
