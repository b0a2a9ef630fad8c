#!/usr/bin/env bash
# Runs COMMAND inside a throw-away virtual machine with Debian's stock kernel (real SocketCAN,
# vcan, V4L2 ...), the host's own root file system shared read-only, and returns its exit code.
#
#   run-in-vm.sh [options] -- COMMAND [ARGS...]
#     --modules "m1 m2.ko ..."  extra kernel modules: names from the Debian kernel (e.g. vivid)
#                               or paths to out-of-tree .ko files (e.g. a freshly built vimc.ko);
#                               their dependencies are loaded first (modinfo), in order.
#     --share HOSTDIR           writable results directory, mounted in the guest at the SAME path
#                               (default: a new /tmp/agvloc-vm.XXXXXX, removed on success).
#     --timeout S               wall-clock limit for COMMAND, counted from its start in the guest
#                               (default 300).
#     --boot-timeout S          wall-clock limit for the boot, up to COMMAND's start (default 300).
#                               Apart from --timeout because TCG's boot time is what a loaded host
#                               stretches most (6 s idle, 64-74 s beside two builds): a slow boot
#                               must not eat the budget of a healthy command.
#     --mem MB / --smp N        guest memory (default 1024) and CPUs (default 2).
#     --keep                    keep the results dir even on success.
#     --quiet                   do not stream the guest console to stdout (it is always logged).
#
# How it works (docs/design/hil.md): an initramfs with busybox-static as /init insmods virtio + 9p (+ CAN
# and the extra modules), mounts the host's / read-only over virtio-9p, mounts proc, sys,
# devtmpfs, devpts and tmpfs on /tmp, /run, /var/tmp, mounts the results share at HOSTDIR,
# bind-mounts the unpacked kernel modules on /lib/modules/<kver> (so modprobe works), chroots and
# runs COMMAND (handed over as a script in HOSTDIR/.vm/, not on the kernel command line) in the
# current directory with the current PATH, writes its exit code to HOSTDIR/.vm/exit_code and
# powers off. Software emulation only (TCG): KVM hangs on the CI machines.
#
# In the guest: AGV_IN_VM=1, AGV_VM_RESULTS=HOSTDIR, HOME=/tmp, PATH and every AGV_* variable of
# the caller.
# Exit status: COMMAND's, or 124 on timeout, or 125 when the VM failed before reporting one.
# Timing is written to HOSTDIR/.vm/timing (boot_to_command_s, command_s, total_s).
set -uo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
modules_extra=""
share=""
timeout_s=300
boot_timeout_s=300
mem_mb=1024
smp=2
keep=0
quiet=0

usage() { sed -n '2,32p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 2; }
die() { echo "run-in-vm: ERROR: $*" >&2; exit 125; }

while [ $# -gt 0 ]; do
  case "$1" in
    --modules) modules_extra="$2"; shift 2 ;;
    --share) share="$2"; shift 2 ;;
    --timeout) timeout_s="$2"; shift 2 ;;
    --boot-timeout) boot_timeout_s="$2"; shift 2 ;;
    --mem) mem_mb="$2"; shift 2 ;;
    --smp) smp="$2"; shift 2 ;;
    --keep) keep=1; shift ;;
    --quiet) quiet=1; shift ;;
    --) shift; break ;;
    -h|--help) usage ;;
    *) echo "run-in-vm: unknown option $1" >&2; usage ;;
  esac
