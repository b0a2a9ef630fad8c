#!/usr/bin/env bash
# agvloc-desk calibrate vehicle end to end on rendered simulated frames (clean, 15 fps, 60 s of
# the `calibration` trajectory), with a perturbed true camera and odometry; the recording states
# the nominal mounting (--nominal-meta), has no use for truth.csv (deleted before calibrating).
# Prints recovered vs true and checks the commissioning targets. Then: a `square` drive (no turns on
# the spot over a landmark) must refuse the offset; a wrong map and a recording without odometry
# must fail naming what is missing.
#   calibrate_vehicle_e2e.sh AGVLOC-DESK WORKDIR
set -euo pipefail
DESK="$1"
WORK="$2"
MAP="$(cd "$(dirname "$0")/../.." && pwd)/tools/maps/default_grid.csv"
rm -rf "$WORK"
mkdir -p "$WORK"
# Unequal wheels at the simulator's default (--odom-asymmetry 0.004: the right wheel reads 0.4 %
# more on the 500 mm track): the yaw_per_metre term must take them, not the mounting.
PERTURB=(--slip-rate-per-s 0 --odom-asymmetry 0.004 --odom-scale-error 0.02 --odom-yaw-scale-error
  -0.015 --odom-yaw-bias-degps 0.3 --odom-time-offset-ms 20 --mount-offset-x-mm 6
  --mount-offset-y-mm -4 --mount-yaw-deg 1.2 --mount-height-mm 203 --roll-deg 0.8
  --pitch-deg -1.0 --nominal-meta)
"$DESK" sim --out "$WORK/rec" --trajectory calibration --duration-s 60 --fps 15 --seed 5 \
  --degrade clean "${PERTURB[@]}" > "$WORK/sim.log"
rm -f "$WORK/rec/truth.csv"
"$DESK" calibrate vehicle "$WORK/rec" --map "$MAP" --out "$WORK/cal" > "$WORK/cal.log" 2>&1 || {
  cat "$WORK/cal.log"; echo "FAIL: calibrate vehicle failed"; exit 1; }
for f in vehicle_calibration.yaml report.txt residuals.svg; do
  [ -s "$WORK/cal/$f" ] || { echo "FAIL: no $f"; exit 1; }
done
python3 - "$WORK/cal/report.txt" <<'PY'
import sys
# true values; odometry: reported v = 1.02 v + a b / 4 omega,
# omega = 0.985 (1.02 omega + a / b v) + 0.3 deg/s with unequal wheels a = 0.004, track b = 0.5 m;
# the correction inverts that (calib_vehicle.hpp: its speed term is yaw_per_metre b^2 / 4).
import math
k = 1.02 * 0.985
a, b = 0.004, 0.5
det = 0.985 * (1.02 ** 2 - a * a / 4)
yaw_per_metre_deg = math.degrees(-0.985 * (a / b) / det)
truth = {"mounting.offset_x_mm": (6, 0.2), "mounting.offset_y_mm": (-4, 0.2),
         "mounting.yaw_deg": (1.2, 0.02), "mounting.height_mm": (203, 0.2),
         "mounting.roll_deg": (0.8, 0.05), "mounting.pitch_deg": (-1.0, 0.05),
         "odometry.speed_scale": (1 / 1.02, 0.0005 / 1.02),
         "odometry.yaw_rate_scale": (1 / k, 0.0005 / k),
         "odometry.yaw_rate_bias_degps": (-0.3 / k, 0.01),
         "odometry.yaw_per_metre_deg": (yaw_per_metre_deg, 0.12),
         "camera.time_offset_ms": (20, 0.5)}
got = {}
for line in open(sys.argv[1]):
    f = line.split()
    if f and f[0] in truth:
        got[f[0]] = (float(f[2]), float(f[3]), f[4])
bad = 0
print("simulated frames (clean, 15 fps, 60 s calibration drive): recovered vs true")
for name, (t, tol) in truth.items():
    v, s, st = got[name]
    ok = abs(v - t) <= tol and st == "ok"
    bad += not ok
    print(f"  {name:30s} true {t:11.5f} recovered {v:11.5f} error {v - t:+.5f} "
          f"sigma {s:.5f} target {tol:.5f} {'ok' if ok else 'FAIL'}")
