#!/usr/bin/env bash
# The desk tools live in agvloc-desk, not in the vehicle binary:
#   desk_split.sh "EMULATOR... AGVLOC" "EMULATOR... AGVLOC-DESK" NM WORKDIR
# 1. `agvloc sim|landmark|report` exit 2 and name agvloc-desk;
# 2. agvloc defines no simulator or desk symbol, agvloc-desk does (so a stripped or renamed
#    binary fails the check instead of passing it);
# 3. sim -> replay -> report end to end: accuracy against truth and trajectory.svg.
set -euo pipefail
read -r -a AGVLOC <<< "$1"
read -r -a DESK <<< "$2"
NM="$3"
WORK="$4"
rm -rf "$WORK"
mkdir -p "$WORK"
fail() { echo "FAIL: $*"; exit 1; }

for c in sim landmark report calibrate sim-board; do
  rc=0
  "${AGVLOC[@]}" "$c" --out "$WORK/x" > "$WORK/$c.out" 2> "$WORK/$c.err" || rc=$?
  [ "$rc" = 2 ] || fail "agvloc $c exited $rc, expected 2"
  grep -q "agvloc-desk $c" "$WORK/$c.err" || fail "agvloc $c: no pointer to agvloc-desk: $(cat "$WORK/$c.err")"
  [ ! -e "$WORK/x" ] || fail "agvloc $c wrote output"
done

# Every desk command and calibrate subcommand is in the top-level help (it once listed only
# calibrate intrinsics).
"${DESK[@]}" --help > "$WORK/desk_help.txt"
for want in "sim " "landmark" "report" "sim-board" "calibrate intrinsics" "calibrate vehicle" \
            "calibrate check" "config apply"; do
  grep -q -- "$want" "$WORK/desk_help.txt" || fail "agvloc-desk --help does not list '$want'"
done

bin_of() { local a=("$@"); echo "${a[-1]}"; }
vehicle_syms="$("$NM" -C --defined-only "$(bin_of "${AGVLOC[@]}")")"
desk_syms="$("$NM" -C --defined-only "$(bin_of "${DESK[@]}")")"
for ns in 'agv::sim::' 'agv::desk::' 'agv::plot::'; do
  n_desk=$(grep -c "$ns" <<< "$desk_syms" || true)
  [ "$n_desk" -gt 0 ] || fail "agvloc-desk defines no $ns symbol: the check would prove nothing"
  if grep "$ns" <<< "$vehicle_syms" > "$WORK/leak.txt"; then
    fail "agvloc defines $(wc -l < "$WORK/leak.txt") $ns symbols, e.g. $(head -1 "$WORK/leak.txt")"
  fi
  echo "ok: $ns: 0 symbols in agvloc, $n_desk in agvloc-desk"
done

"${DESK[@]}" sim --out "$WORK/rec" --trajectory line --duration-s 2 --fps 10 --seed 3 \
  --degrade clean > "$WORK/sim.log"
"${AGVLOC[@]}" replay "$WORK/rec" --out "$WORK/out" --fast --quiet > "$WORK/replay.log"
grep -q "agvloc-desk report" "$WORK/replay.log" || fail "replay does not point to the report"
[ ! -e "$WORK/out/trajectory.svg" ] || fail "the vehicle replay wrote a plot"
"${DESK[@]}" report "$WORK/out" --recording "$WORK/rec" > "$WORK/report.log"
grep -q "^accuracy against truth.csv" "$WORK/report.log" || fail "no accuracy: $(cat "$WORK/report.log")"
# A clean 2 s line past landmarks: the vision fixes are within a few mm of the truth.
awk '/vision fixes/ { split($5, n, "="); if (n[2] + 0 < 1 || $7 + 0 > 10.0) bad = 1; seen = 1 }
     END { exit !(seen && !bad) }' "$WORK/report.log" ||
  fail "vision fixes not n >= 1 with p50 <= 10 mm: $(grep 'vision fixes' "$WORK/report.log")"
grep -q "<svg" "$WORK/out/trajectory.svg" || fail "no trajectory.svg"
grep -q "fused (EKF)" "$WORK/out/trajectory.svg" || fail "trajectory.svg without the fused track"
echo "ok: sim -> replay -> report"