done
[ $# -gt 0 ] || { echo "run-in-vm: no COMMAND given" >&2; usage; }
[[ "$timeout_s" =~ ^[0-9]+$ ]] || die "--timeout wants whole seconds, got '$timeout_s'"
[[ "$boot_timeout_s" =~ ^[0-9]+$ ]] || die "--boot-timeout wants whole seconds, got '$boot_timeout_s'"

for tool in qemu-system-x86_64 cpio gzip modinfo; do
  command -v "$tool" >/dev/null || die "$tool not found (run tools/install-deps.sh)"
done
busybox=""
for b in /bin/busybox /usr/bin/busybox; do
  if [ -x "$b" ] && file -L "$b" 2>/dev/null | grep -q 'statically linked'; then busybox="$b"; fi
done
if [ -z "$busybox" ] && [ -x /bin/busybox ]; then
  # `file` may be missing; trust Debian's busybox-static.
  ldd /bin/busybox >/dev/null 2>&1 || busybox=/bin/busybox
fi
[ -n "$busybox" ] || die "no static busybox (install busybox-static)"

# --- kernel ------------------------------------------------------------------------------------
kdir="$("$here/fetch-kernel.sh" | tail -n1)" || die "fetch-kernel.sh failed"
# shellcheck disable=SC1091
. "$kdir/kernel.env"
[ -f "$VMLINUZ" ] && [ -d "$MODDIR" ] || die "broken kernel cache $kdir (delete it and retry)"

# --- results share -----------------------------------------------------------------------------
own_share=0
if [ -z "$share" ]; then
  share="$(mktemp -d /tmp/agvloc-vm.XXXXXX)"
  own_share=1
else
  mkdir -p "$share" || die "cannot create $share"
fi
share="$(cd "$share" && pwd -P)"
vm="$share/.vm"
rm -rf "$vm"
mkdir -p "$vm"
console="$vm/console.log"

# --- modules: resolve names and dependencies from the unpacked kernel ---------------------------
declare -A mod_path=()   # normalised name -> file
while IFS= read -r f; do
  n="${f##*/}"; n="${n%%.ko*}"; n="${n//-/_}"
  mod_path[$n]="$f"
done < <(find "$MODDIR" -name '*.ko' -o -name '*.ko.xz' -o -name '*.ko.zst' -o -name '*.ko.gz')
declare -A builtin=()
if [ -f "$MODDIR/modules.builtin" ]; then
  while IFS= read -r f; do n="${f##*/}"; n="${n%%.ko*}"; builtin[${n//-/_}]=1; done \
    <"$MODDIR/modules.builtin"
fi
order=()
declare -A seen=()
resolve() {  # $1: module name or path to a .ko file
  local want="$1" file name dep
  if [[ "$want" == */* || "$want" == *.ko* ]]; then
    file="$(readlink -f "$want")"
    [ -f "$file" ] || die "module file $want not found"
    name="${file##*/}"; name="${name%%.ko*}"; name="${name//-/_}"
  else
    name="${want//-/_}"
    if [ -n "${builtin[$name]:-}" ]; then return 0; fi
    file="${mod_path[$name]:-}"
    [ -n "$file" ] || die "kernel $KVER has no module '$want' (looked in $MODDIR)"
  fi
  [ -z "${seen[$name]:-}" ] || return 0
  seen[$name]=1
  for dep in $(modinfo -F depends "$file" 2>/dev/null | tr ',' ' '); do resolve "$dep"; done
  order+=("$file")
}
# virtio + 9p for the root, then the CAN stack; dependencies come first automatically.
for m in virtio_ring virtio virtio_pci_modern_dev virtio_pci_legacy_dev virtio_pci \
         netfs fscache 9pnet 9pnet_virtio 9p can can-raw can-dev vcan can-bcm can-gw \
         $modules_extra; do
  resolve "$m"
done

# --- initramfs ---------------------------------------------------------------------------------
ird="$vm/initramfs"
mkdir -p "$ird"/{bin,dev,proc,sys,newroot,results,modules}
cp "$busybox" "$ird/bin/busybox"
i=0
: >"$ird/modules.list"
for f in "${order[@]}"; do
  i=$((i + 1))
  base="$(printf '%02d' "$i")-${f##*/}"; base="${base%.xz}"; base="${base%.zst}"; base="${base%.gz}"
  # busybox insmod cannot decompress: do it here.
  case "$f" in
    *.ko.xz) xz -dc "$f" >"$ird/modules/$base" ;;
    *.ko.zst) zstd -qdc "$f" >"$ird/modules/$base" ;;
    *.ko.gz) gzip -dc "$f" >"$ird/modules/$base" ;;
    *) cp "$f" "$ird/modules/$base" ;;
  esac || die "cannot unpack module $f"
  echo "$base" >>"$ird/modules.list"
done
mknod -m 600 "$ird/dev/console" c 5 1 2>/dev/null || true

cat >"$ird/init" <<'INIT'
#!/bin/busybox sh
/bin/busybox mkdir -p /sbin /usr/bin /usr/sbin
/bin/busybox --install -s
export PATH=/bin:/sbin:/usr/bin:/usr/sbin
mount -t devtmpfs devtmpfs /dev
exec </dev/console >/dev/console 2>&1
mount -t proc proc /proc
mount -t sysfs sysfs /sys
fail() { echo "AGV-VM: INIT-FAILED: $*"; sync; poweroff -f; sleep 10; }
for m in $(cat /modules.list); do
  insmod "/modules/$m" || echo "AGV-VM: insmod $m failed"
done
mount -t 9p -o trans=virtio,version=9p2000.L,msize=262144 results /results ||
  fail "cannot mount the results share"
. /results/.vm/vm.env
mount -t 9p -o trans=virtio,version=9p2000.L,msize=262144,ro,cache=loose hostroot /newroot ||
  fail "cannot mount the host root over 9p"
R=/newroot
mount -t proc proc $R/proc && mount -t sysfs sysfs $R/sys && mount -t devtmpfs devtmpfs $R/dev ||
  fail "cannot mount proc/sys/dev in the new root"
mkdir -p $R/dev/pts $R/dev/shm
mount -t devpts devpts $R/dev/pts
# Host directories under the guest's tmpfs mount points (a checkout in /tmp, say) are kept
# visible: bound aside before the tmpfs covers them, bound back into it afterwards.
i=0
for p in $AGV_VM_KEEP; do
  mkdir -p /keep/$i && mount -o bind "$R$p" /keep/$i || fail "cannot keep $p"
  i=$((i + 1))
done
for d in /dev/shm /tmp /run /var/tmp; do
  mount -t tmpfs -o mode=1777 tmpfs $R$d || fail "cannot mount tmpfs on $d"
done
i=0
for p in $AGV_VM_KEEP; do
  mkdir -p "$R$p" && mount -o bind /keep/$i "$R$p" || fail "cannot restore $p"
  i=$((i + 1))
done
mkdir -p "$R$AGV_VM_RESULTS" 2>/dev/null
mount -o move /results "$R$AGV_VM_RESULTS" || fail "cannot move the results share to $AGV_VM_RESULTS"
# The guest kernel's modules at the standard place, so that modprobe works inside the chroot.
if [ -d "$R$AGV_VM_MODDIR" ] && mount -t tmpfs tmpfs $R/lib/modules; then
  mkdir -p "$R/lib/modules/$AGV_VM_KVER"
  mount -o bind "$R$AGV_VM_MODDIR" "$R/lib/modules/$AGV_VM_KVER"
fi
# The kernel's on-demand module loading (request_module, e.g. for `tc qdisc ... tbf`) runs
# /sbin/modprobe in THIS root, not in the chroot: give busybox modprobe the modules as well.
if [ -d "$R$AGV_VM_MODDIR" ]; then
  mkdir -p "/lib/modules/$AGV_VM_KVER"
  mount -o bind "$R$AGV_VM_MODDIR" "/lib/modules/$AGV_VM_KVER"
fi
ip link set lo up 2>/dev/null
echo "AGV-VM: COMMAND-START uptime $(cut -d' ' -f1 /proc/uptime)"
cut -d' ' -f1 /proc/uptime >"$R$AGV_VM_RESULTS/.vm/uptime_start"
chroot $R /bin/sh "$AGV_VM_RESULTS/.vm/cmd.sh" </dev/null
rc=$?
cut -d' ' -f1 /proc/uptime >"$R$AGV_VM_RESULTS/.vm/uptime_end"
echo "$rc" >"$R$AGV_VM_RESULTS/.vm/exit_code"
echo "AGV-VM: COMMAND-EXIT $rc"
sync
umount "$R$AGV_VM_RESULTS" 2>/dev/null
poweroff -f
INIT
chmod 755 "$ird/init"

# Paths the guest would otherwise lose under its own tmpfs on /tmp, /run, /var/tmp, /dev/shm:
# the working directory, this checkout and the results share (their top directory below the
# mount point, e.g. /tmp/ci for a clone in /tmp/ci), plus AGV_VM_KEEP_EXTRA (space-separated).
# Paths with spaces are not supported.
keep=""
for p in "$PWD" "$(cd "$(dirname "$0")/../../.." && pwd -P)" "$share" ${AGV_VM_KEEP_EXTRA:-}; do
  case "$p" in
    /tmp/?*|/run/?*|/var/tmp/?*|/dev/shm/?*)
      top="$(printf '%s\n' "$p" | cut -d/ -f1-3)"
      [ "${p#/var/tmp/}" != "$p" ] || [ "${p#/dev/shm/}" != "$p" ] && top="$(printf '%s\n' "$p" | cut -d/ -f1-4)"
      case " $keep " in *" $top "*) ;; *) keep="$keep $top" ;; esac ;;
  esac
