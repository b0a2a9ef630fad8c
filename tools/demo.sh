#!/usr/bin/env bash
# The main job on the bundled default: install dependencies, build, simulate a demo recording
# (if absent), replay it through the localizer (vehicle binary agvloc), print the summary, then the
# accuracy against truth and the trajectory plot (desk tool agvloc-desk report).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/install-deps.sh
cmake --preset default
cmake --build --preset default -j "$(nproc)" --target agvloc agvloc-desk
BIN=build/default/firmware/agvloc
DESK=build/default/firmware/agvloc-desk
REC=demo/recording
OUT=demo/out
if [ ! -f "$REC/frames.csv" ]; then
  echo "demo: simulating a recording into $REC (default map tools/maps/default_grid.csv)"
  "$DESK" sim --out "$REC" --map tools/maps/default_grid.csv --trajectory lawnmower --duration-s 30 \
    --speed-mps 1.0 --exposure-ms 0.5 --seed 1
fi
"$BIN" replay "$REC" --out "$OUT" --fast --map tools/maps/default_grid.csv
"$DESK" report "$OUT" --recording "$REC" --map tools/maps/default_grid.csv
echo "demo: trajectory plot $OUT/trajectory.svg, fused poses $OUT/poses.csv, fixes $OUT/fixes.csv"
