#!/usr/bin/env bash
# test_package.sh BUILD_DIR DEB_ARCH ELF_MACHINE LIVE_CAMERA(0|1) "EMULATOR ARGS" (may be empty)
# Builds the .deb with cpack, unpacks it and checks it; see CMakeLists.txt beside this file.
set -euo pipefail
build="$1" arch="$2" elf="$3" live="$4" emu="$5"
src="${AGV_SOURCE_DIR:?}"
fails=0
check() {  # check DESCRIPTION COMMAND...
  local what="$1"; shift
  if "$@"; then echo "PASS $what"; else echo "FAIL $what"; fails=$((fails + 1)); fi
}

work="$build/package-test"
rm -rf "$work"
mkdir -p "$work"
(cd "$build" && cpack --config CPackConfig.cmake) >"$work/cpack.log" 2>&1 ||
  { cat "$work/cpack.log"; echo "FAIL cpack"; exit 1; }
deb="$(ls "$build"/packages/agvloc_*_"$arch".deb)"
echo "package: $deb ($(du -h "$deb" | cut -f1))"

# Metadata.
info="$(dpkg-deb -f "$deb")"
check "Package: agvloc" grep -qx "Package: agvloc" <<<"$info"
check "Architecture: $arch" grep -qx "Architecture: $arch" <<<"$info"
check "Depends names OpenCV core, libc and libstdc++" \
  grep -qE "^Depends: .*libc6 \(>= .*libopencv-core406 \(>= .*libstdc\+\+6" <<<"$info"
dpkg-deb -e "$deb" "$work/control"
check "config is a conffile" grep -qx "/etc/agvloc/agvloc.yaml" "$work/control/conffiles"
check "map is a conffile" grep -qx "/etc/agvloc/map.csv" "$work/control/conffiles"
for s in postinst prerm postrm; do
  check "$s executable, valid sh" bash -c "test -x '$work/control/$s' && sh -n '$work/control/$s'"
done

# Files.
root="$work/root"
dpkg-deb -x "$deb" "$root"
for f in usr/bin/agvloc etc/agvloc/agvloc.yaml etc/agvloc/map.csv lib/systemd/system/agvloc.service \
         usr/lib/sysusers.d/agvloc.conf usr/share/doc/agvloc/design/frames.md usr/share/doc/agvloc/guide/operation.md; do
  check "contains /$f" test -s "$root/$f"
done
if [ -f "$src/can/agvloc.dbc" ]; then
  check "contains /usr/share/agvloc/agvloc.dbc" cmp -s "$src/can/agvloc.dbc" "$root/usr/share/agvloc/agvloc.dbc"
fi
check "no desk tool in the package" test ! -e "$root/usr/bin/agvloc-desk"
# The site tracker, where this build has it (AGV_BUILD_OVERHEAD_APP): for x86-64 and arm64 edge computers.
if [ -x "$build/overhead/agvloc-overhead" ]; then
  check "contains /usr/bin/agvloc-overhead" test -s "$root/usr/bin/agvloc-overhead"
  check "agvloc-overhead is $elf" grep -q "$elf" <<<"$(file -b "$root/usr/bin/agvloc-overhead")"
fi
check "config names the shipped map" grep -qE "^  map: map.csv" "$root/etc/agvloc/agvloc.yaml"
check "binary is $elf" grep -q "$elf" <<<"$(file -b "$root/usr/bin/agvloc")"
check "binary stripped" grep -q ", stripped" <<<"$(file -b "$root/usr/bin/agvloc")"
unit="$root/lib/systemd/system/agvloc.service"
for line in "User=agvloc" "SupplementaryGroups=video" "Restart=on-failure" "LimitRTPRIO=80" \
            "LimitMEMLOCK=infinity" "ExecStart=/usr/bin/agvloc run --config /etc/agvloc/agvloc.yaml"; do
  check "unit has $line" grep -qx "$line" "$unit"
