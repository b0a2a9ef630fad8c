#!/usr/bin/env bash
# Rack landmarks between floor landmarks on a simulated drive, wheels only (docs/design/ranging.md,
# "Drive evaluation"). Per seed:
#   1. `agvloc-desk sim`: a lawnmower drive of two 9 m aisles over a sparse floor grid (3 x 2
#      landmarks 4 m apart: 4 s legs on the aisles, about 7 s through the U-turn), 1 m/s;
#   2. imu.csv removed (wheels only);
#   3. render_ranging_stream: a rack between the aisles with a pair of tag36h11 landmarks every
#      2 m on both faces and a pair on each end, seen by a camera looking left (640 x 400,
#      f = 400 px, 1 m up), rendered at the truth at 10 fps into REC/ranging/;
#   4. `agvloc replay` without a configuration (floor camera and wheels) and with REC/ranging.yaml
#      (the second camera on), on the same recording;
#   5. tools/eval/fusion/score_replay.py on both (between-landmark = valid ticks >= 200 ms after
#      the last floor fix: rack landmark updates do not reset time_since_fix_ms), and the share of
#      valid ticks after the first fix.
# Not a ctest (about 1-2 min per seed on a 2-core machine). SLIP_RATE_PER_S and DURATION_S (30) set
# the drive.
#   rack_drive_eval.sh WORKDIR AGVLOC AGVLOC-DESK RENDER_RANGING_STREAM [SEEDS...]
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../../.." && pwd)"
WORK="$1"
AGVLOC="$(realpath "$2")"
DESK="$(realpath "$3")"
RENDER="$(realpath "$4")"
shift 4
SEEDS=("$@")
[ "${#SEEDS[@]}" -eq 0 ] && SEEDS=(1)
DURATION_S="${DURATION_S:-30}"
# SLIP_RATE_PER_S: wheel slips per second in the simulated drive (empty: the simulator's default).
SLIP=()
[ -n "${SLIP_RATE_PER_S:-}" ] && SLIP=(--slip-rate-per-s "$SLIP_RATE_PER_S")
mkdir -p "$WORK"
cd "$WORK"

cat > sparse_map.csv <<'EOF'
# rack_drive_eval: 3 x 2 floor landmarks 4 m apart (format: docs/design/landmark.md)
id,x_mm,y_mm,heading_deg
1,0.0,0.0,0.00
2,4000.0,0.0,90.00
3,8000.0,0.0,180.00
4,0.0,4000.0,-90.00
5,4000.0,4000.0,0.00
6,8000.0,4000.0,90.00
EOF

now() { date +%s.%N; }
pairs=()
for seed in "${SEEDS[@]}"; do
  rec="rack_$seed"
  t0=$(now)
  # The simulated drive is kept between runs (same seed, same recording).
  if [ ! -f "$rec/truth.csv" ]; then
    "$DESK" sim --out "$rec" --map sparse_map.csv --grid-spacing-mm 4000 --trajectory lawnmower \
      --duration-s "$DURATION_S" --speed-mps 1.0 --seed "$seed" "${SLIP[@]}" --force > "$rec.sim.log"
  fi
  rm -rf "$rec/imu.csv" "$rec/ranging"
  t1=$(now)
  "$RENDER" "$rec" --seed "$seed" | tee "$rec.render.log"
  t2=$(now)
  rm -rf "out_floor_$seed" "out_rack_$seed"
  "$AGVLOC" replay "$rec" --fast --quiet --out "out_floor_$seed" > "replay_floor_$seed.log" 2>&1 || {
    cat "replay_floor_$seed.log"; echo "rack_drive_eval: replay failed" >&2; exit 1; }
  t3=$(now)
  "$AGVLOC" replay "$rec" --fast --quiet --config "$rec/ranging.yaml" --out "out_rack_$seed" \
    > "replay_rack_$seed.log" 2>&1 || {
    cat "replay_rack_$seed.log"; echo "rack_drive_eval: replay failed" >&2; exit 1; }
  t4=$(now)
  grep -h "ranging camera" "replay_rack_$seed.log" "out_rack_$seed/summary.txt" 2>/dev/null | head -3 || true
  printf 'seed %s wall s: sim %.1f, render %.1f, replay floor only %.1f, with racks %.1f\n' "$seed" \
    "$(echo "$t1 - $t0" | bc)" "$(echo "$t2 - $t1" | bc)" "$(echo "$t3 - $t2" | bc)" \
    "$(echo "$t4 - $t3" | bc)"
  pairs+=("$rec" "out_floor_$seed" "$rec" "out_rack_$seed")
done
python3 "$ROOT/tools/eval/fusion/score_replay.py" "${pairs[@]}"
# Valid share: valid ticks after the first valid one (what a controller sees once localized).
echo
echo "| run | valid % after the first fix | ticks > 200 ms from a floor fix |"
echo "|---|---|---|"
for ((i = 1; i < ${#pairs[@]}; i += 2)); do
  python3 - "${pairs[$i]}/poses.csv" <<'EOF'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
first = next((k for k, r in enumerate(rows) if r["valid"] == "1"), len(rows))
after = rows[first:]
valid = sum(r["valid"] == "1" for r in after)
btw = sum(r["valid"] == "1" and float(r["time_since_fix_ms"]) >= 200 for r in after)
print(f"| {sys.argv[1].split('/')[0]} | {100.0 * valid / max(1, len(after)):.2f} | {btw} |")
EOF
done