done
{
  echo "AGV_VM_RESULTS='$share'"
  echo "AGV_VM_KVER='$KVER'"
  echo "AGV_VM_MODDIR='$MODDIR'"
  echo "AGV_VM_KEEP='${keep# }'"
} >"$vm/vm.env"

{
  echo "# generated by run-in-vm.sh; runs inside the guest's chroot"
  printf 'export PATH=%q\n' "$PATH"
  echo "export HOME=/tmp AGV_IN_VM=1"
  printf 'export AGV_VM_RESULTS=%q\n' "$share"
  [ -n "${LANG:-}" ] && printf 'export LANG=%q\n' "$LANG"
  # AGV_* variables (test knobs) pass through to the guest.
  for v in $(compgen -v AGV_); do
    case "$v" in AGV_VM_*|AGV_IN_VM) ;; *) printf 'export %s=%q\n' "$v" "${!v}" ;; esac
  done
  printf 'cd %q || exit 126\n' "$(pwd -P)"
  printf 'exec'
  printf ' %q' "$@"
  printf '\n'
} >"$vm/cmd.sh"

initrd="$vm/initramfs.cpio.gz"
(cd "$ird" && find . | cpio -o -H newc --quiet | gzip -1) >"$initrd" || die "cpio failed"
rm -rf "$ird"