sys.exit(1 if bad else 0)
PY
# The snippet carries the odometry keys (v_omega mode) ...
for k in speed_scale yaw_rate_scale yaw_rate_bias_degps yaw_per_metre_deg; do
  grep -q "^  $k: " "$WORK/cal/vehicle_calibration.yaml" || { echo "FAIL: odometry.$k not written"; exit 1; }
done
# ... the camera's clock offset in the camera section ...
grep -Pzq '\ncamera:\n  time_offset_ms: ' "$WORK/cal/vehicle_calibration.yaml" || { echo "FAIL: camera.time_offset_ms not written"; exit 1; }
# ... and in wheels mode the yaw-rate scale as the track width the samples were decoded with
# divided by the scale (here 640 mm / scale), odometry.yaw_rate_scale then 1.
printf 'intrinsics: {fx: 769.23076923076917, fy: 769.23076923076917, cx: 319.5, cy: 239.5}\ncan:\n  odometry:\n    mode: wheels\n    track_width_mm: 640\n' > "$WORK/wheels.yaml"
"$DESK" calibrate vehicle "$WORK/rec" --map "$MAP" --config "$WORK/wheels.yaml" --out "$WORK/calw" > "$WORK/calw.log" 2>&1 || {
  cat "$WORK/calw.log"; echo "FAIL: calibrate vehicle (wheels) failed"; exit 1; }
python3 - "$WORK/cal/report.txt" "$WORK/calw/vehicle_calibration.yaml" <<'PY'
import re, sys
scale = next(float(l.split()[2]) for l in open(sys.argv[1]) if l.startswith("odometry.yaw_rate_scale"))
snip = open(sys.argv[2]).read()
m = re.search(r"^can:\n  odometry:\n    track_width_mm: ([\d.]+)", snip, re.M)
y = re.search(r"^  yaw_rate_scale: (\S+)", snip, re.M)
if not m or not y or float(y.group(1)) != 1.0 or abs(float(m.group(1)) - 640 / scale) > 0.01:
    sys.exit(f"FAIL: wheels snippet (scale {scale}):\n{snip}")
print(f"wheels mode: track_width_mm {m.group(1)} = 640 / {scale}")
PY
# No turns on the spot over a landmark: the offset must be refused (exit 1, not written).
"$DESK" sim --out "$WORK/sq" --trajectory square --duration-s 40 --fps 15 --seed 5 \
  --degrade clean "${PERTURB[@]}" > "$WORK/sq_sim.log"
if "$DESK" calibrate vehicle "$WORK/sq" --map "$MAP" --out "$WORK/sq_cal" > "$WORK/sq.log" 2>&1; then
  echo "FAIL: square drive accepted"; exit 1
fi
grep -q "offset_x_mm is not determined" "$WORK/sq.log" || { echo "FAIL: offset not refused"; exit 1; }
grep -q "^  offset_x_mm:" "$WORK/sq_cal/vehicle_calibration.yaml" && { echo "FAIL: offset written"; exit 1; }
# A map without these landmarks.
printf 'id,x_mm,y_mm,heading_deg\n900,0,0,0\n' > "$WORK/wrong.csv"
if "$DESK" calibrate vehicle "$WORK/rec" --map "$WORK/wrong.csv" --out "$WORK/w" > "$WORK/w.log" 2>&1; then
  echo "FAIL: wrong map accepted"; exit 1
fi
grep -q "likely cause: the map: landmarks 1, 2, 3, 4 were read but are not in the map" "$WORK/w.log" ||
  { cat "$WORK/w.log"; echo "FAIL: wrong map not named"; exit 1; }
# A recording without odometry.
cp -r "$WORK/rec" "$WORK/noodo"
head -1 "$WORK/rec/odom.csv" > "$WORK/noodo/odom.csv"
if "$DESK" calibrate vehicle "$WORK/noodo" --map "$MAP" --out "$WORK/n" > "$WORK/n.log" 2>&1; then
  echo "FAIL: recording without odometry accepted"; exit 1
fi
grep -q "has no odometry" "$WORK/n.log" || { cat "$WORK/n.log"; echo "FAIL: missing odometry not named"; exit 1; }
echo "calibrate vehicle end to end OK"
