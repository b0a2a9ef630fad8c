#!/usr/bin/env bash
# A commissioned gyro on rendered drives (docs/design/fusion.md, "Heading on a rendered drive"):
# the integrator's path end to end, all on simulated frames.
#   1. a 60 s calibration drive (15 fps, clean imaging, no slips) of one simulated vehicle:
#      the simulator's default odometry errors and its default MEMS gyro (0.3 % scale error,
#      +0.2 deg/s bias, bias instability and walk, 0.01 deg/s/sqrt(Hz) noise);
#   2. `agvloc-desk calibrate vehicle` on it, and `agvloc-desk config apply` of its snippet to
#      the shipped configuration;
#   3. 40 s lawnmower drives of the same vehicle (30 fps, 0.2 wheel slips/s), seeds 1-3, each
#      replayed with the shipped configuration (gyro and odometry priors at their defaults) and
#      with the commissioned one;
#   4. tools/eval/fusion/score_replay.py on every replay: between-landmark p95 position and
#      heading error, 3-sigma coverage, e/sigma RMS.
# Not run by CI (about 6 min of rendering on a 2-core machine).
#   commissioned_gyro.sh WORKDIR AGVLOC AGVLOC-DESK [SEEDS...]
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../../.." && pwd)"
WORK="$1"
AGVLOC="$(realpath "$2")"
DESK="$(realpath "$3")"
shift 3
SEEDS=("$@")
[ "${#SEEDS[@]}" -eq 0 ] && SEEDS=(1 2 3)
MAP="$ROOT/tools/maps/default_grid.csv"
mkdir -p "$WORK"
cd "$WORK"

if [ ! -f cal_rec/meta.yaml ]; then
  "$DESK" sim --out cal_rec --trajectory calibration --duration-s 60 --fps 15 --seed 7 \
    --degrade clean --slip-rate-per-s 0 --force > cal_sim.log
fi
rm -rf cal
"$DESK" calibrate vehicle cal_rec --map "$MAP" --out cal > cal.log 2>&1 || {
  cat cal.log; echo "commissioned_gyro: calibrate vehicle failed" >&2; exit 1; }
grep -E "^(imu|odometry|mounting)\." cal/report.txt || true
# The shipped configuration with this drive's camera (the simulator's) and the repository's map.
sed -e "s#^  map: .*#  map: $MAP#" "$ROOT/firmware/config/agvloc.yaml" > shipped.yaml
"$DESK" config apply --config shipped.yaml --out commissioned.yaml --force \
  cal/vehicle_calibration.yaml > apply.log 2>&1 || {
  cat apply.log; echo "commissioned_gyro: config apply failed" >&2; exit 1; }

pairs=()
for seed in "${SEEDS[@]}"; do
  rec="lawn_$seed"
  if [ ! -f "$rec/meta.yaml" ]; then
    "$DESK" sim --out "$rec" --trajectory lawnmower --duration-s 40 --fps 30 --speed-mps 1.0 \
      --seed "$seed" --slip-rate-per-s 0.2 --force > "$rec.sim.log"
  fi
  for cfg in shipped commissioned; do
    "$AGVLOC" replay "$rec" --fast --quiet --config "$cfg.yaml" --out "out_${cfg}_$seed" \
      > "replay_${cfg}_$seed.log" 2>&1 || {
      cat "replay_${cfg}_$seed.log"; echo "commissioned_gyro: replay failed" >&2; exit 1; }
    pairs+=("$rec" "out_${cfg}_$seed")
  done
done
python3 "$HERE/score_replay.py" "${pairs[@]}"