# --- boot --------------------------------------------------------------------------------------
qemu=(qemu-system-x86_64 -accel tcg -cpu max -m "$mem_mb" -smp "$smp" -nographic -no-reboot
  -nic none -kernel "$VMLINUZ" -initrd "$initrd"
  -append "console=ttyS0 quiet loglevel=3 panic=-1 rdinit=/init"
  -fsdev local,id=root,path=/,readonly=on,security_model=none,multidevs=remap
  -device virtio-9p-pci,fsdev=root,mount_tag=hostroot
  -fsdev "local,id=res,path=$share,security_model=none,multidevs=remap"
  -device virtio-9p-pci,fsdev=res,mount_tag=results)
printf '%q ' "${qemu[@]}" >"$vm/qemu.cmd"; echo >>"$vm/qemu.cmd"

t0=$EPOCHREALTIME
: >"$console"
# Watchdog: the boot and the command each have their own limit (the command's from the moment the
# guest reports it started). It writes which one ran out, then stops qemu; `timeout` stays as the
# hard cap in case the watchdog itself is starved.
watchdog() {
  local t_start=${t0%[.,]*} now ts pid
  while [ ! -f "$vm/qemu_done" ]; do
    sleep 1
    now=${EPOCHREALTIME%[.,]*}
    ts="$(cat "$vm/t_command_start" 2>/dev/null || true)"
    if { [ -z "$ts" ] && [ $(( now - t_start )) -ge "$boot_timeout_s" ]; } ||
       { [ -n "$ts" ] && [ $(( now - ${ts%[.,]*} )) -ge "$timeout_s" ]; }; then
      if [ -n "$ts" ]; then echo command; else echo boot; fi >"$vm/timed_out"
      pid="$(cat "$vm/qemu.pid" 2>/dev/null || true)"
      [ -n "$pid" ] && kill "$pid" 2>/dev/null
      sleep 5
      [ -n "$pid" ] && kill -9 "$pid" 2>/dev/null
      return
    fi
  done
}
watchdog &
watchdog_pid=$!
timeout -k 5 $(( boot_timeout_s + timeout_s + 30 )) "${qemu[@]}" -pidfile "$vm/qemu.pid" \
  </dev/null 2>&1 | {
  while IFS= read -r line; do
    line="${line%$'\r'}"
    printf '%s\n' "$line" >>"$console"
    case "$line" in
      *"AGV-VM: COMMAND-START"*) echo "$EPOCHREALTIME" >"$vm/t_command_start" ;;
      *"AGV-VM: COMMAND-EXIT"*) echo "$EPOCHREALTIME" >"$vm/t_command_end" ;;
    esac
    [ "$quiet" = 1 ] || printf '%s\n' "$line"
  done
}
qemu_rc=${PIPESTATUS[0]}
t1=$EPOCHREALTIME
touch "$vm/qemu_done"
kill "$watchdog_pid" 2>/dev/null
wait "$watchdog_pid" 2>/dev/null

