# Helpers for scripts that run INSIDE the HIL virtual machine (sourced; POSIX sh).

hil_log() { echo "hil-guest: $*"; }
hil_die() { echo "hil-guest: FAIL: $*"; exit 1; }

# hil_vcan_up IF [MTU]: creates (if needed) and brings up a vcan interface. MTU 72 = CAN FD.
# A real interface (can0) must exist already, with its bitrate set; it is only brought up.
hil_vcan_up() {
  ip link show "$1" >/dev/null 2>&1 || ip link add dev "$1" type vcan || hil_die "ip link add $1"
  if [ -n "${2:-}" ]; then ip link set "$1" mtu "$2" || hil_die "ip link set $1 mtu $2"; fi
  ip link set up "$1" || hil_die "ip link set up $1"
}

# hil_receivers IF: number of CAN receive filters registered on IF (all lists: rx_all, rx_fil,
# rx_inv, rx_sff, rx_eff, rx_err).
hil_receivers() {
  cat /proc/net/can/rcvlist_* 2>/dev/null | awk -v dev="$1" '$1 == dev' | wc -l
}

# hil_wait_receivers IF N [TIMEOUT_S]: waits until at least N CAN receive filters are registered
# on IF (so a freshly started candump or localizer cannot miss the first frames).
hil_wait_receivers() {
  _n=0
  _deadline=$(( $(cut -d. -f1 /proc/uptime) + ${3:-30} ))
  while :; do
    _n=$(hil_receivers "$1")
    [ "$_n" -ge "$2" ] && return 0
    [ "$(cut -d. -f1 /proc/uptime)" -ge "$_deadline" ] &&
      hil_die "only $_n of $2 CAN receivers appeared on $1 within ${3:-30}s"
    sleep 0.1
  done
}

# hil_capture_start IF FILE: candump in log format (same as `candump -l`) into FILE, waits
# until it listens. Sets HIL_CAPTURE_PID.
hil_capture_start() {
  _before=$(hil_receivers "$1")
  candump -L "$1" >"$2" &
  HIL_CAPTURE_PID=$!
  hil_wait_receivers "$1" $((_before + 1)) 30
}

# hil_capture_stop: stops candump cleanly (it flushes on SIGTERM).
hil_capture_stop() {
  kill -TERM "$HIL_CAPTURE_PID" 2>/dev/null
  wait "$HIL_CAPTURE_PID" 2>/dev/null
  return 0
}
