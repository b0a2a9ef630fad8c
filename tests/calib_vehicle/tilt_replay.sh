#!/usr/bin/env bash
# Camera tilt end to end (docs/design/frames.md "Camera tilt"): simulate a tilted camera
# (realistic degradations), replay it with the tilt in the recording's camera model (sub-0.1 mm
# fixes vs truth) and with the tilt removed (a clear bias, about height * tan(tilt) = 5 mm).
#   tilt_replay.sh AGVLOC WORKDIR     (agvloc-desk is beside AGVLOC)
set -euo pipefail
AGVLOC="$1"
DESK="$(dirname "$AGVLOC")/agvloc-desk"
WORK="$2"
rm -rf "$WORK"
mkdir -p "$WORK"
"$DESK" sim --out "$WORK/rec" --trajectory line --duration-s 6 --fps 15 --seed 3 \
  --roll-deg 1.2 --pitch-deg -0.8 --mount-offset-x-mm 30 > "$WORK/sim.log"
grep -q "roll_deg: 1.2" "$WORK/rec/meta.yaml" || { echo "FAIL: meta.yaml has no roll_deg"; exit 1; }
cp -r "$WORK/rec" "$WORK/rec_flat"
sed -i '/roll_deg\|pitch_deg/d' "$WORK/rec_flat/meta.yaml"
"$AGVLOC" replay "$WORK/rec" --out "$WORK/out" --fast --quiet > "$WORK/replay.log"
"$AGVLOC" replay "$WORK/rec_flat" --out "$WORK/out_flat" --fast --quiet > "$WORK/replay_flat.log"
python3 - "$WORK" <<'PY'
import csv, math, sys
w = sys.argv[1]
truth = {int(r["t_ns"]): r for r in csv.DictReader(open(f"{w}/rec/truth.csv"))}
def errs(out):
    e = []
    for r in csv.DictReader(open(f"{w}/{out}/fixes.csv")):
        if r["status"] == "ok":
            t = truth[int(r["t_ns"])]
            e.append(math.hypot(float(r["x_mm"]) - float(t["x_mm"]), float(r["y_mm"]) - float(t["y_mm"])))
    return e
right, flat = errs("out"), errs("out_flat")
print(f"tilted camera (roll 1.2, pitch -0.8 deg), simulated frames: {len(right)} fixes, "
      f"worst {max(right):.4f} mm with the tilt, least {min(flat):.3f} mm without")
ok = len(right) >= 8 and len(flat) == len(right) and max(right) < 0.1 and min(flat) > 3.0
sys.exit(0 if ok else 1)
PY
