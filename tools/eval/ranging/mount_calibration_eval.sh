#!/usr/bin/env bash
# The second camera's mount calibrated from the rack drive (docs/design/ranging.md, "Calibrating
# the mount"). Per seed, on rack_drive_eval.sh's recording (made if missing):
#   1. a configuration whose mount is off by the switch-on evaluation's calibration errors
#      (OFF_MM per offset, OFF_DEG per angle; defaults 5 mm and 1 deg), all four configurations
#      stating the lens's focal doubt FOCAL_SIGMA_REL (0.001);
#   2. `agvloc-desk calibrate ranging-mount` from it, the recording and the floor-only replay;
#      the mount (and its sigma) it writes put into that configuration;
#   3. the calibrated mount against the renderer's (the truth), per axis in sigmas;
#   4. `agvloc replay` with the off mount (stated exact, and with its offsets as its sigma), the
#      calibrated and the true mount, scored as
#      rack_drive_eval.sh scores its replays.
# Not a ctest (a few minutes per seed). SLIP_RATE_PER_S: unset = no slips, empty = the simulator's
# default slips, a number = that rate.
#   mount_calibration_eval.sh WORKDIR AGVLOC AGVLOC-DESK RENDER_RANGING_STREAM [SEEDS...]
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
OFF_MM="${OFF_MM:-5}"
OFF_DEG="${OFF_DEG:-1}"
# The lens calibration's focal-length doubt every configuration states (a ChArUco calibration's
# order): the calibration solves the focal scale beside the mount with it (corners on rendered
# frames read tags about 0.1 % large, which lands on the offset along the optical axis).
FOCAL_SIGMA_REL="${FOCAL_SIGMA_REL:-0.001}"
mkdir -p "$WORK"
for seed in "${SEEDS[@]}"; do
  rec="$WORK/rack_$seed"
  if [ ! -f "$rec/ranging/frames.csv" ] || [ ! -f "$WORK/out_floor_$seed/poses.csv" ]; then
    SLIP_RATE_PER_S="${SLIP_RATE_PER_S-0}" "$HERE/rack_drive_eval.sh" "$WORK" "$AGVLOC" "$DESK" \
      "$RENDER" "$seed" > "$WORK/rack_drive_$seed.log"
  fi
  # The true mount is the one ranging.yaml states; the off one moves every axis.
  python3 - "$rec/ranging.yaml" "$rec/off.yaml" "$OFF_MM" "$OFF_DEG" "$FOCAL_SIGMA_REL" \
    "$rec/true.yaml" <<'EOF'
import re, sys
src, dst, mm, deg = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
text = open(src).read().replace("  mount:", f"  focal_sigma_rel: {sys.argv[5]}\n  mount:")
open(sys.argv[6], "w").write(text)
m = re.search(r"mount: \{x_mm: ([-\d.e]+), y_mm: ([-\d.e]+), z_mm: ([-\d.e]+), yaw_deg: ([-\d.e]+)\}", text)
x, y, z, yaw = (float(v) for v in m.groups())
off = (f"mount: {{x_mm: {x + mm}, y_mm: {y - mm}, z_mm: {z + mm}, roll_deg: {-deg}, "
       f"pitch_deg: {deg}, yaw_deg: {yaw + deg}}}")
open(dst, "w").write(text.replace(m.group(0), off))
EOF
  rm -f "$rec/calibrated.yaml"
  "$DESK" calibrate ranging-mount --config "$rec/off.yaml" --recording "$rec" \
    --replay "$WORK/out_floor_$seed" --out "$rec/mount_snippet.yaml" | tee "$WORK/calibrate_$seed.log"
  # ranging.yaml is an overlay of the recording's configuration, which `config apply` cannot check
  # alone: the snippet's mount replaces the off one here.
  python3 - "$rec/off.yaml" "$rec/mount_snippet.yaml" "$rec/calibrated.yaml" <<'EOF'
import re, sys
text = open(sys.argv[1]).read()
snip = dict(re.findall(r"^\s+(\w+): ([-\d.e]+)$", open(sys.argv[2]).read(), re.M))
mount = "mount: {" + ", ".join(f"{k}: {v}" for k, v in snip.items()) + "}"
open(sys.argv[3], "w").write(re.sub(r"mount: \{[^}]*\}", mount, text))
EOF
  python3 - "$rec/ranging.yaml" "$WORK/calibrate_$seed.log" <<'EOF'
import re, sys
t = open(sys.argv[1]).read()
m = re.search(r"mount: \{x_mm: ([-\d.e]+), y_mm: ([-\d.e]+), z_mm: ([-\d.e]+), yaw_deg: ([-\d.e]+)\}", t)
truth = dict(x_mm=float(m.group(1)), y_mm=float(m.group(2)), z_mm=float(m.group(3)),
             roll_deg=0.0, pitch_deg=0.0, yaw_deg=float(m.group(4)))
# The command's table: key, configured, calibrated, change, sigma.
rows = {r[0]: (float(r[2]), float(r[4])) for r in
        (l.split() for l in open(sys.argv[2])) if len(r) == 5 and r[0] in truth}
print("| axis | calibrated - true | sigma | error / sigma |")
print("|---|---|---|---|")
for k, v in truth.items():
    e = rows[k][0] - v
    print(f"| {k} | {e:+.4f} | {rows[k][1]:.4f} | {e / rows[k][1]:+.2f} |")
EOF
  # The off mount told as the doubt it is (sigma = the offsets): what the filter does without the
  # calibration but knowing it lacks one.
  sed -E "s/yaw_deg: ([-0-9.e]+)\}/yaw_deg: \1, sigma_deg: $OFF_DEG, sigma_mm: $OFF_MM}/" \
    "$rec/off.yaml" > "$rec/off_told.yaml"
  for mode in off off_told calibrated true; do
    cfg="$rec/$mode.yaml"
    rm -rf "$WORK/out_${mode}_$seed"
    "$AGVLOC" replay "$rec" --fast --quiet --config "$cfg" --out "$WORK/out_${mode}_$seed" \
      > "$WORK/replay_${mode}_$seed.log" 2>&1 || {
      cat "$WORK/replay_${mode}_$seed.log"; echo "mount_calibration_eval: replay failed" >&2; exit 1; }
  done
  echo "seed $seed, mounts off by $OFF_MM mm and $OFF_DEG deg per axis:"
  python3 "$ROOT/tools/eval/fusion/score_replay.py" "$rec" "$WORK/out_floor_$seed" \
    "$rec" "$WORK/out_off_$seed" "$rec" "$WORK/out_off_told_$seed" "$rec" \
    "$WORK/out_calibrated_$seed" "$rec" "$WORK/out_true_$seed"
done
