#!/usr/bin/env bash
# The fused pose reaches the vision stage (docs/design/tracking.md): simulate a run over the mapped grid,
# replay it (--fast) with the map, and require that most landmark fixes were found in the
# prediction's search window (fixes.csv column `search`).
#   tracking_replay.sh AGVLOC WORKDIR MAP
set -euo pipefail
source "$(dirname "$0")/replay_env.sh"
MAP="$3"
"${DESK[@]}" sim --out "$WORK/rec" --trajectory line --duration-s 8 --fps 15 --seed 7 \
  --speed-mps 0.5 --map "$MAP" > "$WORK/sim.log"
"${AGVLOC[@]}" replay "$WORK/rec" --out "$WORK/out" --fast --quiet --map "$MAP" > "$WORK/replay.log"
python3 - "$WORK/out/fixes.csv" <<'PY'
import csv
import sys

rows = list(csv.DictReader(open(sys.argv[1], newline="")))
ok = [r for r in rows if r["status"] == "ok"]
window = [r for r in ok if r["search"] == "window"]
print(f"tracking replay: {len(rows)} frames, {len(ok)} fixes, {len(window)} found in the window")
# The first fix initialises the filter (no prediction yet); after it the pose is trusted.
if len(ok) < 10 or len(window) < 0.8 * len(ok):
    sys.exit("too few fixes found in the search window")
if any(r["identity"] != "qr" for r in ok):
    sys.exit("a QR fix without identity qr")
if any(r["search"] not in ("full", "window", "window+full") for r in rows):
    sys.exit("unknown search mode")
PY