timing() {  # writes and prints seconds from qemu start to the command and the command's run time
  local ts te
  ts="$(cat "$vm/t_command_start" 2>/dev/null || true)"
  te="$(cat "$vm/t_command_end" 2>/dev/null || echo "$t1")"
  awk -v t0="$t0" -v t1="$t1" -v ts="$ts" -v te="$te" 'BEGIN {
    if (ts != "") printf "boot_to_command_s %.2f\ncommand_s %.2f\n", ts - t0, te - ts;
    printf "total_s %.2f\n", t1 - t0 }' >"$vm/timing"
}
timing

explain() {
  echo "run-in-vm: $*" >&2
  echo "run-in-vm: guest console log: $console" >&2
  echo "run-in-vm: results dir:       $share" >&2
  echo "run-in-vm: last console lines:" >&2
  tail -n 25 "$console" | sed 's/^/  | /' >&2
}

if [ -f "$vm/timed_out" ] || [ "$qemu_rc" -eq 124 ] || [ "$qemu_rc" -eq 137 ]; then
  if [ -f "$vm/t_command_start" ]; then
    explain "TIMEOUT: the command was still running after its ${timeout_s}s ($(tr '\n' ' ' <"$vm/timing"))"
  else
    explain "TIMEOUT: the boot did not reach the command within ${boot_timeout_s}s"
  fi
  exit 124
fi
if [ ! -f "$share/.vm/exit_code" ]; then
  reason="the VM stopped (qemu status $qemu_rc) without reporting an exit code"
  grep -q "INIT-FAILED" "$console" && reason="$(grep -m1 'INIT-FAILED' "$console")"
  grep -q "Kernel panic" "$console" && reason="guest kernel panic: $(grep -m1 'Kernel panic' "$console")"
  explain "$reason"
  exit 125
fi
rc="$(cat "$share/.vm/exit_code")"
echo "run-in-vm: exit code $rc; $(tr '\n' ' ' <"$vm/timing")" >&2
if [ "$rc" != 0 ]; then
  explain "COMMAND failed with exit code $rc"
elif [ "$own_share" = 1 ] && [ "$keep" = 0 ]; then
  rm -rf "$share"
fi
exit "$rc"