done
# Address families: what each network feature needs that the configuration can enable, and the
# key that enables it (the key must exist: docs/guide/config.md is generated from the key table). A
# RestrictAddressFamilies= without them makes the feature fail only on the vehicle.
families=" $(sed -n 's/^RestrictAddressFamilies=//p' "$unit" | tr '\n' ' ') "
check "unit restricts address families" test -n "${families// /}"
check "unit's address families are an allow-list" bash -c "! grep -q '~' <<<'$families'"
for need in "always:AF_CAN:CAN pose output and odometry" \
            "always:AF_UNIX:journald" \
            "always:AF_NETLINK:libcamera's udev monitor" \
            "diag.enabled:AF_INET AF_INET6:diagnostics page" \
            "vda5050.enabled:AF_INET AF_INET6:VDA 5050 MQTT client"; do
  key="${need%%:*}" rest="${need#*:}"
  fams="${rest%%:*}" what="${rest#*:}"
  if [ "$key" != always ] && [ -f "$src/docs/guide/config.md" ]; then
    check "$key is a configuration key" grep -qF "\`$key\`" "$src/docs/guide/config.md"
  fi
  for fam in $fams; do
    check "unit allows $fam ($what, $key)" grep -q " $fam " <<<"$families"
  done
done
if command -v systemd-analyze >/dev/null 2>&1; then
  # verify checks keys, values and that ExecStart exists: point it at the unpacked binary. It
  # exits 0 even for unknown keys, so any output fails the check.
  sed "s#/usr/bin/agvloc#$root/usr/bin/agvloc#" "$unit" >"$work/agvloc.service"
  systemd-analyze verify "$work/agvloc.service" >"$work/verify.log" 2>&1 || true
  check "systemd-analyze verify: no complaints" test ! -s "$work/verify.log"
  cat "$work/verify.log"
fi

# Run the packaged binary (emulated for arm64).
run() { $emu "$root/usr/bin/agvloc" "$@"; }
ver="$(run --version)"
echo "--version: $ver"
check "--version names the version" grep -qE "^agvloc [0-9]+\.[0-9]+\.[0-9]+ " <<<"$ver"
if [ "$live" = 1 ]; then
  check "--version: live camera build" grep -q "live camera: libcamera" <<<"$ver"
else
  check "--version: replay-only build" grep -q "replay-only build" <<<"$ver"
fi

# The vehicle binary has no simulator: `sim` is a usage error that names the desk tool.
sim_rc=0
run sim --out "$work/nosim" >"$work/nosim.log" 2>&1 || sim_rc=$?
check "packaged agvloc sim exits 2 and names agvloc-desk" \
  bash -c "test $sim_rc = 2 && grep -q 'agvloc-desk sim' '$work/nosim.log'"

# A short simulated drive (2 s at 10 fps over the default landmark grid) from the desk tool of
# the build tree, replayed by the packaged binary with the shipped /etc configuration.
rec="$work/rec"
out="$work/out"
# AGV_DESK: the simulator command (a native one in the cross build: AGV_HOST_DESK).
read -r -a desk <<< "${AGV_DESK:-$emu $build/firmware/agvloc-desk}"
if "${desk[@]}" sim --out "$rec" --duration-s 2 --fps 10 --seed 7 \
     >"$work/sim.log" 2>&1; then
  echo "PASS sim wrote $(($(wc -l <"$rec/frames.csv") - 1)) frames"
else
  cat "$work/sim.log"; echo "FAIL sim"; fails=$((fails + 1))
fi
if run replay "$rec" --out "$out" --fast --config "$root/etc/agvloc/agvloc.yaml" \
     >"$work/replay.log" 2>&1; then
  echo "PASS replay exit 0"
  rows=$(($(wc -l <"$out/poses.csv") - 1))
  check "replay wrote poses ($rows rows)" test "$rows" -gt 0
else
  tail -n 20 "$work/replay.log"; echo "FAIL replay"; fails=$((fails + 1))
fi

if [ "$fails" -ne 0 ]; then
  echo "$fails check(s) failed"
  exit 1
fi
echo "all package checks passed"
