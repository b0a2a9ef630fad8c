#!/usr/bin/env bash
# Replay golden test: simulate a short deterministic recording, replay it (--fast) and compare the
# fused poses and the per-frame fixes with the stored golden files and with the truth.
#   golden_replay.sh AGVLOC WORKDIR [--update]
# AGVLOC may be "EMULATOR ARGS... BINARY"; the simulator is agvloc-desk beside BINARY.
set -euo pipefail
source "$(dirname "$0")/replay_env.sh"
UPDATE="${3:-}"
HERE="$(cd "$(dirname "$0")" && pwd)"
GOLDEN="$HERE/../data/replay"
"${DESK[@]}" sim --out "$WORK/rec" --trajectory line --duration-s 4 --fps 15 --seed 7 \
  --speed-mps 0.5 > "$WORK/sim.log"
"${AGVLOC[@]}" replay "$WORK/rec" --out "$WORK/out" --fast --quiet > "$WORK/replay.log"
if [ "$UPDATE" = "--update" ]; then
  cp "$WORK/out/poses.csv" "$GOLDEN/poses.csv"
  cp "$WORK/out/fixes.csv" "$GOLDEN/fixes.csv"
  echo "golden files updated in $GOLDEN"
  exit 0
fi
python3 "$HERE/compare_golden.py" "$GOLDEN" "$WORK/out" "$WORK/rec/truth.csv" || {
  echo "replay logs: $WORK/sim.log $WORK/replay.log; outputs in $WORK/out"
  exit 1
}
