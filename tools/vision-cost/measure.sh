#!/usr/bin/env bash
# Instructions per frame of the vision pipeline on x86-64 (valgrind callgrind) and on aarch64
# (qemu-aarch64 with insn_count_plugin.c), for the same frames, both RelWithDebInfo (-O2) with the
# architectures' baseline instruction sets; docs/guide/deployment.md reports it.
#   bash tools/vision-cost/measure.sh [RECORDING] [FRAMES]
# AGV_COST_PROFILE=1 also writes aarch64 instructions per function (insn_profile_plugin.c).
# AGV_COST_ARGS adds vision_cost options to every run, e.g.
#   AGV_COST_ARGS="--tracking 3 --map tools/maps/default_grid.csv --row-step 1"
# Without RECORDING it simulates one (agvloc-desk sim, 20 s at 10 fps, seed 7). Needs the cross
# environment (toolchain/prepare-aarch64.sh) and valgrind. Build dirs: build/aarch64-cost-native
# (x86-64) and build/aarch64 (the cross preset, with -DAGV_BUILD_VISION_COST=ON).
# Prints, per frame class (ok = a landmark pose; none = no pose, split into free = no landmark
# found and cut = a landmark partly outside the image), the mean instructions per frame for both
# architectures and their ratio; the aarch64 per-frame lists stay in build/aarch64-cost-results/.
set -euo pipefail
cd "$(dirname "$0")/../.."
src="$PWD"
jobs="${AGV_COST_JOBS:-2}"
nat="$src/build/aarch64-cost-native"
arm="$src/build/aarch64"
res="$src/build/aarch64-cost-results"
mkdir -p "$res"

cmake -S . -B "$nat" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DAGV_BUILD_TESTS=OFF \
      -DAGV_BUILD_BENCHMARKS=OFF -DAGV_BUILD_VISION_COST=ON >/dev/null
cmake --build "$nat" -j "$jobs" --target vision_cost agvloc-desk
# The cross preset's directory (already built by tools/cross-test.sh): only vision_cost is added.
cmake --preset aarch64 -DAGV_BUILD_VISION_COST=ON >/dev/null
cmake --build "$arm" -j "$jobs" --target vision_cost
gcc -O2 -shared -fPIC -Wall -Wextra -o "$res/insn_count_plugin.so" \
    tools/vision-cost/insn_count_plugin.c
gcc -O2 -shared -fPIC -Wall -Wextra -o "$res/insn_profile_plugin.so" \
    tools/vision-cost/insn_profile_plugin.c

rec="${1:-}"
frames="${2:-200}"
if [ -z "$rec" ]; then
  rec="$res/rec"
  "$nat/firmware/agvloc-desk" sim --out "$rec" --duration-s 20 --fps 10 --seed 7 --force >/dev/null
fi
extra="$(grep -o 'LD_LIBRARY_PATH=[^ ;]*' "$arm/CMakeCache.txt" | head -n 1 || true)"
[ -n "$extra" ] || extra="LD_LIBRARY_PATH=/opt/agvloc-aarch64/usr/lib/aarch64-linux-gnu:/opt/agvloc-aarch64/usr/lib"

printf '%-6s %8s %16s %16s %8s\n' class frames x86-64/frame aarch64/frame ratio
for cls in ok none free cut; do
  # x86-64: callgrind collects only inside agv_cost_frame (the measured calls).
  valgrind --tool=callgrind --collect-atstart=no --toggle-collect='agv_cost_frame*' \
           --callgrind-out-file="$res/callgrind.$cls.out" \
           "$nat/tools/vision-cost/vision_cost" "$rec" --frames "$frames" --class "$cls" ${AGV_COST_ARGS:-} \
           >"$res/native.$cls.log" 2>"$res/callgrind.$cls.log"
  n="$(sed -n 's/.*: \([0-9]*\) measured.*/\1/p' "$res/native.$cls.log")"
  ir="$(sed -n 's/^summary: *\([0-9]*\).*/\1/p' "$res/callgrind.$cls.out")"
  # aarch64: the plugin writes one count per measured frame.
  qemu-aarch64 -E "$extra" -plugin "$res/insn_count_plugin.so,out=$res/aarch64.$cls.txt" \
               "$arm/tools/vision-cost/vision_cost" "$rec" --frames "$frames" --class "$cls" ${AGV_COST_ARGS:-} \
               >"$res/aarch64.$cls.log" 2>&1
  n_arm="$(wc -l <"$res/aarch64.$cls.txt")"
  if [ "$n" != "$n_arm" ]; then
    echo "frame counts differ: x86-64 $n, aarch64 $n_arm" >&2
    exit 1
  fi
  arm_sum="$(awk '{s += $1} END {printf "%.0f", s}' "$res/aarch64.$cls.txt")"
  # Check of the counting method: the plugin under qemu-x86_64 on the x86-64 binary must agree
  # with callgrind.
  qemu-x86_64 -plugin "$res/insn_count_plugin.so,out=$res/x86qemu.$cls.txt,nr=157" \
              "$nat/tools/vision-cost/vision_cost" "$rec" --frames "$frames" --class "$cls" ${AGV_COST_ARGS:-} \
              >"$res/x86qemu.$cls.log" 2>&1
  awk -v x="$ir" '{s += $1} END {printf "  method check: qemu-x86_64 plugin / callgrind = %.5f\n", s / x}' \
      "$res/x86qemu.$cls.txt"
  awk -v c="$cls" -v n="$n" -v x="$ir" -v a="$arm_sum" \
      'BEGIN {printf "%-6s %8d %16.0f %16.0f %8.3f\n", c, n, x / n, a / n, a / x}'
  # AGV_COST_PROFILE=1: where the aarch64 instructions go, per function (inlined code counts for
  # its caller), as totals over the class's frames.
  if [ "${AGV_COST_PROFILE:-0}" = 1 ]; then
    qemu-aarch64 -E "$extra" -plugin "$res/insn_profile_plugin.so,out=$res/aarch64-profile.$cls.txt" \
                 "$arm/tools/vision-cost/vision_cost" "$rec" --frames "$frames" --class "$cls" ${AGV_COST_ARGS:-} \
                 >/dev/null 2>&1
    echo "  aarch64 per function: $res/aarch64-profile.$cls.txt (c++filt for names)"
  fi
  sort -n "$res/aarch64.$cls.txt" |
    awk -v c="$cls" '{v[NR] = $1} END {printf "  aarch64 %s: min %d median %d max %d\n", c, v[1], v[int((NR + 1) / 2)], v[NR]}'
done
