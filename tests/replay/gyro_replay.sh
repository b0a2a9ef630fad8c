#!/usr/bin/env bash
# The gyro reaches replay: a simulated recording with imu.csv is replayed and the summary reports
# every sample handed to the localizer, some fused. The same recording made with --no-gyro has no
# imu.csv, says so, and replays exactly like the gyro recording with its imu.csv deleted: the
# other files are the same, and nothing of the gyro path runs without the file. (Whether that is
# also the output from before the gyro input is golden_replay.sh's question.)
#   gyro_replay.sh AGVLOC WORKDIR
set -euo pipefail
source "$(dirname "$0")/replay_env.sh"
SIM=(sim --trajectory line --duration-s 4 --fps 15 --seed 7 --speed-mps 0.5)  # golden_replay.sh's

"${DESK[@]}" "${SIM[@]}" --out "$WORK/gyro" > "$WORK/sim_gyro.log"
test -f "$WORK/gyro/imu.csv" || { echo "FAIL: the simulator wrote no imu.csv"; exit 1; }
"${AGVLOC[@]}" replay "$WORK/gyro" --out "$WORK/out_gyro" --fast --quiet > "$WORK/replay_gyro.log"
rows=$(($(wc -l < "$WORK/gyro/imu.csv") - 1))
line=$(grep '^gyro: ' "$WORK/out_gyro/summary.txt") || { echo "FAIL: no gyro line in the summary"; exit 1; }
echo "with imu.csv ($rows rows): $line"
fused=$(sed -n 's/^gyro: \([0-9]*\) samples fused, \([0-9]*\) rejected (imu.csv: \([0-9]*\) rows)$/\1 \2 \3/p' <<< "$line")
read -r n_fused n_rejected n_rows <<< "$fused"
if [ -z "$fused" ] || [ "$n_rows" -ne "$rows" ] || [ "$n_fused" -le 0 ] ||
   [ $((n_fused + n_rejected)) -ne "$rows" ]; then
  echo "FAIL: expected every one of the $rows gyro samples handed to fusion, some fused"
  exit 1
fi

"${DESK[@]}" "${SIM[@]}" --no-gyro --out "$WORK/nogyro" > "$WORK/sim_nogyro.log"
test ! -e "$WORK/nogyro/imu.csv" || { echo "FAIL: --no-gyro wrote imu.csv"; exit 1; }
"${AGVLOC[@]}" replay "$WORK/nogyro" --out "$WORK/out_nogyro" --fast --quiet > "$WORK/replay_nogyro.log"
grep -qx 'gyro: none (no imu.csv: wheel odometry only)' "$WORK/out_nogyro/summary.txt" ||
  { echo "FAIL: the summary of a replay without imu.csv claims gyro samples"; exit 1; }
for f in odom.csv truth.csv frames.csv; do
  cmp -s "$WORK/gyro/$f" "$WORK/nogyro/$f" || { echo "FAIL: --no-gyro changed $f"; exit 1; }
done
cp -r "$WORK/gyro" "$WORK/deleted"
rm "$WORK/deleted/imu.csv"
"${AGVLOC[@]}" replay "$WORK/deleted" --out "$WORK/out_deleted" --fast --quiet > "$WORK/replay_deleted.log"
cmp -s "$WORK/out_nogyro/poses.csv" "$WORK/out_deleted/poses.csv" ||
  { echo "FAIL: poses.csv of the two recordings without imu.csv differ"; exit 1; }
# fixes.csv without column 13, vision_ms (measured time).
cmp -s <(cut -d, -f1-12,14- "$WORK/out_nogyro/fixes.csv") <(cut -d, -f1-12,14- "$WORK/out_deleted/fixes.csv") ||
  { echo "FAIL: fixes.csv of the two recordings without imu.csv differ"; exit 1; }
if cmp -s "$WORK/out_gyro/poses.csv" "$WORK/out_nogyro/poses.csv"; then
  echo "note: the gyro did not change the fused poses (fusion ignores it?)"
fi
echo "gyro replay OK: $n_fused of $rows gyro samples fused; without imu.csv: no gyro, same replay"
